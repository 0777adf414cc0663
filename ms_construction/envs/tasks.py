"""The five registered construction tasks and their task cards.

All five share ConstructionTaskEnv's mechanics, observation layout (the task type is a one-hot in
every observation, so one policy runs on all of them) and rewards.
"""

from mani_skill.utils.registration import register_env

from ms_construction.agents.suction_gripper import MAX_GRASP_INCIDENCE_DEG
from ms_construction.curriculum import FINAL_STAGE, STAGES
from ms_construction.envs.carry_geometry import PATH_DEVIATION_WEIGHT, PATH_LOOKAHEAD, VIA_DEVIATION_WEIGHT
from ms_construction.envs.construction_env import ROBOT_INIT_QPOS_NOISE, ConstructionTaskEnv
from ms_construction.envs.obstacles import (
    OBSTACLE_OBS_SIZE,
    STACK_HEIGHT,
    STACK_SIZE,
    WORKER_HEIGHT,
    WORKER_RADIUS,
    WORKER_SPEED,
    WORKER_START_S,
)
from ms_construction.parameters import PAPER_KINDS, START_RIM_GAP, START_XY_NOISE, START_YAW_NOISE_DEG, SiteParams

_SITE = SiteParams()
_SLOTS = {"ceiling": len(_SITE.ceiling_slots), "window": len(_SITE.window_ys), "flooring": len(_SITE.floor_slots),
          "paneling": len(_SITE.panel_slots)}
_CP4 = STAGES[FINAL_STAGE]
_STEPS = ConstructionTaskEnv.MAX_EPISODE_STEPS


def _size(kind: str) -> str:
    return " x ".join(f"{v:g}" for v in _SITE.element(kind).size)


