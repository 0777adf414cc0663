"""The mean of snapshots' weights as one checkpoint (stochastic weight averaging over a run's snapshots,
Izmailov et al. 2018): a policy between the snapshots, for scripts/evaluate.py like any other.

    python scripts/average_checkpoints.py --out runs/refine4/average.pt \\
        --checkpoints runs/refine4/ppo/checkpoint_100000.pt runs/refine4/ppo/checkpoint_200000.pt runs/refine4/ppo/checkpoint_300000.pt
    python scripts/evaluate.py --checkpoint runs/refine4/average.pt --all --episodes 200 --seed 500000 --json runs/refine4/val200_average.json

The snapshots must be of one run whose frozen parts (a residual's base, frozen observation statistics)
are the same in all of them; see baselines/ppo/checkpoints.py::average_checkpoints.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import tyro

from baselines.ppo.checkpoints import average_checkpoints


@dataclass
class Args:
    checkpoints: tuple[Path, ...]
    """the snapshots (at least two)."""
    out: Path
    """the averaged checkpoint to write."""


def main(args: Args) -> None:
    if len(args.checkpoints) < 2:
        raise SystemExit(f"--checkpoints: give at least two snapshots to average, got {len(args.checkpoints)}")
    average_checkpoints(list(args.checkpoints), args.out)
    print(f"wrote {args.out}: the mean of {len(args.checkpoints)} snapshots' weights")


if __name__ == "__main__":
    main(tyro.cli(Args))
