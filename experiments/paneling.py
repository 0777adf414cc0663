"""Paneling, the fourth task: the planning expert and the shipped agents zero-shot on PanelInstallation-v1, and the
from-scratch recipe learning it.

    python -m experiments.paneling                       # every zero-shot row; then the RESULTS section and its JSON
    python -m experiments.paneling --episodes 20 --workers 1
    python -m experiments.paneling --train nothing       # the recipe (SAC) on paneling from nothing, resumable
                                                         # (--train-seed S: another seed; --learner ppo: PPO's;
                                                         # --train shipped: PPO from the PPO reward-only agent's;
                                                         # --train shipped --learner sac: SAC from SAC's run's)
    python -m experiments.paneling --train shipped --evaluate   # the paper's protocol on that run's policy
    python -m experiments.paneling --training-report     # RESULTS' section on the training runs there are

The shipped agents were trained on the paper's three task types; on paneling the task one-hot's new slot is the
only thing that says which task it is, and they read it with zero weights (baselines/ppo/checkpoints.py,
`with_task_slots`): their task input is all zeros, and what they do comes from the rest of the observation (the
goal pose, the element's pose). Protocol: cp4, seeds from 1,000,000 (never trained on), the policy's mean. Each
row is written to --out as it finishes and skipped when the file is there with the same seeds, so an interrupted
run goes on where it stopped.

Training (`--train`): the from-scratch recipe on PanelInstallation-v1 with the task's own dense reward, from nothing
(SAC, the recipe's learner; `--learner ppo`: PPO's), from the weights of the reward-only agent PPO's recipe made
(PPO), or from the networks of the SAC run the shipped reward-only agent comes from (`--learner sac`)
(experiments/transfer.py), in campaign/paneling_<start>_s<seed>/ (SAC's: paneling_sac_s<seed>/,
paneling_shipped_sac_s<seed>/):
TRAIN_BUDGET env steps at most, ending at the first 250,000-step mark by which its training episodes placed 90%
(`transfer.steps_to`: the env steps to 90% placed, what the run measures), then confirmed with the paper's protocol
(`--evaluate`).
"""

from __future__ import annotations

import csv
import json
import multiprocessing as mp
import os
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
import torch
import tyro

from baselines.ppo import evaluation
from baselines.ppo.evaluation import episode_job, pct, wilson
from experiments import transfer
from experiments.campaign import Run, checkpoint_of, record_checkpoint_step, training_wall_s
from experiments.from_scratch import csv_column, moving_mean
from experiments.obstacles import RESULTS_PATH, row_name, run_row, with_more_agents
from experiments.transfer import transfer_run
from ms_construction.curriculum import FINAL_STAGE
from ms_construction.reporting import update_section

ENV_ID = "PanelInstallation-v1"
AGENTS = {
    "general agent (imitation: clone + residual PPO)": "assets/checkpoints/general_agent.pt",
    "scratch general agent (reward alone, shipped)": "assets/checkpoints/scratch_general_agent.pt",
    "scratch general agent, PPO's (reward alone, before SAC's)": "assets/checkpoints/scratch_general_agent_ppo.pt",
    "paper setting (sparse reward, ICM, Table I stages)": "assets/checkpoints/paper_general_agent.pt",
}


TRAIN_BUDGET = 3_000_000
"""env steps of a training run on paneling at most (it ends once its training episodes place 90%)."""
MARKS = (0.5, transfer.TARGET)
"""the shares placed by its training episodes whose first crossing the training section reports per run (the
second: what a run measures, `transfer.steps_to`)."""
TRAIN_PLAN = (("ppo", "nothing", 1), ("ppo", "shipped", 1), ("sac", "nothing", 1), ("sac", "nothing", 2),
              ("sac", "shipped", 1), ("sac", "shipped", 2))
"""the (learner, start, seed) of the training runs that the training section reports."""
TRAIN_CURVE = Path("docs/images/paneling_training.png")


def training_run(start: str, seed: int = 1, num_envs: Optional[int] = None, learner: Optional[str] = None) -> Run:
    """The recipe on PanelInstallation-v1 from `start` (experiments/transfer.py's STARTS) with `learner` (default:
    `transfer.learner_for` the start), unchanged but for the env and the budget."""
    return transfer_run("paneling", start, seed, num_envs, TRAIN_BUDGET, "python -m experiments.paneling", "paneling",
                        learner, env_id=ENV_ID)


def train_eval_json(run: Run) -> Path:
    """Where a training run's evaluation with the paper's protocol goes (docs/data/paneling/train_<start>_s<seed>
    or train_sac_s<seed>, _eval50k.json)."""
    return Path(f"docs/data/paneling/train_{run.name.removeprefix('paneling_')}_eval50k.json")


