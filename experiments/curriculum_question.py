"""The paper's question, asked of the recipe that learns from reward alone: does Table I's tolerance curriculum help?

    python -m experiments.curriculum_question --dry-run    # the plan, and where each arm stands
    python -m experiments.curriculum_question              # run (or resume) both arms, one after the other
    python -m experiments.curriculum_question --runs question_curriculum   # one arm (two can run side by side)
    python -m experiments.curriculum_question --report     # both arms at cp4: each snapshot on validation seeds, the
                                                           # last with the paper's protocol; the curves and the tables

Two runs of the from-scratch recipe (experiments/from_scratch.py, `scratch_args`: near-goal starts, the dense reward,
the mirror) from nothing, seed 1, the same env steps each:

| arm | curriculum | as |
|---|---|---|
| `question_cp4` | cp4 from the first step | the from-scratch campaign trained |
| `question_curriculum` | cp1, cp2, cp3 (Table I) for STAGE_STEPS each, then cp4 | the paper's general agent trained |

The curriculum arm moves on by step count alone, as the paper's stages did. Both are judged at cp4, as Table II
was. The paper's stages are 2,000,000 env steps each; on this CPU a 20M-step arm takes several sessions, so the
stages here are STAGE_STEPS long and each arm's budget is BUDGET, as much as both arms can run in one session (a
larger `--total-timesteps` runs cp4 on, in both arms). Each arm keeps a snapshot at every stage's end in
SNAPSHOT_DIR (on the machine that ran it: the report's validations of them are committed, in DATA). Ctrl-C stops
an arm with its checkpoint; the same command resumes it (commit campaign/<arm>/checkpoint.pt and progress.csv
between sessions).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from baselines.ppo import evaluation
from baselines.ppo.checkpoints import load_checkpoint
from baselines.ppo.evaluation import PAPER_CONTROL_GROUPS, PAPER_TABLE_II, pct
from experiments.campaign import Run, checkpoint_of, choose, describe
from experiments.from_scratch import VALIDATION_EPISODES, csv_column, moving_mean, scratch_args, train
from experiments.refine import VALIDATION_SEED, validate
from ms_construction.curriculum import FINAL_STAGE, STAGE_NAMES
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section

STAGE_STEPS = 150_000
"""env steps of each of cp1, cp2 and cp3 in the curriculum arm, and between snapshots in both."""
BUDGET = 6 * STAGE_STEPS
"""env steps of each arm (the default `--total-timesteps`): the curriculum's three stages, then as many at cp4."""
COMMAND = "python -m experiments.curriculum_question"
SNAPSHOT_DIR = Path("runs/question_snapshots")
DATA = Path("docs/data/curriculum_question")
"""the arms' evaluations at cp4 (JSON), committed."""
PAPER_STEPS = 50_000
"""env steps per task of the paper's evaluation protocol."""
CURVE = Path("docs/images/curriculum_question.png")
PAGE = Path("docs/experiments/curriculum_question.md")
TITLE = "The paper's question: does Table I's curriculum help the recipe from reward alone?"
SMOOTH = 25
"""iterations in the training curves' moving average (50,000 env steps)."""


def question_runs(total_timesteps: int = BUDGET, num_envs: Optional[int] = None, seed: int = 1) -> list[Run]:
    """The two arms: the recipe at cp4 from the first step, and through Table I's stages (promoted by step count only,
    as the paper's are)."""
    if total_timesteps < 4 * STAGE_STEPS or total_timesteps % STAGE_STEPS:
        raise SystemExit(f"--total-timesteps {total_timesteps:,}: use a multiple of {STAGE_STEPS:,} of at least "
                         f"{4 * STAGE_STEPS:,} (the curriculum's three stages and one at cp4)")
    common = dict(total_timesteps=total_timesteps, seed=seed, stage_timesteps=STAGE_STEPS)
    return [
        Run("question_cp4", scratch_args(num_envs, exp_name="question_cp4", curriculum=(FINAL_STAGE,), **common),
            "the from-scratch recipe at cp4 from the first step", COMMAND),
        Run("question_curriculum",
            scratch_args(num_envs, exp_name="question_curriculum", curriculum=STAGE_NAMES, promote_success=2.0,
                         **common),  # promote_success above 1: never by success, by step count as the paper's stages
            f"the from-scratch recipe through Table I's stages, {STAGE_STEPS:,} env steps each before cp4", COMMAND),
    ]


