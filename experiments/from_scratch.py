"""The general agent learnt from reward alone: no demonstrations, no expert states, no cloned weights.

    python -m experiments.from_scratch --dry-run        # the plan, and where each run stands
    python -m experiments.from_scratch                  # run (or resume) it, a snapshot every 250,000 env steps;
                                                        # at its budget, ships the best snapshot (--ship-best)
    python -m experiments.from_scratch --ship-now       # ship the policy where the run stands now
    python -m experiments.from_scratch --ship-best      # ship the snapshot that places most on validation seeds
    python -m experiments.from_scratch --report         # its section of docs/RESULTS.md and its curve
    python -m experiments.from_scratch --diagnose       # its policy from near-goal starts, into the experiment page

One PPO run (baselines/ppo/ppo.py) on ConstructionPickPlace-v1, resumed from its checkpoint in campaign/ when it
has one (commit the checkpoint and progress.csv between sessions), shipped to
assets/checkpoints/scratch_general_agent.pt with its campaign record. The recipe, and what each part is for:

| setting | value | why |
|---|---|---|
| reward | normalized_dense: the tasks' dense reward / 10 (placing pays 10, a held step at most 4.5) | its carry term is linear in the arm's joint-space distance from the installation configuration (IK of the goal, ms_construction/goal_configurations.py), so it pulls from the pick, the way the turret's limits allow; its progress term pays each step's fall of that distance at once (probe G) |
| reward options | the carry measured along the start paths (`carry_along_paths`), the reach toward the element half in joint space (`reach_in_joint_space`), since 17,250,000 steps toward the turret side the goal slot's start paths leave from (`reach_toward_path_sides`); since 18,742,000 steps the carry measured only along the grasp side's paths, each radian off a planned via's path from its lift in counting 25 times (`carry_keeps_to_vias`) | the fourth start's policy carried elements straight into the slab, the wall and the barriers beside the staging table and stopped there, and turned the turret the wrong way to its limit on the way to the table (its `--diagnose`); probe N (both) placed the most of the continuations from its 1,682,000-step checkpoint. The window opening at y = +0.85 is reached along its paths only from the turret's +pi side, and every policy grasped windows from -pi: it placed 0-2 of its 17 test episodes in every evaluation. Once it had a way in from -pi (a planned via), the measure still paid for cutting across that detour into the neighbouring opening, where the policy carried those windows (`python -m experiments.via_landscape`) |
| success | absorbing: bootstrapped with its reward for ever | the critic never trains on a state after success; its guess let hovering near the goal outvalue placing |
| start states | 80% of the training episodes (20% from 17,250,000 to 17,540,000 steps) start held on a collision-free joint path out of the goal (`set_near_goal_starts`; IK, and since 17,540,000 steps one planned via for the window opening at y = +0.85 from -pi), each task type's radius widening from 0.1 of the path by 0.1 once 60% of its last 20 such episodes placed; such an episode that has not placed in 80 steps is cut | reverse curriculum generation (Florensa et al. 2017) from resets the env computes by IK: no demonstrations; evaluation always resets as usual. One radius for all three types widened on lucky iterations of the easy type (probe F); with half the episodes and no cut, a failed start wandered for 250 steps and an update held a handful of near-goal episodes (probes I-L) |
| observation | the tasks' state + the joint move to the installation configuration (`obs_install_offset`); since 18,062,000 steps + the joint move a little ahead along the start path (`obs_path_offset`) | what the carry term measures, from IK of the goal pose: following it places from near-goal starts (a test); without it the policy must learn IK of nine goal slots itself |
| policy | Gaussian, its mean bounded by tanh (`bounded_mean`); since 18,742,000 steps a window for the opening at y = +0.85 met as the mirror image of one for -0.85 (`mirror_windows`), that opening's installation cut to the wrist branch that mirrors -0.85's but for joint 6 (`install_mirror_branch`), and seen as -0.85's until the grasp (`mirror_canonical_reach`) and, held, turned half a turn about the plate's axis (`mirror_held_half_turn`) | an unbounded mean drifted past the action bounds, where every draw clips alike and PPO cannot move it back (the third start's `--diagnose`). The opening at y = +0.85 is reached from +pi only, the one at -0.85 from -pi only, where the policy turns every reach; in the mirror the window's head stays up, so the carry must turn it half a turn more, which the held view shows at the grasp, above the table, instead of at the opening (probes AJ-AM, docs/experiments/from_scratch.md) |
| discount | gamma 0.95, GAE lambda 0.95 | values of a few dozen steps: the dense reward carries the rest, and the critic learns them quickly |
| updates | 2,000 samples (2 envs x 1,000 steps), 8 epochs of 8 minibatches, KL stop 0.1 | more gradient steps per env step: env steps are the cost on a CPU |
| curiosity | none | the dense reward explores |
| curriculum | cp4 from the first step | the target is judged at cp4 |
| task sampling | since 17,676,000 steps windows twice as often as either other task (`task_weights` 1 2 1); since 18,742,000 steps the window opening at y = +0.85 three times as often as either other opening (`goal_slot_weights`) | windows are the task below the paper's rate, and that opening holds them back |
"""

