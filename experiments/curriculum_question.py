"""The paper's question, asked of the recipe that learns from reward alone: does Table I's tolerance curriculum help?

    python -m experiments.curriculum_question --seed 1 --dry-run   # seed 1's two arms, and where each stands
    python -m experiments.curriculum_question --seed 1             # run (or resume) seed 1's curriculum arm
    python -m experiments.curriculum_question --report             # both arms of every seed at cp4: table, curves

Per seed, two runs of the from-scratch recipe (experiments/from_scratch.py, `scratch_args`) from nothing, BUDGET env
steps each, judged at cp4 as Table II was:

| arm | curriculum | the run |
|---|---|---|
| `cp4` | cp4 from the first step | the seed's run of the PPO recipe (`from_scratch --seed S --learner ppo`), its first BUDGET env steps |
| `curriculum` | cp1, cp2, cp3 (Table I) for STAGE_STEPS each, then cp4 | campaign/question_curriculum_s<seed>/ |

The cp4 arm is the recipe's own run on the same seed, so only the curriculum arm trains here. The curriculum moves on
by step count alone, as the paper's stages did (2,000,000 env steps each there). Both arms screen every snapshot
(SNAPSHOT_EVERY env steps) at cp4 on validation seeds as they make it, and their snapshots at BUDGET are evaluated
with the paper's protocol (the recipe's run does its own: from_scratch.EVALUATE_AT). BUDGET is where the recipe's
first seed placed at least half of every task at cp4 on validation, so at least one arm does. Ctrl-C stops the arm
with its checkpoint; the same command resumes it (commit campaign/question_curriculum_s<seed>/ and DATA).

The first asking of the question (two arms of 900,000 env steps, one seed, 150,000-step stages, before the recipe
had its reach starts) is on PAGE as it was measured.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from baselines.ppo import evaluation
from baselines.ppo.checkpoints import load_checkpoint
from baselines.ppo.evaluation import PAPER_CONTROL_GROUPS, PAPER_TABLE_II, pct
from experiments import from_scratch
from experiments.campaign import Run, checkpoint_of, describe
from experiments.from_scratch import SNAPSHOT_EVERY, VALIDATION_EPISODES, csv_column, moving_mean, scratch_args, train
from experiments.refine import VALIDATION_SEED, validate
from ms_construction.curriculum import STAGE_NAMES
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section

STAGE_STEPS = 500_000
"""env steps of each of cp1, cp2 and cp3 in the curriculum arm."""
BUDGET = 6 * STAGE_STEPS
"""env steps of each arm: the curriculum's three stages, then as many at cp4."""
ARMS = ("cp4", "curriculum")
COMMAND = "python -m experiments.curriculum_question"
SNAPSHOT_DIR = Path("runs/question_snapshots")
DATA = Path("docs/data/curriculum_question")
"""the curriculum arms' validations and evaluations at cp4 (JSON), committed."""
PAPER_STEPS = 50_000
"""env steps per task of the paper's evaluation protocol."""
CURVE = Path("docs/images/curriculum_question_seeds.png")
PAGE = Path("docs/experiments/curriculum_question.md")
TITLE = "The paper's question: does Table I's curriculum help the recipe from reward alone?"
SMOOTH = 50
"""iterations in the training curves' moving average (100,000 env steps)."""


def curriculum_run(seed: int, num_envs: Optional[int] = None) -> Run:
    """The recipe through Table I's stages (promoted by step count only, as the paper's are), to BUDGET."""
    name = f"question_curriculum_s{seed}"
    args = scratch_args(num_envs, seed=seed, exp_name=name, total_timesteps=BUDGET, curriculum=STAGE_NAMES,
                        stage_timesteps=STAGE_STEPS, promote_success=2.0)  # above 1: never by success
    return Run(name, args, f"the recipe through Table I's stages, {STAGE_STEPS:,} env steps each before cp4, seed {seed}",
               f"{COMMAND} --seed {seed}", method=from_scratch.METHOD)


def question_runs(seed: int, num_envs: Optional[int] = None) -> dict[str, Run]:
    """The seed's two arms: the recipe's own run at cp4 from the first step, and the curriculum arm."""
    return {"cp4": from_scratch.seed_run(seed, num_envs, learner="ppo"), "curriculum": curriculum_run(seed, num_envs)}


def validation_json(arm: str, seed: int, step: int) -> Path:
    if arm == "cp4":
        return from_scratch.seed_validation_json(seed, step, learner="ppo")
    return DATA / f"question_curriculum_s{seed}_val{VALIDATION_EPISODES}_{step}.json"


