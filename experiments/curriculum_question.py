"""The paper's question, asked of the recipe that learns from reward alone: does Table I's tolerance curriculum help?

    python -m experiments.curriculum_question --seed 1 --dry-run   # seed 1's two arms (SAC), and where each stands
    python -m experiments.curriculum_question --seed 1             # run (or resume) seed 1's curriculum arm (SAC)
    python -m experiments.curriculum_question --seed 1 --learner ppo    # the same with PPO's recipe
    python -m experiments.curriculum_question --report             # both arms of every seed at cp4: table, curves

Per learner of the recipe (experiments/from_scratch.py LEARNERS) and seed, two runs from nothing, its PLANS' budget
each, judged at cp4 as Table II was:

| arm | curriculum | the run |
|---|---|---|
| `cp4` | cp4 from the first step | the seed's run of the recipe (`from_scratch --seed S [--learner ppo]`), its first budget env steps |
| `curriculum` | Table I's stages, the plan's env steps each, then cp4 | campaign/question_curriculum[_sac]_s<seed>/ |

The cp4 arm is the recipe's own run on the same seed, so only the curriculum arm trains here. The curriculum moves on
by step count alone, as the paper's stages did (2,000,000 env steps each there). Both arms screen every snapshot
at cp4 on validation seeds as they make it, and their snapshots at the budget are evaluated with the paper's
protocol (the recipe's run does its own: from_scratch.EVALUATE_AT). A plan's budget is one at which the recipe's
first seed placed at least half of every task at cp4 on validation, so at least one arm does. Ctrl-C stops the arm
with its checkpoint; the same command resumes it (commit campaign/question_curriculum[_sac]_s<seed>/ and DATA).

The first asking of the question (two arms of 900,000 env steps, one seed, 150,000-step stages, before the recipe
had its reach starts) is on PAGE as it was measured.
"""

from __future__ import annotations

import csv
import json
import shutil
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from baselines.ppo import evaluation
from baselines.ppo.checkpoints import load_checkpoint
from baselines.ppo.evaluation import PAPER_CONTROL_GROUPS, PAPER_TABLE_II, pct
from experiments import from_scratch, sac_recipe
from experiments.campaign import Run, checkpoint_of, describe
from experiments.from_scratch import (LEARNER, LEARNERS, SNAPSHOT_EVERY, VALIDATION_EPISODES, csv_column, moving_mean,
                                      scratch_args, train)
from experiments.refine import VALIDATION_SEED, validate
from ms_construction.curriculum import STAGE_NAMES
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section


@dataclass(frozen=True)
class Plan:
    """One learner's asking of the question."""

    stage_steps: int
    """env steps of each of the curriculum arm's stages before the last."""
    budget: int
    """env steps of each arm, where the two are compared with the paper's protocol."""
    every: int
    """env steps between the curriculum arm's snapshots (each screened at cp4)."""
    curve: Path
    """the figure of both arms of every seed."""


PLANS = {
    "ppo": Plan(500_000, 3_000_000, SNAPSHOT_EVERY, Path("docs/images/curriculum_question_seeds.png")),
    "sac": Plan(125_000, 500_000, 125_000, Path("docs/images/curriculum_question_sac.png")),
}
"""PPO: cp1, cp2, cp3 for 500,000 env steps each, then as many at cp4 (3M: where PPO's first seed placed half of every
task). SAC: the four stages in equal parts, as the paper's general agent trained (2M each there), to 500,000 env
steps: where SAC's seeds had met the recipe's target (their runs' evaluations there)."""
ARMS = ("cp4", "curriculum")
COMMAND = "python -m experiments.curriculum_question"
SNAPSHOT_DIR = Path("runs/question_snapshots")
DATA = Path("docs/data/curriculum_question")
"""the curriculum arms' validations and evaluations at cp4 (JSON), committed."""
PAPER_STEPS = 50_000
"""env steps per task of the paper's evaluation protocol."""
PAGE = Path("docs/experiments/curriculum_question.md")
TITLE = "The paper's question: does Table I's curriculum help the recipe from reward alone?"
SMOOTH = 50
"""iterations (progress.csv rows: 2,000 env steps each) in the training curves' moving average."""


def command(seed: int, learner: str) -> str:
    return f"{COMMAND} --seed {seed}" + ("" if learner == LEARNER else f" --learner {learner}")


