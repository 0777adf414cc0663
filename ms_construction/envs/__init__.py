"""The construction tasks: importing this registers them with ManiSkill.

`ENV_IDS` and `TASK_ENV_IDS` are read back from ManiSkill's registry, so they name exactly what
`gym.make` knows: the general task first, then one environment per task type in `task_id` order.
"""

from mani_skill.utils.registration import REGISTERED_ENVS

from ms_construction.envs.construction_env import ConstructionTaskEnv
from ms_construction.envs.tasks import (
    CeilingInstallationEnv,
    ConstructionPickPlaceEnv,
    FlooringEnv,
    PanelInstallationEnv,
    WindowInstallationEnv,
)
from ms_construction.parameters import ELEMENT_KINDS, PAPER_KINDS

_OURS = {env_id: spec.cls for env_id, spec in REGISTERED_ENVS.items() if issubclass(spec.cls, ConstructionTaskEnv)}
_SINGLE = {cls.TASKS[0]: env_id for env_id, cls in _OURS.items() if len(cls.TASKS) == 1}
TASK_ENV_IDS = {kind: _SINGLE[kind] for kind in ELEMENT_KINDS}
"""task type -> its single-task environment id, in ELEMENT_KINDS order."""
PAPER_TASK_ENV_IDS = {kind: TASK_ENV_IDS[kind] for kind in PAPER_KINDS}
"""the paper's three task types' environments (Table II's rows)."""
ENV_IDS = (*(env_id for env_id, cls in _OURS.items() if len(cls.TASKS) > 1), *TASK_ENV_IDS.values())
"""every registered construction environment: the general task, then the single tasks."""

__all__ = [
    "ENV_IDS",
    "TASK_ENV_IDS",
    "PAPER_TASK_ENV_IDS",
    "ConstructionTaskEnv",
    "ConstructionPickPlaceEnv",
    "CeilingInstallationEnv",
    "WindowInstallationEnv",
    "FlooringEnv",
    "PanelInstallationEnv",
]
