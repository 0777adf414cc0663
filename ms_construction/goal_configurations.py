"""The arm's joint configurations at the two ends of a carry, from inverse kinematics of the site's poses alone.

- `install_configurations`: per task type and goal slot, the configurations that hold the element installed
  (its goal pose, the element centred on the plate with no turn about the plate's axis), turret facing the
  goal. The dense reward's carry term measures the arm's way to the nearest of them in joint space: a
  distance that falls at every step of a carry from wherever the element was picked, turns the turret the
  way its limits allow, and holds the element's orientation (wrist joints) and position together.
- `lift_configurations`: per task type, the configuration that holds the element lifted above the middle
  of the staging table, one per side the turret can reach the table from. The start-state curriculum poses
  the arm on the joint line between a lift and an installation.
- `mirror_twins`, `mirror_branch_mask`: the goal slots met as the mirror image of another, and which of their
  installation configurations they keep.

Nothing here comes from demonstrations: the URDF, the manifest's goal and grasp poses, and IK; where no IK path
leaves a goal slot from the turret side its task type's other slots are reached from, one via configuration found
once by the planner's RRT on the site (`plan_vias`, assets/start_path_vias.json); and from every turret side a slot has
no usable path from, a detour found the same way (`plan_detours`, assets/start_path_detours.json), which the dense
reward measures along only where a site's obstacles block every usable path.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
from pathlib import Path
from typing import Optional

import numpy as np
import sapien

from ms_construction.assets import ASSET_DIR, load_manifest
from ms_construction.kinematics import ArmIK
from ms_construction.parameters import DROP_CLEARANCE, ELEMENT_KINDS, START_YAW_DEG, SYMMETRIES_DEG

CONFIGS_PER_SLOT = 4
"""installation configurations kept per goal slot (IK branches: elbow, wrist flip); fewer found are repeated."""
LIFT_HEIGHT = 0.5
"""m; the lift configurations hold the element's grasp face this far above where it lies on the table."""
STANDOFF = 0.3
"""m; the start paths' middle point backs the element off its goal this far along the plate's axis (out of
its opening), as the planning expert's install line does."""
IK_SEEDS = 64
"""random IK restarts per pose (seeded: the tables are the same in every process)."""


def symmetry_period(kind: str) -> float:
    """rad; the element's installation repeats when the plate turns by this about its axis (2 pi / symmetries)."""
    return 2 * np.pi / len(SYMMETRIES_DEG[kind])


def _wrap(a: np.ndarray | float) -> np.ndarray | float:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _solutions(ik: ArmIK, target: sapien.Pose) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    seeds = [rng.uniform(ik.lower, ik.upper) for _ in range(IK_SEEDS)]
    return ik.solve_all(target, seeds, min_distance=0.05)


def _pose(raw) -> sapien.Pose:
    raw = np.asarray(raw, dtype=np.float64)
    return sapien.Pose(raw[:3], raw[3:])


@functools.lru_cache(maxsize=None)
def install_configurations() -> np.ndarray:
    """[kinds, slots, CONFIGS_PER_SLOT, 6]: configurations at each goal (kinds in ELEMENT_KINDS order). Joint 6
    is wrapped into [-pi, pi) modulo nothing: the reward compares it modulo the element's symmetry period and
    shifts it by the element's actual turn on the plate."""
    m, ik = load_manifest(), ArmIK()
    table = []
    for kind in ELEMENT_KINDS:
        grasp = _pose(m["elements"][kind]["grasp_pose"])
        period = symmetry_period(kind)
        per_slot = []
        for slot, goal in enumerate(m["goal_poses"][kind]):
            bearing = np.arctan2(goal[1], goal[0])
            kept: list[np.ndarray] = []
            for q in _solutions(ik, _pose(goal) * grasp):
                if abs(_wrap(q[0] - bearing)) > np.pi / 2:  # reaching back over the pedestal
                    continue
                q = q.copy()
                q[5] = (q[5] + period / 2) % period - period / 2
                if all(np.abs(q - k).max() > 0.05 for k in kept):
                    kept.append(q)
            if not kept:
                raise RuntimeError(f"no IK solution facing {kind} goal slot {slot}: the site and the arm disagree")
            kept.sort(key=lambda q: np.abs(q[1:5]).sum())  # the least folded first (deterministic order)
            kept = (kept * CONFIGS_PER_SLOT)[:CONFIGS_PER_SLOT]
            per_slot.append(kept)
        table.append(per_slot)
    return np.asarray(table, dtype=np.float32)