def _card(description: str, kind: str, symmetry: str) -> str:
    """A task card: the task's own description, then what all five share, every number read from
    the code that uses it."""
    return description + f"""
**Randomizations (every episode, per parallel env):**
- the element's start position on the staging table: uniform within +-{START_XY_NOISE:g} m of the table
  centre in x and y (less along an axis where the element would come within {START_RIM_GAP * 1000:g} mm of the
  table's rim), lying flat (grasp face up)
- the element's start yaw: its nominal yaw +-{START_YAW_NOISE_DEG:g} degrees
- the goal slot: uniform among the site's {_SLOTS[kind]} openings of this type
- the arm's start configuration: rest keyframe + N(0, {ROBOT_INIT_QPOS_NOISE:g} rad) per joint

**Grasp:** a ray from the suction plate's centre along its approach axis meets the element's grasp
face (inside the face, within {MAX_GRASP_INCIDENCE_DEG:g} degrees of its normal) at a distance <= tau_pick; the
element is then pulled onto the plate and held (it still collides with the site).

**Success conditions:** the element is held, its centre is within tau_place of the goal position
and its rotation is within tau_angle of the goal rotation (angle of the error rotation, minimised
over the element's symmetries: {symmetry}). Success ends the episode. Tolerances follow the
curriculum stage (`curriculum_stage`, Table I; default cp4: {_CP4["pick"]:.2f} m, {_CP4["place"]:.2f} m,
{_CP4["angle_deg"]:g} degrees).

**Rewards:** `normalized_dense` by default (ManiSkill's convention); sparse = Algorithm 1 (-1/{_STEPS} every step, 1
on the first grasp, 2 on placement), which the paper's setting passes explicitly. One dense reward, the one the
from-scratch recipe trains on (experiments/from_scratch.py), with no variants behind kwargs; normalized_dense =
dense / {ConstructionTaskEnv.DENSE_REWARD_MAX:g}. Its stages:
- before the grasp, reach (<= 1): half is 1 - d / {ConstructionTaskEnv.REACH_RANGE:g} rad of the arm's joint-space distance d (joints 1-5)
  from the nearest configuration that grasps the element on the staging table from a turret side that the goal
  slot's start paths leave the table from (`reach_distance`), so that the turret turns the way its limits allow
  and the element is grasped where a collision-free way to its goal begins; half is 1 - tanh of the plate's
  distance from the grasp face, times its facing;
- held: 2 + carry (<= 1) + fit (<= 1) + progress (<= 0.5). Carry falls linearly, to 0 at {ConstructionTaskEnv.CARRY_RANGE:g} rad, with the
  arm's distance from holding the element installed measured along the goal slot's start paths
  (`carry_distance`: collision-checked joint paths from the installation configurations, IK of the goal, out
  along the plate's axis and up to the staging table; each radian off a path counted {PATH_DEVIATION_WEIGHT:g} times, off a
  path through a planned via {VIA_DEVIATION_WEIGHT:g} times; only the paths from the turret side the element was grasped from),
  so that it falls on the way up and over the site's barriers and into the opening along the plate's axis, not
  on a straight joint move that runs the element into the slab or the wall. Fit is 1 - tanh(5 d) of the
  element's distance d from its goal, times 1 - tanh of its angle error in radians. Progress pays the step's fall
  of the carry distance ({ConstructionTaskEnv.PROGRESS_GAIN:g} per rad, in [0, 0.5], 0.25 standing still): a potential difference, so
  going back and forth earns nothing;
- placed: {ConstructionTaskEnv.DENSE_REWARD_MAX:g}, the most any step pays, more than twice a held step.

What the site's geometry requires is computed by one rule for every goal slot (ms_construction/envs/carry_geometry.py):
the turret sides a slot's start paths leave from, a planned via where none leaves from the side its task type's
other slots are reached from, and, for a slot that is the mirror image of another in the arm's plane y = 0, the
wrist branch that mirrors its twin's (until the grasp its joint moves are measured as its twin's mirror image).
Convention (ManiSkill's): the dense rewards are for a learner that bootstraps at every episode end, success
included (ppo.py's default for them, with `--success-value absorbing`), so that a placed element counts as a
state that keeps paying the most; a learner that values success as an end with nothing after it finds holding
the element near its goal worth more than placing it.

**Start states** (training devices, ms_construction/envs/start_states.py): `set_near_goal_starts(share, radius)` makes a share of the following resets start with the
element held on a collision-free joint path out of its goal (reverse curriculum generation; IK, no
demonstrations; `info["near_goal_start"]` marks them); for training only, off by default. Its `max_steps`
truncates such an episode that has not placed by then, in an env wrapped in `NearGoalTimeLimit`.
`set_reach_starts(share, radius)` carries that curriculum back through the grasp: a share of the other resets
start on the last `radius` of the reach path (the joint line from the reset's configuration to a lift above the
element on a turret side the goal slot's start paths leave from, then down to {ConstructionTaskEnv.GRASP_START_HEIGHT:g} m above it), the element
lying on the table (`info["reach_start"]`, and `info["reach_start_grasped"]`: grasped from the side it started on).

**Observation:** `obs_elapsed_time=True` appends the episode's elapsed steps / {_STEPS} (the step limit) as
the last entry (`extra/elapsed`): the limit is part of the task (success counts within it), and a policy
that knows how much of it is left can hurry (Pardo et al. 2018, time limits in RL). Off by default.
`obs_install_offset=True` appends, before it, the joint move (6 numbers, rad) from the arm's configuration to
the nearest one that holds the element installed (`extra/install_offset`: IK of the goal pose, what the dense
reward's carry term measures; joint 6's part modulo the element's symmetry). Off by default.
`obs_path_offset=True` appends, after that, the joint move to the point {PATH_LOOKAHEAD:g} rad ahead along the start path that
the carry is measured along (`extra/path_offset`, `path_offset`): which way that carry falls. Off by default.

**Obstacles** (a site that changes, ms_construction/envs/obstacles.py; physx_cpu): `obstacles="static"` puts a material
stack ({STACK_SIZE[0]:g} x {STACK_SIZE[1]:g} m, {STACK_HEIGHT[0]:g}-{STACK_HEIGHT[1]:g} m high) and a scaffold post (floor to slab) in the arm's
workspace, seeded per episode, clear of the table, the recesses, the window fronts, the ceiling openings (the post)
and each other; `obstacles="moving"` adds a worker (a cylinder of radius {WORKER_RADIUS:g} m, {WORKER_HEIGHT:g} m tall) walking across the
cell once, along the -y barrier at {WORKER_SPEED[0]:g}-{WORKER_SPEED[1]:g} m/s, entering within the first {WORKER_START_S[1]:g} s. Drawn after the arm,
the element and the goal (before the training start states), so a seed gives the same episode with and without
them where no start states are set (as in every evaluation). A touch of the arm or the element on one is
`info["obstacle_collision"]` and fails the episode (`info["fail"]`): an end with nothing after it, where success
is absorbing (the shipped learners do not bootstrap there: baselines/ppo/evaluation.py `failed_ends`). The
observation ends with their state
(`extra/obstacles`, {OBSTACLE_OBS_SIZE} numbers: the stack's place, height and turn, the post's place, the worker's place and
velocity): `obs_obstacles=None` (the default) where there are obstacles, `True` always (zeros without them),
`False` never (how a policy trained without them meets them). `obstacle_share` below 1 gives only that share of
episodes obstacles, drawn per episode (a mixed scene for training; the others as on the site as built, the entry
zeros). The dense reward measures
the carry and the reach along the goal slot's start paths that keep clear of the stack and the post (checked once
per episode); where they block every usable path of a turret side, along one of them through a via searched around
them at reset (seeded by the layout: the same in every process and replay); where none is found either, along a clear
detour from the other side, or along the blocked paths where none is. A layout may block every way to a goal: the
evaluations keep the seeds the planning expert solves at the start.
"""


