"""Which learner, and whether curiosity helps: SAC against PPO, and PPO's recipe with ICM's curiosity bonus, each from
nothing on the same envs, reward, start states and seed as the recipe, compared at equal env steps and equal wall
time on this CPU.

    python -m experiments.learners --arm sac --dry-run   # the plan, and where the arm's run stands
    python -m experiments.learners --arm sac             # SAC from nothing (baselines/sac/sac.py), to BUDGET, resumable
    python -m experiments.learners --arm icm             # the recipe with curiosity (ICM), to BUDGET, resumable
    python -m experiments.learners --evaluate sac        # the paper's protocol on the arm's latest checkpoint
    python -m experiments.learners --report              # RESULTS' section and its curves, from the arms' progress.csv

The PPO arm is the recipe's own run on seed 1 (campaign/scratch_s1/, experiments/from_scratch.py): its first BUDGET
env steps, so no PPO run is repeated. What is compared is the training episodes from ordinary resets (neither
near-goal nor reach starts), placed per task type, the worst of the three (a mean over MOVING_WINDOW env steps), at
equal env steps and at equal wall time of training (rollouts and updates, from each progress.csv; start-ups,
evaluations and the time between sessions not counted).

What SAC shares with the recipe: the envs, the reward, the observation, the near-goal starts (baselines/sac/sac.py's
docstring). What it does not: the reach starts and the mirror of the twin openings (PPO's network options). SAC's
replay buffer (about 140 MB) is written beside its checkpoint and is not committed: its run resumes exactly on the
machine it ran on; on a fresh machine it goes on with an empty buffer that its actor refills first
(`--refill-lost-buffer`, recorded in its checkpoint's clock as `refilled_at`).
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
from baselines.sac import sac
from experiments.campaign import CAMPAIGN_DIR, Run, describe, run_or_resume
from experiments.from_scratch import csv_column, moving_mean, scratch_args, seed_run
from ms_construction.parameters import PAPER_KINDS
from ms_construction.reporting import update_section

BUDGET = 2_000_000
"""env steps of each arm (the issue: at least 2M)."""
SEED = 1
"""every arm's seed: the recipe's first seed, whose run is the PPO arm."""
MOVING_WINDOW = 100_000
"""env steps over which the training episodes' place success is averaged."""
CURVES = Path("docs/images/learners_curves.png")
COMMAND = "python -m experiments.learners"
EVAL_DIR = Path("docs/data/learners")
"""each arm's evaluation with the paper's protocol (`--evaluate ARM`): <arm>_eval50k.json."""


def sac_args(**overrides) -> sac.Args:
    """SAC's defaults (chosen for this CPU: baselines/sac/sac.py) on the recipe's seed, in campaign/."""
    return sac.Args(**{**dict(exp_name=f"sac_s{SEED}", seed=SEED, total_timesteps=BUDGET, log_dir=str(CAMPAIGN_DIR)),
                       **overrides})


def icm_run(num_envs: Optional[int] = None) -> Run:
    """The recipe, unchanged but for ICM's curiosity bonus (its defaults) and the budget."""
    name = f"scratch_icm_s{SEED}"
    return Run(name, scratch_args(num_envs, seed=SEED, exp_name=name, curiosity="icm", total_timesteps=BUDGET),
               f"the from-scratch recipe with ICM's curiosity bonus, seed {SEED}", f"{COMMAND} --arm icm", None)


ARMS = {"ppo": "PPO (the recipe, seed 1's run)", "icm": "PPO + ICM (the recipe with curiosity)",
        "sac": "SAC (replay, twin Q, tanh Gaussian, auto entropy)"}


def progress_csv(arm: str, log_dir: Path = CAMPAIGN_DIR) -> Path:
    name = {"ppo": seed_run(SEED).args.exp_name, "icm": icm_run().args.exp_name, "sac": sac_args().exp_name}[arm]
    return log_dir / name / "progress.csv"