def mirror_branch_mask(joint_signs, kinds: tuple[str, ...] = ELEMENT_KINDS) -> np.ndarray:
    """[kinds, slots, CONFIGS_PER_SLOT] bool: the installation configurations kept where a goal slot at y > 0 is met as
    the mirror image, in the plane y = 0, of the slot at y < 0 it mirrors (a policy with `mirror_twins`): of each
    such slot of `kinds`, those whose mirror image (joints times `joint_signs`) has the mirrored slot's least folded
    configuration's joints 1-5, so that the two differ in joint 6 alone (by half a turn for a window, whose head is
    up at every opening); every configuration elsewhere. Without it the nearest configuration in the mirror is often
    the other wrist branch, joints 4 and 5 far from any the policy knows (docs/experiments/from_scratch.md)."""
    install, twins = install_configurations(), mirror_twins(kinds)
    keep = np.ones(install.shape[:3], dtype=bool)
    signs = np.asarray(joint_signs, dtype=np.float32)
    for k, slot in zip(*np.nonzero(twins >= 0)):
        keep[k, slot] = np.abs(install[k, slot, :, :5] * signs[:5] - install[k, twins[k, slot], 0, :5]).max(-1) < 0.05
        if not keep[k, slot].any():
            raise RuntimeError(f"no {ELEMENT_KINDS[k]} installation configuration of goal slot {slot} mirrors slot "
                               f"{twins[k, slot]}'s")
    return keep


def mirror_twins(kinds: tuple[str, ...] = ELEMENT_KINDS) -> np.ndarray:
    """[kinds, slots] int: of each goal slot of `kinds` at y > 0, the slot at its mirror image in the plane y = 0
    (-1: none, or not of `kinds`)."""
    goals = load_manifest()["goal_poses"]
    twins = np.full((len(ELEMENT_KINDS), len(goals[ELEMENT_KINDS[0]])), -1)
    for kind in kinds:
        for slot, goal in enumerate(goals[kind]):
            mirrored = [goal[0], -goal[1], goal[2]]
            found = [s for s, g in enumerate(goals[kind]) if np.allclose(g[:3], mirrored, atol=1e-3)]
            if goal[1] > 0 and found:
                twins[ELEMENT_KINDS.index(kind), slot] = found[0]
    return twins


@functools.lru_cache(maxsize=None)
def backoff_configurations() -> np.ndarray:
    """[kinds, slots, CONFIGS_PER_SLOT, 6]: each installation configuration with the element backed off its goal by
    STANDOFF along the plate's axis (out of its opening, as the planning expert's install line starts), the IK
    solution reached from the installation; the installation itself where IK finds none in that branch."""
    ik, install = ArmIK(), install_configurations().astype(np.float64)
    out = install.copy()
    for index in np.ndindex(install.shape[:3]):
        q = ik.solve_from(ik.fk(install[index]) * sapien.Pose([0, 0, -STANDOFF]), install[index])
        if q is not None:
            out[index] = q
    return out.astype(np.float32)


