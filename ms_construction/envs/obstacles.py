"""A site that changes: obstacles in the arm's workspace, seeded per episode (the tasks' `obstacles` option).

- a stack of material on the floor (a box, 0.8 x 0.5 m, of a height drawn per episode);
- a scaffold post from the floor to the slab above;
- a worker's envelope (a cylinder of a walking person's size) in a lane along the -y barrier, past the floor recesses.

`obstacles="static"` puts the stack and the post in the workspace, the worker standing outside the work cell;
`"moving"` is the same scene at the start, and the worker then walks across the cell once, along its lane at walking
speed, entering at a time drawn per episode, and leaves.
`obstacle_share` < 1 draws, per episode, whether the scene has them at all (a mixed scene for training): an episode
without them has them parked off the site (the stack under the floor, the post beyond the arm's reach, the worker
never setting off) and the observation's obstacle entry zeros, as on the site as built.
The stack and the post stand within the arm's reach, clear of the staging table, the floor recesses, the window
fronts, the arm's rest pose and (the post) the ceiling openings; none of the three overlaps another or the lane. A
layout may still block every way to a goal: `experiments/generalization.py` keeps the evaluation seeds whose static
scene the planning expert solves ("solvable at its start").

The dense reward measures its carry along the start paths that keep clear of the stack and the post (`clear_paths`);
where they block every usable one of a turret side, along one of them through a via searched around them at reset
(`obstacle_ways`, seeded by the layout), and a detour from the other side where no via is found
(`CarryGeometry.clear_ways`).
A touch of the arm or the element on an obstacle is `info["obstacle_collision"]`; `info["fail"]` (ManiSkill's
failure key, which ends the episode) holds once one happened. The obstacles are kinematic bodies (immovable; the
static site does not collide with them). physx_cpu only for now: the GPU path (pairwise contact queries, kinematic
poses applied per step) is not written.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Optional

import numpy as np
import sapien
import torch

from mani_skill.utils.structs import Actor, Pose

from ms_construction.envs.carry_geometry import EpisodeWays
from ms_construction.parameters import SiteParams
from ms_construction.rotations import quat_z

OBSTACLE_MODES = ("none", "static", "moving")
STACK_SIZE = (0.8, 0.5, 0.9)
"""m; the material stack's box; it stands in the floor so that STACK_HEIGHT of it shows (the slab does not collide
with the kinematic box)."""
STACK_HEIGHT = (0.3, 0.9)
"""m; the stack's visible height, uniform per episode."""
POST_SIZE = 0.08
"""m; side of the scaffold post's square tube, floor to slab."""
WORKER_RADIUS, WORKER_HEIGHT = 0.18, 1.8
"""m; a walking person's envelope."""
WORKER_SPEED = (1.0, 1.4)
"""m/s; walking speed, uniform per episode."""
WORKER_LANE_Y = (-1.78, -1.74)
"""m; the lane's y (it runs along x, between the floor recesses and the barrier), uniform per episode."""
WORKER_LANE_X = (-1.05, 0.9)
"""m; the lane's ends: clear of the column at -y and of the exterior wall."""
WORKER_START_S = (0.0, 6.0)
"""s; when the worker enters its lane (`moving`), uniform per episode."""
WORKER_PARKED_XY = (0.0, -3.0)
"""m; where the worker stands when not in its lane: outside the barriers, beyond the arm's reach."""
PARKED = (-1.0, -3.0, -20.0, 0.0, 1.0, -3.0)
"""an episode without obstacles (`obstacle_share`): the stack's x, y, top z and yaw, the post's x and y; the stack
buried, the post outside the barriers beyond the arm's reach like the parked worker. A top z below the floor marks
the episode (`obstacles_present`)."""
NEVER = 1e9
"""the control step a parked worker sets off at."""
PLACE_RADIUS = (0.7, 1.7)
"""m; the stack's and the post's distance from the arm's axis, uniform (within the arm's reach)."""
MARGIN = 0.05
"""m; free space kept between obstacles and what they must not overlap."""
CANDIDATES = 512
"""places drawn per obstacle, env and reset; the first that keeps the rules is kept (tests check that one does)."""
OBSTACLE_OBS_SIZE = 11
"""the observation's `obstacles` entry: stack (x, y, top z, cos 2 yaw, sin 2 yaw), post (x, y), worker (x, y, vx,
vy)."""
LAYOUT_SIZE = 11
"""the task state's `obstacle_layout`: stack (x, y, top z, yaw), post (x, y), worker start (x, y), velocity (vx, vy)
and the control step it sets off at."""