from __future__ import annotations

import csv
import json
import math
import os
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

from baselines.ppo import ppo
from baselines.ppo.args import command_line
from baselines.ppo.checkpoints import load_checkpoint
from baselines.ppo.evaluation import PAPER_TABLE_II, failures, kinds, pct
from experiments.campaign import CAMPAIGN_DIR, SHIPPED_DIR, Run, checkpoint_of, describe, ship, training_wall_s
from experiments.expert_modes import placed_per_slot
from experiments.refine import (CONFIRMATION_SEED, VALIDATION_SEED, best_snapshot, content_tag, ranked_snapshots,
                               validate)
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.reporting import update_section
from ms_construction.curriculum import FINAL_STAGE

BUDGET = 20_000_000
"""env steps at most (the issue's budget on this CPU)."""
COMMAND = "python -m experiments.from_scratch"
PAGE = Path("docs/experiments/from_scratch.md")
"""the experiment page: the diagnosis and the snapshots' validations are written into it."""
STARTS = {1_682_000: "fifth start: carry along the start paths, reach in joint space",
          10_010_000: "observation mended: each reset sets the nominal hold (a8d32d8)",
          17_250_000: "sixth start: reach toward the path sides, a fifth of the episodes from near-goal starts (probe U)",
          17_540_000: "seventh start: the window opening at y = +0.85 reached from -pi along a planned via, 80% near-goal "
                      "starts again (probe W)",
          17_676_000: "windows sampled twice as often (probe X)",
          18_062_000: "path offset in the observation (probe Y)",
          18_742_000: "carry kept to the planned via's path, its window opening drawn three times as often and met as "
                      "the mirror image of the one at -0.85, held half a turn about the plate's axis (probe AM)"}
"""env step: the change the campaign went on with there, of the recipe or of the tasks (the fourth start's steps before
the first; the experiment page says how each came to be)."""


RECIPE_BEFORE = {1_682_000: dict(carry_along_paths=False, reach_in_joint_space=False),
                 17_250_000: dict(reach_toward_path_sides=False, near_goal_share=0.8),
                 17_540_000: dict(near_goal_share=0.2),
                 17_676_000: dict(task_weights=None),
                 18_062_000: dict(obs_path_offset=False),
                 18_742_000: dict(carry_keeps_to_vias=False, goal_slot_weights=None, mirror_windows=False,
                                  install_mirror_branch=False, mirror_canonical_reach=False,
                                  mirror_held_half_turn=False)}
"""env step of STARTS: the recipe's settings as they were before the change the campaign went on with there (the
fourth start's recipe before the first)."""


def recipe_before(step: int) -> dict:
    """The settings that turn the recipe now into the one the campaign ran just before env step `step` (what a probe
    from a checkpoint at `step` went on from): every change at `step` or later undone, the earliest last."""
    undo = {}
    for at in sorted(RECIPE_BEFORE, reverse=True):
        if at >= step:
            undo.update(RECIPE_BEFORE[at])
    return undo


def scratch_args(num_envs: Optional[int] = None, **overrides) -> ppo.Args:
    """ppo.Args of the from-scratch recipe (see the module docstring); `overrides` replace any field afterwards."""
    num_envs = num_envs or os.cpu_count() or 1
    args = ppo.Args.of(
        env_id="ConstructionPickPlace-v1", reward_mode="normalized_dense", control_mode="pd_joint_delta_pos",
        sim_backend="physx_cpu", cuda=False, curriculum=(FINAL_STAGE,), total_timesteps=BUDGET, curiosity="none",
        success_value="absorbing", bootstrap_at_done="always", gamma=0.95, gae_lambda=0.95,
        num_envs=num_envs, num_steps=2000 // num_envs, update_epochs=8, num_minibatches=8, target_kl=0.1,
        near_goal_share=0.8, near_goal_radius=0.1, near_goal_step=0.1, near_goal_promote=0.6, near_goal_window=20,
        near_goal_max_steps=80, obs_install_offset=True, obs_path_offset=True, bounded_mean=True, carry_along_paths=True, reach_in_joint_space=True,
        reach_toward_path_sides=True, task_weights=(1.0, 2.0, 1.0),
        carry_keeps_to_vias=True, goal_slot_weights=(1.0, 1.0, 1.0, 1.0, 1.0, 3.0, 1.0, 1.0, 1.0),
        mirror_windows=True, install_mirror_branch=True, mirror_canonical_reach=True, mirror_held_half_turn=True,
        eval_freq=25, checkpoint_freq=10, log_dir=str(CAMPAIGN_DIR),
    )
    return args.replace(**overrides)


