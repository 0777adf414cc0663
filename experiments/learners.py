"""Which learner, and whether curiosity helps: SAC against PPO, and PPO's recipe with ICM's curiosity bonus, each from
nothing on the same envs, reward, start states and seed as the recipe, compared at equal env steps and equal wall
time on this CPU.

    python -m experiments.from_scratch --seed 1          # the SAC arm: the recipe's run with SAC, to BUDGET, resumable
    python -m experiments.learners --arm icm --dry-run   # the plan, and where the curiosity arm's run stands
    python -m experiments.learners --arm icm             # PPO's recipe with curiosity (ICM), to BUDGET, resumable
    python -m experiments.learners --arm sac_utd         # SAC at half the update ratio, a probe to PROBE_BUDGET
    python -m experiments.learners --evaluate sac        # the paper's protocol on the arm's latest checkpoint (--seed)
    python -m experiments.learners --report              # RESULTS' section and its curves, from the arms' progress.csv

The PPO arm on a seed is the recipe's own run on it (campaign/scratch_s<seed>/, experiments/from_scratch.py): its
first BUDGET env steps, so no PPO run is repeated. What is compared is the training episodes from ordinary resets (neither
near-goal nor reach starts), placed per task type, the worst of the three (a mean over MOVING_WINDOW env steps), at
equal env steps and at equal wall time of training (rollouts and updates, from each progress.csv; start-ups,
evaluations and the time between sessions not counted).

The SAC arm on a seed is the recipe's run with SAC (experiments/sac_recipe.py; `python -m experiments.from_scratch
--seed S` runs it with its snapshots), and its evaluations are the recipe's
(docs/data/from_scratch/sac_s<seed>_eval50k_<env steps>.json). What SAC shares with PPO's recipe: the envs, the
reward, the observation, the near-goal starts. What it does not: the reach starts and the mirror of the twin openings
(PPO's network options).

The update-ratio arm (`sac_utd`) is SAC with half the recipe's gradient steps per env step (0.25 against 0.5), a
probe on both seeds: SAC's gradient steps, not its env steps, set its pace on this CPU (docs/BENCHMARKS.md, "Where
SAC's training time goes"), so fewer of them make each env step cheaper; whether that reaches the target sooner in
wall time is what the probe asks, before any recipe change.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
import tyro

from baselines.ppo import evaluation
from baselines.ppo.args import command_line
from baselines.ppo.evaluation import pct
from experiments import from_scratch
from experiments.campaign import CAMPAIGN_DIR, Run, describe, record_checkpoint_step, run_or_resume
from experiments.from_scratch import csv_column, moving_mean, scratch_args, seed_evaluations, seed_run
from baselines.sac import sac
from experiments.sac_recipe import BUDGET, run_sac, sac_args
from ms_construction.parameters import PAPER_KINDS
from ms_construction.reporting import update_section

SEEDS = (1, 2)
"""the seeds each arm may run on: the recipe's (experiments/from_scratch.py SEEDS), whose runs are the PPO arm."""
TARGET = 0.9
"""the recipe's target: every task placed at least this often with the paper's protocol (issue 52)."""
PICK_TARGET = 0.95
LEVELS = (0.5, TARGET)
"""the worst task's place success whose first crossing each arm's row gives, in env steps and in wall time."""
AT_HOURS = (0.5, 1.0, 1.5)
"""training wall times (h) at which the arms' worst task placed is compared."""
MOVING_WINDOW = 100_000
"""env steps over which the training episodes' place success is averaged."""
CURVES = Path("docs/images/learners_curves.png")
COMMAND = "python -m experiments.learners"
PAGE = Path("docs/experiments/learners.md")
"""the experiment's page: every evaluation with the paper's protocol goes there (`evaluations_table`)."""
EVAL_DIR = Path("docs/data/learners")
"""the curiosity and update-ratio arms' evaluations with the paper's protocol (`--evaluate icm|sac_utd`):
<arm>_s<seed>_eval50k.json (the PPO and SAC arms' are the recipe's runs' own, in experiments/from_scratch.py's
SEED_EVAL_DIR)."""


