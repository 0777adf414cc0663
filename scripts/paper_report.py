"""Where the paper's experiment stands, from its runs' progress.csv in campaign/: a table per run and
per curriculum stage in docs/RESULTS.md, and Figure 3 (and Figure 4 once the control groups have run)
as PNGs drawn by scripts/plot_training.py.

    python scripts/paper_report.py                  # print the tables
    python scripts/paper_report.py --write-results  # and write them, with the figures, into docs/

The figures are training figures (the episodes PPO sampled, stochastic actions); Table II's rows, the
paper's 50,000-step protocol on the test seeds, come from scripts/evaluate.py on each finished run's
checkpoint.
"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import tyro

from baselines.ppo import paper_setting
from baselines.ppo.paper_setting import CAMPAIGN_DIR, STAGE_STEPS, control_group_runs, general_runs
from ms_construction.reporting import update_section

LAST = 200_000
"""the window, in env steps, of the 'lately' columns."""


@dataclass
class Args:
    campaign_dir: Path = CAMPAIGN_DIR
    """the campaign's runs (one folder each, as scripts/train_paper_agent.py and train_control_groups.py write)."""
    write_results: bool = False
    """write the section `paper-experiment` of docs/RESULTS.md and the figures into docs/images/."""
    results: Path = Path("docs/RESULTS.md")
    images: Path = Path("docs/images")


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def weighted(rows: list[dict], key: str) -> float:
    """The mean of `key` over the rows' training episodes (each row is one update's episodes)."""
    pairs = [(float(r[key]), float(r["episodes"])) for r in rows if r.get(key) not in (None, "") and r["episodes"] not in ("", "0")]
    n = sum(w for _, w in pairs)
    return sum(v * w for v, w in pairs) / n if n else math.nan


def episodes(rows: list[dict]) -> int:
    return int(sum(float(r["episodes"] or 0) for r in rows))


def fmt(v: float, scale: float = 1.0, digits: int = 1) -> str:
    return "-" if math.isnan(v) else f"{v * scale:.{digits}f}"


def summary_cells(rows: list[dict]) -> str:
    """episodes | picked % | placed % | extrinsic | intrinsic | distance m | angle deg | held %."""
    return " | ".join([f"{episodes(rows):,}", fmt(weighted(rows, "pick_success"), 100), fmt(weighted(rows, "place_success"), 100),
                       fmt(weighted(rows, "extrinsic_return"), digits=2), fmt(weighted(rows, "intrinsic_return"), digits=2),
                       fmt(weighted(rows, "end_place_dist"), digits=2), fmt(weighted(rows, "end_place_angle_deg"), digits=0),
                       fmt(weighted(rows, "held_at_end"), 100, 0)])


HEADER = ("training episodes | picked % | placed % | extrinsic return | intrinsic return | end: distance to goal (m) | "
          "end: angle to goal (deg) | end: held %")


def report(campaign_dir: Path) -> tuple[str, dict[str, Path]]:
    """The tables (markdown) and the progress.csv of each run that has one."""
    plans = {r.name: r for r in general_runs() + control_group_runs()}
    csvs = {name: campaign_dir / name / "progress.csv" for name in plans if (campaign_dir / name / "progress.csv").is_file()}
    lines = [f"| run | what | env steps done / planned | stage now | lately: env steps | {HEADER} |",
             "|---|---|---|---|---|" + "---|" * 8]
    for name, run in plans.items():
        if name not in csvs:
            lines.append(f"| {name} | {run.what} | 0 / {run.args.total_timesteps:,} | not started | |" + " |" * 8)
            continue
        rows = read_rows(csvs[name])
        done = int(rows[-1]["global_step"])
        late = [r for r in rows if int(r["global_step"]) > done - LAST]
        before = [r for r in rows if int(r["global_step"]) <= done - LAST]
        window = done - (int(before[-1]["global_step"]) if before else 0)
        lines.append(f"| {name} | {run.what} | {done:,} / {run.args.total_timesteps:,} | {rows[-1]['stage']} | "
                     f"{window:,} | {summary_cells(late)} |")
    lines += ["", "Each stage of the runs so far, all its training episodes:", "",
              f"| run | stage | env steps | {HEADER} | in-training evaluation placed % (last) |",
              "|---|---|---|" + "---|" * 9]
    for name, path in csvs.items():
        rows = read_rows(path)
        stages: dict[int, list[dict]] = {}  # every stage of the paper's runs is STAGE_STEPS long
        for r in rows:
            stages.setdefault((int(r["global_step"]) - 1) // STAGE_STEPS, []).append(r)
        for srows in stages.values():
            stage = srows[0]["stage"]
            evals = [float(r["eval_place_success"]) for r in srows if r.get("eval_place_success") not in (None, "")]
            start = (int(srows[0]["global_step"]) - 1) // STAGE_STEPS * STAGE_STEPS
            lines.append(f"| {name} | {stage} | {start:,}-{int(srows[-1]['global_step']):,} | {summary_cells(srows)} | "
                         f"{fmt(evals[-1], 100) if evals else '-'} |")
    return "\n".join(lines), csvs


def settings_table() -> str:
    """The settings table of baselines/ppo/paper_setting.py's docstring (the one place it is written)."""
    return "\n".join(line for line in paper_setting.__doc__.splitlines() if line.startswith("|"))


def figures(csvs: dict[str, Path], images: Path) -> list[str]:
    """Draw Figure 3 (and 4 when a control group has run) with plot_training.py; their commands."""
    commands = []
    if "paper_general_agent" in csvs:
        commands.append(["--figure", "fig3", "--csv", str(csvs["paper_general_agent"]), "--out", str(images / "paper_fig3.png"),
                         "--window", "20"])
        controls = [str(p) for n, p in csvs.items() if n.startswith("control_")]
        if controls:
            commands.append(["--figure", "fig4", "--csv", str(csvs["paper_general_agent"]), *controls,
                             "--out", str(images / "paper_fig4.png"), "--window", "20"])
    script = Path(__file__).with_name("plot_training.py")
    for c in commands:
        subprocess.run([sys.executable, str(script), *c], check=True)
    return ["python scripts/plot_training.py " + " ".join(c) for c in commands]


def main(args: Args) -> str:
    body, csvs = report(args.campaign_dir)
    print(body)
    if args.write_results:
        commands = figures(csvs, args.images)
        pictures = [f"![{Path(c.split('--out ')[1].split()[0]).stem}]({Path(*Path(c.split('--out ')[1].split()[0]).parts[1:])})\n\n"
                    f"*Made by `{c}`.*" for c in commands]
        update_section(args.results, "paper-experiment", "\n".join([
            "## The paper's experiment: where the campaign stands", "",
            "Command: `python scripts/paper_report.py --write-results` (from the runs' progress.csv in campaign/; "
            "settings: baselines/ppo/paper_setting.py). Training episodes: the policy's sampled actions; "
            f"'lately' is the last {LAST:,} env steps; 'end' is where the element was when the episode ended "
            "(its distance and angle to the goal, whether the plate held it), the mean over the episodes.", "",
            body, "", *pictures, "",
            "The settings, from baselines/ppo/paper_setting.py (where the paper is silent: ML-Agents' documented "
            "defaults where they carry over, ppo.py's otherwise):", "", settings_table()]), "Results")
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
