"""How long the expert's demonstrations are, per task: the slack a clone of them has before the 250-step limit.

    python -m experiments.demo_lengths \
        --demos 'slow=runs/general_agent_fixed/demos/general.npz' 'fast=runs/general_agent_fast/demos/general.npz' \
        --write-results

Each LABEL=NPZ is a demonstrations file of scripts/collect_demos.py or experiments/general_agent.py (its
demos/*.npz; a label given several files counts them together). Takeover files (*_takeovers<r>.npz) start
mid-episode: leave them out. The lengths are the recorded episodes', the placed ones (the only ones kept).
`--keep JSON` carries the rows of an earlier run of this script (its --json) into the table first, so that an
expert setting's row outlives the run folder its demonstrations were in.
"""

from __future__ import annotations

import json
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.reporting import update_section

STEP_LIMIT = 250


@dataclass
class Args:
    demos: tuple[str, ...]
    """LABEL=NPZ ...: demonstrations files, one label per expert setting."""
    json: Optional[Path] = None
    """write the figures to this file (with the rows of --keep)."""
    keep: Optional[Path] = None
    """an earlier --json of this script whose rows go first (labels also given in --demos are measured anew)."""
    write_results: bool = False
    """write the table into the section `demo-lengths` of docs/experiments/general_agent.md."""
    results: Path = Path("docs/experiments/general_agent.md")


def lengths(path: Path) -> dict[str, np.ndarray]:
    """Per element kind, the length of every episode in the file."""
    with np.load(path) as f:
        episode, task = f["episode"], f["task"]
    starts = np.flatnonzero(np.diff(episode, prepend=-1))
    ends = np.append(starts[1:], len(episode))
    kinds = task[starts]
    return {kind: (ends - starts)[kinds == i] for i, kind in enumerate(ELEMENT_KINDS) if np.any(kinds == i)}


def summary(per_kind: dict[str, list[np.ndarray]]) -> dict[str, dict]:
    out = {}
    for kind, parts in per_kind.items():
        n = np.concatenate(parts)
        out[kind] = dict(episodes=int(len(n)), mean=float(n.mean()), p95=float(np.percentile(n, 95)), max=int(n.max()),
                         over_200=float(np.mean(n > 200)))
    return out


def main(args: Args) -> dict:
    grouped: dict[str, dict[str, list[np.ndarray]]] = {}
    for spec in args.demos:
        label, _, path = spec.partition("=")
        if not label or not Path(path).is_file():
            raise SystemExit(f"--demos {spec}: use LABEL=NPZ, a demonstrations file (scripts/collect_demos.py)")
        for kind, n in lengths(Path(path)).items():
            grouped.setdefault(label, {}).setdefault(kind, []).append(n)
    if args.keep and not args.keep.is_file():
        raise SystemExit(f"--keep {args.keep}: no such file; give an earlier --json of this script")
    kept = json.loads(args.keep.read_text()) if args.keep else {}
    result = {**{label: rows for label, rows in kept.items() if label not in grouped},
              **{label: summary(per_kind) for label, per_kind in grouped.items()}}
    lines = ["| expert | task | episodes | mean length | 95th percentile | longest | longer than 200 steps |",
             "|---|---|---|---|---|---|---|"]
    for label, kinds in result.items():
        for kind in ELEMENT_KINDS:
            if kind in kinds:
                s = kinds[kind]
                lines.append(f"| {label} | {kind} | {s['episodes']} | {s['mean']:.0f} | {s['p95']:.0f} | {s['max']} | "
                             f"{100 * s['over_200']:.1f}% |")
    table = "\n".join(lines)
    print(table)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=1))
    if args.write_results:
        command = "python -m experiments.demo_lengths " + " ".join(shlex.quote(a) for a in sys.argv[1:])
        update_section(args.results, "demo-lengths", f"Command: `{command}` (step limit {STEP_LIMIT})\n\n{table}",
                       "Results")
    return result


if __name__ == "__main__":
    main(tyro.cli(Args))