def icm_run(num_envs: Optional[int] = None, seed: int = 1) -> Run:
    """The recipe, unchanged but for ICM's curiosity bonus (its defaults) and the budget."""
    name = f"scratch_icm_s{seed}"
    return Run(name, scratch_args(num_envs, seed=seed, exp_name=name, curiosity="icm", total_timesteps=BUDGET),
               f"the from-scratch recipe with ICM's curiosity bonus, seed {seed}",
               f"{COMMAND} --arm icm --seed {seed}", None)


PROBE_UTD = 0.25
"""the update-ratio arm's gradient steps per env step (the recipe's: sac.Args.utd)."""
PROBE_BUDGET = 500_000
"""env steps of the update-ratio probe: where the recipe's SAC runs were first judged (both met the target by then)."""


def sac_utd_args(seed: int = 1) -> sac.Args:
    """The recipe's SAC (experiments/sac_recipe.py) unchanged but for PROBE_UTD and the budget."""
    return sac_args(seed, exp_name=f"sac_utd{str(PROBE_UTD).replace('.', '')}_s{seed}", utd=PROBE_UTD,
                    total_timesteps=PROBE_BUDGET)


ARMS = {"ppo": "PPO (the recipe's run)", "icm": "PPO + ICM (the recipe with curiosity)",
        "sac": "SAC (replay, twin Q, tanh Gaussian, auto entropy)",
        "sac_utd": f"SAC at {PROBE_UTD:g} gradient steps per env step (a probe)"}
PLANNED = {"ppo": SEEDS, "icm": (1,), "sac": SEEDS, "sac_utd": SEEDS}
"""the seeds each arm runs on: curiosity is one probe (the issue), the others both seeds."""
BUDGETS = {"ppo": BUDGET, "icm": BUDGET, "sac": BUDGET, "sac_utd": PROBE_BUDGET}


def progress_csv(arm: str, log_dir: Path = CAMPAIGN_DIR, seed: int = 1) -> Path:
    name = {"ppo": seed_run(seed, learner="ppo").args.exp_name, "icm": icm_run(seed=seed).args.exp_name,
            "sac": sac_args(seed).exp_name, "sac_utd": sac_utd_args(seed).exp_name}[arm]
    return log_dir / name / "progress.csv"


def arm_checkpoint(arm: str, log_dir: Path = CAMPAIGN_DIR, seed: int = 1) -> Path:
    return progress_csv(arm, log_dir, seed).with_name("checkpoint.pt")


def eval_json(arm: str, seed: int, eval_dir: Optional[Path] = None) -> Path:
    """Where `evaluate_arm` writes the curiosity arm's evaluation on `seed` (in EVAL_DIR unless `eval_dir`)."""
    return (eval_dir or EVAL_DIR) / f"{arm}_s{seed}_eval50k.json"


def evaluate_arm(arm: str, workers: int = 2, log_dir: Path = CAMPAIGN_DIR, seed: int = 1) -> Path:
    """The paper's protocol (test seeds, 50,000 env steps per task, cp4, the policy's mean) on the arm's latest
    checkpoint on `seed`: the PPO and SAC arms' as the recipe evaluates its runs (from_scratch.evaluate_seed), the
    curiosity arm's to `eval_json` (the env steps it had trained are in its `checkpoint_step`)."""
    if arm not in ARMS:
        raise SystemExit(f"--evaluate {arm}: use one of {', '.join(ARMS)}")
    if arm in from_scratch.LEARNERS:
        return from_scratch.evaluate_seed(seed, workers=workers, learner=arm)
    ckpt = arm_checkpoint(arm, log_dir, seed)
    if not ckpt.is_file():
        raise SystemExit(f"--evaluate {arm}: no checkpoint at {ckpt}; train it first: "
                         f"{COMMAND} --arm {arm} --seed {seed}")
    out = eval_json(arm, seed)
    evaluation.main(evaluation.Args(checkpoint=ckpt, all=True, steps=50_000, workers=workers, json=out))
    record_checkpoint_step(out, ckpt)
    return out


