"""The construction pick-and-place task shared by the four environments.

One class holds the task; `ms_construction/envs/tasks.py` registers the general task and the three single-task
environments with their task cards. Beside it: the suction plate's grasp sensor and hold
(`ms_construction.agents.suction_gripper`), the joint-space geometry the dense reward measures
(`carry_geometry`), the start-state curricula (`start_states`) and the flat observation's layout (`state_layout`).
"""

from __future__ import annotations

import functools
import os
from typing import Any, Mapping, Optional, Sequence

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
from ms_construction.envs.carry_geometry import CarryGeometry, Projection
from ms_construction.envs.obstacles import SiteObstacles
from ms_construction.envs.start_states import StartStates
from ms_construction.parameters import (
    DROP_CLEARANCE,
    ELEMENT_KINDS,
    HIDDEN_POSE,
    START_YAW_DEG,
    START_YAW_NOISE_DEG,
    STORAGE_XY,
    SYMMETRIES_DEG,
    start_xy_noise,
)
from ms_construction.rotations import pose_inv, pose_mul, qangle_deg, qaxis, qconj, qmul, quat_z
from ms_construction.site import ConstructionSiteSceneBuilder, build_element

ROBOT_INIT_QPOS_NOISE = 0.02
"""rad; std of the arm's start configuration around its rest keyframe, per joint."""

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



