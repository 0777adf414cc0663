from ms_construction.envs.construction_env import ConstructionTaskEnv
from ms_construction.envs.tasks import (
    CeilingInstallationEnv,
    ConstructionPickPlaceEnv,
    FlooringEnv,
    WindowInstallationEnv,
)

ENV_IDS = ("ConstructionPickPlace-v1", "CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1")
TASK_ENV_IDS = {"ceiling": "CeilingInstallation-v1", "window": "WindowInstallation-v1", "flooring": "Flooring-v1"}

__all__ = [
    "ENV_IDS",
    "TASK_ENV_IDS",
    "ConstructionTaskEnv",
    "ConstructionPickPlaceEnv",
    "CeilingInstallationEnv",
    "WindowInstallationEnv",
    "FlooringEnv",
]
