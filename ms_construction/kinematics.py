"""Inverse kinematics of the construction arm (CPU, SAPIEN's Pinocchio model).

Used by the tests (every goal slot is reachable) and by the planning expert.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import sapien

import xml.etree.ElementTree as ET

from ms_construction.agents.construction_arm import REST_QPOS
from ms_construction.assets import ARM_URDF_PATH


class ArmIK:
    """Damped least-squares IK for the tcp link, restarted from several seeds."""

    def __init__(self, robot=None, tcp_link_name: str = "tcp"):
        """From a loaded articulation (physx_cpu), or, with `robot=None`, from the committed URDF alone (any
        backend, no scene: the URDF's joint order is the articulation's, a serial chain)."""
        if robot is None:
            from sapien.wrapper.pinocchio_model import PinocchioModel

            xml = ARM_URDF_PATH.read_text()
            self.model = PinocchioModel(xml, [0, 0, -9.81])
            names = _urdf_names(xml, "link")
            self.model.set_link_order(names)
            self.model.set_joint_order([j.get("name") for j in ET.fromstring(xml).iter("joint")
                                        if j.get("type") in ("revolute", "prismatic")])
            limits = np.array([[float(j.find("limit").get("lower")), float(j.find("limit").get("upper"))]
                               for j in ET.fromstring(xml).iter("joint") if j.get("type") in ("revolute", "prismatic")])
        else:
            art = robot._objs[0] if hasattr(robot, "_objs") else robot
            self.model = art.create_pinocchio_model()
            names = [link.name for link in art.get_links()]
            limits = np.concatenate([j.get_limits() for j in art.get_active_joints()])
        self.tcp_index = next(i for i, n in enumerate(names) if n == tcp_link_name or n.endswith("_" + tcp_link_name))
        self.lower, self.upper = limits[:, 0], limits[:, 1]

    def _wrap(self, q: np.ndarray) -> np.ndarray:
        """Shift angles by whole turns into the joint limits where that is possible."""
        q = q.copy()
        for shift in (2 * np.pi, -2 * np.pi):
            moved = q + shift
            fix = ((q < self.lower) | (q > self.upper)) & (moved >= self.lower) & (moved <= self.upper)
            q[fix] = moved[fix]
        return q

    def fk(self, qpos: np.ndarray) -> sapien.Pose:
        self.model.compute_forward_kinematics(np.asarray(qpos, dtype=np.float64))
        return self.model.get_link_pose(self.tcp_index)

    def solve(self, target: sapien.Pose, seeds: Optional[list] = None, n_random: int = 16, rng_seed: int = 0,
              pos_tol: float = 1e-3, rot_tol_deg: float = 0.5) -> Optional[np.ndarray]:
        """A joint configuration within limits whose tcp is at `target`, or None."""
        rng = np.random.default_rng(rng_seed)
        seeds = list(seeds or []) + [REST_QPOS] + [rng.uniform(self.lower, self.upper) for _ in range(n_random)]
        for seed in seeds:
            q = self.solve_from(target, seed, pos_tol, rot_tol_deg)
            if q is not None:
                return q
        return None

    def solve_all(self, target: sapien.Pose, seeds: list, min_distance: float = 0.1, pos_tol: float = 1e-3,
                  rot_tol_deg: float = 0.5) -> list[np.ndarray]:
        """The distinct solutions (further apart than `min_distance` rad) reached from `seeds`, in
        the order of their seeds."""
        found: list[np.ndarray] = []
        for seed in seeds:
            q = self.solve_from(target, seed, pos_tol, rot_tol_deg)
            if q is not None and all(np.abs(q - other).max() > min_distance for other in found):
                found.append(q)
        return found

    def solve_from(self, target: sapien.Pose, seed: np.ndarray, pos_tol: float = 1e-3,
                   rot_tol_deg: float = 0.5) -> Optional[np.ndarray]:
        """The solution damped least squares converges to from `seed`, or None."""
        q, _, _ = self.model.compute_inverse_kinematics(
            self.tcp_index, target, initial_qpos=np.asarray(seed, dtype=np.float64), max_iterations=500
        )
        q = self._wrap(np.asarray(q))
        if np.any(q < self.lower - 1e-6) or np.any(q > self.upper + 1e-6):
            return None
        err_p, err_r = pose_error(self.fk(q), target)
        return q if err_p <= pos_tol and err_r <= rot_tol_deg else None


def _urdf_names(xml: str, tag: str) -> list[str]:
    return [node.get("name") for node in ET.fromstring(xml) if node.tag == tag]


def pose_error(a: sapien.Pose, b: sapien.Pose) -> tuple[float, float]:
    """(position error in m, rotation error in degrees)."""
    dq = (a.inv() * b).q
    return float(np.linalg.norm(a.p - b.p)), float(np.rad2deg(2 * np.arccos(min(1.0, abs(dq[0])))))