def evaluation_json(arm: str, seed: int) -> Path:
    """The arm's snapshot at BUDGET with the paper's protocol."""
    if arm == "cp4":
        return from_scratch.seed_evaluation_json(seed, BUDGET, "ppo")
    return DATA / f"question_curriculum_s{seed}_eval50k_{BUDGET}.json"


def screen(seed: int, step: int, snapshot: Path) -> None:
    """The curriculum arm's snapshot as its run makes it: validated at cp4 (VALIDATION_EPISODES per task from
    VALIDATION_SEED), and at BUDGET evaluated with the paper's protocol."""
    DATA.mkdir(parents=True, exist_ok=True)
    validate(snapshot, validation_json("curriculum", seed, step), VALIDATION_EPISODES)
    if step == BUDGET and not evaluation_json("curriculum", seed).is_file():
        evaluation.main(evaluation.Args(checkpoint=snapshot, all=True, steps=PAPER_STEPS,
                                        json=evaluation_json("curriculum", seed)))


def validations(arm: str, seed: int) -> dict[int, dict]:
    """env steps -> the arm's validation at cp4 (its JSON), for the snapshots up to BUDGET screened so far."""
    found = {}
    for step in range(SNAPSHOT_EVERY, BUDGET + 1, SNAPSHOT_EVERY):
        if (path := validation_json(arm, seed, step)).is_file():
            found[step] = json.loads(path.read_text())
    return found


def progress_rows(run: Run) -> list[dict]:
    """The run's progress.csv rows up to BUDGET (committed in campaign/ with its checkpoint); none before it starts."""
    path = checkpoint_of(run).with_name("progress.csv")
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return [r for r in csv.DictReader(f) if int(r["global_step"]) <= BUDGET]


STYLE = {"cp4": "tab:blue", "curriculum": "tab:red"}
SEED_LINES = ("-", "--", ":")


