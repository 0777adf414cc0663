"""ManiSkill's trajectory replay tool, with the construction tasks registered.

    python scripts/replay_trajectory.py --traj-path outputs/expert/Flooring-v1.expert.h5
    python scripts/replay_trajectory.py --traj-path outputs/expert/Flooring-v1.expert.h5 --use-env-states

Takes every option of `python -m mani_skill.trajectory.replay_trajectory`, which cannot make these
tasks itself: a trajectory records the env id (`Flooring-v1`), registered only by importing
`ms_construction`. Replay with one process (the default `-n 1`): spawned workers would not import it.
"""

from mani_skill.trajectory.replay_trajectory import main, parse_args

import ms_construction  # noqa: F401  (registration)

if __name__ == "__main__":
    main(parse_args())
