"""The general agent learnt from reward alone: no demonstrations, no expert states, no cloned weights.

    python -m experiments.from_scratch --seed 1 --dry-run   # the plan, and where that seed's run stands
    python -m experiments.from_scratch --seed 1             # run (or resume) the recipe from nothing on seed 1 with its
                                                            # learner, SAC, a snapshot every 250,000 env steps, screened
                                                            # on validation seeds as it is made; at the budget the
                                                            # snapshot rule chooses one and the paper's protocol
                                                            # evaluates it (commit campaign/sac_s1/ but its replay
                                                            # buffer, and docs/data/from_scratch/)
    python -m experiments.from_scratch --seed 1 --learner ppo   # the same with PPO (campaign/scratch_s1/)
    python -m experiments.from_scratch --seed 1 --evaluate  # the paper's protocol on that seed's latest snapshot, or
                                                            # --at-step N
    python -m experiments.from_scratch --report             # the seeds' and the shipped agent's sections of
                                                            # docs/RESULTS.md, and the seeds' curves
    python -m experiments.from_scratch --ship-seeds         # ship the better seed's chosen snapshot once both have run

The recipe runs unchanged from step 0 to its budget, one run per seed on ConstructionPickPlace-v1 (resumed from its
checkpoint in campaign/<run_name>/), with one of two learners on the same envs, reward, observation and near-goal
starts: SAC (LEARNER, the default: experiments/sac_recipe.py `sac_args`, baselines/sac/sac.py's defaults, 2M env
steps), which met the recipe's target in about a fifth of PPO's training wall time on this CPU on both seeds
(experiments/learners.py), or PPO (`scratch_args`, baselines/ppo/ppo.py, 10M env steps), whose runs made the agent
shipped now. The better seed's chosen snapshot ships as assets/checkpoints/scratch_general_agent.pt if it places at
least what that one does. The first campaign from reward alone changed its recipe seven times on the way to its
target (docs/experiments/from_scratch.md is its history); the PPO recipe is where it ended, with the task's one dense
reward and without its sampling weights on one task type and one opening. What each part of PPO's recipe is for (SAC
shares the reward, success, the near-goal starts, observation, discount, curriculum and task sampling; not the reach
starts, the mirror of the twin openings or PPO's updates):

| setting | value | why |
|---|---|---|
| reward | normalized_dense, the tasks' default: their one dense reward / 10 (placing pays 10, a held step at most 4.5) | its carry runs in joint space along the goal slot's collision-checked start paths (IK of the goal, ms_construction/envs/carry_geometry.py), so it pulls from the pick, the way the turret's limits allow and over the site's barriers; its reach turns the turret to the side the slot's paths leave the table from; its progress term pays each step's fall of the carry at once (probe G). The fourth start's policy, on a straight joint-space carry, carried elements into the slab, the wall and the barriers and stopped there |
| success | absorbing: bootstrapped with its reward for ever | the critic never trains on a state after success; its guess let hovering near the goal outvalue placing |
| start states | 80% of the training episodes start held on a collision-free joint path out of the goal (`set_near_goal_starts`: IK, and a planned via where a slot's paths leave the table only from the other turret side than its task type's other slots'), each task type's radius widening from 0.1 of the path by 0.1 once 60% of its last 20 such episodes placed; such an episode that has not placed in 80 steps is cut; half of the others start on the last part of the reach path down to the element on the table (`set_reach_starts`), each goal slot's part from a tenth of the path widened by 0.1 once 60% of its last 20 such episodes grasped from the turret side they started on | reverse curriculum generation (Florensa et al. 2017) from resets the env computes by IK: no demonstrations; evaluation always resets as usual. Without the reach starts the policy from nothing picked nothing from ordinary resets in its first probe's steps and its radii widened later; with them ordinary resets began to pick (the probes' table: `python -m experiments.recipe_probes --report`). One radius for all three types widened on lucky iterations of the easy type (probe F); with half the episodes and no cut, a failed start wandered for 250 steps and an update held a handful of near-goal episodes (probes I-L) |
| observation | the tasks' state + the joint move to the installation configuration (`obs_install_offset`); since 18,062,000 steps + the joint move a little ahead along the start path (`obs_path_offset`) | what the carry term measures, from IK of the goal pose: following it places from near-goal starts (a test); without it the policy must learn IK of nine goal slots itself |
| policy | Gaussian, its mean bounded by tanh (`bounded_mean`); a window whose opening is the mirror image of another in the plane y = 0 met as that one (`mirror_twins`, `mirror_canonical_reach`, `mirror_held_half_turn`) | an unbounded mean drifted past the action bounds, where every draw clips alike and PPO cannot move it back (the third start's `--diagnose`). The window openings at y = -0.85 and +0.85 are each other's mirror image: the first is reached from the turret's -pi side, the second from +pi, and a policy meets the second as the first (probes AJ-AM, docs/experiments/from_scratch.md) |
| discount | gamma 0.95, GAE lambda 0.95 | values of a few dozen steps: the dense reward carries the rest, and the critic learns them quickly |
| updates | 2,000 samples (2 envs x 1,000 steps), 8 epochs of 8 minibatches, KL stop 0.1 | more gradient steps per env step: env steps are the cost on a CPU |
| curiosity | none | the dense reward explores |
| curriculum | cp4 from the first step | the target is judged at cp4 |
| task sampling | uniform over task types and goal slots | the campaign's weights (windows twice, the opening at y = +0.85 three times) named one task and one opening |
"""

from __future__ import annotations

import csv
import json
import os
import shlex
import shutil
import dataclasses
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch
import tyro

from baselines.ppo import evaluation, ppo
from baselines.ppo.args import command_line
from baselines.ppo.checkpoints import load_checkpoint
from baselines.ppo.evaluation import PAPER_TABLE_II, failures, kinds, pct
from baselines.ppo.start_states import GOAL_SLOTS
from baselines.sac import sac
from experiments import sac_recipe
from experiments.campaign import (CAMPAIGN_DIR, SHIPPED_DIR, Run, checkpoint_of, describe, policy_only, ship,
                                 training_wall_s)
