"""Short probes of the from-scratch recipe, from nothing, before a long run spends its budget on it.

    python -m experiments.recipe_probes --run recipe_1m --seed 3   # one probe on one seed (runs/recipe_probes/; resumable)
    python -m experiments.recipe_probes --report                   # their table into docs/experiments/from_scratch.md

Each probe is the recipe (experiments/from_scratch.py `scratch_args`) on a seed for its number of env steps with the
changes PROBES names, nothing else. The recipe's own probes on a seed that has a recipe run (campaign/scratch_s<seed>/)
are that run's first env steps, read from its progress.csv: seed 1's 300,000-step probe went on as its run. What a
probe this short can show is the start of learning: how soon each task type's near-goal start radius widens (the
carry and the install from ever farther out), how far each goal slot's reach-start radius has widened (the reach and
the grasp from ever farther out: seed 2's stopped near the element for ceiling panels and windows), and whether the
training episodes from ordinary resets pick. Each probe's progress.csv is copied to docs/data/recipe_probes/ so the
table regenerates.
"""

from __future__ import annotations

import csv
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from baselines.ppo import ppo
from baselines.ppo.checkpoints import load_checkpoint
from experiments.campaign import CAMPAIGN_DIR
from experiments.from_scratch import PAGE, csv_column, reach_radii_now, scratch_args
from ms_construction.parameters import PAPER_KINDS
from ms_construction.reporting import update_section

LOG_DIR = Path("runs/recipe_probes")
DATA_DIR = Path("docs/data/recipe_probes")
PROBES = {
    "without_reach_starts": ("the recipe without reach starts, as the campaign ended (`--reach-start-share 0`)",
                             dict(reach_start_share=0.0, reach_start_radius=None), 300_000),
    "recipe": ("the recipe: half of the resets that are not near-goal starts start on the last tenth of the reach path "
               "down to the element, each goal slot's part widened by 0.1 once 60% of its last 20 such episodes "
               "grasped from their side", {}, 300_000),
    "recipe_1m": ("the recipe, to 1M env steps", {}, 1_000_000),
    # seed 2's ceiling policy turned away from the table with its wrist's mean before tanh past its flat end, where
    # no advantage moves it (docs/experiments/from_scratch.md): two changes that could keep the reach learnable
    "saturation_penalty": ("the recipe with a penalty on the policy's mean before tanh beyond +-2 on every joint "
                           "(`--mean-saturation-coef 0.01`), to 1M env steps", dict(mean_saturation_coef=0.01),
                           1_000_000),
    "fewer_near_goal": ("the recipe with 60% near-goal starts instead of 80%: twice the reach starts and ordinary "
                        "resets, to 1M env steps", dict(near_goal_share=0.6), 1_000_000),
}
"""name: (what it is, its changes to the recipe, its env steps)."""


def probe_args(name: str, seed: int = 1) -> ppo.Args:
    _, changes, steps = PROBES[name]
    return scratch_args(2, seed=seed, exp_name=probe_name(name, seed), log_dir=str(LOG_DIR), total_timesteps=steps,
                        eval_freq=10**6, **changes)


def probe_name(name: str, seed: int) -> str:
    return f"{name}_s{seed}"


def recipe_run_csv(seed: int) -> Path:
    """The recipe's own run on `seed` (experiments/from_scratch.py), whose first env steps are its recipe probes."""
    return CAMPAIGN_DIR / f"scratch_s{seed}" / "progress.csv"


def run(name: str, seed: int) -> None:
    """Run (or resume) the probe on `seed`, then keep its progress.csv in DATA_DIR. The recipe's own probes on a seed
    with a recipe run are read from that run instead."""
    if name not in PROBES:
        raise SystemExit(f"--run {name}: no such probe; the probes are {', '.join(PROBES)}")
    if not PROBES[name][1] and recipe_run_csv(seed).is_file():
        raise SystemExit(f"--run {name} --seed {seed}: the recipe's run on seed {seed} ({recipe_run_csv(seed)}) holds "
                         "this probe's steps; --report reads them from there")
    args = probe_args(name, seed)
    ckpt = LOG_DIR / args.exp_name / "checkpoint.pt"
    if ckpt.is_file() and load_checkpoint(ckpt)["progress"]["global_step"] >= args.total_timesteps:
        print(f"{args.exp_name} has run its {args.total_timesteps:,} env steps")
    else:
        ppo.main(args.replace(resume=str(ckpt)) if ckpt.is_file() else args)
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(LOG_DIR / args.exp_name / "progress.csv", DATA_DIR / f"{args.exp_name}.csv")