def draw_curves(seeds: tuple[int, ...], out: Path, num_envs: Optional[int] = None) -> None:
    """Per task, top: each arm's snapshots placed at cp4 on validation seeds; bottom: its training episodes from
    ordinary resets placed, at the tolerance of the stage it was in (moving average of SMOOTH iterations). An arm a
    colour, a seed a line style; the curriculum's stages shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), sharex=True, sharey=True)
    for col, (kind, env_id) in enumerate(PAPER_TASK_ENV_IDS.items()):
        for seed, line in zip(seeds, SEED_LINES):
            for arm, run in question_runs(seed, num_envs).items():
                vals = validations(arm, seed)
                steps = np.array(sorted(vals)) / 1e6
                axes[0, col].plot(steps, [100 * vals[s]["tasks"][env_id]["place_success"] for s in sorted(vals)],
                                  color=STYLE[arm], ls=line, marker="o", ms=3, label=f"{arm}, seed {seed}")
                rows = progress_rows(run)
                axes[1, col].plot(csv_column(rows, "global_step") / 1e6,
                                  100 * moving_mean(csv_column(rows, f"ordinary_place_{kind}"), SMOOTH),
                                  color=STYLE[arm], ls=line)
        for row in axes[:, col]:
            for i, stage in enumerate(STAGE_NAMES[:-1]):
                row.axvspan(i * STAGE_STEPS / 1e6, (i + 1) * STAGE_STEPS / 1e6, color="gray", alpha=0.08 * (3 - i))
                row.text((i + 0.5) * STAGE_STEPS / 1e6, 2, stage, ha="center", fontsize=7, color="gray")
            row.set_ylim(0, 102)
            row.set_xlim(0, BUDGET / 1e6)
        axes[0, col].set_title(kind)
        axes[1, col].set_xlabel("env steps (millions)")
    axes[0, 0].set_ylabel(f"snapshots placed at cp4, %\n({VALIDATION_EPISODES} validation episodes per task)")
    axes[1, 0].set_ylabel("training episodes placed, %\n(the stage's tolerance; ordinary resets)")
    # one legend for the figure, below the panels, where it hides no curve
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="lower center", ncol=4, fontsize=8, handlelength=3)
    fig.suptitle("The recipe from reward alone with and without Table I's curriculum (shaded: the curriculum's stages)")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)


def report(seeds: tuple[int, ...] = from_scratch.SEEDS, results: Path = Path("docs/RESULTS.md")) -> str:
    """Both arms of every seed at cp4 at BUDGET (the paper's protocol) beside the paper's rows, the curves, and on
    PAGE each snapshot's validation; into the section `curriculum-question` of `results` and of PAGE."""
    draw_curves(seeds, CURVE)
    tasks = list(PAPER_TASK_ENV_IDS.values())
    lines = [f"Command: `{COMMAND} --report` (each arm's snapshot at {BUDGET:,} env steps, the paper's protocol: "
             f"{PAPER_STEPS:,} env steps per task, the test seeds, the policy's mean, at cp4). Demonstrations: none.", "",
             "| seed | arm | " + " | ".join(f"{k}: pick / place % [95% CI]" for k in PAPER_TASK_ENV_IDS) + " |",
             "|---|---|" + "---|" * len(tasks)]
    snap = ["| seed | env steps | curriculum arm's stage | " + " | ".join(
        f"{arm}: placed at cp4, " + " / ".join(PAPER_TASK_ENV_IDS) + " %" for arm in ARMS) + " |",
        "|---|---|---|" + "---|" * len(ARMS)]
    for seed in seeds:
        for arm, run in question_runs(seed).items():
            path = evaluation_json(arm, seed)
            if path.is_file():
                r = json.loads(path.read_text())["tasks"]
                lines.append(f"| {seed} | {arm}: {run.what} | " + " | ".join(
                    f"{100 * r[t]['pick_success']:.1f} / {pct(r[t]['place_success'], r[t]['place_success_ci95'])}"
                    for t in tasks) + " |")
            else:
                ckpt = checkpoint_of(run)
                done = load_checkpoint(ckpt)["progress"]["global_step"] if ckpt.is_file() else 0
                lines.append(f"| {seed} | {arm}: {run.what} | not yet at {BUDGET:,} env steps ({done:,}; `{run.command}` "
                             "goes on) |" + " - |" * (len(tasks) - 1))
        vals = {arm: validations(arm, seed) for arm in ARMS}
        for step in sorted(set().union(*vals.values())):
            stage = STAGE_NAMES[min((step - 1) // STAGE_STEPS, len(STAGE_NAMES) - 1)]
            snap.append(f"| {seed} | {step:,} | {stage} | " + " | ".join(
                " / ".join(f"{100 * vals[arm][step]['tasks'][t]['place_success']:.0f}" for t in tasks)
                if step in vals[arm] else "-" for arm in ARMS) + " |")
    lines.append("| the paper | general agent: cp1 -> cp4, 2M steps each (Table II), 8M env steps | "
                 + " | ".join(f"{PAPER_TABLE_II[t][0]:.2f} / {PAPER_TABLE_II[t][1]:.2f}" for t in tasks) + " |")
    lines.append("| the paper | control groups: one agent per task, cp4 from the first step, 2M env steps each | "
                 + " | ".join(f"{PAPER_CONTROL_GROUPS[t][0]:.2f} / {PAPER_CONTROL_GROUPS[t][1]:.2f}" for t in tasks)
                 + " |")
    lines += ["", f"![curriculum question]({Path(*CURVE.parts[1:])})", "",
              f"*Made by `{COMMAND} --report`: top, each arm's snapshots placed at cp4 ({VALIDATION_EPISODES} episodes "
              f"per task from seed {VALIDATION_SEED:,}); bottom, its training episodes from ordinary resets placed at "
              "the tolerance of the stage it was in. Blue: cp4 from the first step; red: Table I's stages.*"]
    body = "\n".join(lines)
    update_section(results, "curriculum-question", body, "Results")
    on_page = body.replace("](images/", "](../images/")  # the page lies one folder below RESULTS
    update_section(PAGE, "curriculum-question", f"{on_page}\n\nEach snapshot at cp4 (the top row of the figure):\n\n"
                   + "\n".join(snap), TITLE)
    return body


@dataclass
class Args:
    seed: Optional[int] = None
    """the seed whose arms to run (its curriculum arm trains; its cp4 arm is `from_scratch --seed S --learner ppo`)."""
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
    if args.seed is None:
        raise SystemExit("give --seed S (its curriculum arm trains; --dry-run to see both arms), or --report")
    arms = question_runs(args.seed, args.num_envs)
    for arm, run in arms.items():
        print(f"{arm}: {describe(run)}")
    if not args.dry_run:
        run = arms["curriculum"]
        train(run, snapshots=SNAPSHOT_DIR / run.name, after_snapshot=partial(screen, args.seed))


if __name__ == "__main__":
    main(tyro.cli(Args))