def evaluated(arm: str, seed: int, eval_dir: Path = EVAL_DIR) -> list[tuple[int, dict]]:
    """(env steps, scripts/evaluate.py's JSON) of each evaluation of the arm on `seed` with the paper's protocol: the
    PPO and SAC arms' snapshots the recipe evaluated (experiments/from_scratch.py `seed_evaluations`), the curiosity
    arm's latest checkpoint (`evaluate_arm`)."""
    if arm in from_scratch.LEARNERS:
        return [(step, json.loads(p.read_text())) for step, p in seed_evaluations(seed, arm).items()]
    path = eval_json(arm, seed, eval_dir)
    if not path.is_file():
        return []
    data = json.loads(path.read_text())
    return [(int(data["checkpoint_step"]), data)]


def hours_at(c: dict, step: int) -> Optional[float]:
    """The training wall time (h) of curve `c` at its last row at or before env step `step` (None: before its
    first)."""
    i = np.searchsorted(c["steps"], step, side="right") - 1
    return None if i < 0 else float(c["hours"][i])


def met(tasks: dict[str, dict]) -> bool:
    """Whether an evaluation meets the recipe's target on every task."""
    return all(r["place_success"] >= TARGET and r["pick_success"] >= PICK_TARGET for r in tasks.values())


def first_met(arm: str, seed: int, whole: Optional[dict], eval_dir: Path = EVAL_DIR) -> str:
    """The first of an arm's evaluations with the paper's protocol on `seed` that meets the target: its env steps
    and the training wall time its run had taken by then (from its whole curve `whole`), or why there is none."""
    done = evaluated(arm, seed, eval_dir)
    for step, data in done:
        if met(evaluation.task_results(data)):
            hours = hours_at(whole, step) if whole is not None else None
            return f"{step:,}" + ("" if hours is None else f" ({hours:.1f} h)")
    return f"none of {len(done)}" if done else "not evaluated"


def evaluations_table(eval_dir: Path = EVAL_DIR, log_dir: Path = CAMPAIGN_DIR) -> list[str]:
    """A row per evaluation with the paper's protocol of an arm on a seed (`evaluated`), with the training wall time
    its run had taken by then; nothing where none is."""
    rows = []
    for arm, label in ARMS.items():
        for seed in SEEDS:
            progress = progress_csv(arm, log_dir, seed)
            whole = curve(progress, until=None) if progress.is_file() else None
            for step, data in evaluated(arm, seed, eval_dir):
                tasks = evaluation.task_results(data)
                hours = hours_at(whole, step) if whole is not None else None
                rows.append(f"| {label} | {seed} | {step:,} | {'-' if hours is None else f'{hours:.1f}'} | "
                            + " | ".join(pct(r["place_success"], r["place_success_ci95"]) for r in tasks.values())
                            + f" | {'yes' if met(tasks) else 'no'} |")
    if not rows:
        return []
    names = " | ".join(f"{env_id}: placed % [95% CI]" for env_id in tasks)
    return ["", f"The paper's protocol (test seeds, 50,000 env steps per task, cp4, the policy's mean): the SAC and PPO "
            f"arms' snapshots as the recipe evaluated them (`{from_scratch.COMMAND} --seed S [--learner ppo] --evaluate`), "
            f"the curiosity and update-ratio arms' latest checkpoints (`{COMMAND} --evaluate icm|sac_utd --seed S`):", "", f"| learner | seed | its env steps | its training wall time (h) | {names} | target met "
            f"(every task placed >= {TARGET:.0%}, picked >= {PICK_TARGET:.0%}) |",
            "|---|---|---|---|" + "---|" * len(tasks) + "---|", *rows]


