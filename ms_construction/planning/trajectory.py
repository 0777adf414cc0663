"""Joint paths: straight tcp lines by IK, densification, and time parameterization (TOPP-RA).

A planner's path is a polyline in joint space whose segments were collision-checked. mplib's own
`Planner.TOPP` fits a cubic spline through the waypoints at equally spaced path parameters, which
can bulge far off long segments; here the path is first densified and parameterized by its
length, so the spline stays on the checked polyline (and the result is checked again anyway).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import sapien
import toppra as ta
import toppra.algorithm as ta_algo
import toppra.constraint as ta_constraint
from transforms3d.quaternions import qinverse, qmult, quat2axangle

from ms_construction.kinematics import ArmIK

ta.setup_logging("WARNING")


def densify(path: np.ndarray, max_step: float) -> np.ndarray:
    """The polyline `path` [n, dof] with points inserted so that no joint moves more than
    `max_step` (rad) between consecutive points."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(np.ceil(np.abs(b - a).max() / max_step)))
        out.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    return np.concatenate(out)


def time_parameterize(path: np.ndarray, vel: np.ndarray, acc: np.ndarray, dt: float,
                      max_step: float = 0.05) -> np.ndarray:
    """Joint targets [T, dof] at times dt, 2 dt, ... of the fastest motion along `path` within the
    velocity and acceleration limits, starting and ending at rest; the last target is the path's end."""
    path = densify(np.asarray(path, float), max_step)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])  # a spline needs strictly increasing knots
    path, s = path[keep], np.concatenate([[0.0], np.cumsum(seg[seg > 1e-9])])
    if len(path) < 2:
        return path[-1:].copy()
    spline = ta.SplineInterpolator(s, path, bc_type="clamped")
    constraints = [ta_constraint.JointVelocityConstraint(vel), ta_constraint.JointAccelerationConstraint(acc)]
    traj = ta_algo.TOPPRA(constraints, spline, parametrizer="ParametrizeConstAccel").compute_trajectory(0, 0)
    if traj is None:
        raise RuntimeError("TOPP-RA found no parameterization")
    n = max(1, int(np.ceil(traj.duration / dt - 1e-6)))
    qs = traj(np.minimum(np.arange(1, n + 1) * dt, traj.duration))
    qs[-1] = path[-1]
    return qs


def interpolate_pose(a: sapien.Pose, b: sapien.Pose, t: float) -> sapien.Pose:
    """Straight line in position, shortest rotation in orientation."""
    dq = qmult(qinverse(a.q), b.q)
    if dq[0] < 0:
        dq = -dq
    axis, angle = quat2axangle(dq)
    return sapien.Pose(a.p + (b.p - a.p) * t, qmult(a.q, np.r_[np.cos(angle * t / 2), np.sin(angle * t / 2) * axis]))


def tcp_line(ik: ArmIK, q_start: np.ndarray, goal: sapien.Pose, step: float = 0.01, angle_step: float = 0.02,
             max_joint_step: float = 0.1) -> Optional[np.ndarray]:
    """Joint path [n, dof] moving the tcp on a straight line from where it is at `q_start` to `goal`
    (steps of at most `step` m and `angle_step` rad), by IK from each point to the next; None where
    IK fails or a joint would jump."""
    start = ik.fk(q_start)
    angle = quat2axangle(qmult(qinverse(start.q), goal.q))[1]
    angle = min(angle, 2 * np.pi - angle)
    n = max(1, int(np.ceil(max(np.linalg.norm(goal.p - start.p) / step, angle / angle_step))))
    path = [np.asarray(q_start, float)]
    for i in range(1, n + 1):
        q = ik.solve_from(interpolate_pose(start, goal, i / n), path[-1])
        if q is None or np.abs(q - path[-1]).max() > max_joint_step:
            return None
        path.append(q)
    return np.array(path)
