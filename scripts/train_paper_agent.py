"""The paper's general agent, run as the paper ran it (baselines/ppo/paper_setting.py says how), and
its cp1 stage again without curiosity: one after the other, each resumed from its checkpoint in
campaign/ when it has one.

    python scripts/train_paper_agent.py --dry-run               # the plan, and where each run stands
    python scripts/train_paper_agent.py                         # run (or resume) both
    python scripts/train_paper_agent.py --runs paper_general_agent --num-envs 16

Ctrl-C or SIGTERM stops the run in progress after its iteration, with a checkpoint; the same command
resumes it. Control groups: scripts/train_control_groups.py.
"""

from dataclasses import dataclass
from typing import Optional

import tyro

from baselines.ppo.paper_setting import describe, general_runs, run_or_resume


@dataclass
class Args:
    runs: tuple[str, ...] = ("paper_general_agent", "paper_cp1_no_curiosity")
    """which runs, in this order."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); it must divide the 10,000 samples of an update. A run
    resumed from a checkpoint keeps its own."""
    seed: int = 1
    dry_run: bool = False
    """print the plan and where each run stands, and exit."""


def main(args: Args) -> None:
    plan = {r.name: r for r in general_runs(args.num_envs, args.seed)}
    unknown = [n for n in args.runs if n not in plan]
    if unknown:
        raise SystemExit(f"--runs {' '.join(unknown)}: use among {', '.join(plan)}")
    for name in args.runs:
        print(describe(plan[name]))
    if not args.dry_run:
        for name in args.runs:
            run_or_resume(plan[name])


if __name__ == "__main__":
    main(tyro.cli(Args))
