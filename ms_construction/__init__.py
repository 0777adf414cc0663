"""ms_construction: ManiSkill3 construction tasks (ceiling, window, flooring) and their general task.

Importing the package registers the arm (`construction_arm`) and the four environments, so
`gym.make("CeilingInstallation-v1")` works after `import ms_construction`, and
`gym.make("ms_construction:CeilingInstallation-v1")` works without it.

Run time: `envs` (the tasks), `agents` (the arm and its suction gripper), `site` (the scene),
`parameters` (what the generators and the run time share), `curriculum` (Table I), `planning` (the
motion-planning expert and its demonstrations), `vector_env` (physx_cpu envs in worker processes).
Build time only: `build` (the generators of the committed assets; imports mesh libraries).
"""

from ms_construction import agents, envs  # noqa: F401  (registration)
from ms_construction.envs import ENV_IDS, TASK_ENV_IDS

__version__ = "0.1.0"
__all__ = ["ENV_IDS", "TASK_ENV_IDS", "__version__"]