from experiments.expert_modes import placed_per_slot
from experiments.refine import (CONFIRMATION_SEED, TIEBREAK_SEED, VALIDATION_SEED, best_snapshot, placed_score,
                               ranked_snapshots, validate)
from ms_construction.parameters import PAPER_KINDS
from ms_construction.reporting import update_section
from ms_construction.curriculum import FINAL_STAGE

BUDGET = 10_000_000
"""env steps of the recipe from nothing, per seed."""
CAMPAIGN = "scratch_general_agent"
"""the shipped agent's name (assets/checkpoints/<CAMPAIGN>.pt)."""
COMMAND = "python -m experiments.from_scratch"
PAGE = Path("docs/experiments/from_scratch.md")
"""the experiment page: the recipe's probes (experiments/recipe_probes.py) are written into it."""


def scratch_args(num_envs: Optional[int] = None, **overrides) -> ppo.Args:
    """ppo.Args of the from-scratch recipe (see the module docstring); `overrides` replace any field afterwards."""
    num_envs = num_envs or os.cpu_count() or 1
    args = ppo.Args.of(
        env_id="ConstructionPickPlace-v1", reward_mode="normalized_dense", control_mode="pd_joint_delta_pos",
        sim_backend="physx_cpu", cuda=False, curriculum=(FINAL_STAGE,), total_timesteps=BUDGET, curiosity="none",
        success_value="absorbing", bootstrap_at_done="always", gamma=0.95, gae_lambda=0.95,
        num_envs=num_envs, num_steps=2000 // num_envs, update_epochs=8, num_minibatches=8, target_kl=0.1,
        near_goal_share=0.8, near_goal_radius=0.1, near_goal_step=0.1, near_goal_promote=0.6, near_goal_window=20,
        near_goal_max_steps=80, reach_start_share=0.5, reach_start_radius=0.1,
        obs_install_offset=True, obs_path_offset=True, bounded_mean=True,
        mirror_twins=True, mirror_canonical_reach=True, mirror_held_half_turn=True,
        eval_freq=25, checkpoint_freq=10, log_dir=str(CAMPAIGN_DIR),
    )
    return args.replace(**overrides)


METHOD = "PPO from nothing on the tasks' default dense reward, near-goal and reach start states (experiments/from_scratch.py); demonstrations: none"

LEARNERS = ("sac", "ppo")
"""the learners the recipe runs with: SAC (experiments/sac_recipe.py, to its BUDGET) or PPO (`scratch_args`, to
BUDGET)."""
LEARNER = "sac"
"""the recipe's learner, the one of LEARNERS that met its target sooner in training wall time on this CPU: SAC at
1.0-1.2 h on the two seeds, PPO at 5.1-7.3 h (experiments/learners.py, docs/RESULTS.md#which-learner-and-curiosity)."""


def run_name(seed: int, learner: str = LEARNER) -> str:
    """The name of the recipe's run from nothing on `seed` with `learner`: its folder in campaign/ and its files'
    prefix in SEED_EVAL_DIR."""
    if learner not in LEARNERS:
        raise SystemExit(f"--learner {learner}: use one of {', '.join(LEARNERS)}")
    return {"sac": sac_recipe.sac_args(seed).exp_name, "ppo": f"scratch_s{seed}"}[learner]


def seed_run(seed: int, num_envs: Optional[int] = None, learner: str = LEARNER) -> Run:
    """The recipe from nothing on `seed` with `learner`, to its budget; `ship_seeds` ships the better seed once both
    have run."""
    name = run_name(seed, learner)
    command = f"{COMMAND} --seed {seed}" + ("" if learner == LEARNER else f" --learner {learner}")
    if learner == "sac":
        return Run(name, sac_recipe.sac_args(seed, **({"num_envs": num_envs} if num_envs else {})),
                   f"SAC from nothing, seed {seed}", command, None, method=sac_recipe.METHOD)
    return Run(name, scratch_args(num_envs, seed=seed, exp_name=name), f"the PPO recipe from nothing, seed {seed}",
               command, None, method=METHOD)


EVAL_JSON = Path("docs/data/paper/scratch_general_agent_eval_50k.json")
"""the shipped agent's evaluation with the paper's protocol (the command `report` prints writes it)."""
WINDOW = 50
"""iterations in the curve's moving average (100,000 env steps at 2,000 per iteration)."""


def csv_column(rows: list[dict], key: str) -> np.ndarray:
    return np.array([float(r[key]) if r.get(key) not in ("", None) else np.nan for r in rows])


def moving_mean(x: np.ndarray, window: int) -> np.ndarray:
    """The mean of the last `window` values that are there (iterations in which no such episode ended are not)."""
    out = np.full_like(x, np.nan)
    for i in range(len(x)):
        part = x[max(0, i - window + 1):i + 1]
        if np.isfinite(part).any():
            out[i] = np.nanmean(part)
    return out


def standing(run: Run, progress: Path) -> tuple[list[dict], list[str]]:
    """The rows of a run's progress.csv, and where it stands: env steps done / budget, training wall time, each task
    type's start radius now, and over its last 200,000 env steps its training episodes placed from ordinary resets
    per task type and placed from near-goal starts (%)."""
    with open(progress, newline="") as f:
        rows = list(csv.DictReader(f))
    done = int(rows[-1]["global_step"])
    late = [r for r in rows if int(r["global_step"]) > done - 200_000]

    def pct_of(key: str) -> str:
        x = csv_column(late, key)
        return f"{100 * np.nanmean(x):.1f}" if np.isfinite(x).any() else "-"

    wall = training_wall_s(progress, run.args.num_envs * getattr(run.args, "num_steps", 0))
    return rows, [f"{done:,} / {run.args.total_timesteps:,}", f"{wall / 3600:.1f} h",
                  " / ".join(f"{float(rows[-1].get(f'near_goal_radius_{k}') or 0):.1f}" for k in PAPER_KINDS),
                  " / ".join(pct_of(f"ordinary_place_{k}") for k in PAPER_KINDS), pct_of("near_goal_place_success")]


