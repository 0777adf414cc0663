"""Start-state curricula for the construction tasks: training devices, outside the task's reward and evaluation.

Reverse curriculum generation (Florensa et al. 2017) from resets the env computes by IK alone, no demonstrations:

- `set_near_goal_starts`: a share of the resets start with the element held on a collision-free start path out of
  its goal (`carry_geometry`), at most a radius of the path out;
- `set_reach_starts`: the curriculum carried back through the grasp: a share of the other resets start on the last
  part of the reach path down to the element lying on the table.

`StartStates` is a mixin of ConstructionTaskEnv (it reads the task's state and poses its arm and element);
`NearGoalTimeLimit` cuts a near-goal start that has not placed in time. Evaluations reset as usual (share 0, the
default).
"""

from __future__ import annotations

from typing import Optional, Sequence, Union

import gymnasium as gym
import numpy as np
import torch

from mani_skill.utils.structs import Pose

from ms_construction.envs.carry_geometry import path_points
from ms_construction.goal_configurations import lift_configurations
from ms_construction.parameters import ELEMENT_KINDS, START_YAW_NOISE_DEG
from ms_construction.rotations import pose_inv, pose_mul, qmul, quat_z


class StartStates:
    """The start-state curricula of ConstructionTaskEnv (the module docstring)."""

    REACH_START_MAX = 0.75
    """a reach start without `set_reach_starts` poses the arm at most this fraction of the way to the table: the last
    stretch of the joint line passes the plate through the element lying there."""
    GRASP_START_HEIGHT = 0.2
    """m; with `set_reach_starts`, the reach path ends with the plate this far above the element's grasp face, inside
    every stage's tau_pick (0.3-0.4 m): an arm left there grasps at its first step."""

    def _init_start_states(self, reach_start_share: float) -> None:
        if not 0 <= reach_start_share <= 1:
            raise ValueError(f"reach_start_share must lie in [0, 1], got {reach_start_share}")
        self.reach_start_share = torch.tensor(float(reach_start_share)).expand(len(ELEMENT_KINDS))  # per task type
        self.near_goal_share = torch.zeros(len(ELEMENT_KINDS))  # per task type
        self.near_goal_radius, self.near_goal_max_steps = None, None
        self.reach_start_radius: Optional[torch.Tensor] = None  # set_reach_starts: [kinds, slots]; None: the kwarg's way
        self._grasp_start_q: Optional[torch.Tensor] = None

    def set_near_goal_starts(self, share: Union[float, Sequence[float]], radius: Union[float, Sequence[float]],
                             max_steps: Optional[int] = None) -> None:
        """From the next reset on, a `share` of episodes start with the element already held, the arm posed a
        fraction in [0, `radius`] (each one for all task types, or one per type in ELEMENT_KINDS order) of the way out
        along a usable start path from its installation configuration (`carry_geometry`: backed off the goal along
        the plate's axis, then on to a lift above the staging table), within the path's collision-free part.
        `info["near_goal_start"]` marks those episodes; with `max_steps`, one that has not placed within that many
        steps is truncated where the env is wrapped in `NearGoalTimeLimit` (a start close to the goal that has
        wandered off teaches little more for the rest of the step limit)."""
        kinds = len(ELEMENT_KINDS)
        radii = [float(radius)] * kinds if np.isscalar(radius) else [float(r) for r in radius]
        shares = [float(share)] * kinds if np.isscalar(share) else [float(s) for s in share]
        for name, given, values in (("radius", radius, radii), ("share", share, shares)):
            if len(values) != kinds:
                raise ValueError(f"near-goal starts: give one {name} or {kinds} ({', '.join(ELEMENT_KINDS)}), "
                                 f"got {given}")
        for name, value in [("share", s) for s in shares] + [("radius", r) for r in radii]:
            if not 0 <= value <= 1:
                raise ValueError(f"near-goal starts: {name} must lie in [0, 1], got {value}")
        if max_steps is not None and not 0 < max_steps:
            raise ValueError(f"near-goal starts: max_steps must be a positive step count or None, got {max_steps}")
        self.near_goal_share = torch.tensor(shares)
        self.near_goal_max_steps = None if max_steps is None else int(max_steps)
        self.near_goal_radius = torch.tensor(radii, dtype=torch.float32, device=self.device)

    def _start_near_goal(self, env_idx: torch.Tensor) -> None:
        paths, b = self.geometry.paths, len(env_idx)
        chosen = torch.rand(b) < self.near_goal_share[self.task_id[env_idx].cpu()]
        usable = paths["usable"][self.task_id[env_idx], self.goal_slot[env_idx]]
        waypoints = paths["waypoints"][self.task_id[env_idx], self.goal_slot[env_idx]]
        free = paths["free"][self.task_id[env_idx], self.goal_slot[env_idx]]
        ways = self.obstacle_ways()
        if ways is not None:  # with obstacles: on a way clear of them (a searched via or a detour where no usable
            # path is), and an ordinary reset where none is
            usable = self.geometry.clear_ways(self.task_id[env_idx], self.goal_slot[env_idx], ways.clear[env_idx])
            waypoints, free = ways.waypoints[env_idx], ways.free[env_idx]
            chosen &= usable.any(-1)
        if not bool(chosen.any()):
            return
        idx = env_idx[chosen]
        task = self.task_id[idx]
        path = torch.multinomial(usable[chosen].float(), 1)[:, 0]  # a usable (configuration, side)
        rows = torch.arange(len(idx))
        frac = torch.rand(len(idx)) * torch.minimum(free[chosen][rows, path], self.near_goal_radius[task])
        q = path_points(waypoints[chosen][rows, path], frac)
        turn = (torch.rand(len(idx)) * 2 - 1) * START_YAW_NOISE_DEG  # the element's turn on the plate
        q[:, 5] += torch.deg2rad(turn)
        qpos = self.agent.robot.get_qpos()[env_idx].clone()
        qpos[chosen] = q
        self._pose_arm(qpos)
        tcp = self.agent.tcp.pose.raw_pose[idx]
        grasp = self._grasp_in_el[task]
        hold = pose_inv(torch.cat([grasp[:, :3], qmul(grasp[:, 3:], quat_z(turn))], -1))
        element = self.obj.pose.raw_pose[env_idx].clone()
        element[chosen] = pose_mul(tcp, hold)
        self.obj.set_pose(Pose.create(element))
        self.gripper.held[idx] = True
        self.gripper.hold_pose_in_tcp[idx] = hold
        self.picked[idx] = True
        self.carry_side[idx] = path % 2
        self.near_goal_start[idx] = True
        self.reach_start_side[idx] = -1  # a near-goal start takes the place of a reach start drawn before it

    def _pose_arm(self, qpos: torch.Tensor) -> None:
        """Set the arm of the envs being reset to `qpos`, its links posed at once (on the GPU they follow the new
        joint positions only after a kinematics update)."""
        self.agent.reset(qpos)
        if self.gpu_sim_enabled:
            self.scene._gpu_apply_all()
            self.scene.px.gpu_update_articulation_kinematics()
            self.scene._gpu_fetch_all()

    def set_reach_starts(self, share: Union[float, Sequence[float]], radius: Union[float, Sequence[float]]) -> None:
        """From the next reset on, a `share` (one for all task types, or one per type in ELEMENT_KINDS order) of the
        resets that are not near-goal starts start on the last `radius` of the reach path's length, the element lying
        on the table. `radius`: one for all goal slots, one per task type in ELEMENT_KINDS order, or one per goal slot,
        those of each type in turn (a slot reached from the turret side the policy does not grasp from then widens on
        its own, not on the other slots' grasps). The path runs on the joint line from the reset's configuration to
        the lift above the element, on a turret side the goal slot's start paths leave from (`path_sides`), then
        down to GRASP_START_HEIGHT above it: radius 0 starts about to grasp, 1 anywhere from the reset on.
        `info["reach_start"]` marks those episodes and `info["reach_start_grasped"]` whether the element was grasped
        from the side the start was on."""
        kinds, slots = len(ELEMENT_KINDS), self._goal_table.shape[1]
        radii = [float(radius)] if np.isscalar(radius) else [float(r) for r in radius]
        if len(radii) not in (1, kinds, kinds * slots):
            raise ValueError(f"reach starts: give one radius, {kinds} ({', '.join(ELEMENT_KINDS)}) or {kinds * slots} "
                             f"(one per goal slot), got {radius}")
        shares = [float(share)] * kinds if np.isscalar(share) else [float(s) for s in share]
        if len(shares) != kinds:
            raise ValueError(f"reach starts: give one share or {kinds} ({', '.join(ELEMENT_KINDS)}), got {share}")
        for name, value in [("share", s) for s in shares] + [("radius", r) for r in radii]:
            if not 0 <= value <= 1:
                raise ValueError(f"reach starts: {name} must lie in [0, 1], got {value}")
        self.reach_start_share = torch.tensor(shares)
        per_slot = torch.tensor(radii, dtype=torch.float32, device=self.device)
        self.reach_start_radius = per_slot.view(-1, 1).expand(kinds, slots) if len(radii) < kinds * slots \
            else per_slot.view(kinds, slots)

    def _start_on_the_way(self, env_idx: torch.Tensor) -> None:
        """A `reach_start_share` of the resets (before near-goal starts draw theirs) start with the arm on the way to
        a table grasp configuration on a turret side that a usable start path of the goal slot leaves from, the
        element lying on the table: after `set_reach_starts`, on the last part of the path down to the element (its
        docstring); before, a uniform fraction in [0, REACH_START_MAX) of the joint line from the reset's
        configuration to the table grasp configuration."""
        chosen = torch.rand(len(env_idx)) < self.reach_start_share.to(self.device)[self.task_id[env_idx]]
        if not bool(chosen.any()):
            return
        idx = env_idx[chosen]
        task = self.task_id[idx]
        sides = self.geometry.path_sides(self.task_id, self.goal_slot, self.obstacle_ways())[idx]
        side = torch.multinomial(sides.float(), 1)[:, 0]
        qpos = self.agent.robot.get_qpos()[env_idx].clone()
        if self.reach_start_radius is not None:
            if self._grasp_start_q is None:
                f32 = dict(dtype=torch.float32, device=self.device)
                self._grasp_start_q = torch.stack([torch.tensor(lift_configurations(self.GRASP_START_HEIGHT), **f32),
                                                   torch.tensor(lift_configurations(), **f32)], 2)  # [kinds, 2, 2, 6]
            back = torch.cat([self._grasp_start_q[task, side], qpos[chosen][:, None]], 1)  # [m, 3, 6]
            radius = self.reach_start_radius[task, self.goal_slot[idx]]
            qpos[chosen] = path_points(back, torch.rand(len(idx)) * radius)
        else:
            target = self.geometry.table_q[task, side]
            qpos[chosen] += torch.rand(len(idx), 1) * self.REACH_START_MAX * (target - qpos[chosen])
        self._pose_arm(qpos)
        self.reach_start_side[idx] = side


class NearGoalTimeLimit(gym.Wrapper):
    """Truncates an episode that started near its goal (`set_near_goal_starts`) and has not placed within the
    `max_steps` given there; other episodes keep the task's step limit. Outside ManiSkill's TimeLimitWrapper,
    which sets `truncated` from the step limit alone."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        u = self.env.unwrapped
        if u.near_goal_max_steps is not None:
            truncated = truncated | (u.near_goal_start & (u.elapsed_steps >= u.near_goal_max_steps) & ~terminated)
        return obs, reward, terminated, truncated, info