def snapshots_of(run: Run) -> dict[int, Path]:
    """The arm's snapshots on this machine: env steps -> checkpoint."""
    return {int(p.stem.split("_")[1]): p for p in (SNAPSHOT_DIR / run.name).glob("checkpoint_*.pt")}


def evaluated(run: Run) -> tuple[dict[int, dict], dict[int, dict]]:
    """The arm at cp4: each snapshot on this machine validated (VALIDATION_EPISODES per task from VALIDATION_SEED),
    and its checkpoint, once at the end of its plan, with the paper's protocol (PAPER_STEPS per task, the test seeds);
    each evaluation kept in DATA and read back from there (env steps -> the evaluation's JSON)."""
    DATA.mkdir(parents=True, exist_ok=True)
    for step, path in sorted(snapshots_of(run).items()):
        validate(path, DATA / f"{run.name}_val{VALIDATION_EPISODES}_{step}.json", VALIDATION_EPISODES)
    ckpt = checkpoint_of(run)
    done = load_checkpoint(ckpt)["progress"]["global_step"] if ckpt.is_file() else 0
    final = DATA / f"{run.name}_eval50k_{done}.json"
    if done >= run.args.total_timesteps and not final.exists():
        evaluation.main(evaluation.Args(checkpoint=ckpt, all=True, steps=PAPER_STEPS, json=final))

    def read(pattern: str) -> dict[int, dict]:
        return {int(p.stem.split("_")[-1]): json.loads(p.read_text()) for p in DATA.glob(pattern)}

    return (dict(sorted(read(f"{run.name}_val{VALIDATION_EPISODES}_*.json").items())),
            dict(sorted(read(f"{run.name}_eval50k_*.json").items())))


def progress_rows(run: Run) -> list[dict]:
    """The arm's progress.csv (committed in campaign/ with its checkpoint); none before it starts."""
    path = checkpoint_of(run).with_name("progress.csv")
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def draw_curves(runs: list[Run], validations: dict[str, dict[int, dict]], out: Path) -> None:
    """Per task, top: each arm's snapshots placed at cp4 on validation seeds, with 95% intervals; middle: its
    near-goal start radius (the share of the path out of the goal its starts are drawn from, widened as those
    episodes place at the stage's tolerance); bottom: its training episodes from ordinary resets placed, at the
    tolerance of the stage it was in (moving average of SMOOTH iterations). The curriculum's stages are shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 3, figsize=(12, 9), sharex=True)
    colors = {"question_cp4": "tab:blue", "question_curriculum": "tab:red"}
    for col, (kind, env_id) in enumerate(PAPER_TASK_ENV_IDS.items()):
        for run in runs:
            vals = validations[run.name]
            steps = np.array(sorted(vals)) / 1e6
            p = np.array([vals[s]["tasks"][env_id]["place_success"] for s in sorted(vals)])
            ci = np.array([vals[s]["tasks"][env_id]["place_success_ci95"] for s in sorted(vals)]).reshape(-1, 2)
            if len(steps):
                axes[0, col].errorbar(steps, 100 * p, yerr=100 * np.abs(ci.T - p), marker="o", capsize=3,
                                      color=colors[run.name], label=run.name)
            rows = progress_rows(run)
            x = csv_column(rows, "global_step") / 1e6
            axes[1, col].step(x, 100 * csv_column(rows, f"near_goal_radius_{kind}"), where="post",
                              color=colors[run.name], label=run.name)
            axes[2, col].plot(x, 100 * moving_mean(csv_column(rows, f"ordinary_place_{kind}"), SMOOTH),
                              color=colors[run.name])
        for row in axes[:, col]:
            for i, stage in enumerate(STAGE_NAMES[:-1]):
                row.axvspan(i * STAGE_STEPS / 1e6, (i + 1) * STAGE_STEPS / 1e6, color="gray", alpha=0.08 * (3 - i))
                row.text((i + 0.5) * STAGE_STEPS / 1e6, 2, stage, ha="center", fontsize=7, color="gray")
            row.set_ylim(0, 100)
        axes[0, col].set_title(kind)
        axes[2, col].set_xlabel("env steps (millions)")
    axes[0, 0].set_ylabel(f"snapshots placed at cp4, %\n({VALIDATION_EPISODES} validation episodes per task)")
    axes[1, 0].set_ylabel("near-goal start radius,\n% of the path out of the goal")
    axes[2, 0].set_ylabel("training episodes placed, %\n(the stage's tolerance; ordinary resets)")
    axes[1, 0].legend(fontsize=8, loc="upper left")
    fig.suptitle("The recipe from reward alone with and without Table I's curriculum (shaded: the curriculum's stages)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)


def _whole_path_at(rows: list[dict], kind: str) -> str:
    """The env steps at which the task type's near-goal start radius first reached the whole path (1.0)."""
    whole = [int(r["global_step"]) for r in rows if float(r.get(f"near_goal_radius_{kind}") or 0) >= 1.0 - 1e-6]
    return f"{whole[0]:,}" if whole else "not yet"