def first_step(rows: list[dict], key: str, at_least: float) -> Optional[int]:
    """The first env step at which column `key` reached `at_least`, or None."""
    for r in rows:
        if r.get(key) not in ("", None) and float(r[key]) >= at_least:
            return int(r["global_step"])
    return None


def probe_csvs(data_dir: Path = DATA_DIR, campaign_dir: Path = CAMPAIGN_DIR) -> list[tuple[str, int, Path]]:
    """(probe, seed, its progress.csv) of every probe run so far, PROBES' order, then seeds in order: the probes'
    copies in `data_dir`, and the recipe's own probes from the recipe's runs in `campaign_dir`."""
    found = []
    for name, (_, changes, _) in PROBES.items():
        seeds = {int(m[1]): p for p in data_dir.glob("*.csv")
                 if (m := re.fullmatch(rf"{re.escape(name)}_s(\d+)", p.stem))}
        if not changes:  # the recipe's own runs hold its own probes
            seeds.update({int(m[1]): p / "progress.csv" for p in campaign_dir.glob("scratch_s*")
                          if (m := re.fullmatch(r"scratch_s(\d+)", p.name)) and (p / "progress.csv").is_file()})
        found += [(name, seed, seeds[seed]) for seed in sorted(seeds)]
    return found


def table(data_dir: Path = DATA_DIR, campaign_dir: Path = CAMPAIGN_DIR) -> str:
    """A row per probe and seed run so far: when each task type's near-goal start radius reached the whole path, how
    far each goal slot's reach-start radius had come at the probe's end, and over the probe's last
    100,000 env steps its training episodes from ordinary resets picked and placed per task type, and those from
    near-goal starts placed. A probe still running shows where it is."""
    lines = ["Command: `python -m experiments.recipe_probes --report` (each probe: the recipe from nothing on a seed, "
             "with the changes named, for its env steps; from docs/data/recipe_probes/, and the recipe's own probes "
             "from the first env steps of its runs, campaign/scratch_s<seed>/progress.csv).", "",
             "| probe | seed | env steps | near-goal radius 1.0 at (env steps): ceiling / window / flooring | "
             "reach-start radius at the end, per goal slot: ceiling / window / flooring | last 100,000 steps, "
             "ordinary resets picked: ceiling / window / flooring % | placed % | near-goal starts placed % |",
             "|---|---|---|---|---|---|---|---|"]
    for name, seed, path in probe_csvs(data_dir, campaign_dir):
        what, _, steps = PROBES[name]
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if int(r["global_step"]) <= steps]
        if not rows:
            continue
        done = int(rows[-1]["global_step"])
        late = [r for r in rows if int(r["global_step"]) > done - 100_000]

        def pct(key: str) -> str:
            x = csv_column(late, key)
            return f"{100 * np.nanmean(x):.1f}" if np.isfinite(x).any() else "-"

        reached = [first_step(rows, f"near_goal_radius_{k}", 1.0) for k in PAPER_KINDS]
        lines.append(f"| {name}: {what} | {seed} | {done:,} | "
                     + " / ".join("-" if s is None else f"{s:,}" for s in reached) + " | "
                     + reach_radii_now(rows) + " | "
                     + " / ".join(pct(f"ordinary_pick_{k}") for k in PAPER_KINDS) + " | "
                     + " / ".join(pct(f"ordinary_place_{k}") for k in PAPER_KINDS)
                     + f" | {pct('near_goal_place_success')} |")
    return "\n".join(lines)


@dataclass
class Args:
    run: Optional[str] = None
    """run (or resume) this probe (see PROBES)."""
    seed: int = 1
    """the seed --run runs the probe on."""
    report: bool = False
    """write the probes' table into docs/experiments/from_scratch.md."""


def main(args: Args) -> None:
    if args.run is not None:
        run(args.run, args.seed)
    if args.report:
        body = table()
        update_section(PAGE, "recipe-probes", body, "Learning from reward alone: the experiment")
        print(body)
    if args.run is None and not args.report:
        raise SystemExit(f"give --run NAME (one of {', '.join(PROBES)}) or --report")


if __name__ == "__main__":
    main(tyro.cli(Args))