@dataclass
class Args(transfer.TrainOptions):
    episodes: int = 100
    """seeded episodes per row."""
    seed: int = 1_000_000
    """the first seed; the others follow."""
    workers: int = 2
    """processes, one env each."""
    out: Path = Path("docs/data/paneling")
    """where each row's episodes go (one JSON per row)."""
    agents: dict[str, str] = field(default_factory=lambda: dict(AGENTS))
    """label -> checkpoint of the agents to run."""
    more_agents: tuple[str, ...] = ()
    """more agents to run after those, LABEL=CHECKPOINT each (a seed's candidate snapshot, say)."""
    write_results: bool = True
    """write the table into docs/RESULTS.md (section `paneling-zero-shot`; with --train, `paneling-training`)."""
    training_report: bool = False
    """write RESULTS' section on training on paneling (`paneling-training`) from the runs there are, and exit."""


_expert: dict = {}


def _expert_episode(seed: int) -> dict:
    """One seeded expert episode in a worker process (env and expert kept for the next)."""
    import gymnasium as gym

    from ms_construction.planning import MotionPlanningExpert

    torch.set_num_threads(1)
    if not _expert:
        env = gym.make(ENV_ID, num_envs=1, obs_mode="state", control_mode="pd_joint_pos", reward_mode="sparse",
                       sim_backend="physx_cpu", curriculum_stage=FINAL_STAGE)
        _expert["expert"] = MotionPlanningExpert(env)
    return _expert["expert"].run(seed).to_dict()


def _agent_episode(job: tuple[str, int]) -> dict:
    checkpoint, seed = job
    return episode_job((checkpoint, ENV_ID, FINAL_STAGE, seed, None, False, None, 1.0, None, ()))


def summarize(episodes: list[dict], expert: bool) -> dict:
    n = len(episodes)
    picked, placed = sum(e["picked"] for e in episodes), sum(e["placed"] for e in episodes)
    by_slot: dict[int, list[bool]] = {}
    for e in episodes:
        by_slot.setdefault(int(e["goal_slot"]), []).append(bool(e["placed"]))
    return dict(episodes=n, pick_success=picked / max(n, 1), pick_success_ci95=wilson(picked, n),
                place_success=placed / max(n, 1), place_success_ci95=wilson(placed, n),
                place_success_by_goal_slot={s: float(np.mean(v)) for s, v in sorted(by_slot.items())},
                **({} if expert else {"final_place_dist_median": float(np.median([e["final_place_dist"] for e in episodes]))}))


def table(rows: dict[str, dict]) -> str:
    lines = ["| agent | episodes | picked % [95% CI] | placed % [95% CI] | placed % by bay (x = -0.68 / 0 / +0.68 m) | "
             "final distance to the goal, median (m) |", "|---|---|---|---|---|---|"]
    for label, s in rows.items():
        bays = " / ".join(f"{100 * v:.0f}" for v in s["place_success_by_goal_slot"].values())
        dist = f"{s['final_place_dist_median']:.2f}" if "final_place_dist_median" in s else "-"
        lines.append(f"| {label} | {s['episodes']} | {pct(s['pick_success'], s['pick_success_ci95'])} | "
                     f"{pct(s['place_success'], s['place_success_ci95'])} | {bays} | {dist} |")
    return "\n".join(lines)


def train(args: Args) -> None:
    run = training_run(args.train, args.train_seed, args.num_envs, args.learner)
    if args.evaluate:
        out = train_eval_json(run)
        evaluation.main(evaluation.Args(checkpoint=checkpoint_of(run), env_id=ENV_ID, steps=50_000,
                                        workers=args.workers, json=out))
        record_checkpoint_step(out, checkpoint_of(run))
    else:
        transfer.train(run, args.dry_run, stop_at_target=True)
    if not args.dry_run and args.write_results:
        print(training_report())


