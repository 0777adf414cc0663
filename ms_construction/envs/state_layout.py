"""The flat `state` observation's layout, and its mirror image in the arm's plane y = 0.

The construction tasks' `state` observation is ManiSkill's flat state: the agent's entries, then the task's
`_get_obs_extra` in order (STATE_LAYOUT), then the optional joint moves and the elapsed time. Policies that read
entries by position (the mirror, rotation features) take their indices from here.
"""

from __future__ import annotations

import numpy as np
import torch

from ms_construction.envs.carry_geometry import JOINT_MIRROR_SIGNS
from ms_construction.parameters import ELEMENT_KINDS, PAPER_KINDS

MIRROR_SIGNS = {"joints": JOINT_MIRROR_SIGNS, "scalars": (1.0,), "vector": (1.0, -1.0, 1.0),
                "pose": (1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0)}
"""How each kind of entry changes in the mirror image in the plane y = 0: joints by JOINT_MIRROR_SIGNS, the y of a
position or vector, the x and z of a quaternion [w, x, y, z] (the rotation M R M, M = diag(1, -1, 1))."""
STATE_LAYOUT = (("qpos", 6, "joints"), ("qvel", 6, "joints"), ("is_grasped", 1, "scalars"), ("tcp_pose", 7, "pose"),
                ("goal_pose", 7, "pose"), ("task", len(ELEMENT_KINDS), "scalars"), ("obj_pose", 7, "pose"),
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
TASK_SLOTS_BEFORE_PANELING = len(PAPER_KINDS)
"""the task one-hot's size before paneling became the fourth task type (2026-11-28): what older checkpoints read."""


OBSTACLE_MIRROR_SIGNS = (1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0)
"""The obstacles' entry (`obs_obstacles`, last) in the mirror image: the stack's x, y, top z, cos and sin of twice
its yaw (the yaw turns the other way), the post's x, y, the worker's x, y and velocity."""


def state_mirror_signs(obs_dim: int, obstacles: bool = False) -> torch.Tensor:
    """[obs_dim] the signs that turn a flat `state` observation into the one of its mirror image in the plane y = 0:
    each entry of STATE_LAYOUT by its kind's MIRROR_SIGNS, then the joint moves by JOINT_MIRROR_SIGNS, the elapsed
    time unchanged and, with `obstacles`, their entry by OBSTACLE_MIRROR_SIGNS."""
    tail = list(OBSTACLE_MIRROR_SIGNS) if obstacles else []
    extra, elapsed = divmod(obs_dim - STATE_SIZE - len(tail), 6)
    if obs_dim < STATE_SIZE + len(tail) or elapsed > 1:
        raise ValueError(f"state_mirror_signs: a state observation has {STATE_SIZE} numbers, then 6 per joint move, "
                         f"1 for the elapsed time and {len(OBSTACLE_MIRROR_SIGNS)} for the obstacles, not {obs_dim}")
    signs = [x for _, size, kind in STATE_LAYOUT for x in MIRROR_SIGNS[kind] * (size // len(MIRROR_SIGNS[kind]))]
    return torch.tensor(signs + list(JOINT_MIRROR_SIGNS) * extra + [1.0] * elapsed + tail)

