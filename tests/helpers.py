"""Shared test helpers: making envs, IK-driven joint-space moves, a step recorder, pose conversions."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import sapien
import torch
from transforms3d.euler import euler2quat

import ms_construction  # noqa: F401  (registration)
from ms_construction.kinematics import ArmIK
from ms_construction.planning import ExpertConfig

SLOW_MACHINE_RRT_TIME = 3.0
"""s; the expert's RRTConnect time limit in tests, 3x its default: RRTConnect returns as soon as it
connects, so the longer limit costs time only where a goal is out of reach, and a loaded CI machine
does not fail a plan that an idle one finds."""
TEST_EXPERT_CONFIG = ExpertConfig(rrt_time=SLOW_MACHINE_RRT_TIME)
PLAN_TRIES = 3
"""OMPL seeds its sampler from the clock: an expert-driven test gives an unlucky plan this many tries."""


def to_sapien(raw: torch.Tensor, i: int = 0) -> sapien.Pose:
    t = raw.detach().cpu().numpy()[i]
    return sapien.Pose(t[:3], t[3:])


def make_env(env_id: str, **kwargs):
    kwargs.setdefault("obs_mode", "state")
    kwargs.setdefault("control_mode", "pd_joint_pos")
    kwargs.setdefault("reward_mode", "sparse")
    return gym.make(env_id, **kwargs)


class JointMover:
    """Drives a pd_joint_pos env along straight joint-space segments to IK solutions."""

    def __init__(self, env):
        self.env = env
        self.u = env.unwrapped
        self.ik = ArmIK(self.u.agent.robot)
        self.q = self.u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)
        self.rewards, self.terminated, self.infos = [], [], []

    def solve(self, tcp_target: sapien.Pose) -> np.ndarray:
        q = self.ik.solve(tcp_target, seeds=[self.q])
        assert q is not None, f"no IK solution for tcp pose {tcp_target}"
        return q

    def move_to(self, q_goal: np.ndarray, steps: int, stop_on_done: bool = True) -> bool:
        """Step towards q_goal; True if the episode terminated on the way."""
        q_start = self.q.copy()
        for i in range(1, steps + 1):
            self.q = q_start + (q_goal - q_start) * i / steps
            _, r, term, _, info = self.env.step(torch.tensor(self.q[None], dtype=torch.float32))
            self.rewards.append(float(r[0]))
            self.terminated.append(bool(term[0]))
            self.infos.append({k: v[0].item() for k, v in info.items() if torch.is_tensor(v)})
            if stop_on_done and bool(term[0]):
                return True
        return False

    def grasp_pose_above(self, distance: float) -> sapien.Pose:
        """tcp pose facing the element's grasp face at `distance` along its normal."""
        u = self.u
        k = int(u.task_id[0])
        return to_sapien(u.obj.pose.raw_pose) * to_sapien(u._grasp_in_el[k:k + 1]) * sapien.Pose([0, 0, -distance])

    def install_targets(self, psi_deg: float = 0.0, standoff: float = 0.3):
        """(pre-install, install) tcp poses for the held element at its goal."""
        u = self.u
        goal = to_sapien(u.goal_pose.raw_pose)
        hold = to_sapien(u.hold_pose_in_tcp)  # element in tcp frame
        tcp_at_goal = goal * hold.inv()
        return tcp_at_goal * sapien.Pose([0, 0, -standoff]), tcp_at_goal


class StepLog(gym.Wrapper):
    """Records every step's reward, termination and info of a single env."""

    def reset(self, **kwargs):
        self.rewards, self.terminated, self.infos = [], [], []
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.rewards.append(float(reward[0]))
        self.terminated.append(bool(terminated[0]))
        self.infos.append({k: v.reshape(-1)[0].item() for k, v in info.items() if torch.is_tensor(v)})
        return obs, reward, terminated, truncated, info


def quat_z(deg: float) -> np.ndarray:
    return np.array(euler2quat(0, 0, np.deg2rad(deg)))