@functools.lru_cache(maxsize=None)
def lift_configurations(height: float = LIFT_HEIGHT) -> np.ndarray:
    """[kinds, 2, 6]: the element lifted `height` above where it lies in the middle of the staging table at its
    nominal yaw (0: lying there, the plate on it), with the turret at about +pi (row 0) and about -pi (row 1);
    of each side's IK solutions the one whose joints 2-5 are nearest the rest pose."""
    from ms_construction.agents.construction_arm import REST_QPOS

    m, ik = load_manifest(), ArmIK()
    st = m["staging"]
    out = []
    for k, kind in enumerate(ELEMENT_KINDS):
        size = m["elements"][kind]["size"]
        grasp = _pose(m["elements"][kind]["grasp_pose"])
        z = st["center"][2] + size[2] / 2 + DROP_CLEARANCE
        yaw = np.deg2rad(START_YAW_DEG[kind])
        on_table = sapien.Pose([st["center"][0], st["center"][1], z], [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])
        target = on_table * grasp * sapien.Pose([0, 0, -height])  # back along the plate's axis: up
        sols = _solutions(ik, target)
        sides = []
        for sign in (1, -1):
            side = [q for q in sols if abs(q[0] - sign * np.pi) < np.pi / 2]
            side += [q + np.eye(6)[0] * 2 * np.pi * sign for q in sols
                     if abs(q[0] + 2 * np.pi * sign - sign * np.pi) < np.pi / 2 and ik.lower[0] <= q[0] + 2 * np.pi * sign <= ik.upper[0]]
            if not side:
                raise RuntimeError(f"no IK solution lifting the {kind} above the staging table with the turret at {sign:+d} pi")
            sides.append(min(side, key=lambda q: np.abs(q[1:5] - REST_QPOS[1:5]).sum()))
        out.append(sides)
    return np.asarray(out, dtype=np.float32)


START_TURNS_DEG = (-15.0, 0.0, 15.0)
"""the element's turns on the plate at which a start path is checked (the starts draw theirs within them)."""
PATH_CHECKS = 60
"""points checked along each start path."""
PATH_ARM_MARGIN = 0.01
"""m; the arm's links are inflated by this much for the check; the element is taken 2 mm smaller than it is, so
that an element flush in its opening (the path's first point) is clear."""



@dataclasses.dataclass(frozen=True)
class StartPaths:
    """Joint paths from each installation configuration out to a lift above the staging table, in the layout
    [kinds, slots, CONFIGS_PER_SLOT, 2 turret sides, ...]: the start-state curriculum poses the arm at a
    fraction of a path's joint-space length (0: installed)."""

    waypoints: np.ndarray
    """[..., 5, 6]: installation; backed off by STANDOFF along the plate's axis; a corner; the lift; the element
    lying on the staging table where a grasp leaves it (the last two with joint 6 nearest the installation's
    modulo the element's symmetry: the wrist does not spin for nothing). The corner is the back-off with the
    lift's arm joints (2-5), raised before it turns, where that keeps more of the path clear than the straight
    joint line (then the corner is the back-off itself), or a planned via (`plan_vias`) where that keeps more
    clear still."""
    free: np.ndarray
    """[...]: the fraction of the path that is clear of the site and of the arm itself for the held element, by
    the planning expert's collision model (PATH_ARM_MARGIN) at each of START_TURNS_DEG."""
    usable: np.ndarray
    """[...] bool: the paths starts are drawn on, those of each goal slot whose clear fraction is at least half
    the slot's best."""
    planned: np.ndarray
    """[...] bool: the paths whose corner is a planned via (`plan_vias`): a detour around what the straight joint
    line and the raised corner run into."""
    detour: np.ndarray
    """[...] bool: the paths of the turret sides a goal slot has no usable path from, through a planned via
    (`plan_detours`) and wholly clear of the site: never drawn on for starts on the site as built, nor measured
    along there; the dense reward measures along them where a site's obstacles block every usable path (the tasks'
    `obstacles`, CarryGeometry.usable)."""


def _collides_at(planners: list, q: np.ndarray, turns: list[float]) -> bool:
    """Whether the arm at `q` collides holding its element turned by any of `turns` on the plate (one planner each)."""
    for planner, t in zip(planners, turns):
        shifted = q.copy()
        shifted[5] += t
        if planner.collides(shifted):
            return True
    return False


def _clear_fraction(planners: list, waypoints: np.ndarray, turns: list[float]) -> float:
    clear = 0.0
    for a in np.linspace(0.0, 1.0, PATH_CHECKS + 1):
        if _collides_at(planners, path_point(waypoints, a), turns):
            return clear
        clear = a
    return clear


VIAS_PATH = ASSET_DIR / "start_path_vias.json"
"""the planned vias (`plan_vias`): {kind: {slot: {side: {configuration: [6 joints]}}}}, written by
`python -m ms_construction.goal_configurations`."""
DETOURS_PATH = ASSET_DIR / "start_path_detours.json"
"""the detours' vias (`plan_detours`), laid out as VIAS_PATH's, written by the same command."""