def arm_checkpoint(arm: str, log_dir: Path = CAMPAIGN_DIR) -> Path:
    return progress_csv(arm, log_dir).with_name("checkpoint.pt")


def evaluate_arm(arm: str, workers: int = 2, log_dir: Path = CAMPAIGN_DIR) -> Path:
    """The paper's protocol (test seeds, 50,000 env steps per task, cp4, the policy's mean) on the arm's latest
    checkpoint, written to EVAL_DIR/<arm>_eval50k.json (the env steps it had trained are in its `checkpoint_step`)."""
    if arm not in ARMS:
        raise SystemExit(f"--evaluate {arm}: use one of {', '.join(ARMS)}")
    ckpt = arm_checkpoint(arm, log_dir)
    if not ckpt.is_file():
        raise SystemExit(f"--evaluate {arm}: no checkpoint at {ckpt}; train it first: {COMMAND} --arm {arm}")
    out = EVAL_DIR / f"{arm}_eval50k.json"
    evaluation.main(evaluation.Args(checkpoint=ckpt, all=True, steps=50_000, workers=workers, json=out))
    step = int(torch.load(ckpt, map_location="cpu", weights_only=False)["progress"]["global_step"])
    out.write_text(json.dumps(dict(json.loads(out.read_text()), checkpoint_step=step), indent=1) + "\n")
    return out


def evaluations_table(eval_dir: Path = EVAL_DIR) -> list[str]:
    """A row per arm evaluated with the paper's protocol (`evaluate_arm`); nothing where none is."""
    rows = []
    for arm, label in ARMS.items():
        path = eval_dir / f"{arm}_eval50k.json"
        if path.is_file():
            data = json.loads(path.read_text())
            tasks = evaluation.task_results(data)
            rows.append(f"| {label} | {data['checkpoint_step']:,} | "
                        + " | ".join(pct(r["place_success"], r["place_success_ci95"]) for r in tasks.values()) + " |")
    if not rows:
        return []
    names = " | ".join(f"{env_id}: placed % [95% CI]" for env_id in tasks)
    return ["", f"The paper's protocol (test seeds, 50,000 env steps per task, cp4, the policy's mean; `{COMMAND} "
            "--evaluate ARM` on the arm's latest checkpoint):", "", f"| learner | its env steps | {names} |",
            "|---|---|" + "---|" * len(tasks), *rows]


