"""Train the paper's control groups: controlGroup4.1/4.2/4.3, one single-task agent each for the
ceiling, window and flooring tasks, from scratch, directly at cp4 (no curriculum), with the same
total budget as the general agent.

    python scripts/train_control_groups.py                 # the three runs, one after another
    python scripts/train_control_groups.py --dry-run       # print the plan only
    python scripts/train_control_groups.py --total-timesteps 2000000 --curiosity none
"""

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro

from baselines.ppo import ppo
from ms_construction.envs import TASK_ENV_IDS

GROUP_NAMES = {"ceiling": "controlGroup4.1", "window": "controlGroup4.2", "flooring": "controlGroup4.3"}


@dataclass
class Args:
    total_timesteps: int = ppo.Args.total_timesteps
    """per control group: the general agent's whole budget (the paper's comparison)."""
    seed: int = 1
    curiosity: Literal["none", "icm"] = "icm"
    """as the general agent."""
    log_dir: str = "runs"
    dry_run: bool = False
    """print the three runs and exit."""


def plan(args: Args) -> list[ppo.Args]:
    """The three PPO runs: single-task env, cp4 only, the general agent's budget."""
    return [
        ppo.Args(env_id=env_id, curriculum=("cp4",), total_timesteps=args.total_timesteps, seed=args.seed,
                 curiosity=args.curiosity, log_dir=args.log_dir, exp_name=f"{GROUP_NAMES[kind]}_{kind}")
        for kind, env_id in TASK_ENV_IDS.items()
    ]


def main(args: Args) -> None:
    runs = plan(args)
    for run in runs:
        print(f"{run.exp_name}: {run.env_id}, stages {' '.join(run.curriculum)}, {run.total_timesteps} steps, curiosity {run.curiosity}")
    if args.dry_run:
        return
    for run in runs:
        ckpt = Path(run.log_dir) / run.exp_name / "checkpoint.pt"
        # an interrupted group continues where it stopped
        ppo.main(dataclasses.replace(run, resume=str(ckpt)) if ckpt.is_file() else run)


if __name__ == "__main__":
    main(tyro.cli(Args))
