"""The motion-planning expert: solves a seeded episode of any construction task, phase by phase.

1. approach: RRTConnect to a pre-grasp pose facing the grasp face, just outside tau_pick;
2. descend: a straight tcp line towards the face until the grasp triggers, then wait for the pull;
3. lift: a straight tcp line up, clear of the table;
4. carry: RRTConnect, the element now part of the arm's collision model at its actual hold pose,
   to a pre-install pose backed off from the goal along the plate's axis;
5. install: a straight tcp line into the opening, until the task reports success.

With the tasks' `obstacles` option the obstacles where they stand are part of every collision model. With a
walking worker (`obstacles="moving"`) the expert watches the next `worker_lookahead` of its path against the
worker's envelope swept that far ahead at its velocity now: where they meet, it replans the phase's sampled path
around the swept envelope (approach, carry) or, on a straight line or where no path is found, holds still until the
way is clear.

Plans run on mplib 0.1.1 (OMPL RRTConnect, FCL) against the committed site collision parts with a
safety margin; every time-parameterized trajectory is checked again, densely, before it runs.
The install tcp pose is `goal * symmetry * hold^-1` for the element's actual hold pose, over the
element's symmetric goal rotations, the reachable one nearest to the arm chosen (or, with
`branch_preference="fixed"`, the one nearest to a fixed reference configuration, and so for the pre-grasp
configurations: the same goal slot is then reached the same way whichever way the arm happens to stand).
The env must be a single physx_cpu env in pd_joint_pos control; every action is an absolute joint
target at the control rate, so a recorded episode replays from its actions. (`planning/demos.py`
puts it in front of a pd_joint_delta_pos env to record the learner's actions.)
"""

from __future__ import annotations

import tempfile
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import sapien
import torch
from transforms3d.euler import euler2quat

from ms_construction.agents.construction_arm import REST_QPOS
from ms_construction.parameters import SYMMETRIES_DEG
from ms_construction.kinematics import ArmIK
from ms_construction.planning.arm_planner import ArmPlanner
from ms_construction.planning.collision_model import (
    box_object,
    obstacle_objects,
    planning_srdf,
    planning_urdf,
    site_collision_objects,
)
from ms_construction.planning.trajectory import tcp_line, time_parameterize
from ms_construction.parameters import ELEMENT_KINDS


BRANCH_PREFERENCES = ("nearest", "fixed")
FIXED_REFERENCE = REST_QPOS + np.array([-0.5, 0, 0, 0, 0, 0])
"""the `fixed` branch preference's reference: the rest pose with the base turned a little to one side, so that
the two ways of turning to a pick behind the arm (+-pi) are never a tie."""