SHIPPED = SHIPPED_DIR / f"{CAMPAIGN}.pt"


def shipped_how(shipped: Path = SHIPPED) -> str:
    """How the shipped agent learnt, from its record: the recipe's seed and env steps, or (a policy shipped before the
    recipe ran from nothing) the first campaign's."""
    if not shipped.is_file():
        return "not shipped yet"
    ckpt = load_checkpoint(shipped)
    record, learner = ckpt["campaign"]["record"], ckpt["args"].get("algorithm", "ppo").upper()
    steps = record["env steps"].split(" ")[0]
    if record.get("chosen", "").startswith("seed "):
        return (f"{learner} on the dense reward, no demonstrations; the recipe unchanged from step 0, "
                f"{record['chosen'].split(' (')[0]}, {steps} env steps")
    return f"{learner} on the dense reward, no demonstrations; one hand-steered campaign, {steps} env steps"


def shipped_report(results: Path = Path("docs/RESULTS.md"), shipped: Path = SHIPPED) -> str:
    """The section `from-scratch` of docs/RESULTS.md: the shipped agent from reward alone (its record: the seed, the
    snapshot, the recipe's commit) and its evaluation with the paper's protocol (EVAL_JSON) beside the paper's Table II,
    with its placements per goal slot and its failures by kind."""
    if not shipped.is_file():
        lines = [f"Not shipped yet: `{COMMAND} --ship-seeds` ships the better seed's chosen snapshot once every seed "
                 "has run to its end."]
    elif not EVAL_JSON.is_file():
        lines = [f"{shipped} is not evaluated yet: `python scripts/evaluate.py --checkpoint {shipped} --all --steps "
                 f"{EVAL_STEPS} --json {EVAL_JSON}`."]
    else:
        data = json.loads(EVAL_JSON.read_text())
        record = load_checkpoint(shipped)["campaign"]["record"]
        lines = [f"Command: `{COMMAND} --report`. The shipped policy ({shipped}; {record['method']}; env steps: "
                 f"{record['env steps']}" + (f"; {record['chosen']}" if record.get("chosen") else "")
                 + f"), evaluated with the paper's protocol: `{data['command']}`.", "",
                 "| task | pick % [95% CI] | place % [95% CI] | paper's general agent: pick / place % | placed per goal "
                 "slot (0, 1, 2) | failures by kind |",
                 "|---|---|---|---|---|---|"]
        for env_id, r in data["tasks"].items():
            lost = [e for e in r["episode_results"] if not e["placed"]]
            not_picked = sum(not e["picked"] for e in lost)
            failed = failures([e for e in lost if e["picked"]])
            text = ", ".join(([f"{not_picked} never picked"] if not_picked else []) + ([kinds(failed)] if failed else [])) or "none"
            paper = PAPER_TABLE_II[env_id]
            lines.append(f"| {env_id} | {pct(r['pick_success'], r['pick_success_ci95'])} | "
                         f"{pct(r['place_success'], r['place_success_ci95'])} | {paper[0]:.2f} / {paper[1]:.2f} | "
                         f"{placed_per_slot(env_id, r['episode_results'])} | {text} |")
    body = "\n".join(lines)
    update_section(results, "from-scratch", body, "Results")
    return body


SEEDS = (1, 2)
"""the seeds the recipe runs from nothing on."""
SEEDS_CURVE = Path("docs/images/scratch_seeds_curve.png")


SEED_EVAL_DIR = Path("docs/data/from_scratch")
"""where each seed's evaluations with the paper's protocol go (scratch_s<seed>_eval50k_<env steps>.json)."""
EVAL_STEPS = 50_000
"""env steps per task of the paper's protocol."""


def seed_snapshots(seed: int, learner: str = LEARNER) -> Path:
    return SNAPSHOT_DIR / run_name(seed, learner)


def seed_evaluation_json(seed: int, step: int, learner: str = LEARNER) -> Path:
    return SEED_EVAL_DIR / f"{run_name(seed, learner)}_eval50k_{step}.json"


def seed_evaluations(seed: int, learner: str = LEARNER) -> dict[int, Path]:
    """env steps -> `seed_evaluation_json` of each evaluation of the seed's run with the paper's protocol."""
    prefix = f"{run_name(seed, learner)}_eval50k_"
    return dict(sorted((int(p.stem[len(prefix):]), p) for p in SEED_EVAL_DIR.glob(f"{prefix}*.json")))


def evaluate_seed(seed: int, step: Optional[int] = None, workers: int = 2, learner: str = LEARNER) -> Path:
    """The paper's protocol (test seeds from 1,000,000, EVAL_STEPS per task, cp4, the policy's mean) on the seed's
    snapshot at `step` env steps (default: its latest), written to `seed_evaluation_json`; kept where it is there.
    The run's own checkpoint counts as its snapshot at its step (a fresh machine has that one only)."""
    snapshots = seed_snapshots(seed, learner)
    found = {int(p.stem.split("_")[1]): p for p in snapshots.glob("checkpoint_*.pt")}
    found.update({int(p.stem.split("_")[1]): p for p in seed_candidates(seed, learner).glob("candidate_*.pt")
                  if int(p.stem.split("_")[1]) not in found})
    if (ckpt := checkpoint_of(seed_run(seed, learner=learner))).is_file():
        found.setdefault(load_checkpoint(ckpt)["progress"]["global_step"], ckpt)
    if not found:
        raise SystemExit(f"no snapshots of seed {seed} in {snapshots}: `{seed_run(seed, learner=learner).command}` "
                         f"keeps one every {SNAPSHOT_EVERY:,} env steps")
    step = max(found) if step is None else step
    if step not in found:
        raise SystemExit(f"no snapshot of seed {seed} at {step:,} env steps; there are: "
                         + ", ".join(f"{s:,}" for s in sorted(found)))
    out = seed_evaluation_json(seed, step, learner)
    if not out.is_file():
        evaluation.main(evaluation.Args(checkpoint=found[step], all=True, steps=EVAL_STEPS, workers=workers, json=out))
    return out