def curriculum_run(seed: int, num_envs: Optional[int] = None, learner: str = LEARNER) -> Run:
    """The recipe with `learner` through Table I's stages (moving on by step count only, as the paper's do), to its
    plan's budget."""
    plan = PLANS[learner]
    if learner == "sac":
        name = f"question_curriculum_sac_s{seed}"
        args = sac_recipe.sac_args(seed, exp_name=name, total_timesteps=plan.budget, curriculum=STAGE_NAMES,
                                   stage_timesteps=plan.stage_steps, **({"num_envs": num_envs} if num_envs else {}))
        return Run(name, args, f"SAC through Table I's stages, {plan.stage_steps:,} env steps each, seed {seed}",
                   command(seed, learner), method=sac_recipe.METHOD)
    name = f"question_curriculum_s{seed}"
    args = scratch_args(num_envs, seed=seed, exp_name=name, total_timesteps=plan.budget, curriculum=STAGE_NAMES,
                        stage_timesteps=plan.stage_steps, promote_success=2.0)  # above 1: never by success
    return Run(name, args, f"the recipe through Table I's stages, {plan.stage_steps:,} env steps each before cp4, "
               f"seed {seed}", command(seed, learner), method=from_scratch.METHOD)


def question_runs(seed: int, num_envs: Optional[int] = None, learner: str = LEARNER) -> dict[str, Run]:
    """The seed's two arms: the recipe's own run at cp4 from the first step, and the curriculum arm."""
    return {"cp4": from_scratch.seed_run(seed, num_envs, learner=learner),
            "curriculum": curriculum_run(seed, num_envs, learner)}


def validation_json(arm: str, seed: int, step: int, learner: str = LEARNER) -> Path:
    if arm == "cp4":
        return from_scratch.seed_validation_json(seed, step, learner=learner)
    return DATA / f"{curriculum_run(seed, learner=learner).name}_val{VALIDATION_EPISODES}_{step}.json"


def evaluation_json(arm: str, seed: int, learner: str = LEARNER) -> Path:
    """The arm's snapshot at its plan's budget with the paper's protocol."""
    budget = PLANS[learner].budget
    if arm == "cp4":
        return from_scratch.seed_evaluation_json(seed, budget, learner)
    return DATA / f"{curriculum_run(seed, learner=learner).name}_eval50k_{budget}.json"


def screen(seed: int, step: int, snapshot: Path, learner: str = LEARNER) -> None:
    """The curriculum arm's snapshot as its run makes it: validated at cp4 (VALIDATION_EPISODES per task from
    VALIDATION_SEED), and at the budget evaluated with the paper's protocol."""
    DATA.mkdir(parents=True, exist_ok=True)
    validate(snapshot, validation_json("curriculum", seed, step, learner), VALIDATION_EPISODES)
    out = evaluation_json("curriculum", seed, learner)
    if step == PLANS[learner].budget and not out.is_file():
        evaluation.main(evaluation.Args(checkpoint=snapshot, all=True, steps=PAPER_STEPS, json=out))


def keep_snapshot(seed: int, step: int, ckpt: Path) -> None:
    """A SAC curriculum arm's part has ended at `step` (sac_recipe.run_sac's `after_part`): its checkpoint copied to
    the arm's snapshots (PPO's `train` copies its own) and screened."""
    snapshot = SNAPSHOT_DIR / curriculum_run(seed, learner="sac").name / f"checkpoint_{step}.pt"
    snapshot.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ckpt, snapshot)
    screen(seed, step, snapshot, "sac")


def validations(arm: str, seed: int, learner: str = LEARNER) -> dict[int, dict]:
    """env steps -> the arm's validation at cp4 (its JSON), for the snapshots up to the budget screened so far."""
    plan, found = PLANS[learner], {}
    unit = min(plan.every, SNAPSHOT_EVERY)  # the recipe's own run keeps one every SNAPSHOT_EVERY
    for step in range(unit, plan.budget + 1, unit):
        if (path := validation_json(arm, seed, step, learner)).is_file():
            found[step] = json.loads(path.read_text())
    return found


def progress_rows(run: Run, budget: int) -> list[dict]:
    """The run's progress.csv rows up to `budget` (committed in campaign/ with its checkpoint); none before it
    starts."""
    path = checkpoint_of(run).with_name("progress.csv")
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return [r for r in csv.DictReader(f) if int(r["global_step"]) <= budget]