class ConstructionTaskEnv(SiteObstacles, StartStates, BaseEnv):
    """Base of the construction tasks; see ms_construction/envs/tasks.py for the task cards."""

    SUPPORTED_ROBOTS = ["construction_arm"]
    SUPPORTED_REWARD_MODES = ("normalized_dense", "dense", "sparse", "none")
    """the first is the default, as in ManiSkill's tasks (its baselines pass none); the paper's setting passes
    reward_mode="sparse"."""
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
        reach_start_share: float = 0.0,
        obstacles: Optional[str] = None,
        obs_obstacles: Optional[bool] = None,
        obstacle_share: float = 1.0,
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
        self._init_start_states(reach_start_share)
        self._init_obstacles(obstacles, obs_obstacles, obstacle_share)
        self.robot_init_qpos_noise = robot_init_qpos_noise
        self._step_cache: dict = {}
        self._in_step_readout = False
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
        self._start_xy_noise = torch.tensor([start_xy_noise(m["elements"][k]["size"], START_YAW_DEG[k], st["size"],
                                                            st["rim"][1]) for k in kinds], **f32)

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
        self.tolerances = torch.tensor([[self._tol_init[k] for k in TOLERANCE_KEYS]], **f32).repeat(n, 1)
        self.obj = self.elements[self.TASKS[0]]
        self._element_body_index: Optional[torch.Tensor] = None  # [kinds, num_envs], GPU only
        self._task_onehot = torch.eye(len(kinds), **f32)
        # the dense reward's joint-space measures (IK tables, a few seconds once per process: made when first needed)
        self._geometry: Optional[CarryGeometry] = None
        self._load_obstacles()

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
            xyz[:, :2] += (torch.rand(b, 2) * 2 - 1) * self._start_xy_noise[task]
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
            # after the arm, element and goal: a seed draws the same episode with and without obstacles; before the
            # start states (training devices), which pose the arm on the start paths clear of them
            self._place_obstacles(env_idx)
            if bool((self.reach_start_share > 0).any()):
                self._start_on_the_way(env_idx)
            if bool((self.near_goal_share > 0).any()):
                self._start_near_goal(env_idx)

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
        self._step_cache, self._in_step_readout = {}, True  # the poses are final until the step returns
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

    def _after_control_step(self):
        self._advance_obstacles()

    def _before_simulation_step(self):
        self.gripper.hold(self.obj, self.scene, first_substep=self._substep == 0)

    # ------------------------------------------------------------------------------------- #
    # evaluation, observations, rewards
    # ------------------------------------------------------------------------------------- #
    def evaluate(self) -> dict:
        el = self._obj_pose()
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
            **self.obstacle_info(),
        )

    def _get_obs_extra(self, info: dict):
        goal = self._goal_table[self.task_id, self.goal_slot]
        tcp = self._tcp_pose()
        obs = dict(
            is_grasped=info["is_grasped"].float()[:, None],
            tcp_pose=tcp,
            goal_pose=goal,
            task=self._task_onehot[self.task_id],
        )
        if "state" in self.obs_mode:
            el = self._obj_pose()
            obs.update(
                obj_pose=el,
                tcp_to_grasp_pos=self._grasp_frame()[:, :3] - tcp[:, :3],
                obj_to_goal_pos=goal[:, :3] - el[:, :3],
            )
        if self.obs_install_offset:  # after the rest, so that a policy without it reads them unchanged
            obs["install_offset"] = self.install_offset()
        if self.obs_path_offset:  # after it, for the same reason
            obs["path_offset"] = self.path_offset()
        if self.obs_elapsed_time:  # last but the obstacles, so that a policy without it reads the rest unchanged
            obs["elapsed"] = (self.elapsed_steps.float() / self.MAX_EPISODE_STEPS)[:, None]
        if self.obs_obstacles:  # after everything: a policy trained without obstacles reads the rest unchanged
            obs["obstacles"] = self.obstacle_observation()
        return obs

    def compute_sparse_reward(self, obs: Any, action: torch.Tensor, info: dict):
        """Algorithm 1: -1/MaxStep every step; 1 on the episode's first grasp; 2 on placement."""
        reward = torch.full((self.num_envs,), -1.0 / self.MAX_EPISODE_STEPS, device=self.device)
        reward[info["first_grasp"]] = 1.0
        reward[info["success"]] = 2.0
        return reward

    # ------------------------------------------------------------------------------------- #
    # the dense reward's measures (joint space, `carry_geometry`), read once per step
    # ------------------------------------------------------------------------------------- #
    def _per_step(self, name: str, compute):
        """`compute()`, once per step while the step reads out its info, observation and reward (the poses and joints
        are final until it returns); afresh outside a step (set_state_dict, set_pose may move them)."""
        if not self._in_step_readout:
            return compute()
        if name not in self._step_cache:
            self._step_cache[name] = compute()
        return self._step_cache[name]

    @property
    def geometry(self) -> CarryGeometry:
        """The joint-space tables of every task type and goal slot (IK and collision checks: a few seconds, once per
        process)."""
        if self._geometry is None:
            self._geometry = CarryGeometry(self.device)
        return self._geometry

    def _grasp_frame(self) -> torch.Tensor:
        """Raw world pose [n, 7] of the grasp face's centre, z pointing into the element (on physx_cpu reading a pose
        costs about a twentieth of a step: the observation and the dense reward share it)."""
        return self._per_step("grasp_frame", lambda: pose_mul(self._obj_pose(), self._grasp_in_el[self.task_id]))

    def _obj_pose(self) -> torch.Tensor:
        """Raw world pose [n, 7] of each env's element (read once per step: evaluate, the observation and the reward
        share it)."""
        return self._per_step("obj_pose", lambda: self.obj.pose.raw_pose)

    def _tcp_pose(self) -> torch.Tensor:
        """Raw world pose [n, 7] of the plate's tcp (read once per step, as `_obj_pose`)."""
        return self._per_step("tcp_pose", lambda: self.agent.tcp.pose.raw_pose)

    def plate_turn(self) -> torch.Tensor:
        """[n] rad; how far the held element is turned on the plate about the plate's axis (the grasp keeps the
        element's yaw relative to the plate); 0 when it lies as in `install_configurations`, and before the episode's
        grasp (each reset sets the nominal hold), but for a goal slot that is the mirror image of another there the
        turn its installation is from its twin's mirror image (`CarryGeometry.mirror_turn`: half a turn for a window):
        until the grasp the plate's roll is free, and measured so, that slot's joint moves are the mirror image of its
        twin's (a policy may meet the one as the other)."""
        def compute():
            grasp_q = self._grasp_in_el[self.task_id, 3:]
            turn = qmul(qconj(grasp_q), qconj(self.hold_pose_in_tcp[:, 3:]))  # a rotation about the plate's z axis
            turn = 2 * torch.atan2(turn[:, 3], turn[:, 0])
            return torch.where(self.picked, turn, turn + self.geometry.mirror_turn[self.task_id, self.goal_slot])
        return self._per_step("plate_turn", compute)

    def projection(self) -> Projection:
        """The arm's nearest point on its goal slot's start paths, the grasp side's where it has any
        (`CarryGeometry.project`): what the carry and the path offset measure."""
        return self._per_step("projection", lambda: self.geometry.project(
            self.agent.robot.get_qpos(), self.plate_turn(), self.task_id, self.goal_slot, self.carry_side,
            self.obstacle_ways()))

    def carry_distance(self) -> torch.Tensor:
        """[n] rad; how far the arm is from holding its element installed, along the start paths of its goal slot
        (`CarryGeometry.project`): collision-checked joint paths in from the goal along the plate's axis, up to a lift
        above the staging table and down to it, from IK of the goal and the table (no demonstrations). A straight joint
        move to the goal runs the element into the slab, the wall and the barriers beside the staging table; this
        distance falls on the way up and over them and into the opening along the plate's axis."""
        return self.projection().distance

    def path_offset(self) -> torch.Tensor:
        """[n, 6] rad; the joint move to the point a little ahead along the path the carry is measured along
        (`Projection.path_offset`): which way the carry falls from here."""
        return self.projection().path_offset

    def install_offset(self) -> torch.Tensor:
        """[n, 6] rad; the joint move from the arm's configuration to the nearest one that holds its element
        installed, joint 6's part taken modulo the element's symmetry (the projection finds it on the way)."""
        return self.projection().install_offset

    def reach_distance(self) -> torch.Tensor:
        """[n] rad; the arm's joint-space distance (joints 1-5) from the nearest configuration that grasps its element
        on the staging table from a turret side its goal slot's start paths leave from (`CarryGeometry.reach_distance`)."""
        return self.geometry.reach_distance(self.agent.robot.get_qpos(), self.task_id, self.goal_slot,
                                            self.obstacle_ways())

    PROGRESS_GAIN = 1.25
    """per rad; the progress term pays this much per radian the carry distance fell since the last step, within
    +-0.25 around its 0.25 for standing still (a joint at its full 0.1 rad per step earns 0.125 more)."""
    CARRY_RANGE = 12.0
    """rad; the carry term falls linearly from 1 at the installation to 0 this far along the paths from it: a lift
    above the staging table leaves the arm 2.6-10.3 rad from its goal."""
    REACH_RANGE = 6.0
    """rad; the joint-space half of the reach falls linearly from 1 at a table grasp configuration to 0 this far
    (joints 1-5 summed) from the nearest one: the rest pose is 3-4 rad from them."""

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        """Staged, as ManiSkill's tasks (the task card says what each stage pays and why): before the grasp, reach
        (<= 1): half joint-space toward the table grasp configurations on the turret sides the goal slot's start paths
        leave from (`reach_distance`), half 1 - tanh of the plate's distance from the grasp face times its facing;
        held: 2 + carry (<= 1) + fit (<= 1) + progress (<= 0.5); placed: DENSE_REWARD_MAX, more than twice any other
        step, for a learner that bootstraps at success. Carry is linear in the distance along the start paths
        (`carry_distance`); fit is 1 - tanh(5 d) of the element's distance d from its goal, times 1 - tanh of its
        angle error (rad), which takes over for the last decimetres. Progress is the step's fall of the carry
        distance (PROGRESS_GAIN per rad, within [0, 0.5], 0.25 standing still): a potential difference, so it sums to
        the carry's net change over an episode and going back and forth earns nothing, but it pays each step's
        progress at once instead of through the critic's sums. It keeps the last carry distance per env
        (`carry_prev`, in the task state): call this once per step."""
        tcp = self._tcp_pose()
        grasp = self._grasp_frame()
        # tanh(d), not tanh(3d): the element starts about 2 m from the plate and must still pull
        near = 1 - torch.tanh(torch.linalg.norm(grasp[:, :3] - tcp[:, :3], dim=-1))
        face = (1 + (qaxis(tcp[:, 3:], 2) * qaxis(grasp[:, 3:], 2)).sum(-1)) / 2
        approach = 0.5 * (1 - (self.reach_distance() / self.REACH_RANGE).clamp(max=1)) + 0.5 * near * (0.5 + 0.5 * face)
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
            **self.obstacle_state(),
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
            for key in ("task_id", "goal_slot", "held", "picked", "hold_pose_in_tcp", "tolerances", "carry_prev", "carry_side",
                        *self.obstacle_state()):
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
            if self.has_obstacles:
                self._pose_obstacles()
                self._ways = None

