"""The construction pick-and-place task shared by the four environments.

One class holds the mechanics; `ms_construction/envs/tasks.py` registers the general task and the
three single-task environments with their task cards.

The suction plate's grasp sensor and hold are `ms_construction.agents.suction_gripper`; this module
decides which element each env works on, when a grasp counts (first grasp, picked) and when it is
placed.
"""

from __future__ import annotations

import functools
import os
from typing import Any, Mapping, Optional, Sequence, Union

import gymnasium as gym
import numpy as np
import sapien
import torch

from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.structs import Actor, Pose
from mani_skill.utils.structs.types import GPUMemoryConfig, SimConfig

from ms_construction.agents.construction_arm import ConstructionArm
from ms_construction.agents.suction_gripper import PLATE_ELEMENT_COLLISION_BIT, SuctionGripper, grasp_ray
from ms_construction.curriculum import FINAL_STAGE, TOLERANCE_KEYS, resolve_tolerances, stage_tolerances, validate_tolerances
from ms_construction.goal_configurations import (install_configurations, lift_configurations, mirror_branch_mask,
                                                  mirror_twins, symmetry_period)
from ms_construction.parameters import (
    DROP_CLEARANCE,
    ELEMENT_KINDS,
    HIDDEN_POSE,
    START_XY_NOISE,
    START_YAW_DEG,
    START_YAW_NOISE_DEG,
    STORAGE_XY,
    SYMMETRIES_DEG,
)
from ms_construction.rotations import pose_inv, pose_mul, qangle_deg, qaxis, qconj, qmul, quat_z
from ms_construction.site import ConstructionSiteSceneBuilder, build_element

ROBOT_INIT_QPOS_NOISE = 0.02
"""rad; std of the arm's start configuration around its rest keyframe, per joint."""
JOINT_MIRROR_SIGNS = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
"""How each arm joint turns in the mirror image of the arm in its base's plane y = 0: joints 1, 4 and 6 turn about
axes in that plane (z, x, x) and turn the other way, joints 2, 3 and 5 about axes across it (y) the same way; every
link's offsets lie in the plane (assets/arm/construction_arm.urdf), so the mirrored arm is the arm at these signs."""
MIRROR_SIGNS = {"joints": JOINT_MIRROR_SIGNS, "scalars": (1.0,), "vector": (1.0, -1.0, 1.0),
                "pose": (1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0)}
"""How each kind of entry changes in the mirror image in the plane y = 0: joints by JOINT_MIRROR_SIGNS, the y of a
position or vector, the x and z of a quaternion [w, x, y, z] (the rotation M R M, M = diag(1, -1, 1))."""
STATE_LAYOUT = (("qpos", 6, "joints"), ("qvel", 6, "joints"), ("is_grasped", 1, "scalars"), ("tcp_pose", 7, "pose"),
                ("goal_pose", 7, "pose"), ("task", 3, "scalars"), ("obj_pose", 7, "pose"),
                ("tcp_to_grasp_pos", 3, "vector"), ("obj_to_goal_pos", 3, "vector"))
"""The flat `state` observation's entries in order (the agent's, then `_get_obs_extra`'s): name, size, and the kind
of MIRROR_SIGNS it is; after them the optional joint moves (`obs_install_offset`, `obs_path_offset`: 6 joints each)
and the elapsed time (1)."""
STATE_START = dict(zip([name for name, _, _ in STATE_LAYOUT],
                       np.cumsum([0] + [size for _, size, _ in STATE_LAYOUT[:-1]]).tolist()))
"""Where each entry of STATE_LAYOUT starts in the flat `state` observation."""
STATE_SIZE = sum(size for _, size, _ in STATE_LAYOUT)
STATE_QUATERNION_STARTS = tuple(STATE_START[name] + 3 for name in ("tcp_pose", "goal_pose", "obj_pose"))
"""Where the quaternions [w, x, y, z] of the plate (tcp_pose), the goal and the element start."""
STATE_TASK_START = STATE_START["task"]
"""Where the task's one-hot (ELEMENT_KINDS order) starts."""
STATE_GOAL_Y, STATE_IS_GRASPED = STATE_START["goal_pose"] + 1, STATE_START["is_grasped"]
"""Where the goal's y and is_grasped are."""