def scratch_runs(num_envs: Optional[int] = None, seed: int = 1) -> list[Run]:
    return [Run("scratch_general_agent", scratch_args(num_envs, seed=seed, exp_name="scratch_general_agent"),
                "the general agent from reward alone: no demonstrations", COMMAND,
                SHIPPED_DIR / "scratch_general_agent.pt",
                method="PPO from scratch on the dense reward with near-goal start states (experiments/from_scratch.py); "
                       "demonstrations: none")]


EVAL_JSON = Path("docs/data/paper/scratch_general_agent_eval_50k.json")
"""the shipped agent's evaluation with the paper's protocol (the command `report` prints writes it)."""
CURVE = Path("docs/images/scratch_curve.png")
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


def draw_curve(rows: list[dict], out: Path) -> None:
    """Place success of the training episodes from ordinary resets per task, and of the near-goal starts, against
    env steps (moving averages over WINDOW iterations; the policy's sampled actions)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = csv_column(rows, "global_step") / 1e6
    fig, ax = plt.subplots(figsize=(8, 4.2))
    for kind, color in zip(ELEMENT_KINDS, ("tab:blue", "tab:orange", "tab:green")):
        ax.plot(steps, 100 * moving_mean(csv_column(rows, f"ordinary_place_{kind}"), WINDOW), color=color,
                label=f"placed, ordinary resets: {kind}")
    ax.plot(steps, 100 * moving_mean(csv_column(rows, "near_goal_place_success"), WINDOW), color="gray", ls="--",
            label="placed, near-goal starts (all tasks)")
    ax2 = ax.twinx()
    for kind, color in zip(ELEMENT_KINDS, ("tab:blue", "tab:orange", "tab:green")):
        ax2.plot(steps, csv_column(rows, f"near_goal_radius_{kind}"), color=color, lw=0.8, ls=":",
                 label=f"start radius: {kind} (right axis)")
    for step, what in STARTS.items():
        ax.axvline(step / 1e6, color="black", lw=0.8, ls="-.")
        ax.text(step / 1e6, 2, " " + what.split(":")[0], fontsize=7, rotation=90, va="bottom")  # the caption has the rest
    ax2.set_ylim(0, 1.05)
    ax2.set_ylabel("near-goal start radius (fraction of the path)")
    ax.set_xlabel("env steps (millions)")
    ax.set_ylabel(f"training episodes placed, % (mean of {WINDOW} iterations)")
    ax.set_ylim(0, 100)
    ax.set_title("The general agent from reward alone: training curve (cp4)")
    lines = ax.get_legend_handles_labels()
    more = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="upper left", fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def report(run: Run, results: Path = Path("docs/RESULTS.md")) -> str:
    """The section `from-scratch` of docs/RESULTS.md: where the campaign stands, its curve, and (once shipped
    and evaluated) its Table II row beside the paper's with its failures by kind."""
    progress = Path(run.args.log_dir) / run.args.exp_name / "progress.csv"
    with open(progress, newline="") as f:
        rows = list(csv.DictReader(f))
    done = int(rows[-1]["global_step"])
    late = [r for r in rows if int(r["global_step"]) > done - 200_000]
    mean = lambda key: np.nanmean(csv_column(late, key)) if np.isfinite(csv_column(late, key)).any() else math.nan  # noqa: E731
    fmt = lambda x: "-" if math.isnan(x) else f"{100 * x:.1f}"  # noqa: E731
    wall = training_wall_s(progress, run.args.num_envs * run.args.num_steps)
    draw_curve(rows, CURVE)
    lines = [f"Command: `{COMMAND} --report` (from campaign/{run.args.exp_name}/progress.csv; the recipe: "
             "experiments/from_scratch.py). Demonstrations: none.", "",
             "| env steps done / budget | training wall time | start radius now: ceiling / window / flooring | training episodes of the last 200,000 "
             "steps placed, ordinary resets: ceiling / window / flooring % | placed, near-goal starts % | picked % |",
             "|---|---|---|---|---|---|",
             f"| {done:,} / {run.args.total_timesteps:,} | {wall / 3600:.1f} h | "
             + " / ".join(f"{float(rows[-1].get(f'near_goal_radius_{k}') or 0):.1f}" for k in ELEMENT_KINDS) + " | "
             + " / ".join(fmt(mean(f"ordinary_place_{k}")) for k in ELEMENT_KINDS)
             + f" | {fmt(mean('near_goal_place_success'))} | {fmt(mean('pick_success'))} |", "",
             f"![from-scratch curve]({Path(*CURVE.parts[1:])})", "",
             f"*Made by `{COMMAND} --report`: the training episodes' place success per task (ordinary resets) and "
             "from near-goal starts, with the start radius; "
             + "; ".join(f"from {step:,} steps the {what}" for step, what in STARTS.items())
             + " ([the experiment](experiments/from_scratch.md)).*", ""]
    if EVAL_JSON.is_file():
        data = json.loads(EVAL_JSON.read_text())
        shipped = load_checkpoint(run.shipped)["campaign"]["record"] if run.shipped.is_file() else {}
        lines += [f"The shipped policy ({run.shipped}; {shipped.get('method', '?')}; env steps: {shipped.get('env steps', '?')}"
                  + (f"; {shipped['chosen']}" if shipped.get("chosen") else "")
                  + f"), evaluated with the paper's protocol: `{data['command']}`.", "",
                  "| task | pick % [95% CI] | place % [95% CI] | paper's general agent: pick / place % | placed per goal slot "
                  "(0, 1, 2) | failures by kind |",
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
    else:
        lines.append(f"Not shipped yet: `{COMMAND} --ship-now` ships the policy where the run stands, then "
                     f"`python scripts/evaluate.py --checkpoint {run.shipped} --all --steps 50000 --json {EVAL_JSON}`.")
    body = "\n".join(lines)
    update_section(results, "from-scratch", body, "Results")
    return body


DIAGNOSE_RADIUS = 0.2
DIAGNOSE_SEEDS = 6
DIAGNOSE_STEPS = 120


def near_goal_rollouts(checkpoint: Path, radius: float = DIAGNOSE_RADIUS, seeds: int = DIAGNOSE_SEEDS,
                       steps: int = DIAGNOSE_STEPS) -> str:
    """Where the policy takes an element it starts holding near its goal: per task and seed (near-goal starts at
    `radius`, the policy's mean, at most `steps` steps), whether it placed, the element's distance and angle to
    the goal and the arm's carry distance at the start and the end, how far the element trailed its place on the plate
    (`hold_lag`, the median over the steps and at the end), the joints at the end, and how often the policy's mean lay
    past the action bounds (where every draw clips alike: PPO cannot move such a mean back)."""
    import gymnasium as gym
    import torch

    import ms_construction  # noqa: F401  (registration)
    from baselines.ppo.checkpoints import load_policy
    from ms_construction.envs import TASK_ENV_IDS

    agent, kwargs = load_policy(checkpoint, "ConstructionPickPlace-v1")
    kwargs = {k: v for k, v in kwargs.items() if k not in ("obs_mode", "reward_mode")}
    lines = ["| task | seed | steps | placed | distance to goal, start / end (m) | angle, start / end (deg) | "
             "carry distance, start / end (rad) | element behind the plate, median / end (m) | joints at the end (rad) | "
             "mean past the bounds (share; largest) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for env_id in TASK_ENV_IDS.values():
        env = gym.make(env_id, obs_mode="state", reward_mode="normalized_dense", **kwargs)
        u = env.unwrapped
        u.set_near_goal_starts(1.0, radius)
        for seed in range(seeds):
            obs, info = env.reset(seed=seed)
            start = (float(u.evaluate()["place_dist"][0]), float(u.evaluate()["place_angle_deg"][0]), float(u.carry_distance()[0]))
            means, lag = [], []
            for t in range(steps):
                with torch.no_grad():
                    means.append(agent.get_action(obs.float(), deterministic=True))
                obs, _, terminated, truncated, info = env.step(means[-1].clamp(-1, 1))
                lag.append(float(u.hold_lag()[0]))
                if bool(terminated[0]) or bool(truncated[0]):
                    break
            mean = torch.cat(means).abs()
            q = " ".join(f"{v:.2f}" for v in u.agent.robot.get_qpos()[0].tolist())
            lines.append(f"| {env_id} | {seed} | {t + 1} | {'yes' if bool(info['success'][0]) else 'no'} | "
                         f"{start[0]:.2f} / {float(info['place_dist'][0]):.2f} | {start[1]:.0f} / {float(info['place_angle_deg'][0]):.0f} | "
                         f"{start[2]:.2f} / {float(u.carry_distance()[0]):.2f} | {sorted(lag)[len(lag) // 2]:.2f} / {lag[-1]:.2f} | {q} | "
                         f"{float((mean > 1).float().mean()):.2f}; {float(mean.max()):.2f} |")
        env.close()
    return "\n".join(lines)


def _touching(u) -> str:
    """What the element presses against (contacts with an impulse), the plate holding it aside."""
    names = set()
    for contact in u.scene.get_contacts():
        bodies = [b.entity.name.removeprefix("scene-0_") for b in contact.bodies]
        element = [n for n in bodies if n.endswith("_element")]
        if element and sum(float(abs(p.impulse).sum()) for p in contact.points) > 1e-2:
            names |= {n for n in bodies if not n.endswith("_element") and n not in ("flange", "plate")}
    return ", ".join(sorted(names)) or "-"


def ordinary_rollouts(checkpoint: Path, seeds: int = DIAGNOSE_SEEDS) -> str:
    """What the policy does from ordinary resets (the test seeds evaluation starts with, the policy's mean, the task's
    step limit): per task and seed, the goal slot, when it grasped, whether it placed, the carry distance at the grasp, the least
    after it and at the end, the same measured along the start paths (`path_distance`), the element's distance to
    its goal at the end, how far the held element trailed its place on the plate (`hold_lag`: the median over the held
    steps and at the end; jammed against a slab or wall, it stays behind while the arm goes on), what the element
    touched at the end (the plate aside) and whether the arm had stopped (its joints
    moved less than 0.02 rad over the last 20 steps) while the policy's mean still asked for motion."""
    import gymnasium as gym
    import torch

    import ms_construction  # noqa: F401  (registration)
    from baselines.ppo.checkpoints import load_policy
    from baselines.ppo.evaluation import Args as EvalArgs
    from ms_construction.envs import TASK_ENV_IDS
    from ms_construction.rollout import rollout

    agent, kwargs = load_policy(checkpoint, "ConstructionPickPlace-v1")
    kwargs = {k: v for k, v in kwargs.items() if k not in ("obs_mode", "reward_mode")}
    lines = ["| task | seed | goal slot | grasped at step | placed | carry distance at the grasp / least / end (rad) | "
             "along the start paths, at the grasp / end (rad) | element to goal at the end (m) | "
             "element behind the plate, median / end (m) | element touching at the end | arm stopped, still pushing |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for env_id in TASK_ENV_IDS.values():
        env = gym.make(env_id, obs_mode="state", reward_mode="normalized_dense", **kwargs)
        u = env.unwrapped
        for seed in range(EvalArgs.seed, EvalArgs.seed + seeds):
            grasped, carry, path, lag, qs, actions = None, [], [], [], [], []
            for t, step in enumerate(rollout(agent, env, seed)):
                qs.append(u.agent.robot.get_qpos()[0].clone())
                actions.append(step.action[0])
                if bool(step.info["is_grasped"][0]):
                    grasped = t if grasped is None else grasped
                    carry.append(float(u.install_offset().abs().sum()))
                    path.append(float(u.path_distance()[0]))
                    lag.append(float(u.hold_lag()[0]))
                if bool(step.terminated[0]) or bool(step.truncated[0]):
                    break
            moved = float(sum((a - b).abs().sum() for a, b in zip(qs[-20:], qs[-19:])))
            pushing = float(torch.stack(actions[-20:]).abs().mean()) > 0.3
            fmt = lambda xs: f"{xs[0]:.1f} / {min(xs):.1f} / {xs[-1]:.1f}" if xs else "-"  # noqa: E731
            lines.append(f"| {env_id} | {seed} | {int(u.goal_slot[0])} | {'-' if grasped is None else grasped + 1} | "
                         f"{'yes' if bool(step.info['success'][0]) else 'no'} | {fmt(carry)} | "
                         f"{f'{path[0]:.1f} / {path[-1]:.1f}' if path else '-'} | {float(step.info['place_dist'][0]):.2f} | "
                         f"{f'{sorted(lag)[len(lag) // 2]:.2f} / {lag[-1]:.2f}' if lag else '-'} | "
                         f"{_touching(u)} | {'yes' if moved < 0.02 and pushing else 'no'} |")
        env.close()
    return "\n".join(lines)


SNAPSHOT_EVERY = 250_000
"""env steps between the run's snapshots. The policy's deterministic success swings from one checkpoint to the next
(window placements 22% and 8% on the same 50 test seeds at 6,782,000 and 7,168,000 env steps, ceiling panels 2% and
18%: docs/experiments/from_scratch.md), so the run keeps snapshots and ships the one that validates best."""
SNAPSHOT_DIR = Path("runs/scratch_snapshots")
"""where the snapshots are kept (checkpoint_<env steps>.pt, with their validations): not committed, so the candidates
are those of the sessions on this machine, and the shipped policy."""
VALIDATION_EPISODES = 30
"""episodes per task (validation seeds, VALIDATION_SEED on: never the test seeds) that screen each snapshot."""
CONFIRM_TOP = 3
"""the candidates best on the screening that are validated again on CONFIRM_EPISODES fresh episodes, which choose
among them: 30 episodes chose the snapshot at 9,250,000 env steps for its 70% of ceiling panels, and it placed about
half that on the test seeds (a winner on few episodes is most often a lucky one)."""
CONFIRM_EPISODES = 100
"""episodes per task (CONFIRMATION_SEED on: neither the screening's nor the test seeds) that choose the snapshot."""


def train(run: Run, every: int = SNAPSHOT_EVERY, snapshots: Path = SNAPSHOT_DIR, page: Path = PAGE) -> None:
    """Run (or resume) the campaign to its budget in parts of `every` env steps, each part's checkpoint copied to
    `snapshots`, then ship the best snapshot (`ship_best`). Ctrl-C stops it with the checkpoint saved (ppo.py)."""
    ckpt = checkpoint_of(run)
    snapshots.mkdir(parents=True, exist_ok=True)
    while (done := load_checkpoint(ckpt)["progress"]["global_step"] if ckpt.is_file() else 0) < run.args.total_timesteps:
        part = run.args.replace(total_timesteps=min((done // every + 1) * every, run.args.total_timesteps))
        ppo.main(part.replace(resume=str(ckpt), extend=True) if ckpt.is_file() else part)
        shutil.copyfile(ckpt, snapshots / f"checkpoint_{part.total_timesteps}.pt")
    if run.shipped is not None:
        ship_best(run, snapshots=snapshots, page=page)


ADOPT_MAY_DIFFER = ("exp_name", "log_dir", "checkpoint", "resume", "extend", "total_timesteps", "eval_freq",
                    "near_goal_radius")
"""the settings a continuation probe the campaign goes on from may have run with other than the recipe's: where it
logged, what it started or was resumed from, its length and evaluations, and its first start radius (its radii are in
its progress)."""


PROBE_SNAPSHOTS = "snapshots"
"""the folder in a probe's run folder that holds its snapshots (step_<its env steps>.pt: copies of its checkpoint)."""


def adopt(run: Run, probe_dir: Path, snapshots: Path = SNAPSHOT_DIR) -> None:
    """Go on with the campaign from a continuation probe (experiments/probes.py) that ran the recipe, changed as the
    recipe now is, from the campaign's checkpoint (a start of STARTS): the probe's checkpoint (weights, optimizer, start
    radii, random states) becomes the campaign's, with its env steps and iterations counted on from the start's and
    the recipe's args, and its progress.csv rows, so counted, follow the campaign's; its snapshots (PROBE_SNAPSHOTS),
    so counted, join the campaign's in `snapshots`, for `ship_best`. Refuses a probe that ran another recipe than
    `run`'s (beyond ADOPT_MAY_DIFFER) or started elsewhere than the campaign's checkpoint."""
    import torch

    ckpt, csv_path = checkpoint_of(run), checkpoint_of(run).with_name("progress.csv")
    start, probe = load_checkpoint(ckpt), load_checkpoint(probe_dir / "checkpoint.pt", "--adopt")
    resolved = run.args.replace()
    ppo.resolve_defaults(resolved)  # as a run saves its args: defaults that depend on the machine filled in
    recipe, ran = resolved.flat(), ppo.Args.of(**probe["args"]).flat()  # fields newer than the probe: their defaults
    differ = sorted(k for k in recipe if k not in ADOPT_MAY_DIFFER and ran[k] != recipe[k])
    if differ:
        raise SystemExit(f"--adopt {probe_dir}: the probe ran another recipe than the campaign's now ({', '.join(differ)}); "
                         "change the recipe (scratch_args) first")
    began = load_checkpoint(probe["args"]["checkpoint"], "the probe's --checkpoint") if probe["args"].get("checkpoint") else None
    if began is None or not all(torch.equal(v, start["agent"][k]) for k, v in began["agent"].items()):
        raise SystemExit(f"--adopt {probe_dir}: the probe did not start from the campaign's checkpoint ({ckpt})")
    at, iteration = start["progress"]["global_step"], start["progress"]["iteration"]

    def counted_on(ckpt: dict) -> dict:
        return {**ckpt, "args": recipe,
                "progress": {**ckpt["progress"], "global_step": at + ckpt["progress"]["global_step"],
                             "iteration": iteration + ckpt["progress"]["iteration"],
                             "stage_changes": start["progress"]["stage_changes"],
                             "stage_start_step": start["progress"]["stage_start_step"]}}

    probe = counted_on(probe)
    with open(csv_path) as f:
        rows = [r for r in csv.DictReader(f) if int(r["global_step"]) <= at]
    with open(probe_dir / "progress.csv") as f:
        added = list(csv.DictReader(f))
    for r in added:
        r["global_step"], r["iteration"] = str(at + int(r["global_step"])), str(iteration + int(r["iteration"]))
    fields = list(rows[0]) if rows else list(added[0])
    tmp = ckpt.with_name(ckpt.name + ".tmp")
    torch.save(probe, tmp)
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows + added)
    os.replace(tmp, ckpt)
    for path in sorted((probe_dir / PROBE_SNAPSHOTS).glob("step_*.pt")):
        snapshot = counted_on(load_checkpoint(path))
        snapshots.mkdir(parents=True, exist_ok=True)
        torch.save(snapshot, snapshots / f"checkpoint_{snapshot['progress']['global_step']}.pt")
    print(f"the campaign goes on from {probe_dir} at {probe['progress']['global_step']:,} env steps")


def ship_best(run: Run, episodes: int = VALIDATION_EPISODES, snapshots: Path = SNAPSHOT_DIR,
              page: Path = PAGE) -> Optional[Path]:
    """Screen every snapshot in `snapshots` and the policy shipped now (`episodes` per task from VALIDATION_SEED),
    validate the CONFIRM_TOP best of them again on CONFIRM_EPISODES per task from CONFIRMATION_SEED, and ship the
    one that places most there on its worst task, then on average (`refine.best_snapshot`); the shipped policy
    stays where it confirms best. Each validation is kept beside the snapshots; all go to the section
    `snapshot-validations` of `page`. The snapshot shipped, or None."""
    candidates = {int(p.stem.split("_")[1]): p for p in snapshots.glob("checkpoint_*.pt")}
    if not candidates:
        raise SystemExit(f"no snapshots in {snapshots}: `{COMMAND}` keeps one every {SNAPSHOT_EVERY:,} env steps")
    tags = {step: str(step) for step in candidates}
    if run.shipped.is_file():
        candidates[-1], tags[-1] = run.shipped, f"shipped_{content_tag(run.shipped)}"
    screened = {step: validate(candidates[step], snapshots / f"val{episodes}_{tags[step]}.json", episodes)
                for step in sorted(candidates, key=lambda k: (k < 0, k))}  # the policy shipped before last
    top = ranked_snapshots(screened)[:CONFIRM_TOP]
    confirmed = {step: validate(candidates[step], snapshots / f"val{CONFIRM_EPISODES}_{tags[step]}_confirm.json",
                                CONFIRM_EPISODES, seed=CONFIRMATION_SEED) for step in top}
    for step, placed in screened.items():
        print(f"{'shipped now' if step < 0 else f'{step:,} env steps'}: placed on validation "
              + ", ".join(f"{k} {v:.2f}" for k, v in placed.items())
              + ("; confirmed " + ", ".join(f"{k} {v:.2f}" for k, v in confirmed[step].items()) if step in confirmed else ""))
    best = best_snapshot(confirmed)
    update_section(page, "snapshot-validations", snapshot_table(screened, confirmed, best, episodes),
                   "Learning from reward alone: the experiment")
    if best < 0:
        print(f"{run.shipped} validates best: it stays")
        return None
    steps = [step for step in candidates if step >= 0]
    chosen = (f"the best of {len(steps)} snapshots ({min(steps):,} to {max(steps):,} env steps"
              + (", and the policy shipped before" if -1 in candidates else "")
              + f") on {CONFIRM_EPISODES} fresh validation episodes per task (seeds {CONFIRMATION_SEED:,} on) among the "
              + f"{len(confirmed)} best on {episodes} (seeds {VALIDATION_SEED:,} on): placed "
              + ", ".join(f"{k} {v:.2f}" for k, v in confirmed[best].items()))
    ship(run, snapshot=candidates[best], chosen=chosen)
    return candidates[best]


def snapshot_table(screened: dict, confirmed: dict, best: int, episodes: int) -> str:
    """`ship_best`'s validations as a table: a row per candidate (env steps; -1 the policy shipped before it)."""
    tasks = " / ".join(k.removesuffix("-v1") for k in next(iter(screened.values())))
    lines = [f"Command: `{COMMAND} --ship-best` (the policy's mean: {episodes} validation episodes per task, seeds "
             f"{VALIDATION_SEED:,} on, then {CONFIRM_EPISODES} more, seeds {CONFIRMATION_SEED:,} on, for the "
             f"{CONFIRM_TOP} best, which choose; the snapshots kept on the machine that ran it).", "",
             f"| policy | placed on validation: {tasks} % | worst task % | placed on confirmation: {tasks} % | "
             "worst task % | shipped |", "|---|---|---|---|---|---|"]
    for step, placed in screened.items():
        again = confirmed.get(step)
        lines.append(f"| {'shipped before' if step < 0 else f'snapshot at {step:,} env steps'} | "
                     + " / ".join(f"{100 * v:.0f}" for v in placed.values()) + f" | {100 * min(placed.values()):.0f} | "
                     + ("- | - |" if again is None else " / ".join(f"{100 * v:.0f}" for v in again.values())
                        + f" | {100 * min(again.values()):.0f} |")
                     + f" {'yes' if step == best else ''} |")
    return "\n".join(lines)


@dataclass
class Args:
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a run resumed from a checkpoint keeps its own."""
    seed: int = 1
    dry_run: bool = False
    """print the plan and where the run stands, and exit."""
    ship_now: bool = False
    """ship the policy where the run stands now (its record says at which step of the plan), and exit."""
    ship_best: bool = False
    """validate the run's snapshots on this machine and the shipped policy, ship the snapshot that places most (if
    that is not the shipped one), and exit."""
    report: bool = False
    """write its section of docs/RESULTS.md and its curve (docs/images/scratch_curve.png), and exit."""
    diagnose: bool = False
    """run its latest policy from near-goal starts (radius 0.2, 6 seeds per task) and from ordinary resets (the first
    6 test seeds per task) and write where it took the elements into docs/experiments/from_scratch.md, and exit."""
    checkpoint: Optional[Path] = None
    """with --diagnose: this checkpoint's policy instead (a probe's), printed only."""
    adopt: Optional[Path] = None
    """a continuation probe's run folder (runs/probes/<name>) that went on from the campaign's checkpoint with the
    recipe as it is now: the campaign goes on from it, its steps counted on (`adopt`), and exit."""


def main(args: Args) -> None:
    for run in scratch_runs(args.num_envs, args.seed):
        print(describe(run))
        print("as one ppo.py command: python baselines/ppo/ppo.py " + shlex.join(command_line(run.args)))
        if args.diagnose and args.checkpoint is not None:
            print(near_goal_rollouts(args.checkpoint))
            print(ordinary_rollouts(args.checkpoint))
        elif args.diagnose:
            ckpt = Path(run.args.log_dir) / run.args.exp_name / "checkpoint.pt"
            progress = load_checkpoint(ckpt)["progress"]["global_step"]
            near = (f"Command: `{COMMAND} --diagnose` (the campaign's checkpoint at {progress:,} env steps; near-goal starts "
                    f"at radius {DIAGNOSE_RADIUS}, the policy's mean, at most {DIAGNOSE_STEPS} steps).\n\n"
                    + near_goal_rollouts(ckpt))
            ordinary = (f"Command: `{COMMAND} --diagnose` (the campaign's checkpoint at {progress:,} env steps; ordinary "
                        f"resets on the first {DIAGNOSE_SEEDS} test seeds, the policy's mean).\n\n" + ordinary_rollouts(ckpt))
            for name, body in (("near-goal-rollouts", near), ("ordinary-rollouts", ordinary)):
                update_section(PAGE, name, body, "Learning from reward alone: the experiment")
                print(body)
        elif args.report:
            print(report(run))
        elif args.ship_now:
            ship(run, before_the_end=True)
        elif args.ship_best:
            ship_best(run)
        elif args.adopt is not None:
            adopt(run, args.adopt)
        elif not args.dry_run:
            train(run)


if __name__ == "__main__":
    main(tyro.cli(Args))