def _path_planners(workdir, kind: str, site: dict) -> list:
    """One planner per START_TURNS_DEG: the arm holding `kind` turned that much on the plate, among the site."""
    from pathlib import Path

    from ms_construction.planning.arm_planner import ArmPlanner
    from ms_construction.planning.collision_model import planning_srdf, planning_urdf

    m = load_manifest()
    grasp, size = _pose(m["elements"][kind]["grasp_pose"]), np.asarray(m["elements"][kind]["size"])
    return [ArmPlanner(planning_urdf(PATH_ARM_MARGIN, size, (grasp * sapien.Pose(q=[np.cos(np.deg2rad(t) / 2), 0, 0,
                                                                                    np.sin(np.deg2rad(t) / 2)])).inv(), -0.002),
                       planning_srdf(True), Path(workdir), f"{kind}_{i}", dict(site)) for i, t in enumerate(START_TURNS_DEG)]


def _path_ends(k: int, index: tuple, install, backoff, lift, table) -> tuple:
    """A start path's installation, back-off, lift and table configurations; the last two with joint 6 nearest the
    installation's modulo the element's symmetry (the wrist does not spin for nothing)."""
    slot, c, side = index
    q_install, q_back = install[k, slot, c], backoff[k, slot, c]
    q_lift, q_table = lift[k, side].copy(), table[k, side].copy()
    period = symmetry_period(ELEMENT_KINDS[k])
    for q in (q_lift, q_table):
        q[5] = q_install[5] + ((q[5] - q_install[5] + period / 2) % period - period / 2)
    return q_install, q_back, q_lift, q_table


def load_vias(path: Path = VIAS_PATH) -> dict:
    return json.loads(path.read_text()) if path.is_file() else {}


@functools.lru_cache(maxsize=None)
def start_paths() -> StartPaths:
    """The start paths (see StartPaths), with the shipped planned vias and detours. Needs mplib: a few seconds the
    first time on a machine, then read from the disk cache (`cached_start_paths`)."""
    return cached_start_paths(json.dumps(load_vias()), json.dumps(load_vias(DETOURS_PATH)))


CACHE_ENV = "MS_CONSTRUCTION_CACHE"
"""where the start paths are cached (default ~/.cache/ms_construction); empty: no disk cache."""
def cache_inputs() -> list[Path]:
    """The files the start paths are computed from: the manifest, the arm's URDF and SRDF, and the code (the tables'
    IK and collision checks, the arm's rest pose and joints, the site's and the arm's parameters)."""
    from ms_construction.assets import ARM_SRDF_PATH, ARM_URDF_PATH, MANIFEST_PATH

    here = Path(__file__).parent
    code = ("goal_configurations.py", "kinematics.py", "parameters.py", "assets.py", "agents/construction_arm.py",
            "planning/collision_model.py", "planning/arm_planner.py")
    return [MANIFEST_PATH, ARM_URDF_PATH, ARM_SRDF_PATH] + [here / name for name in code]