def training_table(runs: list[Run]) -> str:
    """Where each arm's training stood at the end of its CSV: its stage, its near-goal start radii (and when each first
    reached the whole path), and the share of its last SMOOTH iterations' episodes placed, from near-goal starts and
    from ordinary resets (at that stage's tolerance)."""
    kinds = " / ".join(PAPER_TASK_ENV_IDS)
    lines = [f"| arm | env steps | stage | near-goal start radius: {kinds} | the whole path first drawn from at, env "
             f"steps: {kinds} | placed from near-goal starts % | placed from ordinary resets: {kinds} % |",
             "|---|---|---|---|---|---|---|"]
    fmt = lambda x: "-" if np.isnan(x) else f"{100 * x:.1f}"  # noqa: E731
    for run in runs:
        rows = progress_rows(run)
        if not rows:
            continue
        recent = lambda key: moving_mean(csv_column(rows, key), SMOOTH)[-1]  # noqa: E731
        lines.append(f"| {run.name} | {int(rows[-1]['global_step']):,} | {rows[-1]['stage']} | "
                     + " / ".join(f"{float(rows[-1].get(f'near_goal_radius_{k}') or 0):.1f}" for k in PAPER_TASK_ENV_IDS)
                     + " | " + " / ".join(_whole_path_at(rows, k) for k in PAPER_TASK_ENV_IDS)
                     + f" | {fmt(recent('near_goal_place_success'))} | "
                     + " / ".join(fmt(recent(f"ordinary_place_{k}")) for k in PAPER_TASK_ENV_IDS)
                     + " |")
    return "\n".join(lines)