def _keep_outs(site: SiteParams) -> tuple[torch.Tensor, torch.Tensor]:
    """Axis-aligned rectangles (x0, y0, x1, y1) no obstacle footprint may overlap: the staging table, the floor
    recesses, the columns, the window fronts (the install approaches), the arm at rest; and, for the post only, the
    ceiling openings' footprints."""
    cx, cy = site.staging_center
    sx, sy = site.staging_size
    rects = [(cx - sx / 2, cy - sy / 2, cx + sx / 2, cy + sy / 2)]
    half = site.floor_panel.size[0] / 2 + site.clearance
    rects += [(x - half, y - half, x + half, y + half) for x, y, _ in site.floor_slots]
    c = site.column_size / 2
    rects += [(x - c, y - c, x + c, y + c) for x, y in site.column_xy]
    rects += [(site.wall_x - 0.55, y - 0.45, site.wall_x, y + 0.45) for y in site.window_ys]
    rects.append((-0.35, -0.35, 0.85, 0.35))
    ceiling = [(x - 0.55, y - 0.55, x + 0.55, y + 0.55) for x, y, _ in site.ceiling_slots]
    return torch.tensor(rects), torch.tensor(ceiling)


def _rect_distance(p: torch.Tensor, rects: torch.Tensor) -> torch.Tensor:
    """[..., R] distance from points p [..., 2] to each rectangle (0 inside)."""
    dx = torch.clamp(torch.maximum(rects[:, 0] - p[..., :1], p[..., :1] - rects[:, 2]), min=0)
    dy = torch.clamp(torch.maximum(rects[:, 1] - p[..., 1:2], p[..., 1:2] - rects[:, 3]), min=0)
    return torch.hypot(dx, dy)