def cached_start_paths(vias_json: str, detours_json: str = "{}") -> StartPaths:
    """`_start_paths`, from a file of the disk cache whose name is the hash of everything it is computed from (the
    vias and detours, `cache_inputs`, the versions of mplib and numpy), written there the first time: a changed input
    is a new file, never a stale read. A cache that cannot be read is computed again; one that cannot be written,
    skipped."""
    folder = os.environ.get(CACHE_ENV, str(Path.home() / ".cache" / "ms_construction"))
    if not folder:
        return _start_paths(vias_json, detours_json)
    from importlib.metadata import version

    key = hashlib.sha256(f"{vias_json} {detours_json} mplib {version('mplib')} numpy {np.__version__}".encode())
    for path in cache_inputs():
        key.update(Path(path).read_bytes())
    path = Path(folder) / f"start_paths-{key.hexdigest()[:20]}.npz"
    try:
        with np.load(path) as saved:
            return StartPaths(**{f.name: saved[f.name] for f in dataclasses.fields(StartPaths)})
    except Exception:  # absent, or unreadable (a disk that filled up): computed again below
        pass
    paths = _start_paths(vias_json, detours_json)
    tmp = path.with_suffix(f".{os.getpid()}.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, **dataclasses.asdict(paths))
        os.replace(tmp, path)  # whole or not at all, whichever process writes it
    except OSError:
        tmp.unlink(missing_ok=True)
    return paths


def _planned_via(vias: dict, kind: str, index: tuple) -> Optional[np.ndarray]:
    slot, c, side = index
    via = vias.get(kind, {}).get(str(slot), {}).get(str(side), {}).get(str(c))
    return None if via is None else np.asarray(via, dtype=np.float64)


@functools.lru_cache(maxsize=None)
def _start_paths(vias_json: str, detours_json: str = "{}") -> StartPaths:
    import tempfile

    from ms_construction.planning.collision_model import site_collision_objects

    vias, detours = json.loads(vias_json), json.loads(detours_json)
    m = load_manifest()
    install, lift = install_configurations().astype(np.float64), lift_configurations().astype(np.float64)
    table = lift_configurations(0.0).astype(np.float64)
    backoff = backoff_configurations().astype(np.float64)
    shape = install.shape[:3] + (2,)
    waypoints, free, planned = np.zeros(shape + (5, 6)), np.zeros(shape), np.zeros(shape, dtype=bool)
    usable, detour = np.zeros(shape, dtype=bool), np.zeros(shape, dtype=bool)
    turns = [float(np.deg2rad(t)) for t in START_TURNS_DEG]
    with tempfile.TemporaryDirectory(prefix="ms_construction_paths_") as workdir:
        for k, kind in enumerate(ELEMENT_KINDS):
            # each task type's paths among its own site (tests check that the paper's keep clear of paneling's partition)
            planners = _path_planners(workdir, kind, site_collision_objects(m, (kind,)))
            for index in np.ndindex(shape[1:]):
                q_install, q_back, q_lift, q_table = _path_ends(k, index, install, backoff, lift, table)
                if np.array_equal(q_back, q_install):  # no way out of the opening in this branch
                    waypoints[(k,) + index] = [q_install] * 3 + [q_lift, q_table]
                    continue
                corner = q_back.copy()
                corner[1:5] = q_lift[1:5]
                options = [np.array([q_install, q_back, q_back, q_lift, q_table]),
                           np.array([q_install, q_back, corner, q_lift, q_table])]
                via = _planned_via(vias, kind, index)
                if via is not None:
                    options.append(np.array([q_install, q_back, via, q_lift, q_table]))
                clear = [_clear_fraction(planners, w, turns) for w in options]
                best = int(np.argmax(clear))
                waypoints[(k,) + index], free[(k,) + index] = options[best], clear[best]
                planned[(k,) + index] = best == 2
            best = free[k].reshape(shape[1], -1).max(-1)[:, None, None]
            usable[k] = (free[k] >= 0.5 * best) & (best > 0)
            # a side without usable paths takes its detours (the site as built never measures along them, so the
            # usable paths and the reward there are the same with and without them)
            for index in zip(*np.nonzero(~usable[k].any(1, keepdims=True) & ~usable[k])):
                via = _planned_via(detours, kind, index)
                if via is None:
                    continue
                q_install, q_back, q_lift, q_table = _path_ends(k, index, install, backoff, lift, table)
                path = np.array([q_install, q_back, via, q_lift, q_table])
                if _clear_fraction(planners, path, turns) == 1.0:
                    waypoints[(k,) + index], free[(k,) + index], detour[(k,) + index] = path, 1.0, True
    return StartPaths(waypoints.astype(np.float32), free.astype(np.float32), usable, planned, detour)


def path_point(waypoints: np.ndarray, fraction: float) -> np.ndarray:
    """The configuration `fraction` of the way along a polyline of joint configurations [p, 6], by its summed
    joint-space (L1) length (the batched twin for the env is ConstructionTaskEnv._path_points)."""
    seg = np.abs(np.diff(waypoints, axis=0)).sum(-1)
    at = fraction * seg.sum()
    ends = np.cumsum(seg)
    i = min(int(np.searchsorted(ends, at)), len(seg) - 1)
    start = ends[i] - seg[i]
    w = 0.0 if seg[i] == 0 else (at - start) / seg[i]
    return waypoints[i] + w * (waypoints[i + 1] - waypoints[i])


VIA_PLAN_SECONDS = 5.0
"""RRTConnect's time limit per try (`plan_vias`)."""
VIA_PLAN_TRIES = 10


def _plan_via(planners: list, ends: tuple, turns: list[float]) -> Optional[list[float]]:
    """One via configuration for a start path with these `ends` (`_path_ends`): the middle of an RRTConnect path (the
    planner's, on the site's collision model, the element unturned on the plate) from the back-off to the lift,
    shortcut to a single via, where the path install - back-off - via - lift - table is clear at every turn of
    `turns`; None when VIA_PLAN_TRIES plans find none."""
    q_install, q_back, q_lift, q_table = ends
    planner = planners[START_TURNS_DEG.index(0.0)]
    for _ in range(VIA_PLAN_TRIES):
        path = planner.rrt_connect(q_back, q_lift, VIA_PLAN_SECONDS)
        if path is None:
            continue
        short = planner.shortcut(path)
        via = short[len(short) // 2]
        if len(short) == 3 and _clear_fraction(planners, np.array([q_install, q_back, via, q_lift, q_table]), turns) == 1.0:
            return [round(float(v), 4) for v in via]
    return None


WAY_SEARCH_DRAWS = 400
"""via configurations drawn per turret side by `search_via` before it gives up."""
WAY_SEARCH_SPREAD = 1.5
"""rad; the spread (standard deviation per joint) of `search_via`'s last draw: its draws spread from near the straight
joint line out to this, so that the first clear via found is about the nearest the draws reach."""


def path_clear(planners: list, waypoints: np.ndarray, turns: list[float], checks: int = PATH_CHECKS) -> bool:
    """`_clear_fraction(planners, waypoints, turns) == 1.0` (at `checks` + 1 points, PATH_CHECKS + 1 there), the points
    checked coarse to fine (a blocked path is found after a few checks)."""
    i = np.arange(1, checks + 2)
    fractions = np.linspace(0.0, 1.0, checks + 1)[np.argsort(-(i & -i), kind="stable")]
    return not any(_collides_at(planners, path_point(waypoints, a), turns) for a in fractions)


def search_via(planners: list, ends: list[tuple], turns: list[float], rng: np.random.Generator,
               limits: tuple[np.ndarray, np.ndarray]) -> Optional[tuple[int, np.ndarray]]:
    """A via for one of the start paths with these `ends` (`_path_ends`, one per installation configuration) that
    makes install - back-off - via - lift - table clear at every turn of `turns` among whatever the `planners` hold
    (a site's obstacles too): (which of `ends`, the via), or None after WAY_SEARCH_DRAWS draws. Each draw is a point of
    the straight joint line from the back-off to the lift, moved by Gaussian noise whose spread grows from draw to draw
    up to WAY_SEARCH_SPREAD, within the joint `limits`. Unlike `_plan_via` (OMPL's RRT, whose draws are its own) it
    draws from `rng`: a seeded episode plans the same way in every process, and it takes a few milliseconds where a
    way is easy to find, about a tenth of a second where none is."""
    for d in range(WAY_SEARCH_DRAWS):
        which = d % len(ends)
        q_install, q_back, q_lift, q_table = ends[which]
        spread = WAY_SEARCH_SPREAD * (d + 1) / WAY_SEARCH_DRAWS
        via = np.clip(q_back + rng.uniform() * (q_lift - q_back) + rng.normal(0.0, spread, 6), *limits)
        if path_clear(planners, np.array([q_install, q_back, via, q_lift, q_table]), turns):
            return which, via
    return None


def _plan(kinds: tuple[str, ...], wanted) -> dict:
    """{kind: {slot: {side: {configuration: via}}}} for the start paths `wanted(k)` names ([slots, configurations,
    2] bool) of each task type of `kinds`, those with a way out of their opening, by `_plan_via`."""
    import tempfile

    from ms_construction.planning.collision_model import site_collision_objects

    install, lift = install_configurations().astype(np.float64), lift_configurations().astype(np.float64)
    table = lift_configurations(0.0).astype(np.float64)
    backoff = backoff_configurations().astype(np.float64)
    turns = [float(np.deg2rad(t)) for t in START_TURNS_DEG]
    vias: dict = {}
    with tempfile.TemporaryDirectory(prefix="ms_construction_vias_") as workdir:
        for k, kind in enumerate(ELEMENT_KINDS):
            if kind not in kinds:
                continue
            planners = None
            for slot, c, side in zip(*np.nonzero(wanted(k))):
                ends = _path_ends(k, (slot, c, side), install, backoff, lift, table)
                if np.array_equal(ends[0], ends[1]):  # no way out of the opening in this branch
                    continue
                planners = planners or _path_planners(workdir, kind, site_collision_objects(load_manifest(), (kind,)))
                via = _plan_via(planners, ends, turns)
                if via is not None:
                    vias.setdefault(kind, {}).setdefault(str(slot), {}).setdefault(str(side), {})[str(c)] = via
    return vias


def plan_vias(paths: Optional[StartPaths] = None, kinds: tuple[str, ...] = ELEMENT_KINDS) -> dict:
    """Per task type of `kinds`, the turret side most of its goal slots have usable start paths from (a general agent
    grasps an element type from one side), and for each slot without a wholly clear one from there, one via
    configuration per installation configuration (`_plan_via`). Only the window opening at y = +0.85 needs one (its
    IK paths leave only from +pi; the other openings' only from -pi). The planner's random draws are OMPL's own: a
    new plan differs, so the vias are planned once and shipped (VIAS_PATH)."""
    paths = paths if paths is not None else _start_paths("{}")
    sides = paths.usable.any(2)  # [kinds, slots, 2]
    clear = paths.free.max(2) >= 1.0  # [kinds, slots, 2]

    def wanted(k: int) -> np.ndarray:
        side = int(np.argmax(sides[k].sum(0)))
        out = np.zeros(paths.usable.shape[1:], dtype=bool)
        out[~clear[k, :, side], :, side] = True
        return out

    return _plan(kinds, wanted)


def plan_detours(paths: Optional[StartPaths] = None, kinds: tuple[str, ...] = ELEMENT_KINDS) -> dict:
    """Per task type of `kinds`, a via (`_plan_via`) for every installation configuration of every goal slot on each
    turret side the slot has no usable start path from (with the shipped vias): the detours a site's obstacles may
    leave as the only clear ways (StartPaths.detour). Shipped as DETOURS_PATH, as the vias are."""
    paths = paths if paths is not None else _start_paths(json.dumps(load_vias()))
    return _plan(kinds, lambda k: ~paths.usable[k].any(1, keepdims=True) & ~paths.usable[k])


if __name__ == "__main__":
    import sys

    # the task types named (all by default) are planned anew, their detours alone with --detours (a new plan of the
    # vias differs, and changes the start paths on the site as built); the others keep what is shipped
    detours_only = "--detours" in sys.argv[1:]
    planned_kinds = tuple(a for a in sys.argv[1:] if a != "--detours") or ELEMENT_KINDS
    if not detours_only:
        VIAS_PATH.write_text(json.dumps({**{k: v for k, v in load_vias().items() if k not in planned_kinds},
                                         **plan_vias(kinds=planned_kinds)}, indent=1) + "\n")
    DETOURS_PATH.write_text(json.dumps({**{k: v for k, v in load_vias(DETOURS_PATH).items() if k not in planned_kinds},
                                        **plan_detours(kinds=planned_kinds)}, indent=1) + "\n")
    paths = _start_paths(json.dumps(load_vias()), json.dumps(load_vias(DETOURS_PATH)))
    print(f"wrote {DETOURS_PATH if detours_only else f'{VIAS_PATH} and {DETOURS_PATH}'}; the start paths now, per kind, slot and side: usable",
          paths.usable.any(2).astype(int).tolist(), "detours", paths.detour.any(2).astype(int).tolist())