@dataclass(frozen=True)
class ExpertConfig:
    arm_margin: float = 0.02
    """m; moving links are inflated by this much for the sampled paths (tracking lag, thin parts)."""
    element_margin: float = 0.02
    """m; a held element is inflated by this much (but not through the plate) for the sampled paths.
    An installed ceiling panel's corner is 3.4 cm from the exterior wall (slot 0)."""
    exact_shrink: float = 0.002
    """m; for the straight lines the element is this much smaller than it is, so that an element
    flush in its opening (the floor recess's bottom, a hull's 1 mm tolerance) does not count as hit."""
    pregrasp_clearance: float = 0.05
    """m; the approach ends this far beyond tau_pick from the grasp face (no grasp on the way)."""
    descend_to: float = 0.02
    """m above the face where the descent would end; the grasp triggers long before at cp1..cp4."""
    lift: float = 0.15
    """m; straight up after the grasp."""
    install_standoff: float = 0.25
    """m; the pre-install pose is backed off from the installed one this far along the plate axis."""
    install_overrun: float = 0.02
    """m; the install line must be free this far past the point where the element counts as placed."""
    speed: float = 0.8
    """fraction of the arm's joint velocity limits for sampled paths."""
    max_joint_step: Optional[float] = None
    """rad; if set, no joint's target moves more than this per control step on sampled paths, whatever `speed`
    allows: the learner's delta actions move a target at most 0.1 rad per step, which caps the wrist joints (the
    fastest) long before the shoulder, so that the shoulder joints may keep a higher fraction of their limits."""
    acceleration: float = 2.0
    """joint acceleration limits, in (rad/s^2) per (rad/s) of velocity limit."""
    line_speed: float = 0.35
    """fraction of the velocity limits on straight tcp lines (descend, lift, install)."""
    direct_first: bool = False
    """try paths that need no sampling first (`_direct_paths`: the straight joint move to each goal configuration,
    then two with one corner), RRTConnect only where they all collide: the same start and goal then give the same
    path (RRTConnect's wander, differently every time, and a clone of the demonstrations averages them)."""
    rrt_time: float = 1.0
    """s; time limit of one RRTConnect call."""
    rrt_attempts: int = 4
    """RRTConnect calls per goal configuration: the quickest checked path is kept, and the next
    candidate goal is tried only if none is found."""
    good_enough: float = 1.5
    """no further RRTConnect calls once a path takes at most this times the straight joint move."""
    goal_candidates: int = 4
    """IK solutions tried as goals of one phase, nearest first."""
    ik_seeds: int = 48
    """random IK restarts (besides the current and the rest configuration)."""
    settle_tol: float = 0.01
    """rad; after a sampled path the arm is waited for until it is this close to its target ..."""
    settle_steps: int = 6
    """... for at most this many control steps."""
    pull_steps: int = 10
    """control steps at most to wait for the grasped element to reach the plate."""
    worker_lookahead: float = 1.0
    """s; with a walking worker, how far ahead the path is watched against the worker's swept envelope."""
    escape_distance: float = 0.3
    """m; how far the tcp steps aside (or up) out of the walking worker's way, where the worker comes at the arm."""
    worker_margin: float = 0.05
    """m; the worker's swept envelope is grown by this much (the arm lags its targets)."""
    replan_every: int = 5
    """control steps between replanning attempts while the way is blocked (holding still in between)."""
    branch_preference: str = "nearest"
    """which of several reachable configurations (IK branches, base turns, symmetric goals) a phase heads for:
    `nearest` to the arm, the quickest (the shipped clone's demonstrations), or `fixed`: nearest to
    FIXED_REFERENCE whatever the arm's configuration, so that a goal slot is always reached the same way. With
    `nearest`, near-ties (a pick behind the arm, two wrist branches at a window) go either way from episode to
    episode, and a behaviour clone learns the average of the two where they part (docs/experiments/general_agent.md)."""

    def __post_init__(self):
        if self.branch_preference not in BRANCH_PREFERENCES:
            raise ValueError(f"branch_preference {self.branch_preference!r}: use one of {', '.join(BRANCH_PREFERENCES)}")


@dataclass
class EpisodeResult:
    seed: int
    task: str
    picked: bool
    placed: bool
    steps: int
    planning_time: float
    """s of wall time spent in IK, planning, time parameterization and checks."""
    failure: str = ""
    """'phase: what happened' when not placed."""
    phase_steps: dict = field(default_factory=dict)
    """control steps spent in each phase."""
    collisions: int = 0
    """control steps that ended with the arm or the element touching an obstacle (the tasks' `obstacles`)."""
    replans: int = 0
    """sampled paths planned again because the worker's envelope blocked the one being followed."""
    waited_steps: int = 0
    """control steps held still while the worker blocked the way."""
    escapes: int = 0
    """times the arm got out of the walking worker's way (towards its rest pose) before replanning."""
    goal_slot: int = -1
    """the episode's goal slot (its task type's opening, recess or bay)."""

    def to_dict(self) -> dict:
        return asdict(self)


class PhaseFailure(Exception):
    """A phase found no way to go on."""


def _pose(raw) -> sapien.Pose:
    t = raw.detach().cpu().numpy().reshape(-1)[:7] if torch.is_tensor(raw) else np.asarray(raw).reshape(-1)
    return sapien.Pose(t[:3], t[3:])


def _rz(deg: float) -> sapien.Pose:
    return sapien.Pose(q=euler2quat(0, 0, np.deg2rad(deg)))