def seed_evaluations_table() -> list[str]:
    """Per learner and seed, one row beside the paper's Table II: the snapshot the rule chose, or, before it has
    chosen, the latest evaluated (every evaluated snapshot, with the wall time its run had taken, is in the learners'
    section: experiments/learners.py)."""
    found = [(learner, seed, *shown) for learner in LEARNERS for seed in SEEDS
             if (shown := shown_evaluation(seed, learner)) is not None]
    if not found:
        return ["No seed has been evaluated with the paper's protocol yet "
                f"(`{COMMAND} --seed S --evaluate`, at the end of its run)."]
    envs = list(PAPER_TABLE_II)
    lines = [f"With the paper's protocol (`{COMMAND} --seed S [--learner L] --evaluate [--at-step N]`: test seeds from "
             f"1,000,000, {EVAL_STEPS:,} env steps per task, cp4, the policy's mean; the seed's snapshot at N env "
             "steps), each seed's chosen snapshot or, until the rule has chosen, its latest evaluated one (every one "
             "evaluated: [which learner](#which-learner-and-curiosity)):", "",
             "| learner | seed | env steps | " + " | ".join(f"{e}: picked / placed % [95% CI]" for e in envs)
             + " | which snapshot |",
             "|---|---|---|" + "---|" * len(envs) + "---|",
             "| paper's general agent (Table II, cp4) | | 8,000,000 | "
             + " | ".join(f"{PAPER_TABLE_II[e][0]:.2f} / {PAPER_TABLE_II[e][1]:.2f}" for e in envs) + " | |"]
    for learner, seed, step, path, chosen in found:
        tasks = json.loads(path.read_text())["tasks"]
        lines.append(f"| {learner.upper()} | {seed} | {step:,} | " + " | ".join(
            f"{100 * tasks[e]['pick_success']:.1f} / {pct(tasks[e]['place_success'], tasks[e]['place_success_ci95'])}"
            for e in envs) + f" | {'**the rule chose it**' if chosen else 'the latest, not yet chosen'} |")
    return lines


def rule_table() -> list[str]:
    """Per seed, the snapshot rule's work: snapshots screened, the candidates' confirmation, the choice."""
    lines = [f"The snapshot rule (`screen_snapshot`, `choose_snapshot`): every snapshot screened on {VALIDATION_EPISODES} "
             f"validation episodes per task as the run makes it, the {CONFIRM_TOP} best of them validated again on "
             f"{CONFIRM_EPISODES} fresh episodes per task, the one that places most there on its worst task chosen; "
             f"candidates tied there validated again on {TIEBREAK_EPISODES} more per task and ranked on all "
             f"{CONFIRM_EPISODES + TIEBREAK_EPISODES} (placed there in brackets), a tie still going to the better "
             "screened, then the earliest (validation seeds only; the test seeds judge the choice: the first table):", "",
             "| learner | seed | snapshots screened | candidates: env steps (placed on confirmation, ceiling / window "
             "/ flooring %) | chosen |", "|---|---|---|---|---|"]
    for learner, seed in ((learner, seed) for learner in LEARNERS for seed in SEEDS):
        screened = seed_screening(seed, learner)
        if not chosen_json(seed, learner).is_file():
            lines.append(f"| {learner.upper()} | {seed} | {len(screened)} | (chosen at the end of its run) | - |")
            continue
        chosen = json.loads(chosen_json(seed, learner).read_text())
        tied = chosen.get("tie broken", {})
        lines.append(f"| {learner.upper()} | {seed} | {chosen['screened']} | " + "; ".join(
            f"{int(step):,} ({' / '.join(f'{100 * v:.0f}' for v in placed.values())}"
            + (f"; [{' / '.join(f'{100 * v:.2f}' for v in tied[step].values())}]" if step in tied else "") + ")"
            for step, placed in chosen["confirmed"].items()) + f" | {chosen['step']:,} |")
    return lines


def reach_radius(rows: list[dict], kind: str) -> np.ndarray:
    """The mean of the task type's goal slots' reach-start radii at each row of a progress.csv (NaN where not logged)."""
    return np.mean([csv_column(rows, f"reach_start_radius_{kind}{s}") for s in range(GOAL_SLOTS)], 0)


def reach_radii_now(rows: list[dict]) -> str:
    """Each goal slot's reach-start radius at the last row, per task type: "0.2, 1.0, 0.3 / ... / ..." ("-" if not
    logged)."""
    def of(kind: str) -> str:
        radii = [rows[-1].get(f"reach_start_radius_{kind}{s}") for s in range(GOAL_SLOTS)]
        return "-" if any(r in ("", None) for r in radii) else ", ".join(f"{float(r):.1f}" for r in radii)

    return " / ".join(of(kind) for kind in PAPER_KINDS)


def latest_screening_per_slot(seed: int, learner: str = LEARNER) -> str:
    """Placed / episodes per goal slot, per task, on the screening of the seed's latest snapshot: "0/12, 9/9, 9/9 /
    ..." with its env steps ("-" before the first). A slot the policy has not learnt fails in all its episodes."""
    screened = seed_screening(seed, learner)
    if not screened:
        return "-"
    step = max(screened)
    tasks = json.loads(seed_validation_json(seed, step, learner=learner).read_text())["tasks"]
    return (" / ".join(placed_per_slot(env_id, r["episode_results"]) for env_id, r in tasks.items())
            + f" (at {step:,})")