def curve(path: Path) -> dict[str, np.ndarray]:
    """An arm's env steps, its training wall time so far (hours) and its worst task type's place success from ordinary
    resets (mean over MOVING_WINDOW env steps), up to BUDGET; `last`: each task type's at the last of them."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if int(float(r["global_step"])) <= BUDGET]
    steps = csv_column(rows, "global_step")
    if rows and "wall_s" in rows[0]:  # SAC writes its wall time
        wall = csv_column(rows, "wall_s")
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


def report(results: Path = Path("docs/RESULTS.md"), log_dir: Path = CAMPAIGN_DIR, eval_dir: Path = EVAL_DIR) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = {arm: curve(p) for arm in ARMS if (p := progress_csv(arm, log_dir)).is_file()}
    fmt = lambda v, f="{:.0%}": "-" if v is None else f.format(v)  # noqa: E731
    hours = min((c["hours"][-1] for c in curves.values()), default=0.0)
    lines = [f"| learner | env steps done (of {BUDGET:,}) | training wall time (h) | worst task placed at 1M / 2M env "
             f"steps | at {hours:.1f} h of training (the shortest arm's) | env steps to 50% | wall time to 50% (h) | "
             f"each task placed at its last env step ({' / '.join(PAPER_KINDS)}) |",
             "|---|---|---|---|---|---|---|---|"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for arm, label in ARMS.items():
        if arm not in curves:
            lines.append(f"| {label} | not run: `{COMMAND} --arm {arm}` | | | | | | |")
            continue
        c = curves[arm]
        lines.append(f"| {label} | {int(c['steps'][-1]):,} | {c['hours'][-1]:.1f} | "
                     f"{fmt(value_at(c, 'steps', 1e6))} / {fmt(value_at(c, 'steps', 2e6))} | "
                     f"{fmt(value_at(c, 'hours', hours))} | {fmt(first_reaching(c, 'steps', 0.5), '{:,.0f}')} | "
                     f"{fmt(first_reaching(c, 'hours', 0.5), '{:.1f}')} | "
                     + " / ".join(fmt(None if np.isnan(v) else float(v)) for v in c["last"].values()) + " |")
        for ax, axis, scale in ((axes[0], "steps", 1e6), (axes[1], "hours", 1.0)):
            ax.plot(c[axis] / scale, 100 * c["worst"], label=label)
    axes[0].set_xlabel("env steps (millions)")
    axes[1].set_xlabel("training wall time (h), this 2-core CPU")
    axes[0].set_ylabel("worst task placed, ordinary resets (%)")
    axes[0].set_ylim(0, 102)
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Learners from nothing, seed {SEED}: training episodes (mean over {MOVING_WINDOW:,} env steps)")
    fig.tight_layout()
    CURVES.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(CURVES, dpi=100)
    plt.close(fig)
    sac_ckpt = log_dir / sac_args().exp_name / "checkpoint.pt"
    refilled = (torch.load(sac_ckpt, map_location="cpu", weights_only=False)["clock"].get("refilled_at", [])
                if sac_ckpt.is_file() else [])
    if refilled:  # an inexact resume: the reader should know where
        lines += ["", "SAC's replay buffer was lost between sessions and refilled by its actor at "
                  + ", ".join(f"{step:,}" for step in refilled) + " env steps (`--refill-lost-buffer`)."]
    body = "\n".join([
        "## Which learner, and curiosity", "",
        f"Commands: `{COMMAND} --arm sac`, `{COMMAND} --arm icm` (the PPO arm is the recipe's seed {SEED}), "
        f"`{COMMAND} --report`. Each from nothing on the same envs, dense reward, near-goal starts and seed; the "
        "training episodes from ordinary resets, the worst of the three task types placed.", "", *lines,
        *evaluations_table(eval_dir), "",
        f"![learners]({Path(*CURVES.parts[1:])})"])
    update_section(results, "learners", body, "Results")
    return body


@dataclass
class Args:
    arm: Optional[str] = None
    """train (or resume) this arm to BUDGET: `sac` or `icm` (the PPO arm is the recipe's run)."""
    num_envs: Optional[int] = None
    """--arm icm: env processes (default: one per CPU core); a resumed run keeps its own."""
    dry_run: bool = False
    """print the plan and where the arm's run stands, and exit."""
    report: bool = False
    """write RESULTS' section and its curves from the arms' progress.csv, and exit."""
    evaluate: Optional[str] = None
    """evaluate this arm's latest checkpoint with the paper's protocol (EVAL_DIR), and exit."""


def main(args: Args) -> None:
    if args.report:
        print(report())
        return
    if args.evaluate is not None:
        print(f"wrote {evaluate_arm(args.evaluate)}")
        return
    if args.arm not in ("sac", "icm"):
        raise SystemExit(f"--arm {args.arm}: use sac or icm (the PPO arm is `python -m experiments.from_scratch "
                         f"--seed {SEED}`), or --report")
    if args.arm == "icm":
        run = icm_run(args.num_envs)
        print(describe(run))
        print("as one ppo.py command: python baselines/ppo/ppo.py " + " ".join(command_line(run.args)))
        if not args.dry_run:
            run_or_resume(run)
        return
    a = sac_args()
    ckpt = Path(a.log_dir) / a.exp_name / "checkpoint.pt"
    print(f"SAC from nothing, seed {SEED}, to {BUDGET:,} env steps in {ckpt.parent}: "
          + ("resumes" if ckpt.is_file() else "starts fresh"))
    if not args.dry_run:
        sac.main(sac_args(resume=str(ckpt), extend=True, refill_lost_buffer=True) if ckpt.is_file() else a)


if __name__ == "__main__":
    main(tyro.cli(Args))