@register_env("CeilingInstallation-v1", max_episode_steps=_STEPS)
class CeilingInstallationEnv(ConstructionTaskEnv):
    TASKS = ("ceiling",)


CeilingInstallationEnv.__doc__ = _card(
    f"""**Task Description:** install a {_SITE.ceiling_panel.mass:g} kg ceiling panel ({_size("ceiling")} m) into an
opening of the second-story slab above the robot. The panel is picked from the staging table by its
top face and must end up flipped, flush with the slab's underside, so the plate faces up under it:
the gripper must flip (the paper's hardest task).
""",
    "ceiling",
    "a 180 degree turn about its normal; the finished face must face down",
)


@register_env("WindowInstallation-v1", max_episode_steps=_STEPS)
class WindowInstallationEnv(ConstructionTaskEnv):
    TASKS = ("window",)


WindowInstallationEnv.__doc__ = _card(
    f"""**Task Description:** install a {_SITE.window.mass:g} kg window ({_SITE.window.size[0]:g} m wide,
{_SITE.window.size[1]:g} m tall, {_SITE.window.size[2]:g} m deep, aluminium frame and glass) standing up in an
opening of the exterior wall, centred in the wall's thickness, its inside face towards the room.
""",
    "window",
    "none: head up, inside face in",
)


@register_env("Flooring-v1", max_episode_steps=_STEPS)
class FlooringEnv(ConstructionTaskEnv):
    TASKS = ("flooring",)


FlooringEnv.__doc__ = _card(
    f"""**Task Description:** lay a {_SITE.floor_panel.mass:g} kg raised-access floor panel ({_size("flooring")} m)
flat into a recess of the ground slab, its top flush with the floor.
""",
    "flooring",
    "quarter turns about its normal; the finish must face up",
)


@register_env("PanelInstallation-v1", max_episode_steps=_STEPS)
class PanelInstallationEnv(ConstructionTaskEnv):
    TASKS = ("paneling",)


PanelInstallationEnv.__doc__ = _card(
    f"""**Task Description:** install a {_SITE.wall_panel.mass:g} kg wall panel ({_SITE.wall_panel.size[0]:g} m wide,
{_SITE.wall_panel.size[1]:g} m tall, {_SITE.wall_panel.size[2]:g} m thick, fibre cement) standing up against the steel studs of an
interior partition, into one of the bays its boards leave open, flush with the boards around it, its finished
face towards the room. Not one of the paper's tasks: the fourth task its conclusion names (paneling), built to
measure whether what was learnt on the other three carries over. The partition is built only in the envs that
have paneling among their task types.
""",
    "paneling",
    "a 180 degree turn about its normal; the finished face must face the room",
)


@register_env("ConstructionPickPlace-v1", max_episode_steps=_STEPS)
class ConstructionPickPlaceEnv(ConstructionTaskEnv):
    TASKS = PAPER_KINDS


ConstructionPickPlaceEnv.__doc__ = _card(
    """**Task Description:** the general pick-and-place task. Every episode, each parallel env samples
a task type (ceiling panel, window or floor panel; `tasks=` chooses among those and paneling, the fourth type,
which is sampled only when asked for; `task_weights=`, e.g. `{"window": 2}`, weighs them; unnamed types weigh 1)
and a goal slot of that type; the episode's element starts on the staging table while the others wait in the
storage area outside the barriers. `info["task_id"]`: 0 ceiling, 1 window, 2 flooring, 3 paneling.
""",
    "ceiling",  # the same number of openings of every type
    "those of the episode's element, as in the single tasks",
)