def seeds_report(results: Path = Path("docs/RESULTS.md"), log_dir: Path = CAMPAIGN_DIR) -> str:
    """The section `from-scratch-seeds` of docs/RESULTS.md: where the recipe's run from nothing stands on each seed
    with each learner (its progress.csv in `log_dir`/<run_name>/), a row each, and their curves side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = [f"Command: `{COMMAND} --report` (from campaign/<run>/progress.csv; the recipe: experiments/sac_recipe.py's "
             "`sac_args` with SAC, `scratch_args` in experiments/from_scratch.py with PPO, each unchanged from step 0). "
             "Demonstrations: none.", "", *seed_evaluations_table(), "",
             f"![the recipe from nothing, per seed]({Path(*SEEDS_CURVE.parts[1:])})", "",
             f"*Made by `{COMMAND} --report`: each seed's training episodes placed from ordinary resets per task (solid), "
             f"with PPO its reach-start radius per task, the mean of its goal slots' (dotted, x 100: how far out the "
             f"reach and grasp are trained from; SAC has no reach starts), each snapshot placed on {VALIDATION_EPISODES} "
             "validation episodes per task (dots) and the snapshot the rule chose (dashed).*", "",
             "<details><summary>Where each run stands, and the snapshot rule's choices</summary>", "",
             "| learner | seed | env steps done / budget | training wall time | near-goal start radius now: ceiling / window / "
             "flooring | reach-start radius now, per goal slot: ceiling / window / flooring | training episodes of the "
             "last 200,000 steps placed, ordinary resets: ceiling / window / flooring % | placed, near-goal starts % | "
             "the latest snapshot's screening, placed per goal slot: ceiling / window / flooring |",
             "|---|---|---|---|---|---|---|---|---|"]
    fig, axes = plt.subplots(len(LEARNERS), len(SEEDS), figsize=(10, 3.4 * len(LEARNERS) + 1.2), sharey=True,
                             squeeze=False)
    for (i, learner), (j, seed) in ((a, b) for a in enumerate(LEARNERS) for b in enumerate(SEEDS)):
        ax, run = axes[i][j], seed_run(seed, learner=learner)
        progress = log_dir / run.args.exp_name / "progress.csv"
        ax.set_title(f"{learner.upper()}, seed {seed}")
        ax.set_xlabel("env steps (millions)")
        ax.set_xlim(0, run.args.total_timesteps / 1e6)  # the same scale per learner: where each seed stands
        if not progress.is_file():
            lines.append(f"| {learner.upper()} | {seed} | not started: `{run.command}` | | | | | | |")
            continue
        rows, cells = standing(run, progress)
        lines.append(f"| {learner.upper()} | {seed} | " + " | ".join([*cells[:3], reach_radii_now(rows), *cells[3:],
                                                                      latest_screening_per_slot(seed, learner)]) + " |")
        steps = csv_column(rows, "global_step") / 1e6
        for kind, color in zip(PAPER_KINDS, ("tab:blue", "tab:orange", "tab:green")):
            ax.plot(steps, 100 * moving_mean(csv_column(rows, f"ordinary_place_{kind}"), WINDOW), color=color,
                    label=f"placed, ordinary resets: {kind}")
            ax.plot(steps, 100 * reach_radius(rows, kind), color=color, lw=0.8, ls=":",
                    label=f"reach-start radius x 100: {kind}")
        screened = seed_screening(seed, learner)
        for k, (kind, color) in enumerate(zip(PAPER_KINDS, ("tab:blue", "tab:orange", "tab:green"))):
            ax.scatter([s / 1e6 for s in screened], [100 * v[list(PAPER_TABLE_II)[k]] for v in screened.values()], s=9,
                       color=color, marker="o", label=f"snapshot placed on validation: {kind}")
        if (chosen := chosen_step(seed, learner)) is not None:
            ax.axvline(chosen / 1e6, color="black", lw=0.8, ls="--", label="the snapshot rule's choice")
    for row in axes:
        row[0].set_ylabel(f"% (training episodes: mean of {WINDOW} rows)")
        row[0].set_ylim(0, 102)
    handles = [h for row in axes for ax in row for h in [ax.get_legend_handles_labels()] if h[0]]
    if handles:
        fig.legend(*max(handles, key=lambda h: len(h[0])), loc="lower center", ncol=4, fontsize=7)
    fig.suptitle("The recipe from nothing, per learner and seed (cp4)")
    fig.tight_layout(rect=(0, 1.0 / (3.4 * len(LEARNERS) + 1.2), 1, 1))
    SEEDS_CURVE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(SEEDS_CURVE, dpi=100)
    plt.close(fig)
    lines += ["", *rule_table(), "", "</details>"]
    body = "\n".join(lines)
    update_section(results, "from-scratch-seeds", body, "Results")
    return body

SNAPSHOT_EVERY = 250_000
"""env steps between the run's snapshots. The policy's deterministic success swings from one checkpoint to the next
(window placements 22% and 8% on the same 50 test seeds at 6,782,000 and 7,168,000 env steps, ceiling panels 2% and
18%: docs/experiments/from_scratch.md), so the run keeps snapshots and ships the one that validates best."""
SNAPSHOT_DIR = Path("runs/recipe_snapshots")
"""a seed's snapshots go to <SNAPSHOT_DIR>/<run_name>/ (checkpoint_<env steps>.pt): not committed; the snapshot rule's
candidates among them are (`seed_candidates`)."""
VALIDATION_EPISODES = 30
"""episodes per task (validation seeds, VALIDATION_SEED on: never the test seeds) that screen each snapshot."""
CONFIRM_TOP = 3
"""the candidates best on the screening that are validated again on CONFIRM_EPISODES fresh episodes, which choose
among them: 30 episodes chose the snapshot at 9,250,000 env steps for its 70% of ceiling panels, and it placed about
half that on the test seeds (a winner on few episodes is most often a lucky one)."""
CONFIRM_EPISODES = 100
"""episodes per task (CONFIRMATION_SEED on: neither the screening's nor the test seeds) that choose the snapshot."""
TIEBREAK_EPISODES = 300
"""episodes per task (TIEBREAK_SEED on: none of the others) that validate again the candidates tied on the
confirmation, which then choose among them on all CONFIRM_EPISODES + TIEBREAK_EPISODES: SAC's candidates all placed
every one of the 100 per task on both seeds, and the tie went to the earliest, whatever it placed on the test seeds."""


def break_tie(confirmed: dict, candidate: Callable[[object], Path], out: Callable[[object], Path]) -> tuple[object, dict]:
    """The best of `confirmed` (key -> placed per task on the confirmation; `refine.best_snapshot`), where several
    are tied at its top those only validated again on TIEBREAK_EPISODES per task from TIEBREAK_SEED (`candidate(key)`:
    the policy, `out(key)`: its JSON) and ranked on the confirmation's and these episodes pooled, a tie still going
    to the first in `confirmed`'s order. (the best key, the tied keys' pooled placed per task)."""
    top = placed_score(confirmed[best_snapshot(confirmed)])
    tied = [key for key in confirmed if placed_score(confirmed[key]) == top]
    if len(tied) < 2:
        return tied[0], {}
    pooled = {}
    for key in tied:
        more = validate(candidate(key), out(key), TIEBREAK_EPISODES, seed=TIEBREAK_SEED)
        pooled[key] = {env: (CONFIRM_EPISODES * confirmed[key][env] + TIEBREAK_EPISODES * more[env])
                       / (CONFIRM_EPISODES + TIEBREAK_EPISODES) for env in confirmed[key]}
    return best_snapshot(pooled), pooled


def seed_tiebreak_json(seed: int, step: int, learner: str = LEARNER) -> Path:
    """A seed's candidate validated on TIEBREAK_EPISODES per task from TIEBREAK_SEED (committed, as the others)."""
    return (SEED_EVAL_DIR / "validation"
            / f"{run_name(seed, learner)}_val{TIEBREAK_EPISODES}_{step}_tiebreak.json")


def train(run: Run, snapshots: Path, every: int = SNAPSHOT_EVERY,
          after_snapshot: Optional[Callable[[int, Path], None]] = None, stop: Optional[Callable[[], bool]] = None) -> None:
    """Run (or resume) `run` to its budget in parts of `every` env steps, each part's checkpoint copied to `snapshots`
    and given to `after_snapshot(env steps, path)` (a seed's run: `snapshot_made`); with `stop`, the run ends after
    the first part at whose end `stop()` is true (a run resumed inside a part finishes the part first). Ctrl-C stops
    it with the checkpoint saved (ppo.py)."""
    ckpt = checkpoint_of(run)
    snapshots.mkdir(parents=True, exist_ok=True)
    while (done := load_checkpoint(ckpt)["progress"]["global_step"] if ckpt.is_file() else 0) < run.args.total_timesteps:
        if done and done % every == 0 and stop is not None and stop():
            return
        part = run.args.replace(total_timesteps=min((done // every + 1) * every, run.args.total_timesteps))
        ppo.main(part.replace(resume=str(ckpt), extend=True) if ckpt.is_file() else part)
        shutil.copyfile(ckpt, snapshots / f"checkpoint_{part.total_timesteps}.pt")
        if after_snapshot is not None:
            after_snapshot(part.total_timesteps, snapshots / f"checkpoint_{part.total_timesteps}.pt")


def seed_validation_json(seed: int, step: int, confirm: bool = False, learner: str = LEARNER) -> Path:
    """A seed's snapshot validated: on VALIDATION_EPISODES per task from VALIDATION_SEED (the screening), or on
    CONFIRM_EPISODES from CONFIRMATION_SEED (`confirm`). Committed: they are the rule's record on any machine."""
    n = CONFIRM_EPISODES if confirm else VALIDATION_EPISODES
    return (SEED_EVAL_DIR / "validation"
            / f"{run_name(seed, learner)}_val{n}_{step}{'_confirm' if confirm else ''}.json")


def seed_candidates(seed: int, learner: str = LEARNER) -> Path:
    """The committed policies of a seed's CONFIRM_TOP best-screened snapshots (candidate_<env steps>.pt): the rule
    chooses among them at the end of the run, on a fresh machine too, where runs/ is gone."""
    return CAMPAIGN_DIR / run_name(seed, learner) / "candidates"


def seed_screening(seed: int, learner: str = LEARNER) -> dict[int, dict]:
    """env steps -> placed per task on the screening, for each of the seed's snapshots screened so far."""
    found = {}
    folder = seed_validation_json(seed, 0, learner=learner).parent
    for path in folder.glob(f"{run_name(seed, learner)}_val{VALIDATION_EPISODES}_*.json"):
        if not path.stem.endswith("_confirm"):
            found[int(path.stem.rsplit("_", 1)[1])] = {k: v["place_success"]
                                                       for k, v in json.loads(path.read_text())["tasks"].items()}
    return dict(sorted(found.items()))


EVALUATE_AT = (3_000_000,)
"""env steps at which a seed's snapshot is also evaluated with the paper's protocol as it is made: where other
experiments compare with the recipe's run (the curriculum question's BUDGET), on any machine."""


def snapshot_made(seed: int, step: int, snapshot: Path, learner: str = LEARNER) -> None:
    """What a seed's run does with each snapshot as it makes it: screen it (`screen_snapshot`), and at EVALUATE_AT
    evaluate it with the paper's protocol (`evaluate_seed`)."""
    screen_snapshot(seed, step, snapshot, learner)
    if step in EVALUATE_AT:
        evaluate_seed(seed, step, learner=learner)


def keep_snapshot(seed: int, learner: str, step: int, ckpt: Path) -> None:
    """A SAC run's part has ended at `step` (sac_recipe.run_sac's `after_part`): its checkpoint copied to the seed's
    snapshots (PPO's `train` copies its own) and given to `snapshot_made`."""
    snapshot = seed_snapshots(seed, learner) / f"checkpoint_{step}.pt"
    snapshot.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ckpt, snapshot)
    snapshot_made(seed, step, snapshot, learner)


def screen_snapshot(seed: int, step: int, snapshot: Path, learner: str = LEARNER) -> dict:
    """The snapshot rule's first half, run on each snapshot as the run makes it: validate it (the policy's mean,
    VALIDATION_EPISODES per task from VALIDATION_SEED, never the test seeds), and keep its policy among the seed's
    committed candidates while it ranks among the CONFIRM_TOP best (`refine.ranked_snapshots`: most placed on the
    worst task, then on average); a candidate that drops out is deleted. Its placed per task."""
    out = seed_validation_json(seed, step, learner=learner)
    out.parent.mkdir(parents=True, exist_ok=True)
    placed = validate(snapshot, out, VALIDATION_EPISODES)
    top = set(ranked_snapshots(seed_screening(seed, learner))[:CONFIRM_TOP])
    folder = seed_candidates(seed, learner)
    folder.mkdir(parents=True, exist_ok=True)
    if step in top and not (folder / f"candidate_{step}.pt").is_file():
        torch.save(policy_only(load_checkpoint(snapshot)), folder / f"candidate_{step}.pt")
    for path in folder.glob("candidate_*.pt"):
        if int(path.stem.split("_")[1]) not in top:
            path.unlink()
    return placed


RULE = (f"screened on {VALIDATION_EPISODES} episodes per task (seeds {VALIDATION_SEED:,} on) as made; the {CONFIRM_TOP} "
        f"best confirmed on {CONFIRM_EPISODES} (seeds {CONFIRMATION_SEED:,} on); most placed on the worst task, then on "
        f"average; candidates tied there validated again on {TIEBREAK_EPISODES} (seeds {TIEBREAK_SEED:,} on) and "
        f"ranked on all {CONFIRM_EPISODES + TIEBREAK_EPISODES}")
"""the snapshot rule in a line, as each seed's chosen.json records it."""


def choose_snapshot(seed: int, learner: str = LEARNER) -> int:
    """The snapshot rule's second half, at the end of the seed's run: screen any snapshot on this machine not
    screened yet (a run from before the rule), validate the CONFIRM_TOP candidates again on CONFIRM_EPISODES fresh
    episodes per task from CONFIRMATION_SEED, and choose the one that places most there on its worst task, then
    on average; candidates tied there are validated again and ranked on all their episodes (`break_tie`), a tie
    still going to the better screened, then the earliest; written to the seed's chosen.json. Its env steps."""
    for path in sorted(seed_snapshots(seed, learner).glob("checkpoint_*.pt"), key=lambda p: int(p.stem.split("_")[1])):
        if int(path.stem.split("_")[1]) not in seed_screening(seed, learner):
            screen_snapshot(seed, int(path.stem.split("_")[1]), path, learner)
    top = ranked_snapshots(seed_screening(seed, learner))[:CONFIRM_TOP]
    if not top:
        raise SystemExit(f"seed {seed} has no screened snapshots: `{seed_run(seed, learner=learner).command}` "
                         "screens each as it is made")
    confirmed = {step: validate(seed_candidates(seed, learner) / f"candidate_{step}.pt",
                                seed_validation_json(seed, step, confirm=True, learner=learner), CONFIRM_EPISODES,
                                seed=CONFIRMATION_SEED)
                 for step in top}
    best, pooled = break_tie(confirmed, lambda step: seed_candidates(seed, learner) / f"candidate_{step}.pt",
                             lambda step: seed_tiebreak_json(seed, step, learner))
    chosen_json(seed, learner).write_text(json.dumps(dict(
        step=best, screened=len(seed_screening(seed, learner)),
        confirmed={str(k): confirmed[k] for k in sorted(confirmed)},
        **({"tie broken": {str(k): pooled[k] for k in sorted(pooled)}} if pooled else {}),
        rule=RULE), indent=1))
    return best


def chosen_json(seed: int, learner: str = LEARNER) -> Path:
    return SEED_EVAL_DIR / "validation" / f"{run_name(seed, learner)}_chosen.json"


def chosen_step(seed: int, learner: str = LEARNER) -> Optional[int]:
    """The env steps of the seed's snapshot the rule chose, or None before its run has ended."""
    return json.loads(chosen_json(seed, learner).read_text())["step"] if chosen_json(seed, learner).is_file() else None


def shown_evaluation(seed: int, learner: str = LEARNER) -> Optional[tuple[int, Path, bool]]:
    """The seed's evaluation a reader is shown: (env steps, its JSON, whether the rule chose it) of the snapshot the
    rule chose, or, before it has, of the latest evaluated; None where none is evaluated."""
    evaluated = seed_evaluations(seed, learner)
    if not evaluated:
        return None
    chosen = chosen_step(seed, learner)
    step = chosen if chosen in evaluated else max(evaluated)
    return step, evaluated[step], step == chosen


def recipe_commit(learner: str = LEARNER) -> str:
    """The last commit that changed the recipe with `learner` (PPO: `scratch_args`; SAC: experiments/sac_recipe.py or
    baselines/sac/sac.py, whose Args defaults it takes): the seeds' runs name it in their record."""
    import subprocess

    where = (["-L", "/^def scratch_args/,/^    return args/:" + __file__] if learner == "ppo"
             else ["--", sac_recipe.__file__, sac.__file__])
    log = subprocess.run(["git", "log", "--format=%h", *where], capture_output=True, text=True).stdout
    return next((line for line in log.splitlines() if line and all(c in "0123456789abcdef" for c in line)), "unknown")


def ship_seeds(shipped: Path = SHIPPED, learner: str = LEARNER) -> Optional[Path]:
    """Ship the better seed's chosen snapshot of the recipe with `learner` as the general agent learnt from reward
    alone, once every seed of SEEDS has run to its end (its snapshot chosen and evaluated with the paper's protocol). The better seed is the
    one whose choice confirmed best on the validation seeds (most placed on its worst task, then on average; seeds
    tied there validated again as a seed's tied candidates are, `break_tie`); it ships only if it places at least what
    the policy shipped now does on every task on the test seeds (EVAL_JSON), and its evaluation then becomes
    EVAL_JSON. The path shipped, or None."""
    waiting = [seed for seed in SEEDS if chosen_step(seed, learner) is None
               or not seed_evaluation_json(seed, chosen_step(seed, learner), learner).is_file()]
    if waiting:
        raise SystemExit("not every seed has run to its end: "
                         + ", ".join(f"`{seed_run(s, learner=learner).command}`" for s in waiting))
    confirmed = {seed: json.loads(chosen_json(seed, learner).read_text())["confirmed"][str(chosen_step(seed, learner))]
                 for seed in SEEDS}
    seed, pooled = break_tie(confirmed, lambda s: seed_candidates(s, learner) / f"candidate_{chosen_step(s, learner)}.pt",
                        lambda s: seed_tiebreak_json(s, chosen_step(s, learner), learner))
    step = chosen_step(seed, learner)
    tested = json.loads(seed_evaluation_json(seed, step, learner).read_text())["tasks"]
    now = json.loads(EVAL_JSON.read_text())["tasks"] if EVAL_JSON.is_file() else {}
    short = [env for env, r in now.items() if tested[env]["place_success"] < r["place_success"]]
    if short:
        print(f"seed {seed}'s snapshot at {step:,} env steps places less than the policy shipped now on the test seeds "
              "(" + ", ".join(f"{env} {tested[env]['place_success']:.3f} < {now[env]['place_success']:.3f}" for env in short)
              + f"): {shipped} stays")
        return None
    run = dataclasses.replace(seed_run(seed, learner=learner), shipped=shipped)
    recipe = ("sac_args of experiments/sac_recipe.py" if learner == "sac" else "scratch_args of experiments/from_scratch.py")
    tie = (f"; tied, then on all {CONFIRM_EPISODES + TIEBREAK_EPISODES}: "
           + ", ".join(f"seed {s} {min(c.values()):.3f}" for s, c in pooled.items())
           + (", a tie to the first" if len({placed_score(c) for c in pooled.values()}) == 1 else "")) if pooled else ""
    chosen = (f"seed {seed} of {len(SEEDS)} (the better on validation: placed on its worst task "
              + ", ".join(f"seed {s} {min(c.values()):.2f}" for s, c in confirmed.items())
              + f" of {CONFIRM_EPISODES}{tie}), its snapshot at {step:,} env steps chosen by the snapshot rule; the "
              f"recipe: {learner.upper()}, "
              f"{recipe} at commit {recipe_commit(learner)}, unchanged from step 0; demonstrations: none")
    out = ship(run, snapshot=seed_candidates(seed, learner) / f"candidate_{step}.pt", chosen=chosen)
    # the shipped policy is the snapshot's, weight for weight: its evaluation is the snapshot's, written down as the
    # command that repeats it on the shipped file
    evaluated_as = seed_evaluation_json(seed, step, learner)
    data = json.loads(evaluated_as.read_text())
    data.update(command=evaluation.command_of(evaluation.Args(checkpoint=out, all=True, steps=EVAL_STEPS, json=EVAL_JSON)),
                checkpoint=str(out), evaluated_as=dict(checkpoint=data["checkpoint"], json=str(evaluated_as)))
    EVAL_JSON.write_text(json.dumps(data, indent=1) + "\n")
    return out


@dataclass
class Args:
    seed: Optional[int] = None
    """run (or resume) the recipe from nothing on this seed (campaign/<run_name>/: sac_s<seed> with SAC, scratch_s<seed>
    with PPO)."""
    learner: str = LEARNER
    """the recipe's learner (LEARNERS): `sac` (the recipe's, to experiments/sac_recipe.py's BUDGET) or `ppo` (to
    BUDGET); with --seed, --ship-seeds and --evaluate."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a run resumed from a checkpoint keeps its own."""
    dry_run: bool = False
    """with --seed: print the plan and where the run stands, and exit."""
    evaluate: bool = False
    """with --seed: evaluate the seed's snapshot with the paper's protocol (`evaluate_seed`) and exit; a run that
    reaches its budget does this itself on the snapshot its rule chose."""
    at_step: Optional[int] = None
    """with --evaluate: the snapshot at this many env steps (default: the latest)."""
    ship_seeds: bool = False
    """ship the better seed's chosen snapshot (`ship_seeds`) once every seed has run to its end, and exit."""
    report: bool = False
    """write the seeds' section of docs/RESULTS.md with their curves (docs/images/scratch_seeds_curve.png) and the
    shipped agent's section, and exit."""


def main(args: Args) -> None:
    if args.seed is not None:
        seed, learner = args.seed, args.learner
        run = seed_run(seed, args.num_envs, learner)
        print(describe(run))
        if learner == "ppo":
            print("as one ppo.py command: python baselines/ppo/ppo.py " + shlex.join(command_line(run.args)))
        if args.evaluate:
            print(f"wrote {evaluate_seed(seed, args.at_step, learner=learner)}")
        elif not args.dry_run:
            if learner == "sac":
                sac_recipe.run_sac(run.args, every=SNAPSHOT_EVERY, after_part=partial(keep_snapshot, seed, learner))
            else:
                train(run, snapshots=seed_snapshots(seed, learner),
                      after_snapshot=partial(snapshot_made, seed, learner=learner))
            # the paper's protocol on the rule's choice
            print(f"wrote {evaluate_seed(seed, choose_snapshot(seed, learner), learner=learner)}")
    elif args.ship_seeds:
        ship_seeds(learner=args.learner)
    elif args.report:
        print(seeds_report())
        print(shipped_report())
    else:
        raise SystemExit("give --seed S to run (or resume) the recipe from nothing on seed S, or --report, or "
                         "--ship-seeds")


if __name__ == "__main__":
    main(tyro.cli(Args))