STYLE = {"cp4": "tab:blue", "curriculum": "tab:red"}
SEED_LINES = ("-", "--", ":")


def draw_curves(seeds: tuple[int, ...], learner: str, num_envs: Optional[int] = None) -> None:
    """Per task, top: each arm's snapshots placed at cp4 on validation seeds; bottom: its training episodes from
    ordinary resets placed, at the tolerance of the stage it was in (moving average of SMOOTH rows). An arm a colour,
    a seed a line style; the curriculum's stages shaded. Into the learner's plan's `curve`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plan = PLANS[learner]
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), sharex=True, sharey=True)
    for col, (kind, env_id) in enumerate(PAPER_TASK_ENV_IDS.items()):
        for seed, line in zip(seeds, SEED_LINES):
            for arm, run in question_runs(seed, num_envs, learner).items():
                vals = validations(arm, seed, learner)
                steps = np.array(sorted(vals)) / 1e6
                axes[0, col].plot(steps, [100 * vals[s]["tasks"][env_id]["place_success"] for s in sorted(vals)],
                                  color=STYLE[arm], ls=line, marker="o", ms=3, label=f"{arm}, seed {seed}")
                rows = progress_rows(run, plan.budget)
                axes[1, col].plot(csv_column(rows, "global_step") / 1e6,
                                  100 * moving_mean(csv_column(rows, f"ordinary_place_{kind}"), SMOOTH),
                                  color=STYLE[arm], ls=line)
        for row in axes[:, col]:
            for i, stage in enumerate(STAGE_NAMES[:-1]):
                row.axvspan(i * plan.stage_steps / 1e6, (i + 1) * plan.stage_steps / 1e6, color="gray",
                            alpha=0.08 * (3 - i))
                row.text((i + 0.5) * plan.stage_steps / 1e6, 2, stage, ha="center", fontsize=7, color="gray")
            row.set_ylim(0, 102)
            row.set_xlim(0, plan.budget / 1e6)
        axes[0, col].set_title(kind)
        axes[1, col].set_xlabel("env steps (millions)")
    axes[0, 0].set_ylabel(f"snapshots placed at cp4, %\n({VALIDATION_EPISODES} validation episodes per task)")
    axes[1, 0].set_ylabel("training episodes placed, %\n(the stage's tolerance; ordinary resets)")
    # one legend for the figure, below the panels, where it hides no curve
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="lower center", ncol=4, fontsize=8, handlelength=3)
    fig.suptitle(f"The recipe from reward alone ({learner.upper()}) with and without Table I's curriculum "
                 "(shaded: the curriculum's stages)")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    plan.curve.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(plan.curve, dpi=100)
    plt.close(fig)


def report(seeds: tuple[int, ...] = from_scratch.SEEDS, results: Path = Path("docs/RESULTS.md")) -> str:
    """Both arms of every seed and learner (the recipe's first) at cp4 at their plan's budget (the paper's protocol)
    beside the paper's rows, the curves, and on PAGE each snapshot's validation; into the section
    `curriculum-question` of `results` and of PAGE."""
    tasks = list(PAPER_TASK_ENV_IDS.values())
    learners = sorted(LEARNERS, key=lambda learner: learner != LEARNER)
    lines = [f"Command: `{COMMAND} --report` (each arm's snapshot at its learner's budget, the paper's protocol: "
             f"{PAPER_STEPS:,} env steps per task, the test seeds, the policy's mean, at cp4). Demonstrations: none.", "",
             "| learner | seed | arm | env steps | " + " | ".join(f"{k}: pick / place % [95% CI]"
                                                       for k in PAPER_TASK_ENV_IDS) + " |",
             "|---|---|---|---|" + "---|" * len(tasks)]
    snaps, figures = [], []
    for learner in learners:
        plan = PLANS[learner]
        draw_curves(seeds, learner)
        figures.append(f"![curriculum question, {learner.upper()}]({Path(*plan.curve.parts[1:])})")
        snap = [f"{learner.upper()}:", "", "| seed | env steps | curriculum arm's stage | " + " | ".join(
            f"{arm}: placed at cp4, " + " / ".join(PAPER_TASK_ENV_IDS) + " %" for arm in ARMS) + " |",
            "|---|---|---|" + "---|" * len(ARMS)]
        for seed in seeds:
            for arm, run in question_runs(seed, learner=learner).items():
                path = evaluation_json(arm, seed, learner)
                head = f"| {learner.upper()} | {seed} | {arm}: {run.what} | {plan.budget:,} | "
                if path.is_file():
                    r = json.loads(path.read_text())["tasks"]
                    lines.append(head + " | ".join(
                        f"{100 * r[t]['pick_success']:.1f} / {pct(r[t]['place_success'], r[t]['place_success_ci95'])}"
                        for t in tasks) + " |")
                else:
                    ckpt = checkpoint_of(run)
                    done = load_checkpoint(ckpt)["progress"]["global_step"] if ckpt.is_file() else 0
                    lines.append(head + f"not yet ({done:,}; `{run.command}` goes on) |" + " - |" * (len(tasks) - 1))
            vals = {arm: validations(arm, seed, learner) for arm in ARMS}
            for step in sorted(set().union(*vals.values())):
                stage = STAGE_NAMES[min((step - 1) // plan.stage_steps, len(STAGE_NAMES) - 1)]
                snap.append(f"| {seed} | {step:,} | {stage} | " + " | ".join(
                    " / ".join(f"{100 * vals[arm][step]['tasks'][t]['place_success']:.0f}" for t in tasks)
                    if step in vals[arm] else "-" for arm in ARMS) + " |")
        snaps.append("\n".join(snap))
    lines.append("| the paper | | general agent: cp1 -> cp4, 2M steps each (Table II) | 8,000,000 | "
                 + " | ".join(f"{PAPER_TABLE_II[t][0]:.2f} / {PAPER_TABLE_II[t][1]:.2f}" for t in tasks) + " |")
    lines.append("| the paper | | control groups: one agent per task, cp4 from the first step | 2,000,000 each | "
                 + " | ".join(f"{PAPER_CONTROL_GROUPS[t][0]:.2f} / {PAPER_CONTROL_GROUPS[t][1]:.2f}" for t in tasks)
                 + " |")
    lines += ["", *figures, "",
              f"*Made by `{COMMAND} --report`, one figure per learner: top, each arm's snapshots placed at cp4 "
              f"({VALIDATION_EPISODES} episodes per task from seed {VALIDATION_SEED:,}); bottom, its training episodes "
              "from ordinary resets placed at the tolerance of the stage it was in. Blue: cp4 from the first step; "
              "red: Table I's stages.*"]
    body = "\n".join(lines)
    update_section(results, "curriculum-question", body, "Results")
    on_page = body.replace("](images/", "](../images/")  # the page lies one folder below RESULTS
    update_section(PAGE, "curriculum-question", f"{on_page}\n\nEach snapshot at cp4 (the top row of the figures):\n\n"
                   + "\n\n".join(snaps), TITLE)
    return body


@dataclass
class Args:
    seed: Optional[int] = None
    """the seed whose arms to run (its curriculum arm trains; its cp4 arm is `from_scratch --seed S`)."""
    learner: str = LEARNER
    """the recipe's learner whose question to run: sac (the recipe's) or ppo."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a run resumed from a checkpoint keeps its own."""
    dry_run: bool = False
    """print the seed's arms and where each stands, and exit."""
    report: bool = False
    """write the comparison of every seed's arms into docs/ (RESULTS and PAGE) and draw the curves, and exit."""


def main(args: Args) -> None:
    if args.report:
        print(report())
        return
    if args.learner not in LEARNERS:
        raise SystemExit(f"--learner {args.learner}: use one of {', '.join(LEARNERS)}")
    if args.seed is None:
        raise SystemExit("give --seed S (its curriculum arm trains; --dry-run to see both arms), or --report")
    arms = question_runs(args.seed, args.num_envs, args.learner)
    for arm, run in arms.items():
        print(f"{arm}: {describe(run)}")
    if args.dry_run:
        return
    run = arms["curriculum"]
    if args.learner == "sac":
        sac_recipe.run_sac(run.args, every=PLANS["sac"].every, after_part=partial(keep_snapshot, args.seed))
    else:
        train(run, snapshots=SNAPSHOT_DIR / run.name, after_snapshot=partial(screen, args.seed, learner="ppo"))


if __name__ == "__main__":
    main(tyro.cli(Args))
