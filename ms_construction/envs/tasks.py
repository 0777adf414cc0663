"""The four registered construction tasks and their task cards.

All four share ConstructionTaskEnv's mechanics, observation layout (the task type is a one-hot in
every observation, so one policy runs on all of them) and rewards.
"""

from mani_skill.utils.registration import register_env

from ms_construction.envs.construction_env import ConstructionTaskEnv

_COMMON = """
**Randomizations (every episode, per parallel env):**
- the element's start position on the staging table: uniform within +-0.08 m of the table centre
  in x and y, lying flat (grasp face up)
- the element's start yaw: its nominal yaw +-15 degrees
- the goal slot: uniform among the site's {n} openings of this type
- the arm's start configuration: rest keyframe + N(0, 0.02 rad) per joint

**Grasp:** a ray from the suction plate's centre along its approach axis meets the element's grasp
face (inside the face, within 60 degrees of its normal) at a distance <= tau_pick; the element is
then pulled onto the plate and held (it still collides with the site).

**Success conditions:** the element is held, its centre is within tau_place of the goal position
and its rotation is within tau_angle of the goal rotation (angle of the error rotation, minimised
over the element's symmetries: {sym}). Success ends the episode. Tolerances follow the curriculum
stage (`curriculum_stage`, Table I; default cp4: 0.30 m, 0.10 m, 20 degrees).

**Rewards:** sparse = Algorithm 1 (-1/250 every step, 1 on the first grasp, 2 on placement);
dense = staged reach, grasp, carry and orient, place (max 5); normalized_dense = dense / 5.
"""


@register_env("CeilingInstallation-v1", max_episode_steps=ConstructionTaskEnv.MAX_EPISODE_STEPS)
class CeilingInstallationEnv(ConstructionTaskEnv):
    TASKS = ("ceiling",)


CeilingInstallationEnv.__doc__ = (
    """**Task Description:** install a 15 kg ceiling panel (0.8 x 0.6 x 0.03 m) into an opening of the
second-story slab above the robot. The panel is picked from the staging table by its top face and
must end up flipped, flush with the slab's underside, so the plate faces up under it: the
gripper must flip (the paper's hardest task).
"""
    + _COMMON.format(n=3, sym="a 180 degree turn about its normal; the finished face must face down")
)


@register_env("WindowInstallation-v1", max_episode_steps=ConstructionTaskEnv.MAX_EPISODE_STEPS)
class WindowInstallationEnv(ConstructionTaskEnv):
    TASKS = ("window",)


WindowInstallationEnv.__doc__ = (
    """**Task Description:** install a 15 kg window (0.6 m wide, 0.8 m tall, 0.07 m deep, aluminium
frame and glass) standing up in an opening of the exterior wall, centred in the wall's thickness,
its inside face towards the room.
"""
    + _COMMON.format(n=3, sym="none: head up, inside face in")
)


@register_env("Flooring-v1", max_episode_steps=ConstructionTaskEnv.MAX_EPISODE_STEPS)
class FlooringEnv(ConstructionTaskEnv):
    TASKS = ("flooring",)


FlooringEnv.__doc__ = (
    """**Task Description:** lay a 15 kg raised-access floor panel (0.6 x 0.6 x 0.035 m) flat into a
recess of the ground slab, its top flush with the floor.
"""
    + _COMMON.format(n=3, sym="quarter turns about its normal; the finish must face up")
)


@register_env("ConstructionPickPlace-v1", max_episode_steps=ConstructionTaskEnv.MAX_EPISODE_STEPS)
class ConstructionPickPlaceEnv(ConstructionTaskEnv):
    TASKS = ("ceiling", "window", "flooring")


ConstructionPickPlaceEnv.__doc__ = (
    """**Task Description:** the general pick-and-place task. Every episode, each parallel env samples
a task type (ceiling panel, window or floor panel; `tasks=` restricts the choice) and a goal slot
of that type; the episode's element starts on the staging table while the other two wait in the
storage area outside the barriers. `info["task_id"]`: 0 ceiling, 1 window, 2 flooring.
"""
    + _COMMON.format(n=3, sym="those of the episode's element, as in the single tasks")
)