def report(runs: list[Run], results: Path = Path("docs/RESULTS.md")) -> str:
    """Both arms at cp4 (`evaluated`), their curves (`draw_curves`), and the Table II-shaped comparison beside the
    paper's rows, into the section `curriculum-question` of `results` and of PAGE (with where training stood and the
    snapshots' table)."""
    validations, finals = {}, {}
    for run in runs:
        validations[run.name], finals[run.name] = evaluated(run)
    draw_curves(runs, validations, CURVE)
    tasks = list(PAPER_TASK_ENV_IDS.values())
    head = "| agent | env steps | " + " | ".join(f"{k}: pick / place % [95% CI]" for k in PAPER_TASK_ENV_IDS) + " |"
    lines = [f"Command: `{COMMAND} --report` (each arm's last checkpoint, the paper's protocol: {PAPER_STEPS:,} env "
             "steps per task, the test seeds, the policy's mean, at cp4). One seed per arm; demonstrations: none.", "",
             head, "|---|---|" + "---|" * len(tasks)]
    for run in runs:
        rows = progress_rows(run)
        for step, data in finals[run.name].items():
            r = data["tasks"]
            lines.append(f"| {run.name}: {run.what} | {step:,} | " + " | ".join(
                f"{100 * r[t]['pick_success']:.1f} / {pct(r[t]['place_success'], r[t]['place_success_ci95'])}"
                for t in tasks) + " |")
        if not finals[run.name]:
            done = int(rows[-1]["global_step"]) if rows else 0
            lines.append(f"| {run.name}: {run.what} | {done:,} of {run.args.total_timesteps:,} (not evaluated: "
                         f"`{COMMAND} --runs {run.name}` goes on) |" + " - |" * len(tasks))
    lines.append("| the paper's general agent: cp1 -> cp4, 2M steps each (Table II) | 8,000,000 | "
                 + " | ".join(f"{PAPER_TABLE_II[t][0]:.2f} / {PAPER_TABLE_II[t][1]:.2f}" for t in tasks) + " |")
    lines.append("| the paper's control groups: one agent per task, cp4 from the first step | 2,000,000 per task | "
                 + " | ".join(f"{PAPER_CONTROL_GROUPS[t][0]:.2f} / {PAPER_CONTROL_GROUPS[t][1]:.2f}" for t in tasks)
                 + " |")
    lines += ["", f"![curriculum question]({Path(*CURVE.parts[1:])})", "",
              f"*Made by `{COMMAND} --report`: top, each arm's snapshots placed at cp4 ({VALIDATION_EPISODES} "
              f"episodes per task from seed {VALIDATION_SEED:,}, 95% intervals); middle, its near-goal start radius; "
              "bottom, its training episodes from ordinary resets placed at the tolerance of the stage it was in.*"]
    body = "\n".join(lines)
    update_section(results, "curriculum-question", body, "Results")
    steps = sorted(set().union(*validations.values()))
    snap = ["| env steps | curriculum arm's stage | " + " | ".join(f"{r.name}: placed at cp4, "
                                                                     + " / ".join(PAPER_TASK_ENV_IDS) + " %" for r in runs)
            + " |", "|---|---|" + "---|" * len(runs)]
    for step in steps:
        stage = STAGE_NAMES[min((step - 1) // STAGE_STEPS, len(STAGE_NAMES) - 1)]
        stage += "" if stage == FINAL_STAGE else " (its end)"
        snap.append(f"| {step:,} | {stage} | " + " | ".join(
            " / ".join(f"{100 * validations[r.name][step]['tasks'][t]['place_success']:.0f}" for t in tasks)
            if step in validations[r.name] else "-" for r in runs) + " |")
    training = (f"Where each arm's training stood at its end (its last {SMOOTH} iterations, at the tolerance of the "
                f"stage it was in; from its progress.csv):\n\n{training_table(runs)}")
    update_section(PAGE, "curriculum-question", f"{body}\n\n{training}\n\nEach snapshot at cp4 (the top row of the "
                   "figure):\n\n" + "\n".join(snap), TITLE)
    return body


@dataclass
class Args:
    runs: tuple[str, ...] = ("question_cp4", "question_curriculum")
    """which arms, in this order."""
    total_timesteps: int = BUDGET
    """env steps of each arm: a multiple of STAGE_STEPS, at least 4 of them; more runs cp4 on, in both arms."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a run resumed from a checkpoint keeps its own."""
    seed: int = 1
    dry_run: bool = False
    """print the plan and where each arm stands, and exit."""
    report: bool = False
    """evaluate the arms at cp4 (each snapshot on validation seeds, the last checkpoint with the paper's protocol),
    draw the curves, write the tables into docs/, and exit."""


def main(args: Args) -> None:
    arms = question_runs(args.total_timesteps, args.num_envs, args.seed)
    runs = choose(arms, args.runs)
    for run in runs:
        print(describe(run))
    if args.report:
        print(report(arms))
    elif not args.dry_run:
        for run in runs:
            train(run, every=STAGE_STEPS, snapshots=SNAPSHOT_DIR / run.name)


if __name__ == "__main__":
    main(tyro.cli(Args))
