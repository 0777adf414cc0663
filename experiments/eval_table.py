"""Agents side by side from the JSONs scripts/evaluate.py wrote: a table of their place success (95% intervals)
and mean episode length per task, printed or written as a generated section of docs/RESULTS.md.

    python -m experiments.eval_table --section probe-branches \
        --rows 'nearest to the arm=docs/data/probe_branches/window_clone_nearest.json' \
               'one way per goal slot=docs/data/probe_branches/window_clone_fixed.json' --write-results

A JSON of `evaluate.py --all` gives a row per task; one of `--env-id` a single row.
"""

from __future__ import annotations

import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import tyro

from baselines.ppo.evaluation import read_labelled
from ms_construction.reporting import update_section


@dataclass
class Args:
    rows: tuple[str, ...]
    """LABEL=JSON ...: each agent's label and the file scripts/evaluate.py --json wrote for it, in the table's order."""
    section: str = "eval-table"
    """the name of the generated section of --results to write (with --write-results)."""
    write_results: bool = False
    results: Path = Path("docs/RESULTS.md")


def table(rows: dict[str, dict]) -> str:
    pct = lambda p: f"{100 * p:.1f}"  # noqa: E731
    lines = ["| agent | task | episodes | place success % [95% CI] | mean length | evaluation |", "|---|---|---|---|---|---|"]
    for label, row in rows.items():
        for env_id, r in row["tasks"].items():
            lo, hi = r["place_success_ci95"]
            lines.append(f"| {label} | {env_id} | {r['episodes']} | {pct(r['place_success'])} [{pct(lo)}, {pct(hi)}] | "
                         f"{r['mean_length']:.0f} | {row['path']} |")
    return "\n".join(lines)


def main(args: Args) -> str:
    command = "python -m experiments.eval_table " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    body = f"Command: `{command}`\n\n" + table(read_labelled(args.rows, "--rows"))
    print(body)
    if args.write_results:
        update_section(args.results, args.section, title="Results", body=body)
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