def _segment_distance(p: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Distance from points p [..., 2] to the lane's segment along x at height y [...]."""
    x = p[..., 0].clamp(*WORKER_LANE_X)
    return torch.hypot(p[..., 0] - x, p[..., 1] - y)


R_STACK = float(np.hypot(STACK_SIZE[0], STACK_SIZE[1])) / 2
R_POST = POST_SIZE / np.sqrt(2)
"""m; the radii of the circles around the stack's and the post's footprints, which the rules keep clear."""


def _inside(p: torch.Tensor, r: float, site: SiteParams) -> torch.Tensor:
    x0, y0, x1, y1 = site.barrier_extent[0], -site.barrier_extent[2], site.wall_x, site.barrier_extent[2]
    return (p[..., 0] - r > x0) & (p[..., 0] + r < x1) & (p[..., 1] - r > y0) & (p[..., 1] + r < y1)


def stack_keeps_rules(stack: torch.Tensor, lane_y: torch.Tensor, site: SiteParams) -> torch.Tensor:
    """[...] whether the stack (footprint centres [..., 2]) stands inside the barriers, clear of the keep-outs
    (`_keep_outs`) and of the lane (its y [...])."""
    rects, _ = (t.to(stack.device) for t in _keep_outs(site))
    ok = _inside(stack, R_STACK + MARGIN, site) & (_rect_distance(stack, rects) > R_STACK + MARGIN).all(-1)
    return ok & (_segment_distance(stack, lane_y) > R_STACK + WORKER_RADIUS + MARGIN)


def post_keeps_rules(post: torch.Tensor, lane_y: torch.Tensor, stack: torch.Tensor, site: SiteParams) -> torch.Tensor:
    """[...] whether the post stands inside the barriers, clear of the keep-outs, the ceiling openings, the lane and
    the stack."""
    rects, ceiling = (t.to(post.device) for t in _keep_outs(site))
    ok = _inside(post, R_POST + MARGIN, site) & (_rect_distance(post, rects) > R_POST + MARGIN).all(-1)
    ok &= (_rect_distance(post, ceiling) > R_POST).all(-1)
    ok &= _segment_distance(post, lane_y) > R_POST + WORKER_RADIUS + MARGIN
    return ok & (torch.linalg.norm(post - stack, dim=-1) > R_STACK + R_POST + MARGIN)


def sample_layouts(b: int, site: SiteParams, control_freq: float, device, share: float = 1.0) -> torch.Tensor:
    """[b, LAYOUT_SIZE] obstacle layouts, from torch's generator (ManiSkill seeds it per reset): the lane, then
    CANDIDATES stacks per env, the first that keeps the rules, then CANDIDATES posts, the first that keeps them; with
    `share` < 1, then whether each episode has them (the others PARKED). At share 1 nothing more is drawn: a seed's
    episode is the same as before the option."""
    with torch.device(device):
        def in_ring() -> torch.Tensor:
            r = torch.empty(b, CANDIDATES).uniform_(*PLACE_RADIUS)
            a = torch.rand(b, CANDIDATES) * 2 * torch.pi
            return torch.stack([r * torch.cos(a), r * torch.sin(a)], -1)

        def first(candidates: torch.Tensor, ok: torch.Tensor) -> torch.Tensor:
            return candidates[torch.arange(b), torch.argmax(ok.int(), dim=1)]  # candidate 0 where none keeps them

        lane_y = torch.empty(b).uniform_(*WORKER_LANE_Y)
        stacks = in_ring()
        stack = first(stacks, stack_keeps_rules(stacks, lane_y[:, None], site))
        posts = in_ring()
        post = first(posts, post_keeps_rules(posts, lane_y[:, None], stack[:, None], site))
        stack_h = torch.empty(b).uniform_(*STACK_HEIGHT)
        stack_yaw = torch.rand(b) * torch.pi
        forward = torch.rand(b) < 0.5  # walking towards +x
        start_x = torch.where(forward, torch.tensor(WORKER_LANE_X[0]), torch.tensor(WORKER_LANE_X[1]))
        speed = torch.empty(b).uniform_(*WORKER_SPEED) * torch.where(forward, 1.0, -1.0)
        set_off = torch.floor(torch.empty(b).uniform_(*WORKER_START_S) * control_freq)
        layout = torch.cat([stack, stack_h[:, None], stack_yaw[:, None], post,
                            torch.stack([start_x, lane_y, speed, torch.zeros(b), set_off], -1)], -1)
        if share < 1.0:
            absent = torch.rand(b) >= share
            layout[absent, 0:6] = torch.tensor(PARKED)
            layout[absent, 10] = NEVER
        return layout


def keeps_rules(layout: torch.Tensor, site: SiteParams) -> torch.Tensor:
    """[b] whether each layout [b, LAYOUT_SIZE] keeps every rule of the module docstring."""
    stack, post, lane_y = layout[:, 0:2], layout[:, 4:6], layout[:, 7]
    return stack_keeps_rules(stack, lane_y, site) & post_keeps_rules(post, lane_y, stack, site)


class SiteObstacles:
    """The `obstacles` option of ConstructionTaskEnv (a mixin; the module docstring)."""

    def _init_obstacles(self, obstacles: Optional[str], obs_obstacles: Optional[bool], share: float = 1.0) -> None:
        mode = "none" if obstacles is None else obstacles
        if mode not in OBSTACLE_MODES:
            raise ValueError(f"obstacles={obstacles!r}: use one of {', '.join(map(repr, OBSTACLE_MODES))} (or None)")
        if not 0.0 < share <= 1.0 or (share < 1.0 and mode == "none"):
            raise ValueError(f"obstacle_share={share!r}: the share of episodes with obstacles, in (0, 1], below 1 only "
                             f"with obstacles='static' or 'moving' (obstacles={obstacles!r})")
        self.obstacle_mode = mode
        self.obstacle_share = float(share)
        # None: the entry where there are obstacles; True: always (zeros without them: a policy trained among
        # obstacles on a site without); False: never (a policy trained without them meets them blind)
        self.obs_obstacles = mode != "none" if obs_obstacles is None else bool(obs_obstacles)
        self._ways: Optional[EpisodeWays] = None

    @property
    def has_obstacles(self) -> bool:
        return self.obstacle_mode != "none"

    def _load_obstacles(self) -> None:
        if not self.has_obstacles:
            return
        if self.gpu_sim_enabled:
            raise NotImplementedError("obstacles run on physx_cpu only for now (sim_backend='physx_cpu')")
        if "paneling" in self.TASKS:  # their layout rules know the paper's site, not paneling's partition
            raise NotImplementedError("obstacles are drawn on the paper's three task types' site only, not with paneling")
        site = self._obstacle_site = SiteParams()  # the manifest's (assets.load_manifest checks them equal)
        material = sapien.render.RenderMaterial
        stack = self.scene.create_actor_builder()
        half = np.array(STACK_SIZE) / 2
        stack.add_box_collision(half_size=half)
        stack.add_box_visual(half_size=half, material=material(base_color=[0.62, 0.5, 0.36, 1]))
        post = self.scene.create_actor_builder()
        half = np.array([POST_SIZE / 2, POST_SIZE / 2, site.story_height / 2])
        post.add_box_collision(half_size=half)
        post.add_box_visual(half_size=half, material=material(base_color=[0.55, 0.57, 0.6, 1], metallic=0.8))
        worker = self.scene.create_actor_builder()
        # a cylinder's axis is x in SAPIEN: turned upright at placement
        worker.add_cylinder_collision(radius=WORKER_RADIUS, half_length=WORKER_HEIGHT / 2)
        worker.add_cylinder_visual(radius=WORKER_RADIUS, half_length=WORKER_HEIGHT / 2,
                                   material=material(base_color=[1.0, 0.85, 0.1, 0.8]))
        self.obstacles: dict[str, Actor] = {}
        for name, builder in (("stack", stack), ("post", post), ("worker", worker)):
            builder.initial_pose = sapien.Pose(p=[0, 0, -20])
            self.obstacles[name] = builder.build_kinematic(name=f"obstacle_{name}")
        self._obstacle_entities = {a._objs[0] for a in self.obstacles.values()}
        n = self.num_envs
        self.obstacle_layout = torch.zeros(n, LAYOUT_SIZE, device=self.device)
        self.obstacle_clock = torch.zeros(n, dtype=torch.long, device=self.device)
        self.obstacle_collided = torch.zeros(n, dtype=torch.bool, device=self.device)
        self.obstacle_contact_now = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._worker_upright = torch.tensor([np.sqrt(0.5), 0, np.sqrt(0.5), 0], device=self.device)
        self._worker_parked_xy = torch.tensor(WORKER_PARKED_XY, device=self.device)

    def _place_obstacles(self, env_idx: torch.Tensor) -> None:
        self._ways = None
        if not self.has_obstacles:
            return
        layouts = sample_layouts(len(env_idx), self._obstacle_site, self.control_freq, self.device, self.obstacle_share)
        self.obstacle_layout[env_idx] = layouts
        self.obstacle_clock[env_idx] = 0
        self.obstacle_collided[env_idx] = False
        self.obstacle_contact_now[env_idx] = False
        self._pose_obstacles()

    def _pose_obstacles(self) -> None:
        """Every obstacle at its place by the layout and the clock."""
        lay = self.obstacle_layout
        stack_z = lay[:, 2] - STACK_SIZE[2] / 2
        stack = torch.cat([lay[:, 0:2], stack_z[:, None], quat_z(torch.rad2deg(lay[:, 3]))], -1)
        post_z = torch.full_like(lay[:, 0], self._obstacle_site.story_height / 2)
        post = torch.cat([lay[:, 4:6], post_z[:, None], quat_z(torch.zeros_like(post_z))], -1)
        self.obstacles["stack"].set_pose(Pose.create(stack))
        self.obstacles["post"].set_pose(Pose.create(post))
        self._pose_worker()

    def _pose_worker(self) -> None:
        """The worker at its place by the layout and the clock (the stack and the post stay where an episode put
        them: per control step only the worker moves), and its place and velocity as the observation gives them
        until it moves again (`_worker_now`, [n, 4]: worked out once per step rather than again for the
        observation)."""
        n = len(self.obstacle_layout)
        upright = self._worker_upright.expand(n, 4)
        worker_z = torch.full((n, 1), WORKER_HEIGHT / 2, device=self.device)
        xy = self.worker_xy()
        self._worker_now = torch.cat([xy, self.worker_velocity()], -1)
        self.obstacles["worker"].set_pose(Pose.create(torch.cat([xy, worker_z, upright], -1)))

    def obstacles_present(self) -> torch.Tensor:
        """[n] whether each env's episode has its obstacles on the site (not PARKED: `obstacle_share`)."""
        return self.obstacle_layout[:, 2] > 0

    def worker_walking(self, clock: Optional[torch.Tensor] = None) -> torch.Tensor:
        """[n] whether the worker is in its lane at control step `clock` of the episode (default: now)."""
        lay = self.obstacle_layout
        clock = self.obstacle_clock if clock is None else clock
        t = (clock.float() - lay[:, 10]) / self.control_freq
        crossing = (WORKER_LANE_X[1] - WORKER_LANE_X[0]) / lay[:, 8].abs().clamp(min=1e-6)
        return (t >= 0) & (t <= crossing) & (self.obstacle_mode == "moving")

    def worker_xy(self, clock: Optional[torch.Tensor] = None) -> torch.Tensor:
        """[n, 2] the worker's place at control step `clock` of the episode (default: now)."""
        lay = self.obstacle_layout
        clock = self.obstacle_clock if clock is None else clock
        t = ((clock.float() - lay[:, 10]) / self.control_freq).clamp(min=0)
        lane = torch.stack([lay[:, 6] + lay[:, 8] * t, lay[:, 7] + lay[:, 9] * t], -1)
        return torch.where(self.worker_walking(clock)[:, None], lane, self._worker_parked_xy.expand_as(lane))

    def worker_velocity(self) -> torch.Tensor:
        """[n, 2] m/s; the worker's velocity now (0 outside its lane)."""
        return torch.where(self.worker_walking()[:, None], self.obstacle_layout[:, 8:10], 0.0)

    def _advance_obstacles(self) -> None:
        """After a control step: the clock on, the worker to its next place (`moving`), the step's contacts read."""
        if not self.has_obstacles:
            return
        self.obstacle_clock += 1
        if self.obstacle_mode == "moving":
            self._pose_worker()
        self.obstacle_contact_now = self._obstacle_contacts()
        self.obstacle_collided |= self.obstacle_contact_now

    def _obstacle_contacts(self) -> torch.Tensor:
        """[n] whether anything (the arm or an element: nothing else collides with a kinematic body) touches an
        obstacle at the end of the control step's physics."""
        ents = self._obstacle_entities
        for c in self.scene.px.get_contacts():
            a, b = c.bodies[0].entity, c.bodies[1].entity
            if (a in ents) != (b in ents) and any(p.separation < 2e-3 for p in c.points):
                return torch.ones(1, dtype=torch.bool, device=self.device)
        return torch.zeros(1, dtype=torch.bool, device=self.device)

    def clear_paths(self) -> Optional[torch.Tensor]:
        """[n, M] bool: which start paths of each env's goal slot (`CarryGeometry.paths`) keep the arm and its element
        clear of the stack and the post as they stand, a searched via's among them (`obstacle_ways`); None without
        obstacles. The dense reward measures the carry along the usable ones of those, where any is, else along the
        clear detours (`CarryGeometry.usable`), so that it does not lead the arm into them."""
        ways = self.obstacle_ways()
        return None if ways is None else ways.clear

    def obstacle_ways(self) -> Optional[EpisodeWays]:
        """The start paths of each env's goal slot as this episode has them among its obstacles (None without them),
        once per episode when first asked: which keep clear of the stack and the post (checked as the start paths are
        against the site, goal_configurations: the same points, turns and margins; the walking worker is left out, as
        it is outside the cell at the start), and, for a turret side whose usable paths they block all of, a via
        around them searched for that side's paths (`_search_vias`): the carry is paid along a clear way from the
        side the element is usually grasped from, as the site as built pays it, rather than only along a detour from
        the other side or into the obstacles. An episode without them (`obstacle_share`) has every path clear."""
        if not self.has_obstacles:
            return None
        if self._ways is None:
            n_paths = self.geometry.paths["waypoints"].shape[2]
            present = bool(self.obstacles_present().all())
            clear = (self._check_paths() if present
                     else torch.ones(self.num_envs, n_paths, dtype=torch.bool, device=self.device))
            self._ways = self.geometry.episode_ways(self.task_id, self.goal_slot, clear,
                                                    self._search_vias(clear) if present else {})
        return self._ways

    def _search_vias(self, clear: torch.Tensor) -> dict[tuple[int, int], np.ndarray]:
        """{(env, path): via} for each turret side of the episode's goal slot that has usable start paths, none of them
        clear (`clear` [1, M]): a via that makes one of them clear among the site and the stack and the post
        (goal_configurations.search_via), from a generator seeded by the task type, the goal slot and the layout, so
        that the episode's ways are the same in every process, in a replay and after `set_state_dict`. A side where
        none is found keeps its blocked paths (the detours stay)."""
        from ms_construction.goal_configurations import START_TURNS_DEG, search_via

        kind, slot = int(self.task_id[0]), int(self.goal_slot[0])
        usable = self.geometry.paths["usable"][kind, slot].cpu().numpy()
        clear = clear[0].cpu().numpy()
        waypoints = self.geometry.paths["waypoints"][kind, slot].cpu().numpy().astype(np.float64)
        turns = [float(np.deg2rad(t)) for t in START_TURNS_DEG]
        limits = self.agent.robot.get_qlimits()[0].cpu().numpy().astype(np.float64).T
        layout = self.obstacle_layout[0].cpu().numpy().astype(np.float32).view(np.uint32)
        rng = np.random.default_rng([kind, slot, *layout.tolist()])
        vias = {}
        for side in (0, 1):
            paths = [m for m in range(side, len(usable), 2) if usable[m]]
            if not paths or clear[paths].any():
                continue
            ends = [tuple(waypoints[m][[0, 1, 3, 4]]) for m in paths]  # install, back-off, lift, table
            found = search_via(self._path_planners(kind, with_site=True), ends, turns, rng, limits)
            if found is not None:
                vias[0, paths[found[0]]] = found[1]
        return vias

    def _check_paths(self) -> torch.Tensor:
        """[1, M]: `_clear_fraction(...) == 1` of goal_configurations for each start path of the episode's goal slot
        with the stack and the post in the planners' world, computed in two halves with the same result: whether the
        arm collides with itself at each checked point is the same in every episode, so it is checked once per goal
        slot (`_path_points`), and each episode checks only the obstacles, at the points of the paths clear of the
        arm itself, coarse to fine (a blocked path is found after a few checks)."""
        kind, slot = int(self.task_id[0]), int(self.goal_slot[0])
        planners = self._path_planners(kind)
        points, self_clear = self._path_points(kind, slot)
        clear = [bool(free) and not any(planner.world.set_qpos_all(q) or planner.world.collide_with_others()
                                        for q_turns in path for planner, q in zip(planners, q_turns))
                 for path, free in zip(points, self_clear)]
        return torch.tensor([clear], device=self.device)

    def _path_planners(self, kind: int, with_site: bool = False) -> list:
        """goal_configurations' path checkers (one per START_TURNS_DEG) for task type `kind`, made once per env, with
        the stack and the post where they stand now: the arm holding its element among them alone (the start paths
        were checked against the site when they were made), or `with_site` among the site's collision parts too (for
        a via's search)."""
        from ms_construction.assets import load_manifest
        from ms_construction.goal_configurations import _path_planners
        from ms_construction.parameters import ELEMENT_KINDS
        from ms_construction.planning.collision_model import obstacle_objects, site_collision_objects

        if not hasattr(self, "_path_checkers"):
            self._path_checkers_dir = tempfile.TemporaryDirectory(prefix="ms_construction_obstacles_")
            self._path_checkers, self._path_point_cache = {}, {}
        if (kind, with_site) not in self._path_checkers:
            site = site_collision_objects(load_manifest(), (ELEMENT_KINDS[kind],)) if with_site else {}
            folder = Path(self._path_checkers_dir.name) / ("site" if with_site else "obstacles")
            folder.mkdir(exist_ok=True)
            self._path_checkers[kind, with_site] = _path_planners(folder, ELEMENT_KINDS[kind], site)
        planners = self._path_checkers[kind, with_site]
        for key, obj in obstacle_objects(self).items():
            if key != "obstacle_worker":
                for planner in planners:
                    planner.set_obstacle(key, obj)
        return planners

    def _path_points(self, kind: int, slot: int) -> tuple[np.ndarray, np.ndarray]:
        """The checked configurations of goal slot `slot`'s start paths, [M, PATH_CHECKS + 1, turns, 6] with the
        points coarse to fine, and [M] whether the arm holding its element keeps clear of itself at all of them
        (`self_collide`: the world's obstacles play no part); once per goal slot and env."""
        from ms_construction.goal_configurations import PATH_CHECKS, START_TURNS_DEG, path_point

        planners = self._path_planners(kind)
        if (kind, slot) not in self._path_point_cache:
            i = np.arange(1, PATH_CHECKS + 2)
            order = np.argsort(-(i & -i), kind="stable")  # by the largest power of two dividing i
            fractions = np.linspace(0.0, 1.0, PATH_CHECKS + 1)[order]
            turns = np.deg2rad(START_TURNS_DEG)
            waypoints = self.geometry.paths["waypoints"][kind, slot].cpu().numpy().astype(float)
            points = np.array([[[path_point(path, a) + np.eye(6)[5] * t for t in turns] for a in fractions]
                               for path in waypoints])
            self_clear = np.array([not any(planner.world.set_qpos_all(q) or planner.world.self_collide()
                                           for q_turns in path for planner, q in zip(planners, q_turns))
                                   for path in points])
            self._path_point_cache[kind, slot] = points, self_clear
        return self._path_point_cache[kind, slot]

    def obstacle_observation(self) -> torch.Tensor:
        """[n, OBSTACLE_OBS_SIZE] (the module's OBSTACLE_OBS_SIZE says what); zeros without obstacles."""
        if not self.has_obstacles:
            return torch.zeros(self.num_envs, OBSTACLE_OBS_SIZE, device=self.device)
        lay = self.obstacle_layout
        two_yaw = 2 * lay[:, 3]  # the box looks the same turned half a turn
        obs = torch.cat([lay[:, 0:3], torch.cos(two_yaw)[:, None], torch.sin(two_yaw)[:, None], lay[:, 4:6],
                         self._worker_now], -1)
        return torch.where(self.obstacles_present()[:, None], obs, 0.0)

    def obstacle_info(self) -> dict:
        if not self.has_obstacles:
            return {}
        return dict(obstacle_collision=self.obstacle_contact_now.clone(), fail=self.obstacle_collided.clone())

    def obstacle_state(self) -> dict:
        if not self.has_obstacles:
            return {}
        return dict(obstacle_layout=self.obstacle_layout.clone(), obstacle_clock=self.obstacle_clock[:, None].clone(),
                    obstacle_collided=self.obstacle_collided[:, None].clone(),
                    obstacle_contact_now=self.obstacle_contact_now[:, None].clone())
