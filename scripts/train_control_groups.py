"""The paper's control groups 4.1 / 4.2 / 4.3: one agent each on CeilingInstallation-v1,
WindowInstallation-v1 and Flooring-v1, at cp4 from the first step, otherwise the paper setting
(baselines/ppo/paper_setting.py), one after the other, each resumed from its checkpoint in campaign/.

    python scripts/train_control_groups.py --dry-run                       # the plan, and where each run stands
    python scripts/train_control_groups.py                                 # 2M steps each (Fig. 4's length)
    python scripts/train_control_groups.py --total-timesteps 8000000       # continue them to the general agent's 8M

A run is a chain of 2M-step cp4 stages, each restarting the learning-rate, clip and entropy schedules as
the general agent's stages do, so the first 2M steps are the same whatever the total.
"""

from dataclasses import dataclass
from typing import Optional

import tyro

from baselines.ppo.paper_setting import STAGE_STEPS, control_group_runs, describe, run_or_resume
from ms_construction.envs import TASK_ENV_IDS


@dataclass
class Args:
    total_timesteps: int = STAGE_STEPS
    """per control group, a multiple of 2M: 2M (the general agent's cp4 stage) or 8M (its whole budget)."""
    tasks: tuple[str, ...] = tuple(TASK_ENV_IDS)
    """which groups, in this order: ceiling (4.1), window (4.2), flooring (4.3)."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a resumed run keeps its own."""
    seed: int = 1
    dry_run: bool = False
    """print the plan and where each run stands, and exit."""


def main(args: Args) -> None:
    unknown = [t for t in args.tasks if t not in TASK_ENV_IDS]
    if unknown:
        raise SystemExit(f"--tasks {' '.join(unknown)}: use among {', '.join(TASK_ENV_IDS)}")
    plan = {r.name: r for r in control_group_runs(args.total_timesteps, args.num_envs, args.seed)}
    runs = [plan[f"control_{t}"] for t in args.tasks]
    for run in runs:
        print(describe(run))
    if not args.dry_run:
        for run in runs:
            run_or_resume(run)


if __name__ == "__main__":
    main(tyro.cli(Args))