class MotionPlanningExpert:
    """Solves episodes of a (RecordEpisode-wrapped) construction env; see the module docstring."""

    def __init__(self, env, config: ExpertConfig = ExpertConfig()):
        self.env, self.u, self.cfg = env, env.unwrapped, config
        takes_targets = self.u.control_mode == "pd_joint_pos" or getattr(env, "accepts_joint_targets", False)
        if not takes_targets or self.u.num_envs != 1:
            raise ValueError("the expert drives one env in pd_joint_pos control (or one wrapped by "
                             "ms_construction.planning.demos.JointTargetsAsDeltas)")
        self.ik = ArmIK(self.u.agent.robot)
        manifest = self.u.site.manifest
        vmax = np.asarray(manifest["arm_params"]["velocity"], float)
        self.vmax = vmax
        self.dt = 1.0 / self.u.control_freq
        self.vel, self.acc = config.speed * vmax, config.acceleration * vmax
        if config.max_joint_step is not None:
            self.vel = np.minimum(self.vel, config.max_joint_step / self.dt)
        self.grasp_in_el = {k: _pose(manifest["elements"][k]["grasp_pose"]) for k in ELEMENT_KINDS}
        self.el_size = {k: np.asarray(manifest["elements"][k]["size"], float) for k in ELEMENT_KINDS}
        self._tmp = tempfile.TemporaryDirectory(prefix="ms_construction_planning_")
        self.workdir = Path(self._tmp.name)
        self.site = site_collision_objects(manifest, self.u.TASKS)
        # the free arm: inflated for sampling, exact for the descent onto the element
        self.free = ArmPlanner(planning_urdf(config.arm_margin), planning_srdf(False), self.workdir, "free", self.site)
        self.free_exact = ArmPlanner(planning_urdf(0.0), planning_srdf(False), self.workdir, "free_exact", self.site)
        # with a walking worker: the arm among nothing but the worker's swept envelope, for watching the path ahead
        self.moving = self.u.has_obstacles and self.u.obstacle_mode == "moving"
        if self.moving:
            self.free_watch = ArmPlanner(planning_urdf(config.arm_margin), planning_srdf(False), self.workdir,
                                         "free_watch", {})

    def close(self) -> None:
        self._tmp.cleanup()

    # ------------------------------------------------------------------------------------- #
    # episode
    # ------------------------------------------------------------------------------------- #
    def run(self, seed: int) -> EpisodeResult:
        """Reset the env with `seed` and solve the episode."""
        self.env.reset(seed=seed)
        return self.solve(seed)

    def solve(self, seed: int) -> EpisodeResult:
        """Solve the episode from the env's current state: a fresh reset, or a state a policy led to
        (a takeover). With the element already held, the approach and descent are skipped, and the
        lift is skipped where its straight line up is not free (a policy may be carrying it already)."""
        u = self.u
        self.kind = ELEMENT_KINDS[int(u.task_id[0])]
        self.steps, self.plan_time, self.info, self.phase_steps, self.phase = 0, 0.0, {}, {}, "approach"
        self.q = u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)
        self.rng = np.random.default_rng(seed)
        self.held_at_start, self.ended = bool(u.held[0]), False
        self.collisions, self.replans, self.waited_steps, self.escapes = 0, 0, 0, 0
        self.watch, self.replan = (self.free_watch if self.moving else None), None
        phases = [("approach", self._approach), ("descend", self._descend), ("lift", self._lift),
                  ("carry", self._carry), ("install", self._install)]
        failure = ""
        try:
            self._set_obstacles()
            for name, phase in phases[1:] if self.held_at_start else phases:
                with self._phase(name):
                    phase()
                if self.ended:  # success ends the episode, and so does the time limit
                    break
        except PhaseFailure as e:
            failure = str(e)
        placed = bool(self.info.get("success"))
        if not placed and not failure:
            failure = (f"{self.phase}: touched an obstacle at step {self.steps}" if self.info.get("fail") else
                       f"{self.phase}: the episode was truncated after {self.steps} steps" if self.ended else
                       f"install: no success at the end of the line (element {self.info['place_dist']:.3f} m, "
                       f"{self.info['place_angle_deg']:.1f} deg from the goal, held {self.info['is_grasped']})")
        return EpisodeResult(seed=seed, task=self.kind, picked=bool(u.picked[0]), placed=placed, steps=self.steps,
                             planning_time=self.plan_time, failure=failure, phase_steps=self.phase_steps,
                             collisions=self.collisions, replans=self.replans, waited_steps=self.waited_steps,
                             escapes=self.escapes, goal_slot=int(u.goal_slot[0]))

    # ------------------------------------------------------------------------------------- #
    # phases
    # ------------------------------------------------------------------------------------- #
    def _approach(self) -> None:
        cfg, u = self.cfg, self.u
        pre = self._grasp_pose() * sapien.Pose([0, 0, -(float(u.tau_pick[0]) + cfg.pregrasp_clearance)])
        with self._planning():
            goals = self._pregrasp_goals(pre)
        _, traj = self._plan_when_clear(self.free, goals, "approach")
        self.replan = lambda: self._plan(self.free, goals, "approach", quick=True)[1]
        self._follow(traj, until=lambda: bool(u.held[0]))
        self.replan = None
        if not bool(u.held[0]):
            self._settle()

    def _descend(self) -> None:
        """A straight line towards the grasp face until the grasp triggers (unless the approach
        ended inside the grasp range, or the element was held from the start), then the pull."""
        if not bool(self.u.held[0]):
            self._descend_line()
        if not self.ended:
            self._await_pull()

    def _descend_line(self) -> None:
        u = self.u
        with self._planning():
            line = tcp_line(self.ik, self.q, self._grasp_pose() * sapien.Pose([0, 0, -self.cfg.descend_to]))
            if line is None:
                raise PhaseFailure("descend: no IK along the line to the grasp face")
            self._check_free(self.free_exact, line, "descend")
            traj = time_parameterize(line, self.cfg.line_speed * self.vmax, self.acc, self.dt)
        self._follow(traj, until=lambda: bool(u.held[0]))
        if not bool(u.held[0]) and not self.ended:
            raise PhaseFailure(f"descend: no grasp (ray distance {float(u.grasp_ray()[0][0]):.3f} m)")

    def _await_pull(self) -> None:
        """Hold still while the grasped element is pulled onto the plate."""
        u = self.u
        for _ in range(self.cfg.pull_steps):
            held_at = _pose(u.agent.tcp_pose.raw_pose) * _pose(u.hold_pose_in_tcp)
            if np.linalg.norm(held_at.p - _pose(u.obj.pose.raw_pose).p) < 0.005:
                return
            if self._step(self.q):
                return

    def _lift(self) -> None:
        """Straight up; a takeover that starts held may skip it where the line up is not free."""
        self.loaded, self.loaded_exact = self._loaded_planners()
        if self.moving:
            hold, size = _pose(self.u.hold_pose_in_tcp), self.el_size[self.kind]
            with self._planning():
                self.watch = ArmPlanner(planning_urdf(self.cfg.arm_margin, size, hold, self.cfg.element_margin),
                                        planning_srdf(True), self.workdir, "loaded_watch", {})
        try:
            self._lift_line()
        except PhaseFailure:
            if not self.held_at_start:
                raise

    def _lift_line(self) -> None:
        tcp = self.ik.fk(self.q)
        with self._planning():
            line = tcp_line(self.ik, self.q, sapien.Pose(tcp.p + [0, 0, self.cfg.lift], tcp.q))
            if line is None:
                raise PhaseFailure("lift: no IK along the line up")
            self._check_free(self.loaded_exact, line, "lift")
            traj = time_parameterize(line, self.cfg.line_speed * self.vmax, self.acc, self.dt)
        self._follow(traj)

    def _carry(self) -> None:
        """Carry to the pre-install pose; keeps the joint targets of the install line from there."""
        loaded, loaded_exact = self.loaded, self.loaded_exact
        with self._planning():
            lines = self._install_lines(loaded, loaded_exact)
            installs = [time_parameterize(line, self.cfg.line_speed * self.vmax, self.acc, self.dt) for line in lines]

        def budget() -> int:
            """What is left of the episode once the install line and the waits are done (after any wait for the
            worker)."""
            return self.u.MAX_EPISODE_STEPS - self.steps - max(map(len, installs)) - 2 * self.cfg.settle_steps

        i, traj = self._plan_when_clear(loaded, [line[0] for line in lines], "carry", budget)
        self.install_traj = installs[i]

        def replan() -> np.ndarray:
            i, traj = self._plan(loaded, [line[0] for line in lines], "carry", quick=True)
            self.install_traj = installs[i]
            return traj

        self.replan = replan
        self._follow(traj)
        self.replan = None
        self._settle()

    def _install(self) -> None:
        """Along the install line until the task reports success (which ends the episode)."""
        self._follow(self.install_traj)
        self._settle()

    # ------------------------------------------------------------------------------------- #
    # goals
    # ------------------------------------------------------------------------------------- #
    def _seeds(self, ref: np.ndarray) -> list[np.ndarray]:
        return [ref, REST_QPOS] + [self.rng.uniform(self.ik.lower, self.ik.upper) for _ in range(self.cfg.ik_seeds)]

    def _turns(self, q: np.ndarray, joint: int) -> list[np.ndarray]:
        """`q` and its copies with `joint` turned by whole turns, within the joint's limits."""
        out = []
        for k in (-2, -1, 0, 1, 2):
            v = q.copy()
            v[joint] += 2 * np.pi * k
            if self.ik.lower[joint] <= v[joint] <= self.ik.upper[joint]:
                out.append(v)
        return out

    def _nearest_turns(self, q: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """`q` with every joint turned by whole turns to lie nearest `ref` (same arm pose)."""
        q = q.copy()
        for j in range(len(q)):
            q[j] = min(self._turns(q, j), key=lambda v: abs(v[j] - ref[j]))[j]
        return q

    def _travel(self, a: np.ndarray, b: np.ndarray, joints=slice(None)) -> float:
        """s a joint move takes at the velocity limits (the slowest joint's time)."""
        return float(np.max(np.abs(a - b)[joints] / self.vel[joints]))

    def _pregrasp_goals(self, pre: sapien.Pose) -> list[np.ndarray]:
        """Collision-free configurations at `pre` up to the rotation about the plate axis (joint 6
        stays where it is, which fixes the grasp's yaw), ranked by the time to reach them plus the
        time from them to the installation (whose joints 1-5 do not depend on that yaw)."""
        goal = _pose(self.u.goal_pose.raw_pose)
        installs = self.ik.solve_all(goal * self.grasp_in_el[self.kind], self._seeds(self.q))
        goals = []
        for sol in self.ik.solve_all(pre, self._seeds(self.q)):
            sol[5] = self.q[5]
            for g in self._turns(sol, 0):
                if self.free.collides(g):
                    continue
                if self.cfg.branch_preference == "fixed":
                    goals.append((self._preference(g), g))
                    continue
                onward = min((self._travel(g, self._nearest_turns(i, g), slice(0, 5)) for i in installs), default=0.0)
                goals.append((self._travel(self.q, g) + onward, g))
        return [g for _, g in sorted(goals, key=lambda t: t[0])]

    def _preference(self, q: np.ndarray) -> float:
        """The `fixed` branch preference's rank of a configuration: its summed joint moves from FIXED_REFERENCE,
        each in seconds at the velocity limits (a sum, so that every joint's branch counts, not the slowest's)."""
        return float(np.sum(np.abs(q - FIXED_REFERENCE) / self.vmax))

    def _install_lines(self, loaded: ArmPlanner, loaded_exact: ArmPlanner) -> list[np.ndarray]:
        """Joint paths of the straight install approach (pre-install first), over the element's
        symmetric goal rotations and IK branches, for the actual hold pose; nearest first."""
        u, cfg = self.u, self.cfg
        hold = _pose(u.hold_pose_in_tcp)
        goal = _pose(u.goal_pose.raw_pose)
        # the episode ends once the element is within tau_place of its goal: the line beyond that
        # is never driven (but for the arm's lag), so it need not be free
        driven_to = float(u.tau_place[0]) - cfg.install_overrun
        lines, rejected = [], set()
        for sym in SYMMETRIES_DEG[self.kind]:
            at_goal = goal * _rz(sym) * hold.inv()
            back = at_goal * sapien.Pose([0, 0, -cfg.install_standoff])
            sols = [self._nearest_turns(sol, self.q) for sol in self.ik.solve_all(at_goal, self._seeds(self.q))]
            for i, sol in enumerate(sols):
                if any(np.allclose(sol, other) for other in sols[:i]):
                    continue
                line = tcp_line(self.ik, sol, back)
                if line is None:
                    rejected.add("no IK along the line")
                elif loaded.collides(line[-1]):
                    rejected.add(f"pre-install pose hits {', '.join(loaded.contacts(line[-1]))}")
                elif (hit := loaded_exact.collision_on(
                        line[np.linspace(0.0, cfg.install_standoff, len(line)) >= driven_to])) is not None:
                    rejected.add(f"line hits {', '.join(loaded_exact.contacts(hit))}")
                else:
                    lines.append(line[::-1])
        if not lines:
            raise PhaseFailure(f"carry: no install approach ({'; '.join(sorted(rejected)) or 'no IK at the goal'})")
        if self.cfg.branch_preference == "fixed":
            return sorted(lines, key=lambda line: self._preference(line[-1]))
        return sorted(lines, key=lambda line: self._travel(self.q, line[0]))

    # ------------------------------------------------------------------------------------- #
    # planning
    # ------------------------------------------------------------------------------------- #
    @contextmanager
    def _phase(self, name: str):
        start, self.phase = self.steps, name
        try:
            yield
        finally:
            self.phase_steps[name] = self.steps - start

    @contextmanager
    def _planning(self):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.plan_time += time.perf_counter() - t

    def _plan(self, planner: ArmPlanner, goals: list[np.ndarray], phase: str,
              max_steps: Optional[int] = None, quick: bool = False) -> tuple[int, np.ndarray]:
        """(index of the goal, joint targets at the control rate) along an RRTConnect path to the
        first reachable of `goals`, checked densely for collisions after time parameterization and
        taking at most `max_steps` control steps; `quick` (a replan while the arm waits): one RRTConnect call per
        goal, for the two first goals."""
        self._place_worker(planner)
        if planner.collides(self.q):
            raise PhaseFailure(f"{phase}: start in collision ({', '.join(planner.contacts(self.q))})")
        if not goals:
            raise PhaseFailure(f"{phase}: no collision-free goal configuration")
        for i, goal in enumerate(goals[: 2 if quick else self.cfg.goal_candidates]):
            best, direct = None, len(time_parameterize(np.array([self.q, goal]), self.vel, self.acc, self.dt))
            for path in self._direct_paths(goal) if self.cfg.direct_first else []:
                traj = time_parameterize(path, self.vel, self.acc, self.dt)
                if len(traj) <= (max_steps or np.inf) and not planner.path_collides(np.vstack([self.q, traj])):
                    return i, traj
            for _ in range(1 if quick else self.cfg.rrt_attempts):
                path = planner.rrt_connect(self.q, goal, self.cfg.rrt_time)
                if path is None:
                    continue
                path = planner.shortcut(path)
                traj = time_parameterize(path, self.vel, self.acc, self.dt)
                if planner.path_collides(np.vstack([self.q, traj])):
                    continue
                if best is None or len(traj) < len(best):
                    best = traj
                if len(best) <= min(self.cfg.good_enough * direct, max_steps or np.inf):
                    break
            if best is not None and len(best) <= (max_steps or np.inf):
                return i, best
        raise PhaseFailure(f"{phase}: RRTConnect found no collision-free path"
                           + (f" within {max_steps} steps" if max_steps is not None else ""))

    def _direct_paths(self, goal: np.ndarray) -> list[np.ndarray]:
        """Joint polylines to `goal` that need no sampling (`direct_first`): straight, then through one corner, the
        shoulder and elbow (joints 1 and 2: the element's height and reach) moved last or first."""
        turn_first, lift_first = goal.copy(), self.q.copy()
        turn_first[1:3], lift_first[1:3] = self.q[1:3], goal[1:3]
        return [np.array([self.q, goal]), np.array([self.q, turn_first, goal]), np.array([self.q, lift_first, goal])]

    def _check_free(self, planner: ArmPlanner, path: np.ndarray, phase: str) -> None:
        """A straight line's collision check: the exact planners hold the static obstacles, not the walking worker
        (`_follow` watches it while the line is driven)."""
        hit = planner.collision_on(path)
        if hit is not None:
            raise PhaseFailure(f"{phase}: the straight line collides ({', '.join(planner.contacts(hit))})")

    def _standing_obstacles(self) -> dict:
        """The obstacles as they stand, for the collision models; a walking worker is not among them: `_plan` puts
        its swept envelope into the planner it samples with, and `_follow` watches it."""
        return {k: v for k, v in obstacle_objects(self.u).items() if not (self.moving and k == "obstacle_worker")}

    def _place_worker(self, planner: ArmPlanner) -> None:
        """A walking worker's envelope, where it stands and swept `worker_lookahead` ahead, into `planner`."""
        if self.moving:
            swept = obstacle_objects(self.u, self.cfg.worker_lookahead, margin=self.cfg.worker_margin)
            planner.set_obstacle("obstacle_worker", swept["obstacle_worker"])

    def _set_obstacles(self) -> None:
        """Every element where it lies: on the table (this episode's, but not for the descent, whose
        plate meets it) or in storage (the general task's others); the site's obstacles where they stand."""
        for key, obj in self._standing_obstacles().items():
            self.free.set_obstacle(key, obj)
            self.free_exact.set_obstacle(key, obj)
        self._place_worker(self.free)  # where it is now (not where the last episode's last plan saw it)
        for kind, actor in self.u.elements.items():
            key, box = f"element_{kind}", box_object(self.el_size[kind], _pose(actor.pose.raw_pose))
            self.free.set_obstacle(key, box)
            if kind == self.kind:
                self.free_exact.remove_obstacle(key)
            else:
                self.free_exact.set_obstacle(key, box)

    def _loaded_planners(self) -> tuple[ArmPlanner, ArmPlanner]:
        """The arm with the element at its actual hold pose: inflated and exact."""
        hold, size = _pose(self.u.hold_pose_in_tcp), self.el_size[self.kind]
        obstacles = {**self.site, **self._standing_obstacles()}
        for kind, actor in self.u.elements.items():
            if kind != self.kind:
                obstacles[f"element_{kind}"] = box_object(self.el_size[kind], _pose(actor.pose.raw_pose))
        cfg = self.cfg
        with self._planning():
            loaded = ArmPlanner(planning_urdf(cfg.arm_margin, size, hold, cfg.element_margin), planning_srdf(True),
                                self.workdir, "loaded", obstacles)
            exact = ArmPlanner(planning_urdf(0.0, size, hold, -cfg.exact_shrink), planning_srdf(True),
                               self.workdir, "loaded_exact", obstacles)
        return loaded, exact

    def _grasp_pose(self) -> sapien.Pose:
        """The tcp pose at the centre of the element's grasp face, facing it (yaw 0)."""
        return _pose(self.u.obj.pose.raw_pose) * self.grasp_in_el[self.kind]

    # ------------------------------------------------------------------------------------- #
    # execution
    # ------------------------------------------------------------------------------------- #
    def _step(self, target: np.ndarray) -> bool:
        """One control step to `target`; returns whether the episode ended (success or time limit)."""
        self.q = np.asarray(target, np.float64)
        _, _, terminated, truncated, info = self.env.step(torch.as_tensor(self.q[None], dtype=torch.float32))
        self.steps += 1
        self.info = {k: v.reshape(-1)[0].item() for k, v in info.items() if torch.is_tensor(v)}
        self.collisions += int(self.info.get("obstacle_collision", False))
        self.ended = bool(terminated) or bool(truncated)
        return self.ended

    def _follow(self, traj: np.ndarray, until: Optional[Callable[[], bool]] = None) -> None:
        """Send the targets one per control step, stopping at the episode's end or once `until()` holds. With a
        walking worker, where the next `worker_lookahead` of targets meets its swept envelope: replan (every
        `replan_every` steps, where the phase samples its path), else hold still; where the worker is coming at the
        arm itself, get out of its way (`_escape`) where the phase samples its path, else go back the way it came
        (and forward along it again once the way is clear)."""
        ahead = int(round(self.cfg.worker_lookahead / self.dt))
        trail, redo = [self.q], []  # the targets sent (the last is where the arm is headed); those gone back from
        i, blocked, stale = 0, 0, False  # stale: the arm left the path (an escape), a new one is needed
        while i < len(traj) or redo:
            if stale or (self.watch is not None and
                         self._worker_blocks(np.array([*redo[::-1], *traj[i:i + ahead]][:ahead]))):
                if self.replan is not None and blocked % self.cfg.replan_every == 0:
                    with self._planning():
                        try:
                            traj, i, redo, stale = self.replan(), 0, [], False
                            self.replans += 1
                            continue
                        except PhaseFailure:
                            pass
                blocked += 1
                self.waited_steps += 1
                in_the_way = self._worker_blocks(self.q[None])
                if in_the_way and self.replan is not None:
                    if self._escape():
                        return
                    trail, redo, blocked, stale = [self.q], [], 0, True
                    continue
                if in_the_way and len(trail) > 1:
                    redo.append(trail.pop())
                if self._step(trail[-1]):
                    return
                continue
            if redo:
                target = redo.pop()
            else:
                target, i = traj[i], i + 1
            trail.append(target)
            if self._step(target) or (until is not None and until()):
                return

    def _escape(self) -> bool:
        """The worker is coming at the arm: out of its way, by the first of these that is free (the exact arm among the
        site and the static obstacles): a straight tcp line `escape_distance` aside, horizontally away from the
        worker's line of walking; one as far straight up; a path to the rest pose (joint 6 kept). Followed at the
        sampled paths' speed until the arm and its target are clear of the worker's swept envelope (or it ends).
        Returns whether the episode ended."""
        planner = self.free_exact if self.phase == "approach" else self.loaded_exact
        tcp = self.ik.fk(self.q)
        walk = self.u.worker_velocity()[0].cpu().numpy().astype(float)
        away = tcp.p[:2] - self.u.worker_xy()[0].cpu().numpy().astype(float)
        if np.linalg.norm(walk) > 0:  # the part of `away` across the worker's line of walking
            along = walk / np.linalg.norm(walk)
            away = away - along * (away @ along)
        away = away / max(np.linalg.norm(away), 1e-6)
        d = self.cfg.escape_distance
        rest = REST_QPOS.copy()
        rest[5] = self.q[5]
        traj = None
        with self._planning():  # the exact planners hold the standing obstacles, not the worker
            for shift in ([d * away[0], d * away[1], 0.0], [0.0, 0.0, d]):
                line = tcp_line(self.ik, self.q, sapien.Pose(tcp.p + shift, tcp.q))
                if line is not None and planner.collision_on(line) is None:
                    traj = time_parameterize(line, self.vel, self.acc, self.dt)  # as fast as sampled paths
                    break
            if traj is None and not planner.collides(rest):
                path = planner.rrt_connect(self.q, rest, self.cfg.rrt_time)
                if path is not None:
                    traj = time_parameterize(planner.shortcut(path), self.vel, self.acc, self.dt)
        if traj is None:
            return self._step(self.q)
        self.escapes += 1
        for target in traj[1:]:
            if self._step(target):
                return True
            arm = self.u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)  # where it is, not its target
            if not self._worker_blocks(np.array([arm, self.q])):
                break
        return False

    def _worker_blocks(self, targets: np.ndarray) -> bool:
        """Whether any of `targets` meets the worker's envelope swept `worker_lookahead` ahead."""
        with self._planning():
            self._place_worker(self.watch)
            return any(self.watch.collides(q) for q in targets[::2])

    def _plan_when_clear(self, planner: ArmPlanner, goals: list[np.ndarray], phase: str,
                         max_steps: Optional[Callable[[], int]] = None) -> tuple[int, np.ndarray]:
        """`_plan` (within `max_steps()` control steps, asked at each try); with a walking worker in the cell, where
        no path is found, held still and tried again every `replan_every` steps until the worker has left or the
        episode ends."""
        while True:
            try:
                with self._planning():
                    return self._plan(planner, goals, phase, max_steps() if max_steps else None)
            except PhaseFailure:
                if not (self.moving and bool(self.u.worker_walking()[0])):
                    raise
            for _ in range(self.cfg.replan_every):
                self.waited_steps += 1
                if self._step(self.q):
                    raise PhaseFailure(f"{phase}: the episode ended while the worker blocked every path")

    def _settle(self) -> None:
        """Hold the last target until the arm has caught up with it (not past the episode's end)."""
        for _ in range(0 if self.ended else self.cfg.settle_steps):
            qpos = self.u.agent.robot.get_qpos()[0].cpu().numpy()
            if np.abs(qpos - self.q).max() <= self.cfg.settle_tol or self._step(self.q):
                return
