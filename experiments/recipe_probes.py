"""Short probes of the from-scratch recipe, from nothing, before a long run spends its budget on it.

    python -m experiments.recipe_probes --run recipe          # one probe (runs/recipe_probes/<name>/; resumable)
    python -m experiments.recipe_probes --report              # their table into docs/experiments/from_scratch.md

Each probe is the recipe (experiments/from_scratch.py `scratch_args`, seed 1) for PROBE_STEPS env steps with the
changes PROBES names, nothing else. The recipe's own probe became the first PROBE_STEPS env steps of seed 1's run
(campaign/scratch_s1/): its checkpoint went on as that run. What a probe this short can show is the start of learning: how soon each task
type's near-goal start radius widens (the carry and the install from ever farther out) and whether the training
episodes from ordinary resets pick (the reach and the grasp), which the campaign's cp4 run from nothing never
showed by placing. Each probe's progress.csv is copied to docs/data/recipe_probes/ so the table regenerates.
"""

from __future__ import annotations

import csv
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from baselines.ppo import ppo
from baselines.ppo.checkpoints import load_checkpoint
from experiments.from_scratch import PAGE, csv_column, scratch_args
from ms_construction.parameters import PAPER_KINDS
from ms_construction.reporting import update_section

PROBE_STEPS = 300_000
LOG_DIR = Path("runs/recipe_probes")
DATA_DIR = Path("docs/data/recipe_probes")
PROBES = {
    "without_reach_starts": ("the recipe without reach starts, as the campaign ended (`--reach-start-share 0`)",
                             dict(reach_start_share=0.0, reach_start_radius=None)),
    "recipe": ("the recipe: half of the resets that are not near-goal starts start on the last tenth of the reach "
               "path down to the element, each goal slot's part widened by 0.1 once 60% of its last 20 such episodes "
               "grasped from their side", {}),
}
"""name: (what it is, its changes to the recipe)."""


def probe_args(name: str) -> ppo.Args:
    if name not in PROBES:
        raise SystemExit(f"--run {name}: no such probe; the probes are {', '.join(PROBES)}")
    return scratch_args(2, exp_name=name, log_dir=str(LOG_DIR), total_timesteps=PROBE_STEPS, eval_freq=10**6,
                        **PROBES[name][1])


def run(name: str) -> None:
    """Run (or resume) the probe, then keep its progress.csv in DATA_DIR."""
    args = probe_args(name)
    ckpt = LOG_DIR / name / "checkpoint.pt"
    if ckpt.is_file() and load_checkpoint(ckpt)["progress"]["global_step"] >= PROBE_STEPS:
        print(f"{name} has run its {PROBE_STEPS:,} env steps")
    else:
        ppo.main(args.replace(resume=str(ckpt)) if ckpt.is_file() else args)
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(LOG_DIR / name / "progress.csv", DATA_DIR / f"{name}.csv")


def first_step(rows: list[dict], key: str, at_least: float) -> Optional[int]:
    """The first env step at which column `key` reached `at_least`, or None."""
    for r in rows:
        if r.get(key) not in ("", None) and float(r[key]) >= at_least:
            return int(r["global_step"])
    return None


def table(data_dir: Path = DATA_DIR) -> str:
    """A row per probe run so far: when each task type's start radius reached the whole path, and over the probe's
    last 100,000 env steps its training episodes from ordinary resets picked and placed per task type, and those from
    near-goal starts placed."""
    lines = [f"Command: `python -m experiments.recipe_probes --report` (each probe: the recipe from nothing, seed 1, "
             f"{PROBE_STEPS:,} env steps, with the changes named; from docs/data/recipe_probes/).", "",
             "| probe | env steps | start radius 1.0 at (env steps): ceiling / window / flooring | last 100,000 steps, "
             "ordinary resets picked: ceiling / window / flooring % | placed % | near-goal starts placed % |",
             "|---|---|---|---|---|---|"]
    for name, (what, _) in PROBES.items():
        path = data_dir / f"{name}.csv"
        if not path.is_file():
            continue
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if int(r["global_step"]) <= PROBE_STEPS]
        done = int(rows[-1]["global_step"])
        late = [r for r in rows if int(r["global_step"]) > done - 100_000]

        def pct(key: str) -> str:
            x = csv_column(late, key)
            return f"{100 * np.nanmean(x):.1f}" if np.isfinite(x).any() else "-"

        reached = [first_step(rows, f"near_goal_radius_{k}", 1.0) for k in PAPER_KINDS]
        lines.append(f"| {name}: {what} | {done:,} | " + " / ".join("-" if s is None else f"{s:,}" for s in reached)
                     + " | " + " / ".join(pct(f"ordinary_pick_{k}") for k in PAPER_KINDS) + " | "
                     + " / ".join(pct(f"ordinary_place_{k}") for k in PAPER_KINDS)
                     + f" | {pct('near_goal_place_success')} |")
    return "\n".join(lines)


@dataclass
class Args:
    run: Optional[str] = None
    """run (or resume) this probe (see PROBES)."""
    report: bool = False
    """write the probes' table into docs/experiments/from_scratch.md."""


def main(args: Args) -> None:
    if args.run is not None:
        run(args.run)
    if args.report:
        body = table()
        update_section(PAGE, "recipe-probes", body, "Learning from reward alone: the experiment")
        print(body)
    if args.run is None and not args.report:
        raise SystemExit(f"give --run NAME (one of {', '.join(PROBES)}) or --report")


if __name__ == "__main__":
    main(tyro.cli(Args))
