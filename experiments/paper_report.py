"""The paper's experiment, from its evaluation JSONs and its runs' progress.csv in campaign/: Table II in
docs/RESULTS.md; on docs/experiments/paper.md a table of the runs, where each of Table II's rows comes from, each run's
curriculum stages and the settings; Figure 3 (and Figure 4 once the control groups have run) as PNGs drawn by
scripts/plot_training.py, shown on that page.

    python -m experiments.paper_report                  # print the tables
    python -m experiments.paper_report --write-results  # and write them, with the figures, into docs/

The figures are training figures (the episodes PPO sampled, stochastic actions). Table II's rows, the
paper's 50,000-step protocol on the test seeds, come from scripts/evaluate.py on each shipped
checkpoint and each stage-end policy of the general agent, run with the command its row names (a
JSON in docs/data/paper/); a row whose JSON is not there yet says so.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from experiments import paper
from baselines.ppo.evaluation import EXPERT_RESULTS, PAPER_CONTROL_GROUPS, PAPER_TABLE_II, pct, wilson
from experiments.campaign import CAMPAIGN_DIR
from experiments.paper import STAGE_STEPS, control_group_runs, general_runs
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section

LAST = 200_000
"""the window, in env steps, of the 'lately' columns."""
EVAL_DIR = Path("docs/data/paper")
"""the Table II rows' evaluations (scripts/evaluate.py --json), one JSON per agent."""
SHIPPED_AGENT_EVAL = Path("docs/data/general_agent_eval_50k.json")
"""the shipped general agent's evaluation on the same protocol (its own section of docs/RESULTS.md)."""
PROTOCOL = "--steps 50000"


@dataclass
class Args:
    campaign_dir: Path = CAMPAIGN_DIR
    """the campaign's runs (one folder each, as experiments/paper.py writes them)."""
    write_results: bool = False
    """write the section `paper-experiment` of docs/RESULTS.md and the figures into docs/images/."""
    results: Path = Path("docs/RESULTS.md")
    experiment_page: Path = Path("docs/experiments/paper.md")
    """where the runs, each Table II row's source, each run's stages and the settings go (its section `paper-stages`),
    with --write-results."""
    readme: Path = Path("README.md")
    """where the headline table goes (its section `headline`)."""
    images: Path = Path("docs/images")
    eval_dir: Path = EVAL_DIR
    """where Table II's evaluation JSONs are (scripts/evaluate.py --json, as each row's command writes them)."""


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