def state_mirror_signs(obs_dim: int) -> torch.Tensor:
    """[obs_dim] the signs that turn a flat `state` observation into the one of its mirror image in the plane y = 0:
    each entry of STATE_LAYOUT by its kind's MIRROR_SIGNS, then the joint moves by JOINT_MIRROR_SIGNS and the elapsed
    time unchanged."""
    extra, elapsed = divmod(obs_dim - STATE_SIZE, 6)
    if obs_dim < STATE_SIZE or elapsed > 1:
        raise ValueError(f"state_mirror_signs: a state observation has {STATE_SIZE} numbers, then 6 per joint move and "
                         f"1 for the elapsed time, not {obs_dim}")
    signs = [x for _, size, kind in STATE_LAYOUT for x in MIRROR_SIGNS[kind] * (size // len(MIRROR_SIGNS[kind]))]
    return torch.tensor(signs + list(JOINT_MIRROR_SIGNS) * extra + [1.0] * elapsed)


def _bearing(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(1 + cos of the angle between two horizontal directions from the arm's axis) / 2, in [0, 1]."""
    cos = (a * b).sum(-1) / (torch.linalg.norm(a, dim=-1) * torch.linalg.norm(b, dim=-1)).clamp(min=1e-6)
    return (1 + cos) / 2


RENDER_BACKEND_ENV = "MS_CONSTRUCTION_RENDER_BACKEND"
"""the render backend chosen by `default_render_backend`, passed on to child processes (env workers)."""


@functools.lru_cache(maxsize=None)
def default_render_backend() -> str:
    """ManiSkill's default render backend ("gpu") where sapien finds a CUDA device, else "cpu", said
    once: asked for "gpu" without CUDA, ManiSkill warns in every env it makes (every env process,
    every evaluation) before falling back to the CPU."""
    if os.environ.get(RENDER_BACKEND_ENV):
        return os.environ[RENDER_BACKEND_ENV]
    try:
        sapien.Device("cuda")
        backend = "gpu"
    except RuntimeError:
        backend = "cpu"
        print("ms_construction: no CUDA device found, rendering on the CPU (render_backend='cpu')")
    os.environ[RENDER_BACKEND_ENV] = backend
    return backend


class ConstructionTaskEnv(BaseEnv):
    """Base of the construction tasks; see ms_construction/envs/tasks.py for the task cards."""

    SUPPORTED_ROBOTS = ["construction_arm"]
    SUPPORTED_REWARD_MODES = ("sparse", "dense", "normalized_dense", "none")
    MAX_EPISODE_STEPS = 250
    """10 s at 20 Hz: a planned pick-carry-place takes about half of it."""
    DENSE_REWARD_MAX = 10.0
    """what placing pays; the most a held step pays is 4.5, so that an absorbing success is worth more than twice
    hovering near the goal for ever (at 5, hovering was worth 85% of placing and policies settled for it)."""
    TASKS: tuple[str, ...] = ELEMENT_KINDS
    """task types this environment samples from."""
    agent: ConstructionArm

    def __init__(
        self,
        *args,
        robot_uids: str = "construction_arm",
        robot_init_qpos_noise: float = ROBOT_INIT_QPOS_NOISE,
        curriculum_stage: str = FINAL_STAGE,
        tolerances: Optional[dict] = None,
        tasks: Optional[Sequence[str]] = None,
        task_weights: Optional[Mapping[str, float]] = None,
        goal_slot_weights: Optional[Mapping[str, Sequence[float]]] = None,
        obs_elapsed_time: bool = False,
        obs_install_offset: bool = False,
        obs_path_offset: bool = False,
        carry_along_paths: bool = False,
        reach_in_joint_space: bool = False,
        reach_toward_path_sides: bool = False,
        reach_avoids_vias: bool = False,
        reach_start_share: float = 0.0,
        reach_starts_to_lift: bool = False,
        carry_counts_lag: bool = False,
        carry_keeps_to_vias: bool = False,
        install_mirror_branch: bool = False,
        **kwargs,
    ):
        self._tol_init = resolve_tolerances(curriculum_stage, tolerances)
        self.curriculum_stage = curriculum_stage
        if tasks is not None:
            if len(self.TASKS) == 1:
                raise ValueError(f"'tasks' is a kwarg of the general task only; {type(self).__name__} is {self.TASKS[0]}")
            tasks = tuple(tasks)
            bad = [t for t in tasks if t not in ELEMENT_KINDS]
            if bad or not tasks or len(set(tasks)) != len(tasks):
                raise ValueError(f"tasks={tasks!r}: give distinct task types from {ELEMENT_KINDS}")
            self.TASKS = tuple(t for t in ELEMENT_KINDS if t in tasks)
        self._task_weights = self._check_task_weights(task_weights)
        self._goal_slot_weights_kwarg = goal_slot_weights
        self.obs_elapsed_time = bool(obs_elapsed_time)
        self.obs_install_offset = bool(obs_install_offset)
        self.obs_path_offset = bool(obs_path_offset)
        self.carry_along_paths = bool(carry_along_paths)
        self.reach_in_joint_space = bool(reach_in_joint_space)
        if reach_toward_path_sides and not reach_in_joint_space:
            raise ValueError("reach_toward_path_sides=True narrows the joint-space reach: give reach_in_joint_space=True too")
        self.reach_toward_path_sides = bool(reach_toward_path_sides)
        if reach_avoids_vias and not reach_toward_path_sides:
            raise ValueError("reach_avoids_vias=True narrows the sides the reach counts: give reach_toward_path_sides=True too")
        self.reach_avoids_vias = bool(reach_avoids_vias)
        if not 0 <= reach_start_share <= 1:
            raise ValueError(f"reach_start_share must lie in [0, 1], got {reach_start_share}")
        self.reach_start_share = torch.tensor(float(reach_start_share)).expand(len(ELEMENT_KINDS))  # per task type
        self.reach_starts_to_lift = bool(reach_starts_to_lift)
        self.carry_counts_lag = bool(carry_counts_lag)
        self.carry_keeps_to_vias = bool(carry_keeps_to_vias)
        self.install_mirror_branch = bool(install_mirror_branch)
        self.robot_init_qpos_noise = robot_init_qpos_noise
        self._step_grasp_frame, self._in_step_readout = None, False
        self.near_goal_share, self.near_goal_radius, self.near_goal_max_steps = 0.0, None, None
        self.reach_start_radius: Optional[torch.Tensor] = None  # set_reach_starts: [kinds, slots]; None: the kwargs' way
        kwargs.setdefault("render_backend", default_render_backend())
        super().__init__(*args, robot_uids=robot_uids, **kwargs)

    def _check_task_weights(self, weights: Optional[Mapping[str, float]]) -> Optional[torch.Tensor]:
        """`task_weights` as sampling probabilities in the order of self.TASKS (None: uniform). A task type
        not named weighs 1, so {"window": 2} samples window installation half the time."""
        if weights is None:
            return None
        if len(self.TASKS) == 1:
            raise ValueError(f"'task_weights' is a kwarg of the general task only; {type(self).__name__} is {self.TASKS[0]}")
        bad = [k for k in weights if k not in self.TASKS]
        w = [float(weights.get(k, 1.0)) for k in self.TASKS]
        if bad or min(w) < 0 or sum(w) <= 0:
            raise ValueError(f"task_weights={dict(weights)!r}: give weights >= 0, not all 0, for task types of {self.TASKS}")
        return torch.tensor(w) / sum(w)

    def _check_goal_slot_weights(self, weights: Optional[Mapping[str, Sequence[float]]]) -> Optional[torch.Tensor]:
        """`goal_slot_weights` as per-task-type sampling probabilities of the goal slots [3 kinds, slots] (None: uniform).
        A task type not named draws its slots uniformly, so {"window": (1, 1, 4)} draws the window opening at
        y = +0.85 two times in three."""
        if weights is None:
            return None
        slots = self._goal_table.shape[1]
        table = torch.ones(len(ELEMENT_KINDS), slots)
        for kind, w in weights.items():
            w = [float(x) for x in w]
            if kind not in ELEMENT_KINDS or len(w) != slots or min(w) < 0 or sum(w) <= 0:
                raise ValueError(f"goal_slot_weights={dict(weights)!r}: give, per task type of {ELEMENT_KINDS}, {slots} "
                                 "weights >= 0, not all 0")
            table[ELEMENT_KINDS.index(kind)] = torch.tensor(w)
        return (table / table.sum(-1, keepdim=True)).to(self.device)

    def set_task_weights(self, weights: Optional[Mapping[str, float]]) -> None:
        """From the next reset on, sample the general task's task types with these weights (as the `task_weights`
        kwarg; None: uniform): how a trainer samples more of the task types its policy fails."""
        self._task_weights = self._check_task_weights(weights)

    # ------------------------------------------------------------------------------------- #
    # configuration
    # ------------------------------------------------------------------------------------- #
    @property
    def _default_sim_config(self):
        return SimConfig(
            spacing=12.0,  # the site with its storage area spans about 5.5 m
            sim_freq=100,
            control_freq=20,
            gpu_memory_config=GPUMemoryConfig(
                max_rigid_contact_count=2**21, max_rigid_patch_count=2**19, found_lost_pairs_capacity=2**25
            ),
        )

    @property
    def _default_sensor_configs(self):
        pose = sapien_utils.look_at(eye=[-0.2, -2.1, 2.2], target=[-0.1, 0.0, 0.8])
        return [CameraConfig("base_camera", pose, 128, 128, 1.4, 0.01, 20)]

    @property
    def _default_human_render_camera_configs(self):
        # from a corner of the site under the slab: staging table, arm, wall with windows, floor
        # recesses and (above) the ceiling openings
        pose = sapien_utils.look_at(eye=[-1.1, -1.9, 2.25], target=[0.3, 0.3, 0.95])
        return CameraConfig("render_camera", pose, 512, 512, 1.45, 0.01, 30)

    def _load_agent(self, options: dict):
        super()._load_agent(options, sapien.Pose())

    # ------------------------------------------------------------------------------------- #
    # scene
    # ------------------------------------------------------------------------------------- #
    def _load_scene(self, options: dict):
        self.site = ConstructionSiteSceneBuilder(self, robot_init_qpos_noise=self.robot_init_qpos_noise)
        self.site.build()
        m = self.site.manifest
        self.elements: dict[str, Actor] = {}
        self.goal_markers: dict[str, Actor] = {}
        for kind in self.TASKS:
            el = build_element(self.scene, kind, f"{kind}_element", manifest=m)
            el.set_collision_group_bit(2, PLATE_ELEMENT_COLLISION_BIT, 1)
            self.elements[kind] = el
            self.goal_markers[kind] = self._build_goal_marker(kind, m)
        self.agent.plate.set_collision_group_bit(2, PLATE_ELEMENT_COLLISION_BIT, 1)

        n, dev = self.num_envs, self.device
        kinds = ELEMENT_KINDS
        f32 = dict(dtype=torch.float32, device=dev)
        # per task type (indexed by task_id): goals [3, slots, 7], grasp pose [3, 7], sizes [3, 3]
        self._goal_table = torch.tensor([m["goal_poses"][k] for k in kinds], **f32)
        self._goal_slot_weights = self._check_goal_slot_weights(self._goal_slot_weights_kwarg)
        self._grasp_in_el = torch.tensor([m["elements"][k]["grasp_pose"] for k in kinds], **f32)
        self._el_size = torch.tensor([m["elements"][k]["size"] for k in kinds], **f32)
        syms = [list(SYMMETRIES_DEG[k]) + [0.0] * (4 - len(SYMMETRIES_DEG[k])) for k in kinds]
        self._sym_quats = quat_z(torch.tensor(syms, **f32))  # [3, 4, 4]; padding repeats identity
        self._start_yaw = torch.tensor([START_YAW_DEG[k] for k in kinds], **f32)
        self._task_choices = torch.tensor([kinds.index(k) for k in self.TASKS], device=dev)
        st = m["staging"]
        self._staging_xyz = torch.tensor(st["center"], **f32)

        # task state (also in get_state_dict)
        self.task_id = torch.full((n,), int(self._task_choices[0]), dtype=torch.long, device=dev)
        self.goal_slot = torch.zeros(n, dtype=torch.long, device=dev)
        self.gripper = SuctionGripper(self.agent.tcp, n, dev, self.sim_config.scene_config.gravity, self.sim_freq,
                                      self.gpu_sim_enabled)
        self.picked = torch.zeros(n, dtype=torch.bool, device=dev)
        self.first_grasp_now = torch.zeros(n, dtype=torch.bool, device=dev)
        self.near_goal_start = torch.zeros(n, dtype=torch.bool, device=dev)
        self.reach_start_side = torch.full((n,), -1, dtype=torch.long, device=dev)  # a reach start's turret side; -1: none
        self.carry_prev = torch.full((n,), -1.0, **f32)  # the carry distance at the last dense reward; -1: none
        # the turret side (0: +pi, 1: -pi, as StartPaths) the held element was grasped from; -1: none this episode
        self.carry_side = torch.full((n,), -1, dtype=torch.long, device=dev)
        self._start_paths = None  # the start-state curriculum's paths, loaded when it is first switched on
        self.tolerances = torch.tensor([[self._tol_init[k] for k in TOLERANCE_KEYS]], **f32).repeat(n, 1)
        self.obj = self.elements[self.TASKS[0]]
        self._element_body_index: Optional[torch.Tensor] = None  # [kinds, num_envs], GPU only
        self._task_onehot = torch.eye(len(kinds), **f32)
        # the dense reward's carry: installation configurations [3, slots, K, 6] (IK, a few seconds: made when
        # first needed) and joint 6's period per kind
        self._install_q: Optional[torch.Tensor] = None
        self._mirrored_slot: Optional[torch.Tensor] = None  # [3, slots] bool, with `install_mirror_branch`
        self._table_q: Optional[torch.Tensor] = None
        self._lift_q: Optional[torch.Tensor] = None
        self._grasp_start_q: Optional[torch.Tensor] = None
        self._sym_period = torch.tensor([symmetry_period(k) for k in kinds], **f32)

    def _build_goal_marker(self, kind: str, manifest: dict) -> Actor:
        """A translucent green ghost of the element at its goal (human render only)."""
        builder = self.scene.create_actor_builder()
        half = np.array(manifest["elements"][kind]["size"]) / 2
        builder.add_box_visual(half_size=half, material=sapien.render.RenderMaterial(base_color=[0.1, 0.9, 0.2, 0.35]))
        builder.initial_pose = sapien.Pose(p=HIDDEN_POSE[:3], q=HIDDEN_POSE[3:])
        marker = builder.build_kinematic(name=f"{kind}_goal_marker")
        self._hidden_objects.append(marker)
        return marker

    # ------------------------------------------------------------------------------------- #
    # episode
    # ------------------------------------------------------------------------------------- #
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            self.site.initialize(env_idx)
            if len(self.TASKS) > 1:
                if self._task_weights is None:
                    pick = torch.randint(len(self._task_choices), (b,))
                else:
                    pick = torch.multinomial(self._task_weights.to(self.device), b, replacement=True)
                self.task_id[env_idx] = self._task_choices[pick]
                self._select_active_elements()
            task = self.task_id[env_idx]
            if self._goal_slot_weights is None:
                self.goal_slot[env_idx] = torch.randint(self._goal_table.shape[1], (b,))
            else:  # one draw per env from its task type's row
                self.goal_slot[env_idx] = torch.multinomial(self._goal_slot_weights[task], 1)[:, 0]

            xyz = self._staging_xyz.repeat(b, 1)
            xyz[:, :2] += (torch.rand(b, 2) * 2 - 1) * START_XY_NOISE
            xyz[:, 2] += self._el_size[task, 2] / 2 + DROP_CLEARANCE
            yaw = self._start_yaw[task] + (torch.rand(b) * 2 - 1) * START_YAW_NOISE_DEG
            start = torch.cat([xyz, quat_z(yaw)], -1)
            zeros = torch.zeros(b, 3)
            for kind, el in self.elements.items():
                k = ELEMENT_KINDS.index(kind)
                active = (task == k)[:, None]
                el.set_pose(Pose.create(torch.where(active, start, self._storage_pose(kind, b))))
                el.set_linear_velocity(zeros)
                el.set_angular_velocity(zeros)
            self._place_goal_markers(env_idx)

            # `plate_turn` (the joint 6 part of `install_offset`, `path_offset` and the carry) reads the hold before the
            # grasp sets it: until then the element counts as unturned, as it lies in `install_configurations`
            self.gripper.reset(env_idx, pose_inv(self._grasp_in_el[task]))
            self.picked[env_idx] = False
            self.first_grasp_now[env_idx] = False
            self.near_goal_start[env_idx] = False
            self.reach_start_side[env_idx] = -1
            self.carry_prev[env_idx] = -1.0
            self.carry_side[env_idx] = -1
            if bool((self.reach_start_share > 0).any()):
                self._start_on_the_way(env_idx)
            if self.near_goal_share > 0:
                self._start_near_goal(env_idx)

    # ------------------------------------------------------------------------------------- #
    # start-state curriculum (reverse curriculum generation, Florensa et al. 2017)
    # ------------------------------------------------------------------------------------- #
    def set_near_goal_starts(self, share: float, radius: Union[float, Sequence[float]],
                             max_steps: Optional[int] = None) -> None:
        """From the next reset on, a `share` of episodes start with the element already held, the arm posed a
        fraction in [0, `radius`] (one for all task types, or one per type in ELEMENT_KINDS order) of the way out
        along a start path from its installation configuration
        (`goal_configurations.StartPaths`: backed off the goal along the plate's axis, then on the joint line to
        a lift above the staging table), within the path's collision-free part. Everything comes from IK of
        the goal and the table (no demonstrations). `info["near_goal_start"]` marks those episodes; with
        `max_steps`, one that has not placed within that many steps is truncated where the env is wrapped in
        `NearGoalTimeLimit` (a start close to the goal that has wandered off teaches little more for the rest of
        the step limit). A training device: evaluations use
        ordinary resets (share 0, the default)."""
        radii = [float(radius)] * len(ELEMENT_KINDS) if np.isscalar(radius) else [float(r) for r in radius]
        if len(radii) != len(ELEMENT_KINDS):
            raise ValueError(f"near-goal starts: give one radius or {len(ELEMENT_KINDS)} ({', '.join(ELEMENT_KINDS)}), got {radius}")
        for name, value in [("share", share)] + [("radius", r) for r in radii]:
            if not 0 <= value <= 1:
                raise ValueError(f"near-goal starts: {name} must lie in [0, 1], got {value}")
        if share > 0:
            self._load_start_paths()
        if max_steps is not None and not 0 < max_steps:
            raise ValueError(f"near-goal starts: max_steps must be a positive step count or None, got {max_steps}")
        self.near_goal_share = float(share)
        self.near_goal_max_steps = None if max_steps is None else int(max_steps)
        self.near_goal_radius = torch.tensor(radii, dtype=torch.float32, device=self.device)

    def _load_start_paths(self) -> dict:
        """The start paths (`goal_configurations.start_paths`, a few seconds once per process) as tensors."""
        if self._start_paths is None:
            from ms_construction.goal_configurations import start_paths

            paths = start_paths()
            f32 = dict(dtype=torch.float32, device=self.device)
            usable = paths.usable & self._kept_configurations()[..., None]
            self._start_paths = dict(waypoints=torch.tensor(paths.waypoints, **f32), free=torch.tensor(paths.free, **f32),
                                     usable=torch.tensor(usable, device=self.device).flatten(2).float(),
                                     planned=torch.tensor(paths.planned, device=self.device).flatten(2).float())
        return self._start_paths

    def _kept_configurations(self) -> np.ndarray:
        """[kinds, slots, configurations] bool: the installation configurations (and their start paths) the carry is
        measured to, and near-goal starts start on: with `install_mirror_branch`, those of the window opening at
        y = +0.85 cut to the wrist branch whose mirror image is the opening at -0.85's but for joint 6
        (`goal_configurations.mirror_branch_mask`), for a policy that meets the one as the mirror image of the
        other (ppo.py's `--mirror-windows`); all of them otherwise."""
        shape = install_configurations().shape[:3]
        return mirror_branch_mask(JOINT_MIRROR_SIGNS) if self.install_mirror_branch else np.ones(shape, dtype=bool)

    @staticmethod
    def _path_points(waypoints: torch.Tensor, fraction: torch.Tensor) -> torch.Tensor:
        """[m, 6]: the configurations `fraction` [m] of the way along polylines of joint configurations [m, p, 6],
        by their summed joint-space (L1) length (goal_configurations.path_point, batched)."""
        seg = (waypoints[:, 1:] - waypoints[:, :-1]).abs().sum(-1)  # [m, p - 1]
        at = (fraction * seg.sum(-1))[:, None]
        start = torch.cumsum(seg, -1) - seg
        w = ((at - start) / seg.clamp(min=1e-9)).clamp(0, 1) * (seg > 0)  # how far along each segment
        return waypoints[:, 0] + (w[..., None] * (waypoints[:, 1:] - waypoints[:, :-1])).sum(1)

    def _start_near_goal(self, env_idx: torch.Tensor) -> None:
        sp, b = self._start_paths, len(env_idx)
        chosen = torch.rand(b) < self.near_goal_share
        if not bool(chosen.any()):
            return
        idx = env_idx[chosen]
        task, slot = self.task_id[idx], self.goal_slot[idx]
        path = torch.multinomial(sp["usable"][task, slot], 1)[:, 0]  # a usable (configuration, side) of the slot
        c, side = path // 2, path % 2
        frac = torch.rand(len(idx)) * torch.minimum(sp["free"][task, slot, c, side], self.near_goal_radius[task])
        q = self._path_points(sp["waypoints"][task, slot, c, side], frac)
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
        self.carry_side[idx] = side
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

    REACH_START_MAX = 0.75
    """a reach start poses the arm at most this fraction of the way to the table: the last stretch of the joint line
    passes the plate through the element lying there."""
    GRASP_START_HEIGHT = 0.2
    """m; with `set_reach_starts`, the reach path ends with the plate this far above the element's grasp face, inside
    every stage's tau_pick (0.3-0.4 m): an arm left there grasps at its first step."""

    def set_reach_starts(self, share: float, radius: Union[float, Sequence[float]]) -> None:
        """From the next reset on, a `share` (one for all task types, or one per type in ELEMENT_KINDS order) of the
        resets that are not near-goal starts start on the last `radius` of the reach path's length, the element lying
        on the table. `radius`: one for all goal slots, one per task type in ELEMENT_KINDS order, or one per goal slot,
        those of each type in turn (a slot reached from the turret side the policy does not grasp from then widens on
        its own, not on the other slots' grasps). The path runs on the joint line from the reset's configuration to
        the lift LIFT_HEIGHT above the element, on a turret side the goal slot's start paths leave from
        (`_path_sides`), then down to GRASP_START_HEIGHT above it.

        The start-state curriculum carried back through the grasp (reverse curriculum generation): radius 0 starts
        about to grasp, 1 anywhere from the reset on; everything from IK of the table (`lift_configurations`), no
        demonstrations. `info["reach_start"]` marks those episodes and `info["reach_start_grasped"]` whether the
        element was grasped from the side the start was on. A training device: evaluations use ordinary resets
        (share 0, the default)."""
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
        if self.reach_starts_to_lift:
            raise ValueError("reach starts: set_reach_starts draws along the path down to the element; "
                             "reach_starts_to_lift=True is the kwargs' fixed way, give one or the other")
        self.reach_start_share = torch.tensor(shares)
        per_slot = torch.tensor(radii, dtype=torch.float32, device=self.device)
        self.reach_start_radius = per_slot.view(-1, 1).expand(kinds, slots) if len(radii) < kinds * slots \
            else per_slot.view(kinds, slots)

    def _start_on_the_way(self, env_idx: torch.Tensor) -> None:
        """A `reach_start_share` of the resets (before near-goal starts draw theirs) start with the arm a uniform
        fraction in [0, REACH_START_MAX) of the way along the joint line from its start configuration to a table grasp
        configuration (`reach_distance`'s) on a turret side that a usable start path of the goal slot leaves from, the
        element lying on the table: the start-state curriculum's first stretch, which near-goal starts (the element
        already held) leave out, meant for a policy that grasps every element from one turret side where a goal slot
        is reached from the other one (the window opening at y = +0.85; it did not turn the from-scratch policy's
        reach there: docs/experiments/from_scratch.md, rounds 6 and 9). With
        `reach_starts_to_lift`, along the joint line to the lift LIFT_HEIGHT above the element instead, any fraction
        of the way up to all of it (the arm above the element, about to grasp it): a policy that turns back from
        most of the way to a side it never grasps from may still grasp from right above the element. After
        `set_reach_starts`, on the last part of the path down to the element instead (its docstring)."""
        chosen = torch.rand(len(env_idx)) < self.reach_start_share.to(self.device)[self.task_id[env_idx]]
        if not bool(chosen.any()):
            return
        idx = env_idx[chosen]
        side = torch.multinomial(self._path_sides(self.task_id[idx], self.goal_slot[idx]).float(), 1)[:, 0]
        qpos = self.agent.robot.get_qpos()[env_idx].clone()
        if self.reach_start_radius is not None:
            if self._grasp_start_q is None:
                self._lift_q = torch.tensor(lift_configurations(), dtype=torch.float32, device=self.device)
                self._grasp_start_q = torch.tensor(lift_configurations(self.GRASP_START_HEIGHT), dtype=torch.float32,
                                                   device=self.device)
            task = self.task_id[idx]
            back = torch.stack([self._grasp_start_q[task, side], self._lift_q[task, side], qpos[chosen]], 1)  # [m, 3, 6]
            radius = self.reach_start_radius[task, self.goal_slot[idx]]
            qpos[chosen] = self._path_points(back, torch.rand(len(idx)) * radius)
        else:
            if self.reach_starts_to_lift and self._lift_q is None:
                self._lift_q = torch.tensor(lift_configurations(), dtype=torch.float32, device=self.device)
            elif not self.reach_starts_to_lift and self._table_q is None:
                self._table_q = torch.tensor(lift_configurations(0.0), dtype=torch.float32, device=self.device)
            ends, most = (self._lift_q, 1.0) if self.reach_starts_to_lift else (self._table_q, self.REACH_START_MAX)
            target = ends[self.task_id[idx], side]
            qpos[chosen] += torch.rand(len(idx), 1) * most * (target - qpos[chosen])
        self._pose_arm(qpos)
        self.reach_start_side[idx] = side

    def _place_goal_markers(self, env_idx: torch.Tensor) -> None:
        task, goal = self.task_id[env_idx], self._goal_table[self.task_id[env_idx], self.goal_slot[env_idx]]
        hidden = torch.tensor(HIDDEN_POSE, device=self.device).expand_as(goal)
        for kind, marker in self.goal_markers.items():
            active = (task == ELEMENT_KINDS.index(kind))[:, None]
            marker.set_pose(Pose.create(torch.where(active, goal, hidden)))

    def _storage_pose(self, kind: str, b: int) -> torch.Tensor:
        k = ELEMENT_KINDS.index(kind)
        x, y = STORAGE_XY[kind]
        ground = -self.site.manifest["site_params"]["ground_thickness"]
        pose = torch.tensor([x, y, ground + float(self._el_size[k, 2]) / 2 + DROP_CLEARANCE, 1, 0, 0, 0],
                            device=self.device)
        return pose.repeat(b, 1)

    def _select_active_elements(self):
        """Point `self.obj` at each env's element of its task type. physx_cpu has one env: its
        kind's actor. On the GPU, one view built once whose rigid-body index is gathered by task_id
        on the device at every (partial) reset: no loop over envs, no host sync. The view's entity
        list stays the first kind's; ManiSkill's GPU paths (poses, velocities, setters) read the
        rigid bodies through that index alone."""
        if not self.gpu_sim_enabled:
            self.obj = self.elements[ELEMENT_KINDS[int(self.task_id[0])]]
            return
        envs = torch.arange(self.num_envs, device=self.device)
        if self._element_body_index is None:
            kinds = [k for k in ELEMENT_KINDS if k in self.elements]
            self._element_body_index = torch.full((len(ELEMENT_KINDS), self.num_envs), -1, dtype=torch.long,
                                                  device=self.device)
            for k in kinds:
                self._element_body_index[ELEMENT_KINDS.index(k)] = self.elements[k]._body_data_index
            self.obj = Actor.create_from_entities(list(self.elements[kinds[0]]._objs), self.scene, envs)
            self.obj.name = "element"
        self.obj._body_data_index_internal = self._element_body_index[self.task_id, envs]

    # ------------------------------------------------------------------------------------- #
    # tolerances (curriculum)
    # ------------------------------------------------------------------------------------- #
    def set_curriculum_stage(self, stage: str, env_idx: Optional[torch.Tensor] = None) -> None:
        """Switch to a stage of Table I: changes the tolerances and nothing else."""
        tol = stage_tolerances(stage)
        self._set_tol(tol, env_idx)
        self.curriculum_stage = stage

    def set_tolerances(self, pick: Optional[float] = None, place: Optional[float] = None,
                       angle_deg: Optional[float] = None, env_idx: Optional[torch.Tensor] = None) -> None:
        """Override some tolerances (m, m, degrees) at run time; the others keep their values."""
        given = {k: v for k, v in dict(pick=pick, place=place, angle_deg=angle_deg).items() if v is not None}
        self._set_tol(validate_tolerances(given), env_idx)

    def _set_tol(self, tol: dict, env_idx) -> None:
        idx = slice(None) if env_idx is None else env_idx
        for i, key in enumerate(TOLERANCE_KEYS):
            if key in tol:
                self.tolerances[idx, i] = tol[key]

    @property
    def tau_pick(self) -> torch.Tensor:
        return self.tolerances[:, 0]

    @property
    def tau_place(self) -> torch.Tensor:
        return self.tolerances[:, 1]

    @property
    def tau_angle_deg(self) -> torch.Tensor:
        return self.tolerances[:, 2]

    # ------------------------------------------------------------------------------------- #
    # grasp and hold
    # ------------------------------------------------------------------------------------- #
    @property
    def goal_pose(self) -> Pose:
        """Where the element's own frame must end up."""
        return Pose.create(self._goal_table[self.task_id, self.goal_slot])

    @property
    def held(self) -> torch.Tensor:
        """[n] whether each env's element is on the suction plate (the gripper's state)."""
        return self.gripper.held

    @property
    def hold_pose_in_tcp(self) -> torch.Tensor:
        """[n, 7] raw pose of the held element in the plate's tcp frame."""
        return self.gripper.hold_pose_in_tcp

    def grasp_ray(self, tcp_in_el: Optional[torch.Tensor] = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The plate's grasp sensor on each env's element: (distance along the ray to the grasp face,
        whether the ray hits the face); `suction_gripper.grasp_ray`, by default at the tcp's pose now."""
        if tcp_in_el is None:
            tcp_in_el = self.gripper.tcp_in_element(self.obj)
        return grasp_ray(tcp_in_el, self._el_size[self.task_id])

    def _update_grasp(self) -> None:
        grasp_now = self.gripper.grasp(self.obj, self._grasp_in_el, self._el_size, self.task_id, self.tau_pick)
        self.first_grasp_now = grasp_now & ~self.picked
        self.picked |= grasp_now
        # the staging table lies at turret +-pi: the side a grasp's turret is on is the side its carry leaves from
        turret = self.agent.robot.get_qpos()[:, 0]
        self.carry_side = torch.where(grasp_now, (turret <= 0).long(), self.carry_side)

    def _step_action(self, action):
        action = super()._step_action(action)
        self._update_grasp()
        self._step_grasp_frame, self._in_step_readout = None, True  # the poses are final until the step returns
        return action

    def step(self, action):
        try:
            return super().step(action)
        finally:
            self._in_step_readout = False  # between steps the poses may move (set_state_dict, set_pose)

    def _before_control_step(self):
        self._substep = 0

    def _after_simulation_step(self):
        self._substep += 1

    def _before_simulation_step(self):
        self.gripper.hold(self.obj, self.scene, first_substep=self._substep == 0)

    # ------------------------------------------------------------------------------------- #
    # evaluation, observations, rewards
    # ------------------------------------------------------------------------------------- #
    def evaluate(self) -> dict:
        el = self.obj.pose.raw_pose
        goal = self._goal_table[self.task_id, self.goal_slot]
        place_dist = torch.linalg.norm(el[:, :3] - goal[:, :3], dim=-1)
        # error rotation in the element frame, minimised over the element's symmetries
        q_err = qmul(qconj(goal[:, 3:]), el[:, 3:])
        place_angle = qangle_deg(qmul(q_err[:, None], self._sym_quats[self.task_id])).min(dim=1).values
        success = self.held & (place_dist <= self.tau_place) & (place_angle <= self.tau_angle_deg)
        return dict(
            is_grasped=self.held.clone(),
            picked=self.picked.clone(),
            first_grasp=self.first_grasp_now.clone(),
            success=success,
            place_dist=place_dist,
            place_angle_deg=place_angle,
            task_id=self.task_id.clone(),
            goal_slot=self.goal_slot.clone(),
            near_goal_start=self.near_goal_start.clone(),
            reach_start=self.reach_start_side >= 0,
            # whether a reach start's element was grasped from the turret side the start was on
            reach_start_grasped=self.picked & (self.carry_side == self.reach_start_side),
        )

    def _grasp_frame(self) -> torch.Tensor:
        """Raw world pose [n, 7] of the grasp face's centre, z pointing into the element; read once
        per step (the observation and the dense reward both need it, and on physx_cpu reading a pose
        costs about a twentieth of a step)."""
        if not self._in_step_readout:
            return pose_mul(self.obj.pose.raw_pose, self._grasp_in_el[self.task_id])
        if self._step_grasp_frame is None:
            self._step_grasp_frame = pose_mul(self.obj.pose.raw_pose, self._grasp_in_el[self.task_id])
        return self._step_grasp_frame

    def _get_obs_extra(self, info: dict):
        goal = self._goal_table[self.task_id, self.goal_slot]
        tcp = self.agent.tcp.pose.raw_pose
        obs = dict(
            is_grasped=info["is_grasped"].float()[:, None],
            tcp_pose=tcp,
            goal_pose=goal,
            task=self._task_onehot[self.task_id],
        )
        if "state" in self.obs_mode:
            el = self.obj.pose.raw_pose
            obs.update(
                obj_pose=el,
                tcp_to_grasp_pos=self._grasp_frame()[:, :3] - tcp[:, :3],
                obj_to_goal_pos=goal[:, :3] - el[:, :3],
            )
        if self.obs_install_offset:  # after the rest, so that a policy without it reads them unchanged
            obs["install_offset"] = self.install_offset()
        if self.obs_path_offset:  # after it, for the same reason
            obs["path_offset"] = self.path_offset()
        if self.obs_elapsed_time:  # last, so that a policy without it reads the rest unchanged
            obs["elapsed"] = (self.elapsed_steps.float() / self.MAX_EPISODE_STEPS)[:, None]
        return obs

    def compute_sparse_reward(self, obs: Any, action: torch.Tensor, info: dict):
        """Algorithm 1: -1/MaxStep every step; 1 on the episode's first grasp; 2 on placement."""
        reward = torch.full((self.num_envs,), -1.0 / self.MAX_EPISODE_STEPS, device=self.device)
        reward[info["first_grasp"]] = 1.0
        reward[info["success"]] = 2.0
        return reward

    PROGRESS_GAIN = 1.25
    """per rad; the progress term pays this much per radian the carry distance fell since the last step, within
    +-0.25 around its 0.25 for standing still (a joint at its full 0.1 rad per step earns 0.125 more)."""
    CARRY_RANGE = 12.0
    """rad; the carry term falls linearly from 1 at an installation configuration to 0 this far (summed over the
    joints) from the nearest one: a lift above the staging table leaves the arm 2.6-10.3 rad from its goal."""

    PATH_DEVIATION_WEIGHT = 3.0
    """`path_distance` counts each radian off the path this many times: cutting across to the goal (or to a later
    point of the path) costs more than going along the path, whose length from a lift above the table to the goal is
    up to about twice the straight joint move's."""
    VIA_DEVIATION_WEIGHT = 25.0
    """with `carry_keeps_to_vias`, each radian off a path through a planned via, from the lift above the table in,
    counts this many times: that detour exists because cutting across runs the element into the site. At
    PATH_DEVIATION_WEIGHT a window for the opening at y = +0.85 carried from -pi into the neighbouring opening
    measured about as near its goal as the via, and the cut across nearer than the lift; at this weight both measure
    farther than the path's table end (`python -m experiments.via_landscape`, docs/experiments/from_scratch.md)."""

    def plate_turn(self) -> torch.Tensor:
        """[n] rad; how far the held element is turned on the plate about the plate's axis (the grasp keeps the
        element's yaw relative to the plate); 0 when it lies as in `install_configurations`, and before the episode's
        grasp (each reset sets the nominal hold), but half a turn there with `install_mirror_branch` for the slot it
        cuts."""
        grasp_q = self._grasp_in_el[self.task_id, 3:]
        turn = qmul(qconj(grasp_q), qconj(self.hold_pose_in_tcp[:, 3:]))  # a rotation about the plate's z axis
        turn = 2 * torch.atan2(turn[:, 3], turn[:, 0])
        if self.install_mirror_branch:
            # until the grasp, a slot met as its twin's mirror image is measured for the element held half a turn on
            # (the plate's roll is free until then): its joint moves are then the mirror image of its twin's
            if self._mirrored_slot is None:
                self._mirrored_slot = torch.tensor(mirror_twins() >= 0, device=self.device)
            ahead = self._mirrored_slot[self.task_id, self.goal_slot] & ~self.picked
            turn = torch.where(ahead, turn + torch.pi, turn)
        return turn

    def carry_distance(self) -> torch.Tensor:
        """[n] rad; how far the arm is from holding its element installed, in joint space (summed over the joints):
        to the nearest installation configuration of the env's goal slot, joint 6 shifted by the element's turn
        on the plate and compared modulo the element's symmetry period. Falls at every step of a straight joint
        move to the goal from anywhere (the turret turning the way its limits allow), and so along any carry
        that heads there; no demonstrations involved. With `carry_along_paths`, `path_distance` instead; with
        `carry_counts_lag`, plus LAG_WEIGHT times `hold_lag`."""
        distance = self.path_distance() if self.carry_along_paths else self.install_offset().abs().sum(-1)
        if self.carry_counts_lag:
            distance = distance + self.LAG_WEIGHT * self.hold_lag()
        return distance

    LAG_WEIGHT = 10.0
    """rad per m; with `carry_counts_lag`, each metre the held element trails its place on the plate adds this much to
    the carry distance: an element jammed 0.25 m under the slab's rim counts as far from its goal as a 2.5 rad joint
    move, where the arm's joints alone say it is nearly there."""

    def hold_lag(self) -> torch.Tensor:
        """[n] m; how far the held element's centre is from where the suction plate holds it. The hold cannot pass an
        element through walls and slabs: stopped there, it trails the plate while the arm goes on (the ceiling panels
        pushed against the slab's underside beside their opening, docs/experiments/from_scratch.md). About 0 while
        carrying, up to tau_pick for a step or two after the grasp (the pull onto the plate), a few cm pressed into
        the goal; meaningless while nothing is held."""
        target = pose_mul(self.agent.tcp.pose.raw_pose, self.gripper.hold_pose_in_tcp)
        return torch.linalg.norm(self.obj.pose.raw_pose[:, :3] - target[:, :3], dim=-1)

    def path_distance(self) -> torch.Tensor:
        """[n] rad; how far the arm is from holding its element installed along the nearest start path of its goal
        slot (`goal_configurations.StartPaths`, the near-goal starts' collision-checked joint paths: in from the
        goal along the plate's axis, up to a lift above the staging table and down to it): the least, over the
        points of the path, of PATH_DEVIATION_WEIGHT times the joint-space (L1) distance to the point plus the
        path's length from there to the installation, joint 6 compared as in `carry_distance`. A straight joint
        move to the goal runs the element into the slab, the wall and the barriers beside the staging table (the
        fourth start's carries, docs/experiments/from_scratch.md); this distance falls on the way up and over them
        and into the opening along the plate's axis. No demonstrations: the paths come from IK of the goal and
        the table. With `carry_keeps_to_vias`, only along the paths that leave the table from the turret side the
        element was grasped from (where the slot has any: the turret cannot cross to the other side holding it),
        each radian off a path through a planned via, from its lift in, counting VIA_DEVIATION_WEIGHT times."""
        return self._path_projection()[0]

    def _path_projection(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """`path_distance` [n], the waypoints [n, P, 6] of the start path it is measured along, and the path's length
        from the installation to the point it is measured from [n]."""
        sp = self._load_start_paths()
        n = len(self.task_id)
        w = sp["waypoints"][self.task_id, self.goal_slot].flatten(1, 2)  # [n, M, P, 6], M paths of P waypoints
        a, seg = w[:, :, :-1], w[:, :, 1:] - w[:, :, :-1]  # [n, M, P - 1, 6]
        rel = self.agent.robot.get_qpos()[:, None, None, :] - a
        rel[..., 5] -= self.plate_turn()[:, None, None]
        period = self._sym_period[self.task_id][:, None, None]
        # each segment's nearest point by joints 1-5 (joint 6, the plate's roll, is compared modulo the element's
        # symmetry, which a projection cannot take), and its ends
        t_near = ((rel[..., :5] * seg[..., :5]).sum(-1) / (seg[..., :5] ** 2).sum(-1).clamp(min=1e-9)).clamp(0, 1)
        length = seg.abs().sum(-1)
        before = torch.cumsum(length, -1) - length  # the path's length from the installation to each segment
        ts = torch.stack([t_near, torch.zeros_like(t_near), torch.ones_like(t_near)])  # [3, n, M, P - 1]
        diff = rel[None] - ts[..., None] * seg[None]
        off_path = diff[..., :5].abs().sum(-1) + (torch.remainder(diff[..., 5] + period / 2, period) - period / 2).abs()
        usable = sp["usable"][self.task_id, self.goal_slot] > 0  # [n, M]
        weight = torch.full_like(length, self.PATH_DEVIATION_WEIGHT)  # [n, M, P - 1]
        if self.carry_keeps_to_vias:
            # from the lift in: the table's segment keeps the lenient weight, where the grasp's posture need not match
            # the path's and nothing lies across
            not_table = torch.arange(length.shape[-1], device=length.device) < length.shape[-1] - 1  # [P - 1]
            detour = (sp["planned"][self.task_id, self.goal_slot] > 0)[..., None] & not_table
            weight = torch.where(detour, self.VIA_DEVIATION_WEIGHT, weight)
            side = torch.arange(usable.shape[1], device=usable.device)[None] % 2 == self.carry_side[:, None]  # [n, M]
            usable = torch.where((usable & side).any(-1, keepdim=True), usable & side, usable)
        cost = weight[None] * off_path + before + ts * length
        cost = torch.where(usable[None, :, :, None], cost, torch.full_like(cost, torch.inf))
        total, best = cost.permute(1, 0, 2, 3).reshape(n, -1).min(-1)
        k, m, j = torch.unravel_index(best, cost.permute(1, 0, 2, 3).shape[1:])
        rows = torch.arange(n, device=cost.device)
        return total, w[rows, m], before[rows, m, j] + ts[k, rows, m, j] * length[rows, m, j]

    PATH_LOOKAHEAD = 0.5
    """rad; `path_offset` points this far (joint-space, L1) along the path ahead of the arm's nearest point on it."""

    def path_offset(self) -> torch.Tensor:
        """[n, 6] rad; the joint move from the arm's configuration to the point PATH_LOOKAHEAD ahead, toward the
        installation, of its nearest point on the start path `path_distance` measures along (the installation
        configuration itself within PATH_LOOKAHEAD of it), joint 6's part taken modulo the element's symmetry, as
        `install_offset` is for the straight move: which way the path-measured carry falls from here."""
        _, w, at = self._path_projection()
        length = (w[:, 1:] - w[:, :-1]).abs().sum(-1).sum(-1)
        target = self._path_points(w, ((at - self.PATH_LOOKAHEAD).clamp(min=0) / length.clamp(min=1e-9)).clamp(0, 1))
        diff = target - self.agent.robot.get_qpos()
        period = self._sym_period[self.task_id]
        diff[:, 5] = torch.remainder(diff[:, 5] + self.plate_turn() + period / 2, period) - period / 2
        return diff

    REACH_RANGE = 6.0
    """rad; with `reach_in_joint_space`, the joint-space reach falls linearly from 1 at a grasp configuration to 0
    this far (joints 1-5 summed) from the nearest one: the rest pose is 3-4 rad from them."""

    def reach_distance(self) -> torch.Tensor:
        """[n] rad; how far the arm is, in joint space (joints 1-5 summed: the plate's roll does not matter to the
        suction grasp, which keeps the element's turn), from the nearest configuration that grasps the element where
        it lies on the staging table (its centre: `goal_configurations.lift_configurations(0)`, with the turret at
        about +pi or -pi). Falls along a joint move to the table the way the turret's limits allow, where the
        bearing around the pedestal turns the turret either way. With `reach_toward_path_sides`, only to those on the
        turret sides that a usable start path of the env's goal slot leaves the table from: an element grasped
        from the other side has no collision-free way to its goal along them (the two window openings at y <= 0 only
        from -pi), and the carry measured along them pulls it nowhere; `reach_avoids_vias` (`_path_sides`) leaves out
        the side reached only through a planned via (the opening at y = +0.85 from -pi)."""
        if self._table_q is None:
            self._table_q = torch.tensor(lift_configurations(0.0), dtype=torch.float32, device=self.device)
        q = self.agent.robot.get_qpos()
        distance = (self._table_q[self.task_id][..., :5] - q[:, None, :5]).abs().sum(-1)  # [n, 2 turret sides]
        if self.reach_toward_path_sides:
            distance = torch.where(self._path_sides(self.task_id, self.goal_slot), distance, torch.full_like(distance, torch.inf))
        return distance.amin(-1)

    def _path_sides(self, task: torch.Tensor, slot: torch.Tensor) -> torch.Tensor:
        """[n, 2] bool: the turret sides (+pi, -pi) a usable start path of each goal slot leaves the table from; both for
        a slot without usable paths. With `reach_avoids_vias`, only the sides a usable path without a planned via
        leaves from, where there is one: the way in through a via is a detour of the turret's whole turn past the
        neighbouring openings (the window opening at y = +0.85 from -pi), the direct way from the other side a short one."""
        sp = self._load_start_paths()
        usable = sp["usable"][task, slot]  # [n, configurations x sides]
        sides = usable.view(len(task), -1, 2).amax(1) > 0
        if self.reach_avoids_vias:
            direct = (usable * (1 - sp["planned"][task, slot])).view(len(task), -1, 2).amax(1) > 0
            sides = torch.where(direct.any(-1, keepdim=True), direct, sides)
        return sides | ~sides.any(-1, keepdim=True)

    def install_offset(self) -> torch.Tensor:
        """[n, 6] rad; the joint move from the arm's configuration to the nearest one that holds its element
        installed (the one `carry_distance` measures to), joint 6's part taken modulo the element's symmetry."""
        if self._install_q is None:
            # a configuration not kept is replaced by its slot's first kept one (the table repeats them already)
            table, kept = install_configurations().copy(), self._kept_configurations()
            first = kept.argmax(-1)[..., None, None].repeat(table.shape[-1], -1)
            table = np.where(kept[..., None], table, np.take_along_axis(table, first, 2))
            self._install_q = torch.tensor(table, dtype=torch.float32, device=self.device)
        q = self.agent.robot.get_qpos()
        diff = self._install_q[self.task_id, self.goal_slot] - q[:, None, :]  # [n, K, 6]
        period = self._sym_period[self.task_id][:, None]
        diff[..., 5] = torch.remainder(diff[..., 5] + self.plate_turn()[:, None] + period / 2, period) - period / 2
        nearest = diff.abs().sum(-1).argmin(-1)
        return diff[torch.arange(len(q), device=q.device), nearest]

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        """Staged, as ManiSkill's tasks: reach and face the grasp surface (<= 1); held: 2 + carry (<= 1) + fit
        (<= 1) + progress (<= 0.5); placed: 10, more than twice any other step, for a learner that bootstraps at success
        (ManiSkill's convention; see the task card). Carry is linear in the arm's joint-space distance from its
        installation configuration (`carry_distance`), so it pulls at the same rate from the pick to the goal, the
        way the turret's limits allow, and turns the element as it carries it; fit is 1 - tanh(5 d) of the
        element's distance d from its goal, times 1 - tanh of its angle error (rad), which takes over for the last decimetres.
        Progress is the step's fall of the carry distance (PROGRESS_GAIN per rad, within [0, 0.5], 0.25 standing
        still): a potential difference, so it sums to the carry's net change over an episode and going back and
        forth earns nothing, but it pays each step's progress at once instead of through the critic's sums. It
        keeps the last carry distance per env (`carry_prev`, in the task state): call this once per step."""
        tcp = self.agent.tcp.pose.raw_pose
        grasp = self._grasp_frame()
        # tanh(d), not tanh(3d): the element starts about 2 m from the plate and must still pull
        reach = 1 - torch.tanh(torch.linalg.norm(grasp[:, :3] - tcp[:, :3], dim=-1))
        face = (1 + (qaxis(tcp[:, 3:], 2) * qaxis(grasp[:, 3:], 2)).sum(-1)) / 2
        # bearing around the pedestal: straight-line distance alone pulls the plate over the
        # pedestal (a dead end) when the target is behind the arm; turning the turret must pay
        approach = 0.25 * _bearing(tcp[:, :2], grasp[:, :2]) + 0.75 * reach * (0.5 + 0.5 * face)
        if self.reach_in_joint_space:  # the turret's way round to the table as its limits allow, as the carry's
            approach = 0.5 * (1 - (self.reach_distance() / self.REACH_RANGE).clamp(max=1)) + 0.5 * reach * (0.5 + 0.5 * face)
        held = info["is_grasped"]
        distance = self.carry_distance()
        fell = torch.where(held & (self.carry_prev >= 0), self.carry_prev - distance, torch.zeros_like(distance))
        self.carry_prev = torch.where(held, distance, torch.full_like(distance, -1.0))
        progress = 0.25 + (self.PROGRESS_GAIN * fell).clamp(-0.25, 0.25)
        carry = 1 - (distance / self.CARRY_RANGE).clamp(max=1)
        fit = (1 - torch.tanh(5 * info["place_dist"])) * (1 - torch.tanh(torch.deg2rad(info["place_angle_deg"])))
        reward = torch.where(held, 2 + carry + fit + progress, approach)
        return torch.where(info["success"], torch.full_like(reward, self.DENSE_REWARD_MAX), reward)

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return self.compute_dense_reward(obs, action, info) / self.DENSE_REWARD_MAX

    # ------------------------------------------------------------------------------------- #
    # state
    # ------------------------------------------------------------------------------------- #
    def get_state_dict(self):
        """ManiSkill's state plus the task state under "task"; every task leaf is [num_envs, k]
        (task_id, goal_slot, held, picked: k = 1), as ManiSkill's trajectory tools expect."""
        state = super().get_state_dict()
        state["task"] = dict(
            task_id=self.task_id[:, None].clone(),
            goal_slot=self.goal_slot[:, None].clone(),
            held=self.held[:, None].clone(),
            picked=self.picked[:, None].clone(),
            hold_pose_in_tcp=self.hold_pose_in_tcp.clone(),
            tolerances=self.tolerances.clone(),
            carry_prev=self.carry_prev[:, None].clone(),
            carry_side=self.carry_side[:, None].clone(),
        )
        return state

    def set_held(self, held: bool = True) -> None:
        """Every env's element held by the plate (or let go), through the task state as a grasp
        leaves it: a carry without a pick, for benchmarks and tests (batched, either backend)."""
        state = self.get_state_dict()
        state["task"]["held"][:] = held
        self.set_state_dict(state)

    def set_state_dict(self, state: dict, env_idx: Optional[torch.Tensor] = None):
        """Restore a state from `get_state_dict`. A task leaf may be [b, k] (as saved), one env's
        row [k] (a trajectory step as ManiSkill's replay tool passes it), or, for the one-column
        leaves, the earlier 1-D layout [b] (or a scalar)."""
        state = dict(state)
        task = state.pop("task", None)
        if task is not None:
            idx = slice(None) if env_idx is None else env_idx
            for key in ("task_id", "goal_slot", "held", "picked", "hold_pose_in_tcp", "tolerances", "carry_prev", "carry_side"):
                if key not in task:  # a state saved before the key existed (carry_prev: 2026-11-25, carry_side: 2026-11-27)
                    continue
                dest = getattr(self, key)
                k = dest.shape[1] if dest.ndim == 2 else 1
                value = task[key]
                value = torch.as_tensor(value if torch.is_tensor(value) else np.asarray(value), device=self.device)
                if value.ndim == 2 and value.shape[1] == k:
                    pass
                elif value.ndim == 1 and k == 1:  # the earlier 1-D layout [b]
                    value = value[:, None]
                elif value.ndim == 1 and value.shape[0] == k:  # one env's row
                    value = value[None]
                elif value.ndim == 0 and k == 1:
                    value = value.reshape(1, 1)
                else:
                    raise ValueError(f"task state {key!r} has shape {tuple(value.shape)}; expected [num_envs, {k}]")
                value = value.to(dest.dtype)
                if dest.ndim == 1:
                    value = value[:, 0]
                dest[idx] = value[idx] if env_idx is not None and len(value) == self.num_envs else value
            if len(self.TASKS) > 1:
                self._select_active_elements()
        super().set_state_dict(state, env_idx)
        if task is not None:
            self._place_goal_markers(torch.arange(self.num_envs, device=self.device))


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