def curve(path: Path, until: Optional[int] = BUDGET) -> dict[str, np.ndarray]:
    """An arm's env steps, its training wall time so far (hours) and its worst task type's place success from ordinary
    resets (mean over MOVING_WINDOW env steps), up to `until` env steps (None: the whole run); `last`: each task
    type's at the last of them."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if until is None or int(float(r["global_step"])) <= until]
    steps = csv_column(rows, "global_step")
    if rows and "update_s" in rows[0]:  # SAC writes its env and update seconds (its evaluations' are not training)
        wall = csv_column(rows, "env_s") + csv_column(rows, "update_s")
    else:  # PPO: each row is an iteration of (its env steps) at its sps
        wall = np.cumsum(np.diff(steps, prepend=0.0) / csv_column(rows, "sps"))
    window = max(1, int(round(MOVING_WINDOW / max(float(np.median(np.diff(steps, prepend=0.0))), 1.0))))
    per_kind = np.stack([moving_mean(csv_column(rows, f"ordinary_place_{k}"), window) for k in PAPER_KINDS])
    worst = np.where(np.isnan(per_kind).any(0), np.nan, np.nanmin(np.nan_to_num(per_kind, nan=np.inf), 0))
    return dict(steps=steps, hours=wall / 3600, worst=worst, last=dict(zip(PAPER_KINDS, per_kind[:, -1])))


def value_at(c: dict, axis: str, at: float) -> Optional[float]:
    """The worst task's place success at `at` on `axis` ("steps" or "hours"): the last value there; None beyond the
    run."""
    i = np.searchsorted(c[axis], at, side="right") - 1
    if i < 0 or c[axis][-1] < at:
        return None
    return None if np.isnan(c["worst"][i]) else float(c["worst"][i])


def first_reaching(c: dict, axis: str, level: float) -> Optional[float]:
    hit = np.flatnonzero(np.nan_to_num(c["worst"]) >= level)
    return float(c[axis][hit[0]]) if len(hit) else None


def report(results: Path = Path("docs/RESULTS.md"), log_dir: Path = CAMPAIGN_DIR, eval_dir: Path = EVAL_DIR,
           page: Path = PAGE) -> str:
    """RESULTS' section `learners` (each arm's training against env steps and wall time, its first evaluation that
    met the target, the curves) and on `page` every evaluation with the paper's protocol; the section's body."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = {(arm, seed): curve(p) for arm in ARMS for seed in SEEDS
              if (p := progress_csv(arm, log_dir, seed)).is_file()}
    fmt = lambda v, f="{:.0%}": "-" if v is None else f.format(v)  # noqa: E731
    lines = [f"| learner | seed | env steps done / its budget | training wall time (h) | worst task placed at 1M / "
             f"2M env steps | at {' / '.join(map(str, AT_HOURS))} h of training | env steps to 50% / 90% (its whole run) | "
             f"wall time to 50% / 90% (h) | each task placed at its last env step ({' / '.join(PAPER_KINDS)}) | "
             f"first evaluated snapshot meeting the target: env steps (training wall time) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for colour, (arm, label) in enumerate(ARMS.items()):
        for seed in PLANNED[arm]:
            if (arm, seed) not in curves:
                command = (seed_run(seed, learner=arm).command if arm in from_scratch.LEARNERS
                           else f"{COMMAND} --arm {arm} --seed {seed}")
                lines.append(f"| {label} | {seed} | not run: `{command}` | | | | | | | |")
                continue
            c, whole = curves[arm, seed], curve(progress_csv(arm, log_dir, seed), until=None)
            lines.append(f"| {label} | {seed} | {int(c['steps'][-1]):,} / {BUDGETS[arm]:,} | {c['hours'][-1]:.1f} | "
                         f"{fmt(value_at(c, 'steps', 1e6))} / {fmt(value_at(c, 'steps', 2e6))} | "
                         + " / ".join(fmt(value_at(c, "hours", h)) for h in AT_HOURS)
                         + " | " + " / ".join(fmt(first_reaching(whole, "steps", v), "{:,.0f}") for v in LEVELS)
                         + " | " + " / ".join(fmt(first_reaching(whole, "hours", v), "{:.1f}") for v in LEVELS) + " | "
                         + " / ".join(fmt(None if np.isnan(v) else float(v)) for v in c["last"].values())
                         + f" | {first_met(arm, seed, whole, eval_dir)} |")
            for ax, axis, scale in ((axes[0], "steps", 1e6), (axes[1], "hours", 1.0)):
                ax.plot(c[axis] / scale, 100 * c["worst"], color=f"C{colour}", linestyle=("-", "--")[seed != 1],
                        label=f"{label}, seed {seed}")
    axes[0].set_xlabel("env steps (millions)")
    axes[1].set_xlabel("training wall time (h), this 2-core CPU")
    axes[0].set_ylabel("worst task placed, ordinary resets (%)")
    axes[0].set_ylim(0, 102)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Learners from nothing: training episodes (mean over {MOVING_WINDOW:,} env steps)")
    fig.tight_layout()
    CURVES.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(CURVES, dpi=100)
    plt.close(fig)
    notes = []  # the inexact resumes and the probe's clock, folded under the figure
    for seed in SEEDS:
        sac_ckpt = arm_checkpoint("sac", log_dir, seed)
        refilled = (torch.load(sac_ckpt, map_location="cpu", weights_only=False)["clock"].get("refilled_at", [])
                    if sac_ckpt.is_file() else [])
        if refilled:  # an inexact resume: the reader should know where
            notes += ["", f"SAC seed {seed}'s replay buffer was lost between sessions and refilled by its actor at "
                      + ", ".join(f"{step:,}" for step in refilled) + " env steps (`--refill-lost-buffer`)."]
    for seed in SEEDS:
        if (probe := progress_csv("sac_utd", log_dir, seed)).is_file():
            recipe = progress_csv("sac", log_dir, seed)
            notes += ["", update_ratio_sentence(probe, curve(recipe, until=None) if recipe.is_file() else None, seed)]
    body = "\n".join([
        "## Which learner, and curiosity", "",
        f"Commands: `{from_scratch.COMMAND} --seed S [--learner ppo]` (the SAC and PPO arms on a seed are the "
        f"recipe's runs on it), `{COMMAND} --arm icm`, `{COMMAND} --arm sac_utd --seed S` (a probe: the recipe's SAC "
        f"at {PROBE_UTD:g} gradient steps per env step to {PROBE_BUDGET:,}), `{COMMAND} --report`. Each from nothing on the same envs, dense reward, near-goal starts and seeds; "
        "the training episodes from ordinary resets, the worst of the three task types placed; the target: every task "
        f"placed >= {TARGET:.0%} and picked >= {PICK_TARGET:.0%} with the paper's protocol (every evaluation: "
        f"[the experiment page]({Path(*page.parts[1:])}#every-evaluation-with-the-papers-protocol)).", "", *lines, "",
        f"![learners]({Path(*CURVES.parts[1:])})",
        *(["", "<details><summary>Inexact resumes, and the update-ratio probe's clock</summary>", *notes, "",
           "</details>"] if notes else [])])
    update_section(results, "learners", body, "Results")
    table = evaluations_table(eval_dir, log_dir)
    update_section(page, "learners-evaluations", "\n".join(
        ["## Every evaluation with the paper's protocol", "", f"Command: `{COMMAND} --report`.", *table]
        if table else ["## Every evaluation with the paper's protocol", "", "None yet."]), "Which learner")
    return body


def update_ratio_sentence(probe: Path, recipe: Optional[dict], seed: int = 1) -> str:
    """What the update-ratio probe's own clock (its progress.csv's last row) says it saves per env step, and the env
    steps it took to 90% against the recipe's SAC run on its seed (`recipe`, its whole curve; None: not there): the
    probe wins in wall time where it needs fewer than the saving's factor times the recipe's env steps."""
    with open(probe, newline="") as f:
        last = list(csv.DictReader(f))[-1]
    steps, updates = float(last["global_step"]), float(last["updates"])
    env_ms, update_ms = 1e3 * float(last["env_s"]) / steps, 1e3 * float(last["update_s"]) / max(updates, 1.0)
    recipe_utd = sac_args().utd
    cost, recipe_cost = env_ms + PROBE_UTD * update_ms, env_ms + recipe_utd * update_ms
    probe_90 = first_reaching(curve(probe, None), "steps", TARGET)
    recipe_90 = None if recipe is None else first_reaching(recipe, "steps", TARGET)
    reached = ("it has not reached 90% yet" if probe_90 is None else
               f"it reached 90% at {probe_90:,.0f} env steps"
               + ("" if recipe_90 is None else f", the recipe's run on its seed at {recipe_90:,.0f} "
                                                f"({probe_90 / recipe_90:.2f}x)"))
    return (f"The update-ratio probe's own clock on seed {seed} ({int(steps):,} env steps): its env steps took {env_ms:.2f} ms per env "
            f"step and a gradient step {update_ms:.1f} ms, so an env step of training costs {cost:.2f} ms at "
            f"{PROBE_UTD:g} gradient steps per env step against {recipe_cost:.2f} ms at the recipe's {recipe_utd:g} "
            f"({recipe_cost / cost:.2f}x): it is sooner in wall time where it needs fewer than "
            f"{recipe_cost / cost:.2f}x the recipe's env steps; {reached}.")


@dataclass
class Args:
    arm: Optional[str] = None
    """train (or resume) this arm to its budget: `icm` (to BUDGET) or `sac_utd` (to PROBE_BUDGET); the SAC and PPO
    arms are the recipe's runs (experiments/from_scratch.py)."""
    seed: int = 1
    """the recipe's seed the arm runs (or is evaluated) on: one of SEEDS."""
    num_envs: Optional[int] = None
    """--arm icm: env processes (default: one per CPU core); a resumed run keeps its own."""
    dry_run: bool = False
    """print the plan and where the arm's run stands, and exit."""
    report: bool = False
    """write RESULTS' section and its curves from the arms' progress.csv, and exit."""
    evaluate: Optional[str] = None
    """evaluate this arm's latest checkpoint on --seed with the paper's protocol (EVAL_DIR), and exit."""


def main(args: Args) -> None:
    if args.report:
        print(report())
        return
    if args.seed not in SEEDS:
        raise SystemExit(f"--seed {args.seed}: use one of {', '.join(map(str, SEEDS))} (the recipe's seeds)")
    if args.evaluate is not None:
        print(f"wrote {evaluate_arm(args.evaluate, seed=args.seed)}")
        return
    if args.arm == "sac_utd":
        a = sac_utd_args(args.seed)
        print(f"SAC at {a.utd:g} gradient steps per env step, seed {a.seed}, to {a.total_timesteps:,} env steps in "
              f"{Path(a.log_dir) / a.exp_name}")
        if not args.dry_run:
            run_sac(a)
        return
    if args.arm != "icm":
        raise SystemExit(f"--arm {args.arm}: use icm or sac_utd (the SAC and PPO arms are the recipe's runs: "
                         f"`{from_scratch.COMMAND} --seed {args.seed}` with SAC, `... --learner ppo` with PPO), or "
                         "--report")
    run = icm_run(args.num_envs, args.seed)
    print(describe(run))
    print("as one ppo.py command: python baselines/ppo/ppo.py " + " ".join(command_line(run.args)))
    if not args.dry_run:
        run_or_resume(run)


if __name__ == "__main__":
    main(tyro.cli(Args))