def report(campaign_dir: Path) -> tuple[str, str, dict[str, Path]]:
    """The runs' table and their stages' table (markdown), and the progress.csv of each run that has one."""
    plans = {r.name: r for r in general_runs() + control_group_runs()}
    continued = {r.name: r for r in control_group_runs(4 * STAGE_STEPS)}  # a control group past 2M is on its way to 8M
    csvs = {name: campaign_dir / name / "progress.csv" for name in plans if (campaign_dir / name / "progress.csv").is_file()}
    lines = [f"| run | what | env steps done / planned | stage now | lately: env steps | {HEADER} |",
             "|---|---|---|---|---|" + "---|" * 8]
    for name, run in plans.items():
        if name not in csvs:
            lines.append(f"| {name} | {run.what} | 0 / {run.args.total_timesteps:,} | not started | |" + " |" * 8)
            continue
        rows = read_rows(csvs[name])
        done = int(rows[-1]["global_step"])
        if done > run.args.total_timesteps and name in continued:
            run = continued[name]
        late = [r for r in rows if int(r["global_step"]) > done - LAST]
        before = [r for r in rows if int(r["global_step"]) <= done - LAST]
        window = done - (int(before[-1]["global_step"]) if before else 0)
        lines.append(f"| {name} | {run.what} | {done:,} / {run.args.total_timesteps:,} | {rows[-1]['stage']} | "
                     f"{window:,} | {summary_cells(late)} |")
    stages_lines = [f"| run | stage | env steps | {HEADER} | in-training evaluation placed % (last) |",
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
            stages_lines.append(f"| {name} | {stage} | {start:,}-{int(srows[-1]['global_step']):,} | "
                                f"{summary_cells(srows)} | {fmt(evals[-1], 100) if evals else '-'} |")
    return "\n".join(lines), "\n".join(stages_lines), csvs


@dataclass
class TableRow:
    """One agent of Table II: who, how trained and for how long, and where its figures come from (an
    evaluation JSON and the command that writes it, or the paper's numbers)."""

    agent: str
    method: str
    json: Optional[Path] = None
    command: str = ""
    pending: str = ""
    """why the JSON is not there yet."""
    kept: bool = True
    """False where the policy the row judges was not kept, so that its JSON never will be there."""
    paper: Optional[dict] = None
    env_ids: tuple[str, ...] = tuple(PAPER_TASK_ENV_IDS.values())
    """the tasks the agent is judged on (a control group: its own only)."""


def _evaluation_row(label: str, method: str, checkpoint: Path, name: str, env_ids: tuple[str, ...], pending: str,
                    eval_dir: Path) -> TableRow:
    """A row from `scripts/evaluate.py` on `checkpoint` (at cp4, the test seeds, 50,000 steps per task)."""
    task = "--all" if len(env_ids) == 3 else f"--env-id {env_ids[0]}"
    json_path = eval_dir / f"{name}_eval_50k.json"
    return TableRow(label, method, json_path, f"python scripts/evaluate.py --checkpoint {checkpoint} {task} {PROTOCOL} "
                    f"--json {json_path}", pending, env_ids=env_ids)


def table_ii_rows(campaign_dir: Path, eval_dir: Path = EVAL_DIR) -> list[TableRow]:
    """Table II's agents in order: the paper's, our paper-setting general agent (and each of its stages'
    end policies at cp4), our control groups at 2M and 8M steps, the shipped general agent, the expert."""
    general = general_runs()[0]
    done = lambda run: (f"its run is at step {last_step(campaign_dir / run.name / 'progress.csv'):,} of "  # noqa: E731
                        f"{run.args.total_timesteps:,} ({run.command})")
    rows = [TableRow("paper: general agent", "PPO + ICM (ML-Agents), curriculum cp1 -> cp4, 2M steps each", paper=PAPER_TABLE_II),
            TableRow("paper: control groups 4.1 / 4.2 / 4.3", "PPO + ICM, cp4 from the first step, one agent per task",
                     paper=PAPER_CONTROL_GROUPS),
            _evaluation_row("ours: paper setting, general agent", f"{general.what}; 8M env steps", general.shipped,
                            general.name, tuple(PAPER_TASK_ENV_IDS.values()), done(general), eval_dir)]
    for k, stage in enumerate(general.args.stages.curriculum[:-1], start=1):
        snapshot = campaign_dir / general.name / f"checkpoint_stage{k}_{stage}.pt"
        passed = k * STAGE_STEPS <= last_step(campaign_dir / general.name / "progress.csv")
        reached = ("that stage's final policy was not kept (ppo.py keeps them since 3.42M)" if passed
                   else f"the end of {stage} comes at step {k * STAGE_STEPS:,}")
        row = _evaluation_row(f"ours: paper setting, end of {stage}", f"the general agent after {k * STAGE_STEPS:,} env "
                              f"steps, judged at cp4", snapshot, f"{general.name}_stage{k}_{stage}",
                              tuple(PAPER_TASK_ENV_IDS.values()), reached if not snapshot.is_file() else "not evaluated yet",
                              eval_dir)
        row.kept = snapshot.is_file() or not passed
        rows.append(row)
    for total in (STAGE_STEPS, 4 * STAGE_STEPS):
        runs = control_group_runs(total)
        for run in runs:
            rows.append(_evaluation_row(f"ours: {run.what.split(':')[0]}, {total // 1_000_000}M", f"{run.what}; {total // 1_000_000}M env steps",
                                        run.shipped, run.shipped.stem, (run.args.env_id,), done(run), eval_dir))
    rows.append(TableRow("ours: shipped general agent", "behaviour clone of the planning expert, then PPO on a residual "
                         "(docs/RESULTS.md, the general agent's section)", SHIPPED_AGENT_EVAL))
    rows.append(scratch_row(eval_dir))
    rows.append(TableRow("ours: planning expert", "mplib RRTConnect; 100 episodes per task (its own section)", EXPERT_RESULTS))
    return rows


def scratch_row(eval_dir: Path = EVAL_DIR) -> TableRow:
    """The general agent learnt from reward alone (experiments/from_scratch.py): the better seed's choice, once shipped."""
    from experiments.from_scratch import COMMAND, SHIPPED, shipped_how

    pending = f"not shipped yet: `{COMMAND} --ship-seeds`" if not SHIPPED.is_file() else "not evaluated yet"
    how = (f"{shipped_how(SHIPPED)}, the better of two seeds (its section)" if SHIPPED.is_file() else
           "the recipe from nothing on the default dense reward, the better of two seeds; no demonstrations")
    return _evaluation_row("ours: from reward alone", how, SHIPPED, SHIPPED.stem,
                           tuple(PAPER_TASK_ENV_IDS.values()), pending, eval_dir)


HEADLINE_AGENTS = ("ours: shipped general agent", "ours: from reward alone", "paper: general agent",
                   "ours: paper setting, general agent", "ours: planning expert")
"""the README's headline rows, from Table II's."""


def headline(campaign_dir: Path, eval_dir: Path = EVAL_DIR) -> str:
    """The README's table: pick / place % per task of the agents a reader compares first (Table II's rows)."""
    env_ids = list(PAPER_TASK_ENV_IDS.values())
    rows = {r.agent: r for r in table_ii_rows(campaign_dir, eval_dir)}
    lines = ["| agent | " + " | ".join(f"{e.split('-')[0].replace('Installation', '')}: pick / place % [95% CI]"
                                       for e in env_ids) + " |", "|---|" + "---|" * len(env_ids)]
    for name in HEADLINE_AGENTS:
        cells = _cells(rows[name]) or {e: "not yet" for e in env_ids}
        lines.append(f"| {name.replace('ours: ', '')} | " + " | ".join(cells.get(e, "-") for e in env_ids) + " |")
    return ("Generated by `python -m experiments.paper_report --write-results` from the evaluation JSONs of "
            "[Table II](docs/RESULTS.md#table-ii): the paper's protocol, 50,000 env steps per task at cp4, "
            "test seeds never trained on.\n\n" + "\n".join(lines))


def last_step(progress_csv: Path) -> int:
    return int(read_rows(progress_csv)[-1]["global_step"]) if progress_csv.is_file() else 0


def _cells(row: TableRow) -> Optional[dict[str, str]]:
    """Per task 'pick / place' (95% intervals for ours); None where the row's evaluation is missing."""
    if row.paper is not None:
        return {env_id: f"{pick:.2f} / {place:.2f}" for env_id, (pick, place) in row.paper.items()}
    if row.json is None or not row.json.is_file():
        return None
    data = json.loads(row.json.read_text())
    if "summary" in data:  # scripts/run_expert.py's JSON: rates of `episodes` episodes
        tasks = {e: s for e, s in data["summary"].items() if e in PAPER_TABLE_II}
        return {e: " / ".join(pct(s[k], wilson(round(s[k] * s["episodes"]), s["episodes"])) for k in ("pick_success", "place_success"))
                for e, s in tasks.items()}
    tasks = data.get("tasks", {data.get("env_id"): data})
    return {e: f"{pct(r['pick_success'], r['pick_success_ci95'])} / {pct(r['place_success'], r['place_success_ci95'])}"
            for e, r in tasks.items()}


def table_ii(campaign_dir: Path, eval_dir: Path = EVAL_DIR) -> tuple[str, str]:
    """Table II: pick / place success % per task and agent (ours with 95% intervals, the paper's as printed); and
    where each of our rows comes from (its command and JSON, or why it is not there yet and the command then)."""
    env_ids = list(PAPER_TASK_ENV_IDS.values())
    lines = ["| agent | method; env steps | " + " | ".join(f"{e}: pick / place % [95% CI]" for e in env_ids) + " |",
             "|---|---|" + "---|" * len(env_ids)]
    notes = []
    for row in table_ii_rows(campaign_dir, eval_dir):
        cells = _cells(row)
        if cells is None and not row.kept:
            cells = {e: "not kept" for e in row.env_ids}
            notes.append(f"- {row.agent}: not kept ({row.pending})")
        elif cells is None:
            cells = {e: "not yet" for e in row.env_ids}
            notes.append(f"- {row.agent}: not yet ({row.pending}); then `{row.command}`")
        elif row.json is not None:
            notes.append(f"- {row.agent}: `{json.loads(row.json.read_text())['command']}` ({row.json})")
        lines.append(f"| {row.agent} | {row.method} | " + " | ".join(cells.get(e, "-") for e in env_ids) + " |")
    return "\n".join(lines + ["", "-: not this agent's task (a control group trains on one task and is judged on it "
                               "alone, as in the paper)."]), "\n".join(notes)


def settings_table() -> str:
    """The settings table of experiments/paper.py's docstring (the one place it is written)."""
    return "\n".join(line for line in paper.__doc__.splitlines() if line.startswith("|"))


def figures(csvs: dict[str, Path], images: Path) -> list[str]:
    """Draw Figure 3 (and 4 when a control group has run, and curiosity's effect when run 3 has) with
    plot_training.py; their commands."""
    commands = []
    if "paper_general_agent" in csvs:
        commands.append(["--figure", "fig3", "--csv", str(csvs["paper_general_agent"]), "--out", str(images / "paper_fig3.png"),
                         "--window", "20"])
        controls = [str(p) for n, p in csvs.items() if n.startswith("control_")]
        if controls:
            commands.append(["--figure", "fig4", "--csv", str(csvs["paper_general_agent"]), *controls,
                             "--out", str(images / "paper_fig4.png"), "--window", "20"])
        if "paper_cp1_no_curiosity" in csvs:  # run 3 beside run 1's own cp1 stage, the same seed
            commands.append(["--csv", str(csvs["paper_general_agent"]), str(csvs["paper_cp1_no_curiosity"]),
                             "--max-steps", str(STAGE_STEPS), "--out", str(images / "paper_curiosity.png"), "--window", "20",
                             "--title", "cp1 of the paper setting: with curiosity (run 1) and without (run 3)"])
    script = Path(__file__).resolve().parents[1] / "scripts" / "plot_training.py"
    for c in commands:
        subprocess.run([sys.executable, str(script), *c], check=True)
    return ["python scripts/plot_training.py " + shlex.join(c) for c in commands]


def main(args: Args) -> str:
    body, stages, csvs = report(args.campaign_dir)
    print(body)
    print(stages)
    if args.write_results:
        update_section(args.readme, "headline", headline(args.campaign_dir, args.eval_dir), "ms_construction")
        commands = figures(csvs, args.images)
        pictures = []
        for c in commands:  # the figures sit on the experiment page, beside the runs they draw
            out = Path(c.split("--out ")[1].split()[0])
            pictures.append(f"![{out.stem}]({Path(os.path.relpath(out, args.experiment_page.parent)).as_posix()})\n\n"
                            f"*Made by `{c}`.*")
        page = Path(os.path.relpath(args.experiment_page, args.results.parent)).as_posix()
        table, sources = table_ii(args.campaign_dir, args.eval_dir)
        update_section(args.results, "paper-experiment", "\n".join([
            "## The paper's experiment", "",
            "Command: `python -m experiments.paper_report --write-results` (Table II from the evaluation JSONs of "
            f"docs/data/paper/; each row's command, the training runs and Figures 3 and 4: [the experiment page]({page}"
            "#the-training-runs)).", "",
            "### Table II", "",
            "The paper's protocol: 50,000 env steps per task at cp4, deterministic actions (the policy's mean), seeds "
            "1,000,000 on (never used in training); the paper's rows as it printed them.", "",
            table]), "Results")
        update_section(args.experiment_page, "paper-stages", "\n".join([
            "## The training runs", "",
            "Made by `python -m experiments.paper_report --write-results`, from each run's progress.csv in campaign/. "
            f"Training episodes: the policy's sampled actions; 'lately' is the last {LAST:,} env steps; 'end' is where "
            "the element was when the episode ended (its distance and angle to the goal, whether the plate held it), "
            "the mean over the episodes.", "",
            body, "", *pictures, "",
            "### Where each row of Table II comes from", "", sources, "",
            "## Each stage, and the settings", "",
            "Each stage of the runs, all its training episodes:", "", stages, "",
            "The settings, from experiments/paper.py (where the paper is silent: ML-Agents' documented "
            "defaults where they carry over, ppo.py's otherwise):", "", settings_table()]), "The paper's experiment")
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