def training_report(results: Path = RESULTS_PATH, curve: Path = TRAIN_CURVE) -> str:
    """RESULTS' section on the recipe trained on paneling, from each run's progress.csv and its evaluation (where
    there is one): the env steps its training episodes took to place 50% and 90% (MARKS), and its curve."""
    head = ("| run | env steps trained | env steps to 50% / 90% placed (its training episodes) | training wall time (h) | "
            "placed % [95% CI], the paper's protocol | placed % by bay (x = -0.68 / 0 / +0.68 m) |\n|---|---|---|---|---|---|")
    lines, curves = [head], {}
    for learner, start, seed in TRAIN_PLAN:
        run = training_run(start, seed, learner=learner)
        progress = checkpoint_of(run).parent / "progress.csv"
        if not progress.is_file():
            lines.append(f"| {run.what} | not run: `{run.command}` | | | | |")
            continue
        with open(progress, newline="") as f:
            rows = list(csv.DictReader(f))
        steps = csv_column(rows, "global_step")
        curves[run.what] = (steps, moving_mean(csv_column(rows, "ordinary_place_success"), transfer.STEPS_WINDOW))
        reached = [transfer.steps_to(progress, target) for target in MARKS]
        wall_h = training_wall_s(progress, transfer.samples_per_row(run)) / 3600
        evaluated = train_eval_json(run)
        if evaluated.is_file():
            task = evaluation.task_results(json.loads(evaluated.read_text()))[ENV_ID]
            placed = pct(task["place_success"], task["place_success_ci95"])
            bays = " / ".join(f"{100 * v:.0f}" for v in task.get("place_success_by_goal_slot", {}).values())
        else:
            placed, bays = f"not yet: `{run.command} --evaluate`", ""
        # a run that used its whole budget did not get there; one still going may yet
        short = f"not within {TRAIN_BUDGET:,}" if steps[-1] >= TRAIN_BUDGET else "not yet"
        to_target = short if reached[0] is None else " / ".join(short if r is None else f"{r:,}" for r in reached)
        lines.append(f"| {run.what} | {int(steps[-1]):,} | {to_target} | {wall_h:.1f} | {placed} | {bays} |")
    if curves:
        transfer.plot_training({"": curves}, curve, "The from-scratch recipe learning paneling")
    body = ("## Paneling, trained\n\n"
            "Commands: `python -m experiments.paneling --train nothing` (SAC), `--train nothing --learner ppo`, "
            "`--train shipped` (PPO), `--train shipped --learner sac` (each resumable; `--train-seed S`), then "
            "`--evaluate` beside any; this section: `python -m "
            "experiments.paneling --training-report`. The from-scratch recipe unchanged but for the env "
            "(PanelInstallation-v1, its dense reward from the same rule as the paper's tasks) and the budget "
            f"({TRAIN_BUDGET:,} env steps at most, ending at the first {transfer.STOP_EVERY:,}-step mark by which its "
            f"training episodes placed {transfer.TARGET:.0%}), from nothing or from the weights of the reward-only "
            "agent PPO's recipe made (scratch_general_agent_ppo.pt); SAC on the same envs, reward and near-goal "
            "starts, from nothing or from the networks of the SAC run the shipped reward-only agent comes from. Env "
            f"steps to {' / '.join(f'{m:.0%}' for m in MARKS)}: the first at which its training episodes from ordinary "
            "resets placed that share (their mean over the last "
            f"{transfer.STEPS_WINDOW} iterations); the paper's protocol: 50,000 env steps, cp4, test seeds, the "
            "policy's mean.\n\n" + "\n".join(lines) + "\n"
            + (f"\n![paneling, trained]({os.path.relpath(curve, results.parent)})\n" if curves else ""))
    update_section(results, "paneling-training", title="Results", body=body)
    return body


def main(args: Args) -> dict:
    if args.training_report:
        print(training_report())
        return {}
    if args.train is not None:
        return train(args)
    if args.episodes < 1 or args.workers < 1:
        raise SystemExit("--episodes and --workers must be positive")
    args.agents = with_more_agents(args.agents, args.more_agents)
    command = " ".join(["python -m experiments.paneling", *map(shlex.quote, sys.argv[1:])])
    seeds = list(range(args.seed, args.seed + args.episodes))
    rows: dict[str, dict] = {}
    with mp.get_context("spawn").Pool(args.workers) as pool:
        expert = run_row(pool, args.out / "expert.json", _expert_episode, seeds, seeds, "expert paneling")
        rows["planning expert"] = summarize(expert, True)
        failures = "; ".join(f"seed {e['seed']} (bay {e['goal_slot']}): {e['failure']}" for e in expert if not e["placed"])
        for label, checkpoint in args.agents.items():
            name = row_name(checkpoint)
            episodes = run_row(pool, args.out / f"{name}.json", _agent_episode, [(checkpoint, s) for s in seeds], seeds,
                               f"{name} paneling", checkpoint)
            rows[f"{label}, zero-shot"] = summarize(episodes, False)
    none_place = all(r["place_success"] == 0 for label, r in rows.items() if label != "planning expert")
    body = ("## Paneling, a fourth task: zero-shot\n\n"
            f"Command: `{command}`\n\n{table(rows)}\n\n"
            f"{ENV_ID}: a 15 kg wall panel into one of three open bays of an interior partition's board layer, standing, "
            "flush with the boards around it (cp4 tolerances; seeds "
            f"{args.seed}..{args.seed + args.episodes - 1}, never trained on; the policies' mean). The agents were "
            "trained on the paper's three task types only: those made before paneling existed read the task one-hot's "
            "new slot with zero weights (their task input is all zeros here); SAC's reward-only agent, trained after, "
            "saw that slot at 0 throughout and meets a 1 there, far outside its observation statistics (its "
            "normalization clips it at 10 standard deviations)" + (", and none places a panel: what they learnt does not carry over "
                                                        "to a fourth task without training on it" if none_place else "")
            + ".\n\n"
            f"The expert's failures: {failures or 'none'}. The dense reward for paneling comes from the same rule as "
            "for the paper's tasks (start paths from each bay to the staging table, a planned via where no path from "
            "the table's main side is wholly clear), with no code of its own; a straight joint move from the table "
            "toward any bay pays less than stepping along its paths (tests/test_near_goal_starts.py). Training on "
            "paneling: [the next section](#paneling-trained).\n")
    print(body)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps({"command": command, "rows": rows}, indent=1) + "\n")
    if args.write_results:
        update_section(RESULTS_PATH, "paneling-zero-shot", title="Results", body=body)
        print(f"wrote {RESULTS_PATH}")
    return rows


if __name__ == "__main__":
    main(tyro.cli(Args))
