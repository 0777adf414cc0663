"""Agents side by side from the JSONs scripts/evaluate.py wrote: a table of their place success (95% intervals)
and mean episode length per task, printed or written as a generated section of docs/RESULTS.md.

    python scripts/eval_table.py --section probe-branches \
        --rows 'nearest to the arm=docs/data/probe_branches/window_clone_nearest.json' \
               'one way per goal slot=docs/data/probe_branches/window_clone_fixed.json' --write-results

A JSON of `evaluate.py --all` gives a row per task; one of `--env-id` a single row.
"""

from __future__ import annotations

import json
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import tyro

from ms_construction.reporting import update_section


@dataclass
class Args:
    rows: tuple[str, ...]
    """LABEL=JSON ...: each agent's label and the file scripts/evaluate.py --json wrote for it, in the table's order."""
    section: str = "eval-table"
    """the name of the generated section of --results to write (with --write-results)."""
    write_results: bool = False
    results: Path = Path("docs/RESULTS.md")


def tasks_of(spec: str) -> tuple[str, str, dict]:
    label, _, path = spec.partition("=")
    if not path or not Path(path).is_file():
        raise SystemExit(f"--rows {spec}: use LABEL=JSON, a file that scripts/evaluate.py --json wrote")
    data = json.loads(Path(path).read_text())
    if "tasks" not in data and "place_success" not in data:
        raise SystemExit(f"--rows {spec}: {path} is not a JSON of scripts/evaluate.py --json")
    return label, path, data.get("tasks", {data.get("env_id"): data})


def table(rows: list[tuple[str, str, dict]]) -> str:
    pct = lambda p: f"{100 * p:.1f}"  # noqa: E731
    lines = ["| agent | task | episodes | place success % [95% CI] | mean length | evaluation |", "|---|---|---|---|---|---|"]
    for label, path, tasks in rows:
        for env_id, r in tasks.items():
            lo, hi = r["place_success_ci95"]
            lines.append(f"| {label} | {env_id} | {r['episodes']} | {pct(r['place_success'])} [{pct(lo)}, {pct(hi)}] | "
                         f"{r['mean_length']:.0f} | {path} |")
    return "\n".join(lines)


def main(args: Args) -> str:
    command = "python scripts/eval_table.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    body = f"Command: `{command}`\n\n" + table([tasks_of(spec) for spec in args.rows])
    print(body)
    if args.write_results:
        update_section(args.results, args.section, title="Results", body=body)
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
