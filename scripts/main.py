"""The main job: the shipped general agent installs ceiling panels, windows and floor panels.

    python scripts/main.py                         # 20 episodes per task, a video of the first of each
    python scripts/main.py --episodes 100 --out outputs/main

Evaluates `assets/checkpoints/general_agent.pt` (one policy for the three tasks, deterministic
actions, cp4 tolerances, seeds never used in training) with scripts/evaluate.py (baselines/ppo/evaluation.py), prints the
Table II-shaped table and writes one video per task. The full 100-episode table and how the agent
was trained: docs/RESULTS.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import tyro

from baselines.ppo import evaluation as evaluate


@dataclass
class Args:
    checkpoint: Path = evaluate.DEFAULT_CHECKPOINT
    """the agent to show."""
    episodes: int = 20
    """episodes per task."""
    seed: int = 1_000_000
    """seed of the first episode of each task."""
    out: Path = Path("outputs/main")
    """videos (videos/) and the results (results.json) go here."""
    workers: int = 2
    """processes, one env each."""


def main(args: Args) -> None:
    evaluate.main(evaluate.Args(checkpoint=args.checkpoint, all=True, episodes=args.episodes, seed=args.seed,
                                json=args.out / "results.json", video_dir=args.out / "videos", videos=1,
                                workers=args.workers))


if __name__ == "__main__":
    main(tyro.cli(Args))
