"""A site that changes, zero-shot: the planning expert and the shipped agents among obstacles (the tasks' `obstacles`).

    python -m experiments.obstacles                       # every row; then the RESULTS section and its JSON
    python -m experiments.obstacles --episodes 20 --workers 1
    python -m experiments.obstacles --train shipped      # PPO's recipe among obstacles from the weights of the
                                                         # reward-only agent PPO made (or: nothing, SAC's), resumable
    python -m experiments.obstacles --train shipped --evaluate   # that run's rows beside the zero-shot ones
    python -m experiments.obstacles --share 0.5 --train nothing   # SAC on a mixed scene: half of its training
                                                                  # episodes among obstacles, half without
    python -m experiments.obstacles --share 1 --train shipped --learner sac   # SAC from its reward-only agent's
                                                  # run, every training episode among obstacles
    python -m experiments.obstacles --training-curve      # the training runs' curves (docs/images/)
    python -m experiments.obstacles --share 0.5 --train shipped --learner sac --snapshot-table   # that run's
                                                          # evaluated snapshots, each seed
    python -m experiments.obstacles --share 1 --train shipped --learner sac --reach-touches   # which way its
                                                          # latest snapshot turned where it touched before the pick

Protocol, per task (ceiling, window, flooring), on evaluation seeds (from 1,000,000: never trained on):
1. the planning expert solves each seed's static scene (a material stack and a scaffold post, seeded per episode):
   the seeds it places are the evaluation set, "solvable at its start";
2. the expert on those seeds with the worker walking across the cell (`moving`), replanning around it;
3. each shipped agent on those seeds, without obstacles, static and moving. The agents were trained on a site
   without obstacles and meet them blind (no obstacle entry in their observation): zero-shot.
4. with `--train S --evaluate`: the from-scratch recipe's run among obstacles (experiments/transfer.py: TRAIN_SCENE,
   TRAIN_BUDGET env steps, from nothing or from the PPO reward-only agent's weights, the obstacles' entry in its
   observation) on the same seeds and scenes.

An episode with obstacles ends, failed, at the first touch of the arm or the element on one. Every seed draws the
same arm, element and goal in all three scenes. Each (row, task) is written to --out as it finishes and skipped when
the file is there with the same seeds, so an interrupted run goes on where it stopped.
"""

from __future__ import annotations

import csv
import itertools
import json
import multiprocessing as mp
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Optional

import gymnasium as gym
import numpy as np
import torch
import tyro
from tqdm import tqdm

from baselines.ppo.evaluation import episode_job, pct, wilson
from experiments import transfer
from baselines.ppo.checkpoints import load_checkpoint
from experiments.campaign import Run, checkpoint_of, policy_only
from experiments.from_scratch import csv_column, moving_mean
from ms_construction.assets import sha256
from ms_construction.curriculum import FINAL_STAGE
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section

AGENTS = {
    "general agent (imitation: clone + residual PPO)": "assets/checkpoints/general_agent.pt",
    "scratch general agent (reward alone, shipped)": "assets/checkpoints/scratch_general_agent.pt",
    "scratch general agent, PPO's (reward alone, before SAC's)": "assets/checkpoints/scratch_general_agent_ppo.pt",
}
BLIND = "scratch general agent (reward alone, shipped)"
"""the agent of AGENTS whose touches --snapshot-table compares a trained run's with: SAC's reward-only agent, blind to
the obstacles (SAC's runs from the shipped weights start from its run's networks)."""
SCENES = ("none", "static", "moving")
RESULTS_PATH = Path("docs/RESULTS.md")
VERSIONS_PATH = Path("docs/experiments/generalization.md")
"""the experiment page whose section `obstacle-versions` tables every snapshot of SHOWN: RESULTS keeps today's
version's (OBSTACLE_REWARD) beside the expert and the blind agents."""
TRAIN_SCENE = "moving"
"""the scene a training run among obstacles draws: the stack and the post, and the worker walking across."""
TRAIN_BUDGET = 3_000_000
"""env steps of each training run among obstacles."""
OBSTACLE_REWARDS = (1, 2, 3, 4, 5, 6, 7)
OBSTACLE_REWARD = OBSTACLE_REWARDS[-1]
"""the version of what `--train` trains on among obstacles, the dense reward and the value of a touch, named in the
run's folder: 1, the carry
measured along the usable start paths clear of the stack and the post, and along all usable ones (into them) where
none is clear (the runs before 2026-12-06, folders without a suffix); 2, a clear detour from the other turret side
before that last resort (CarryGeometry.clear_ways), even after a grasp from the side it does not leave from, which the
turret cannot reach holding the element (one probe, `_r2`); 3, after a grasp, that side's clear ways first, else its
usable paths (CarryGeometry.carry_paths; `_r3`); 4, reward 3, and a touch of an obstacle (`info["fail"]`) is an
end with nothing after it in the learners' targets (baselines/ppo/evaluation.py `failed_ends`); until 2026-12-07 they
valued it as they value success, the touching step's reward for ever, so that a touch while holding the element was
worth about as much as carrying on (`_r4`); 5, reward 4, and the near-goal starts handed back to ordinary resets
once they cover the whole way to the goal (HAND_BACK_END; `_r5`): a start-state device, not the reward, but a change
of what a run trains on all the same; 6, version 5, and half of the training episodes (before near-goal starts draw
theirs) start on the way to the element, toward a turret side the clear ways leave from (REACH_START_SHARE; `_r6`);
7, version 6 on reward 5: where the stack or the post blocks every usable start path of a turret side, the episode
searches a via around them for that side's paths at reset (SiteObstacles.obstacle_ways), and the reach and the carry
are paid along it, where versions 1-6 paid only a detour from the other side or the blocked paths (`_r7`).
The site as built measures the same in all seven."""
TRAINABLE = (7,)
"""the versions whose code is still here: a run on one of them can be trained (or resumed)."""
HAND_BACK_END = 0.2
"""version 5: the share of near-goal starts each task type's falls to once its radius is 1 (the learners'
--near-goal-share-end), from the recipe's 0.8: about 2 in 100 training episodes were the window's reaches that must
turn away from the scaffold post, and four in five started holding the element at a radius every type reached within
60,000 env steps and then placed about 95% of the time."""
REACH_START_SHARE = 0.5
"""version 6: the learners' --reach-start-share. Handing near-goal starts back (version 5) left windows where they
were: the same ten static window layouts were touched before the pick by every agent, blind or trained, the turret
swept the way the site as built taught it, and a sweep the other way round, toward the side the reach measures
toward, has to be found from the rest pose by chance; a start part of the way along it shows where it leads."""
TRAIN_RUNS = {
    "PPO from PPO's reward-only agent, reward 1": ("shipped", None, 1.0, 1),
    "SAC from nothing, reward 1": ("nothing", "sac", 1.0, 1),
    "SAC from nothing, mixed scene (--share 0.5), reward 1": ("nothing", "sac", 0.5, 1),
    "SAC from SAC's reward-only agent, mixed scene (--share 0.5), reward 1": ("shipped", "sac", 0.5, 1),
    "the same, reward 2 (detours)": ("shipped", "sac", 0.5, 2),
    "the same, reward 3 (the grasp side's ways first)": ("shipped", "sac", 0.5, 3),
    "the same, every episode among obstacles (--share 1)": ("shipped", "sac", 1.0, 3),
    "the same, reward 4 (a touch ends with nothing after it)": ("shipped", "sac", 1.0, 4),
    "the same, near-goal starts handed back (version 5)": ("shipped", "sac", 1.0, 5),
    "the same, and reach starts (version 6)": ("shipped", "sac", 1.0, 6),
    "version 6 on the mixed scene (--share 0.5)": ("shipped", "sac", 0.5, 6),
    "version 7 (ways searched at reset), mixed scene": ("shipped", "sac", 0.5, 7),
}
"""the runs among obstacles `--training-curve` draws, each seed of TRAIN_SEEDS it has: label -> (--train, --learner,
--share, --obstacle-reward)."""
TRAIN_SEEDS = (1, 2)
"""the seeds (--train-seed) `--training-curve` looks for."""
TRAIN_CURVE = Path("docs/images/obstacles_training.png")
TRAINED = " (trained among obstacles)"
"""what the label of an agent trained on the moving scene (`--train`) ends with in summary.json."""
SHOWN = (  # (--train, --learner, --share, --obstacle-reward, --train-seed, env steps)
    ("shipped", None, 1.0, 1, 1, 460_000),
    ("nothing", "sac", 1.0, 1, 1, 500_018),
    ("nothing", "sac", 0.5, 1, 1, 918_090),
    ("shipped", "sac", 0.5, 1, 1, 1_000_606),
    ("shipped", "sac", 0.5, 1, 2, 500_000),
    ("shipped", "sac", 0.5, 3, 1, 1_200_000),
    ("shipped", "sac", 0.5, 3, 2, 1_000_000),
    ("shipped", "sac", 1.0, 3, 1, 700_000),
    ("shipped", "sac", 1.0, 4, 1, 600_000),
    ("shipped", "sac", 1.0, 5, 1, 400_000),
    ("shipped", "sac", 1.0, 6, 1, 1_000_000),
    ("shipped", "sac", 0.5, 6, 1, 400_000),
    ("shipped", "sac", 0.5, 7, 1, 600_000),
)
"""the trained runs' snapshots evaluated with AGENTS (each an evaluated candidate, `candidate_path`): RESULTS shows
those of today's version (OBSTACLE_REWARD), VERSIONS_PATH every one."""


def training_run(start: str, seed: int = 1, num_envs: Optional[int] = None, learner: Optional[str] = None,
                 share: float = 1.0, reward: int = OBSTACLE_REWARD) -> Run:
    """The recipe among obstacles (TRAIN_SCENE) from `start` (experiments/transfer.py's STARTS) with `learner`
    (default: `transfer.learner_for` the start), unchanged but for the tasks' `obstacles` and the budget; with
    `share` < 1 (SAC only), a mixed scene: that share of its training episodes with obstacles, the others on the
    site as built (the tasks' `obstacle_share`). `reward`: the OBSTACLE_REWARD version its folder is for (an earlier
    one names the runs trained on it, to evaluate or tabulate)."""
    if reward not in OBSTACLE_REWARDS:
        raise SystemExit(f"--obstacle-reward {reward}: one of {', '.join(map(str, OBSTACLE_REWARDS))} "
                         f"({OBSTACLE_REWARD}: today's)")
    if not 0 < share <= 1:
        raise SystemExit(f"--share {share}: the share of training episodes with obstacles, in (0, 1]")
    if share < 1 and transfer.learner_for(start, learner) != "sac":
        raise SystemExit(f"--share {share:g}: a mixed scene is SAC's option (--learner sac); PPO's recipe has none")
    mixed = share < 1
    return transfer.transfer_run(f"obstacles_{TRAIN_SCENE}" + (f"_share{round(100 * share)}" if mixed else "")
                                 + ("" if reward == 1 else f"_r{reward}"), start, seed, num_envs, TRAIN_BUDGET,
                                 "python -m experiments.obstacles" + (f" --share {share:g}" if mixed else "")
                                 + ("" if reward == OBSTACLE_REWARD else f" --obstacle-reward {reward}"),
                                 f"a site with obstacles ({TRAIN_SCENE})"
                                 + (f" in {share:.0%} of its training episodes" if mixed else "")
                                 + ("" if reward == 1 else f" (obstacle {version_name(reward)})"),
                                 learner, obstacles=TRAIN_SCENE, **({"obstacle_share": share} if mixed else {}),
                                 **({"near_goal_share_end": HAND_BACK_END} if reward >= 5 else {}),
                                 **({"reach_start_share": REACH_START_SHARE} if reward >= 6 else {}))


def scene_name(share: float) -> str:
    """The scene a run trained on, in words: TRAIN_SCENE's obstacles, and in what share of its training episodes."""
    return f"{TRAIN_SCENE} obstacles" + ("" if share == 1 else f" in {share:.0%} of episodes")


def version_name(reward: int) -> str:
    """What an OBSTACLE_REWARDS version trains on, in words for a row label: its reward, and from version 5 on the
    start-state devices (not a reward of their own)."""
    if reward < 5:
        return f"reward {reward}"
    return (("reward 5 (ways searched at reset)" if reward >= 7 else "reward 4") + ", near-goal starts handed back"
            + (", reach starts" if reward >= 6 else ""))


def trained_label(start: str, learner: Optional[str], share: float, reward: int, seed: int, step: int) -> str:
    """The row label of a training run's snapshot at `step`: its learner and start, scene and reward, seed, steps."""
    return (f"{transfer.start_name(start, learner)}, {scene_name(share)}, {version_name(reward)}, seed {seed}, "
            f"{step:,} env steps{TRAINED}")


def candidate_path(run: Run, step: int) -> Path:
    """Where a training run's policy at `step` is kept (committed once evaluated)."""
    return checkpoint_of(run).parent / "candidates" / f"candidate_{step}.pt"


def shown_agents() -> dict[str, str]:
    """label -> candidate policy of each snapshot of SHOWN."""
    return {trained_label(start, learner, share, reward, seed, step):
            str(candidate_path(training_run(start, seed, None, learner, share, reward), step))
            for start, learner, share, reward, seed, step in SHOWN}


def earlier_versions() -> set[str]:
    """The labels of SHOWN's snapshots trained on a version before today's (OBSTACLE_REWARD): the experiment page's
    rows, not RESULTS'."""
    return {trained_label(*shown) for shown in SHOWN if shown[3] != OBSTACLE_REWARD}


def trained_policy(run: Run) -> tuple[int, Path]:
    """The env steps of a training run's checkpoint, and its policy kept (committed) as
    campaign/<run>/candidates/candidate_<env steps>.pt: its rows are named for it, so an evaluation of a run still
    training is never read back as a later checkpoint's."""
    ckpt = checkpoint_of(run)
    if not ckpt.is_file():
        raise SystemExit(f"--evaluate: {run.name} has no checkpoint at {ckpt}; train it first: {run.command}")
    saved = load_checkpoint(ckpt)
    step = int(saved["progress"]["global_step"])
    policy = candidate_path(run, step)
    if not policy.is_file():
        policy.parent.mkdir(parents=True, exist_ok=True)
        torch.save(policy_only(saved), policy)
    return step, policy


def row_name(checkpoint: str) -> str:
    """The name an agent's row files take: its checkpoint's file name; a run's checkpoint.pt, its run's folder; a
    seed's candidate snapshot (campaign/<run>/candidates/), the run's folder and the candidate's name."""
    path = Path(checkpoint)
    if path.parent.name == "candidates":
        return f"{path.parent.parent.name}_{path.stem}"
    return path.parent.name if path.stem == "checkpoint" else path.stem


@dataclass
class Args(transfer.TrainOptions):
    episodes: int = 60
    """seeds per task tried by the expert in the static scene (the evaluation set is those it solves)."""
    seed: int = 1_000_000
    """the first seed; the others follow."""
    workers: int = 2
    """processes, one env each."""
    out: Path = Path("docs/data/obstacles")
    """where each row's episodes go (one JSON per row and task)."""
    agents: dict[str, str] = field(default_factory=lambda: {**AGENTS, **shown_agents()})
    """label -> checkpoint of the agents to run: the shipped ones, and the trained snapshots RESULTS shows."""
    more_agents: tuple[str, ...] = ()
    """more agents to run after those, LABEL=CHECKPOINT each (a seed's candidate snapshot, say)."""
    obstacle_reward: int = OBSTACLE_REWARD
    """with --train: the version of the obstacle scenes' dense reward (OBSTACLE_REWARD) whose run it means; an earlier
    one only to --evaluate or tabulate its runs (that reward is gone)."""
    share: float = 1.0
    """with --train (SAC): the share of its training episodes with obstacles; below 1, a mixed scene, the others on
    the site as built, in its own run (campaign/obstacles_moving_share<%>_sac_s<seed>/)."""
    write_results: bool = True
    """write the table into docs/RESULTS.md (section `obstacles-zero-shot`) and its rows to --out/summary.json; with
    --no-write-results (a snapshot evaluated on its own, say) both are left as they are and the table only printed."""
    training_curve: bool = False
    """draw the training runs among obstacles (TRAIN_RUNS, those with a progress.csv) to TRAIN_CURVE, and exit."""
    touches_by: Optional[Literal["post-side", "clear-way", "searched-way"]] = None
    """with --train: per task, the episodes each evaluated snapshot of that run (each seed's), and the blind reward-only
    agent (BLIND), placed its element in and touched an obstacle in (static scene), by the side of the arm the scaffold post stands on
    (post-side) or by the ways the dense reward finds clear of the obstacles (clear-way: LAYOUT_GROUPS); and exit.
    It resets an env per seed to read the layout (a minute or two per task)."""
    reach_touches: bool = False
    """with --train: per task, the static scene's episodes that the blind reward-only agent (BLIND) and each seed's
    latest evaluated snapshot of that run touched an obstacle in before the pick, replayed to the touch: which way the
    turret had turned, against the turret sides the dense reward's reach measures toward (`reach_distance`); and
    exit."""
    carry_along_expert: int = 0
    """above 0: per task and clear-way class of the static scene's layouts (LAYOUT_GROUPS), how the dense reward's carry
    distance went along the planning expert's placed episodes of up to this many seeds each (`carry_along_expert`);
    print the table, and exit."""
    snapshot_table: bool = False
    """with --train: print the table of that run's evaluated snapshots, each seed of TRAIN_SEEDS (from the JSONs in
    --out that --evaluate or --more-agents wrote for its candidates), and exit."""


_experts: dict = {}


def _expert_episode(job: tuple[str, str, int]) -> dict:
    """One seeded expert episode in a worker process (env and expert kept for the next)."""
    from ms_construction.planning import MotionPlanningExpert

    env_id, scene, seed = job
    torch.set_num_threads(1)
    if (env_id, scene) not in _experts:
        env = gym.make(env_id, num_envs=1, obs_mode="state", control_mode="pd_joint_pos", reward_mode="sparse",
                       sim_backend="physx_cpu", curriculum_stage=FINAL_STAGE, obstacles=scene)
        _experts[(env_id, scene)] = MotionPlanningExpert(env)
    return _experts[(env_id, scene)].run(seed).to_dict()


def _agent_episode(job: tuple[str, str, str, int]) -> dict:
    checkpoint, env_id, scene, seed = job
    obstacles = None if scene == "none" else scene
    return episode_job((checkpoint, env_id, FINAL_STAGE, seed, None, False, None, 1.0, obstacles, ()))


def run_row(pool, path: Path, fn, jobs: list[tuple], seeds: list[int], desc: str,
            checkpoint: Optional[str] = None) -> list[dict]:
    """The episodes of one row and task: read from `path` when it holds these seeds (and, for an agent's row, the
    episodes of this `checkpoint`'s weights: a file shipped again under the same name is run again), else run and
    written there."""
    digest = sha256(checkpoint) if checkpoint is not None else None
    if path.exists():
        saved = json.loads(path.read_text())
        if saved["seeds"] == seeds and saved.get("checkpoint_sha256") == digest:
            return saved["episodes"]
    episodes = []
    bar = tqdm(total=len(jobs), desc=desc, unit="ep", dynamic_ncols=True)
    for e in pool.imap(fn, jobs):
        episodes.append(e)
        bar.update()
        bar.set_postfix(placed=f"{sum(x['placed'] for x in episodes)}/{len(episodes)}")
    bar.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"seeds": seeds, **({"checkpoint_sha256": digest} if digest else {}),
                                "episodes": episodes}, indent=0) + "\n")
    return episodes


def summarize(episodes: list[dict], expert: bool) -> dict:
    n = len(episodes)
    placed = sum(e["placed"] for e in episodes)
    collided = sum(bool(e["collisions"] if expert else e["collided"]) for e in episodes)
    steps = sum(e["steps" if expert else "length"] for e in episodes)
    compute = sum(e["planning_time" if expert else "policy_time_s"] for e in episodes)
    return dict(episodes=n, place_success=placed / max(n, 1), place_success_ci95=wilson(placed, n),
                collision_rate=collided / max(n, 1), collision_ci95=wilson(collided, n),
                compute_per_episode_s=compute / max(n, 1), compute_per_step_ms=1000 * compute / max(steps, 1),
                **({f"{k}_per_episode": float(np.mean([e[k] for e in episodes])) if n else float("nan")
                    for k in ("replans", "escapes", "waited_steps")} if expert else {}))


def table(rows: dict[tuple[str, str], dict[str, dict]], scene_only: Optional[str] = None) -> str:
    """The rows (agent label, scene) as a table; with `scene_only`, those of that scene (SCENES) alone, one per
    agent, without the scene column."""
    tasks = list(PAPER_TASK_ENV_IDS)
    head = " | ".join(f"{k}: placed % [95% CI] / collided %" for k in tasks)
    scene_head = "" if scene_only else " scene |"
    lines = [f"| agent |{scene_head} episodes | {head} | compute per decision (ms) |",
             "|---|" + "---|" * (len(tasks) + (3 if scene_only is None else 2))]
    for (label, scene), per_task in rows.items():
        if scene_only is not None and not scene.startswith(scene_only):
            continue
        cells = []
        for kind in tasks:
            s = per_task[PAPER_TASK_ENV_IDS[kind]]
            cells.append(f"{pct(s['place_success'], s['place_success_ci95'])} / {100 * s['collision_rate']:.0f}")
        n = "/".join(str(per_task[PAPER_TASK_ENV_IDS[k]]["episodes"]) for k in tasks)
        ms = np.mean([per_task[PAPER_TASK_ENV_IDS[k]]["compute_per_step_ms"] for k in tasks])
        lines.append(f"| {label} |{'' if scene_only else f' {scene} |'} {n} | " + " | ".join(cells) + f" | {ms:.2f} |")
    return "\n".join(lines)


def with_more_agents(agents: dict[str, str], specs: tuple[str, ...]) -> dict[str, str]:
    """`agents` and those of --more-agents LABEL=CHECKPOINT ...; a spec that is not one, or names no file, is refused."""
    more = {}
    for spec in specs:
        label, _, checkpoint = spec.partition("=")
        if not label or not Path(checkpoint).is_file():
            raise SystemExit(f"--more-agents {spec}: give LABEL=CHECKPOINT, a checkpoint that exists")
        more[label] = checkpoint
    return {**agents, **more}


def scene_rows(summary: dict, scene: str) -> dict[str, dict]:
    """{agent label: its per-task results} of one scene (SCENES) in summary.json, whose rows are keyed
    "<label> | <scene> (...)" (`main`)."""
    return {label: per_task for key, per_task in summary.get("rows", {}).items()
            for label, _, rest in [key.partition(" | ")] if rest.startswith(scene)}


def training_curve(out: Path = TRAIN_CURVE) -> Path:
    """Each run of TRAIN_RUNS, each seed of TRAIN_SEEDS, that has a progress.csv: its training episodes from ordinary
    resets placed per task type (their moving mean over transfer.STEPS_WINDOW rows) against env steps, one panel per
    task type, and below them the share of those episodes that touched an obstacle where the run logged it. A mixed
    run's curves count its episodes on both scenes; a touch on an obstacle fails an episode."""
    panels: dict[str, dict] = {kind: {} for kind in PAPER_TASK_ENV_IDS}
    collided: dict[str, dict] = {kind: {} for kind in PAPER_TASK_ENV_IDS}
    for (label, (start, learner, share, reward)), seed in itertools.product(TRAIN_RUNS.items(), TRAIN_SEEDS):
        progress = checkpoint_of(training_run(start, seed, None, learner, share, reward)).parent / "progress.csv"
        if not progress.is_file():
            continue
        with open(progress, newline="") as f:
            rows = list(csv.DictReader(f))
        steps = csv_column(rows, "global_step")
        name = f"{label}, seed {seed}, {int(steps[-1]):,} env steps"
        for kind, curves in panels.items():
            curves[name] = (steps, moving_mean(csv_column(rows, f"ordinary_place_{kind}"), transfer.STEPS_WINDOW))
            touched = csv_column(rows, f"ordinary_collided_{kind}")
            if np.isfinite(touched).any():  # logged by runs (or parts of runs) since SAC's CSV had the column
                collided[kind][name] = (steps, moving_mean(touched, transfer.STEPS_WINDOW))
    if not panels[next(iter(panels))]:
        raise SystemExit("--training-curve: no run among obstacles has a progress.csv yet; train one with --train")
    transfer.plot_training(panels, out, f"Training among obstacles ({TRAIN_SCENE} scene)", collided)
    return out


def evaluated_snapshots(start: str, learner: Optional[str], share: float, out: Path,
                        reward: int = OBSTACLE_REWARD) -> dict[int, tuple[str, list[int]]]:
    """{seed of TRAIN_SEEDS: (its run's folder name, the env steps of its candidates with episode JSONs in `out`)}
    of one training run among obstacles."""
    found = {}
    for seed in TRAIN_SEEDS:
        name = checkpoint_of(training_run(start, seed, None, learner, share, reward)).parent.name
        found[seed] = (name, sorted({int(path.name.removeprefix(f"{name}_candidate_").partition("_")[0])
                                     for path in out.glob(f"{name}_candidate_*_*.json")}))
    return found


def snapshot_table(start: str, learner: Optional[str], share: float, out: Path,
                   reward: int = OBSTACLE_REWARD) -> list[str]:
    """The evaluated snapshots (campaign/<run>/candidates/candidate_<env steps>.pt) of one training run among
    obstacles, each seed of TRAIN_SEEDS: a row per seed, env steps and scene (none, moving), each task's placed %
    [95% CI] / touched an obstacle %, read from the episodes' JSONs in `out` ("-" where a task's is not there). Then,
    per seed, where its latest snapshot's static scene was evaluated: how many of the episodes it touched an obstacle
    in the shipped reward-only agent, blind to them (BLIND), touched too: whether training taught it to avoid what
    the blind agent hits; and how many of each's touches came before it picked its element up (on the reach, which
    the dense reward measures in joint space, not along a way clear of the obstacles)."""
    tasks = list(PAPER_TASK_ENV_IDS)
    notes = []
    lines = ["| seed | env steps | scene | " + " | ".join(f"{k}: placed % [95% CI] / touched %" for k in tasks) + " |",
             "|---|---|---|" + "---|" * len(tasks)]
    for seed, (name, steps) in evaluated_snapshots(start, learner, share, out, reward).items():
        for step, scene in itertools.product(steps, ("none", "moving")):
            cells = []
            for kind in tasks:
                path = out / f"{name}_candidate_{step}_{scene}_{kind}.json"
                s = summarize(json.loads(path.read_text())["episodes"], False) if path.is_file() else None
                cells.append("-" if s is None else
                             f"{pct(s['place_success'], s['place_success_ci95'])} / {100 * s['collision_rate']:.0f}")
            lines.append(f"| {seed} | {step:,} | {scene} | " + " | ".join(cells) + " |")
        static = {k: out / f"{name}_candidate_{steps[-1]}_static_{k}.json" for k in tasks} if steps else {}
        blind = {k: out / f"{row_name(AGENTS[BLIND])}_static_{k}.json" for k in tasks}
        if static and all(path.is_file() for path in [*static.values(), *blind.values()]):
            touched, hit = ({k: {e["seed"]: e["picked"] for e in json.loads(files[k].read_text())["episodes"]
                                 if e["collided"]} for k in tasks} for files in (static, blind))

            def counts(seeds: dict) -> str:
                return " / ".join(str(len(seeds[k])) for k in tasks)

            def unpicked(seeds: dict) -> str:  # of the touched episodes, those before the pick
                return counts({k: [s for s, picked in seeds[k].items() if not picked] for k in tasks})

            notes.append(f"Seed {seed} at {steps[-1]:,} env steps, static scene: touched an obstacle in {counts(touched)} "
                         f"episodes (ceiling / window / flooring; {unpicked(touched)} before picking its element up), "
                         f"of which the blind reward-only agent touched "
                         f"{counts({k: touched[k].keys() & hit[k] for k in tasks})} too (it touched {counts(hit)}; "
                         f"{unpicked(hit)} before picking it up).")
    return lines + ([""] + notes if notes else [])


LAYOUT_GROUPS = {
    "post-side": ("-y", "+y"),
    "clear-way": ("a usable path", "a detour only", "none"),
    "searched-way": ("a via searched", "the start paths only"),
}
"""how `--touches-by` groups the static scene's layouts (`layouts`): the side of the arm (its base at the origin) the
scaffold post stands on; the start paths clear of the stack and the post for the episode's goal slot
(CarryGeometry.clear_ways: a usable start path; only a detour from a turret side without usable paths; none, where
it measures along the usable paths, into the obstacles); whether the episode got a way through a via searched around
them at reset (SiteObstacles.obstacle_ways: for a turret side whose usable paths they block all of; version 7 on)."""


def layouts(env_id: str, seeds: list[int]) -> dict[int, dict[str, str]]:
    """{seed: {group of LAYOUT_GROUPS: its value}} of each seed's static scene (the tasks' `obstacle_layout` and
    `clear_paths`, the same for a seed in every scene)."""
    env = gym.make(env_id, num_envs=1, obs_mode="state", reward_mode="sparse", sim_backend="physx_cpu",
                   curriculum_stage=FINAL_STAGE, obstacles="static")
    u, found = env.unwrapped, {}
    for seed in seeds:
        env.reset(seed=seed)
        ways = u.obstacle_ways()
        clear = ways.clear & ~ways.searched  # the start paths as the site has them, before a via is searched
        usable = (u.geometry.paths["usable"][u.task_id, u.goal_slot] & clear).any()
        way = ("a usable path" if usable else "a detour only" if u.geometry.clear_ways(u.task_id, u.goal_slot, clear).any()
               else "none")
        found[seed] = {"post-side": "-y" if float(u.obstacle_layout[0, 5]) < 0 else "+y", "clear-way": way,
                       "searched-way": LAYOUT_GROUPS["searched-way"][0 if bool(ways.searched.any()) else 1]}
    env.close()
    return found


def rank_correlation(values: list[float]) -> float:
    """Spearman's rank correlation of `values` with their order (ties are rare in a measured distance): -1 where they
    fall all the way, +1 where they rise all the way; 0 for fewer than three."""
    if len(values) < 3:
        return 0.0
    ranks = np.argsort(np.argsort(values)).astype(float)
    return float(np.corrcoef(np.arange(len(values)), ranks)[0, 1])


def carry_course(carries: list[float], carry_range: float) -> dict:
    """How the dense reward's carry distance (rad) went over the held steps of one placed episode: its rank correlation
    with the step, the share of steps it stood beyond `carry_range` (where the carry term pays 0), its value at the
    grasp and its most."""
    c = np.asarray(carries, dtype=float)
    return dict(rho=rank_correlation(carries), beyond=float((c > carry_range).mean()), first=float(c[0]),
                most=float(c.max()))


class HeldCarries(gym.Wrapper):
    """Records the dense reward's carry distance at each step of a single env that ends with the element held."""

    def __init__(self, env):
        super().__init__(env)
        self.carries: list[float] = []

    def step(self, action):
        result = super().step(action)
        if bool(result[4]["is_grasped"][0]):
            self.carries.append(float(self.env.unwrapped.carry_distance()[0]))
        return result


def carry_along_expert(out: Path, per_class: int) -> list[str]:
    """A row per task, clear-way class of the static scene's layouts (LAYOUT_GROUPS) and scene (the site as built,
    then the static obstacles): along the planning expert's placed episodes of those seeds (the seeds it solved among
    the obstacles, by the JSONs in `out`; the first `per_class` of each class), how the dense reward's carry distance
    went while the element was held (`carry_course`), the median over the episodes and the worst. The reward means it
    to fall along any clear way to the goal (a rank correlation near -1); on the site as built the class only says
    what the obstacles would have left clear."""
    from ms_construction.planning import MotionPlanningExpert

    classes = LAYOUT_GROUPS["clear-way"]
    lines = ["| task | clear way among the obstacles | scene | expert episodes placed | carry against the step: rank "
             "correlation, median (worst) | held steps beyond the carry range %, median (worst) | carry at the grasp / "
             "its most, median (rad) |", "|---|---|---|---|---|---|---|"]
    for kind, env_id in PAPER_TASK_ENV_IDS.items():
        solved = [e["seed"] for e in json.loads((out / f"expert_static_{kind}.json").read_text())["episodes"]
                  if e["placed"]]
        found = layouts(env_id, solved)
        picked = {c: [s for s in solved if found[s]["clear-way"] == c][:per_class] for c in classes}
        rows: dict[tuple[str, str], list[dict]] = {}
        for scene in ("none", "static"):
            env = HeldCarries(gym.make(env_id, num_envs=1, obs_mode="state", control_mode="pd_joint_pos",
                                       reward_mode="dense", sim_backend="physx_cpu", curriculum_stage=FINAL_STAGE,
                                       obstacles=None if scene == "none" else scene))
            expert = MotionPlanningExpert(env)
            for c, seeds in picked.items():
                for seed in seeds:
                    env.carries.clear()
                    if expert.run(seed).placed and env.carries:
                        rows.setdefault((c, scene), []).append(carry_course(env.carries, env.unwrapped.CARRY_RANGE))
            expert.close()
            env.close()
        for c in classes:
            for scene in ("none", "static"):
                if not (courses := rows.get((c, scene))):
                    continue
                rho, beyond = [x["rho"] for x in courses], [x["beyond"] for x in courses]
                lines.append(f"| {kind} | {c} | {scene} | {len(courses)} of {len(picked[c])} | {np.median(rho):.2f} "
                             f"({max(rho):.2f}) | {100 * np.median(beyond):.0f} ({100 * max(beyond):.0f}) | "
                             f"{np.median([x['first'] for x in courses]):.1f} / "
                             f"{np.median([x['most'] for x in courses]):.1f} |")
    return lines


def touches_by(group: str, start: str, learner: Optional[str], share: float, out: Path,
               reward: int = OBSTACLE_REWARD) -> list[str]:
    """A row per task and agent (BLIND, then each seed's evaluated snapshots of the run, as `snapshot_table` finds
    them): of the static scene's episodes in each of `group`'s classes (LAYOUT_GROUPS), how many it placed its
    element in and how many it touched an obstacle in (the rest ran out of steps untouched)."""
    agents = {BLIND: row_name(AGENTS[BLIND])}
    for seed, (name, steps) in evaluated_snapshots(start, learner, share, out, reward).items():
        for step in steps:
            agents[f"seed {seed} at {step:,} env steps"] = f"{name}_candidate_{step}"
    classes = LAYOUT_GROUPS[group]
    lines = ["| task | agent | " + " | ".join(f"{group.replace('-', ' ')} {c}: placed / touched / episodes"
                                          for c in classes) + " |",
             "|---|---|" + "---|" * len(classes)]
    for kind, env_id in PAPER_TASK_ENV_IDS.items():
        found = None
        for label, name in agents.items():
            path = out / f"{name}_static_{kind}.json"
            if not path.is_file():
                continue
            episodes = json.loads(path.read_text())["episodes"]
            found = found or layouts(env_id, [e["seed"] for e in episodes])
            cells = []
            for c in classes:
                members = [e for e in episodes if found[e["seed"]][group] == c]
                cells.append(f"{sum(e['placed'] for e in members)} / {sum(e['collided'] for e in members)} / "
                             f"{len(members)}")
            lines.append(f"| {kind} | {label} | " + " | ".join(cells) + " |")
    return lines


def first_touches(checkpoint: str, env_id: str, seeds: list[int]) -> list[dict]:
    """Each seed's static-scene episode of a policy (its mean action, as evaluated) replayed to its first touch of
    an obstacle or its end: the control step, whether it touched one and had picked its element up by then, the
    turret's angle (joint 1) there, and whether the dense reward's reach measures toward the turret side it had
    turned to (`CarryGeometry.path_sides`: +pi for a turret at or above 0, -pi below). Not always quite the
    evaluated episode: the physics carries state from one episode to the next, and the evaluation ran the seeds in
    another order, in two processes (a touch may come a step later, or not at all)."""
    from mani_skill.utils.gym_utils import find_max_episode_steps_value

    from baselines.ppo.checkpoints import load_policy

    agent, env_kwargs = load_policy(Path(checkpoint), env_id)
    env = gym.make(env_id, num_envs=1, obs_mode="state", reward_mode="sparse", sim_backend="physx_cpu",
                   curriculum_stage=FINAL_STAGE, obstacles="static", **{"obs_obstacles": False, **env_kwargs})
    u, found = env.unwrapped, []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        sides = u.geometry.path_sides(u.task_id, u.goal_slot, u.obstacle_ways())[0]
        for step in range(1, find_max_episode_steps_value(env) + 1):
            with torch.no_grad():
                obs, _, terminated, truncated, info = env.step(agent.get_action(obs, deterministic=True))
            if bool(info["obstacle_collision"][0] | terminated[0] | truncated[0]):
                break
        turret = float(u.agent.robot.get_qpos()[0, 0])
        found.append(dict(seed=seed, step=step, touched=bool(info["obstacle_collision"][0]),
                          picked=bool(info["picked"][0]), turret=turret, toward=bool(sides[0 if turret >= 0 else 1])))
    env.close()
    return found


def reach_touches(start: str, learner: Optional[str], share: float, out: Path,
                  reward: int = OBSTACLE_REWARD) -> list[str]:
    """A row per task and agent (BLIND, then each seed's latest evaluated snapshot of the run): of the static
    scene's episodes it touched an obstacle in before picking its element up (its JSONs in `out`), replayed by
    `first_touches`, how many the replay touched before the pick too, and of those how many with the turret turned
    toward a side the dense reward's reach measures toward and how many away from it, and the control steps of the
    touches."""
    agents = {BLIND: AGENTS[BLIND]}
    for seed, (name, steps) in evaluated_snapshots(start, learner, share, out, reward).items():
        if steps:
            agents[f"seed {seed} at {steps[-1]:,} env steps"] = str(
                candidate_path(training_run(start, seed, None, learner, share, reward), steps[-1]))
    lines = ["| task | agent | touched before the pick | replayed to a touch before the pick | turret turned toward the "
             "reach's side | away from it | control step of the touch (median, range) |", "|---|---|---|---|---|---|---|"]
    for kind, env_id in PAPER_TASK_ENV_IDS.items():
        for label, checkpoint in agents.items():
            path = out / f"{row_name(checkpoint)}_static_{kind}.json"
            if not path.is_file():
                continue
            seeds = [e["seed"] for e in json.loads(path.read_text())["episodes"] if e["collided"] and not e["picked"]]
            found = first_touches(checkpoint, env_id, seeds) if seeds else []
            same = [f for f in found if f["touched"] and not f["picked"]]
            toward = sum(f["toward"] for f in same)
            steps = sorted(f["step"] for f in same)
            when = f"{int(np.median(steps))} ({steps[0]}-{steps[-1]})" if steps else "-"
            lines.append(f"| {kind} | {label} | {len(seeds)} | {len(same)} | {toward} | {len(same) - toward} | {when} |")
    return lines


def main(args: Args) -> dict:
    if args.training_curve:
        print(f"wrote {training_curve()}")
        return {}
    if args.episodes < 1 or args.workers < 1:
        raise SystemExit("--episodes and --workers must be positive")
    if args.carry_along_expert > 0:
        print("\n".join(carry_along_expert(args.out, args.carry_along_expert)))
        return {}
    args.agents = with_more_agents(args.agents, args.more_agents)
    if args.train is not None:
        if args.snapshot_table:
            print("\n".join(snapshot_table(args.train, args.learner, args.share, args.out, args.obstacle_reward)))
            return {}
        if args.reach_touches:
            print("\n".join(reach_touches(args.train, args.learner, args.share, args.out, args.obstacle_reward)))
            return {}
        if args.touches_by:
            print("\n".join(touches_by(args.touches_by, args.train, args.learner, args.share, args.out,
                                        args.obstacle_reward)))
            return {}
        run = training_run(args.train, args.train_seed, args.num_envs, args.learner, args.share, args.obstacle_reward)
        if not args.evaluate:
            if args.obstacle_reward not in TRAINABLE:
                raise SystemExit(f"--obstacle-reward {args.obstacle_reward}: that reward is gone; its runs can be "
                                 f"evaluated (--evaluate) and tabulated, and trained on "
                                 f"{' or '.join(map(str, TRAINABLE))} only")
            return transfer.train(run, args.dry_run)
        step, policy = trained_policy(run)
        label = trained_label(args.train, args.learner, args.share, args.obstacle_reward, args.train_seed, step)
        args.agents = {**args.agents, label: str(policy)}
    command = " ".join(["python -m experiments.obstacles", *map(shlex.quote, sys.argv[1:])])
    rows: dict[tuple[str, str], dict[str, dict]] = {}
    giving_way = []
    with mp.get_context("spawn").Pool(args.workers) as pool:
        for kind, env_id in PAPER_TASK_ENV_IDS.items():
            tried = list(range(args.seed, args.seed + args.episodes))
            static = run_row(pool, args.out / f"expert_static_{kind}.json", _expert_episode,
                             [(env_id, "static", s) for s in tried], tried, f"expert static {kind}")
            solvable = ("planning expert", "static: which seeds are solvable")
            rows.setdefault(solvable, {})[env_id] = summarize(static, True)
            seeds = [e["seed"] for e in static if e["placed"]]
            moving = run_row(pool, args.out / f"expert_moving_{kind}.json", _expert_episode,
                             [(env_id, "moving", s) for s in seeds], seeds, f"expert moving {kind}")
            rows.setdefault(("planning expert", "moving (solvable seeds)"), {})[env_id] = s = summarize(moving, True)
            giving_way.append(f"{kind} {s['replans_per_episode']:.2f} / {s['escapes_per_episode']:.2f} / "
                              f"{s['waited_steps_per_episode']:.1f}")
            for label, checkpoint in args.agents.items():
                name = row_name(checkpoint)
                for scene in SCENES:
                    episodes = run_row(pool, args.out / f"{name}_{scene}_{kind}.json", _agent_episode,
                                       [(checkpoint, env_id, scene, s) for s in seeds], seeds, f"{name} {scene} {kind}",
                                       checkpoint)
                    rows.setdefault((label, scene + " (solvable seeds)"), {})[env_id] = summarize(episodes, False)
    earlier = earlier_versions()
    front = {key: per_task for key, per_task in rows.items() if key[0] not in earlier}
    body = ("## A site that changes: obstacles, zero-shot\n\n"
            f"The moving scene, each agent (the expert's solvable seeds; every scene below; the snapshots of earlier "
            f"versions of training among obstacles: [their table](experiments/{VERSIONS_PATH.name}"
            "#every-version-trained-among-obstacles)):\n\n"
            f"{table(front, TRAIN_SCENE)}\n\n"
            "<details><summary>Every scene: the site as built, static and moving obstacles; the command</summary>\n\n"
            f"Command: `{command}`\n\n{table(front)}\n\n</details>\n\n"
            "Scenes: none (the site as trained on), static (a material stack and a scaffold post, seeded per episode), "
            "moving (the same, and a worker walking across the cell once). Episodes: per task, the seeds of "
            f"{args.seed}..{args.seed + args.episodes - 1} whose static scene the planning expert solved (the full table's first "
            "row: how many it solved). A touch on an obstacle ends the episode, failed. The shipped agents meet the "
            "obstacles blind (trained without them, no obstacle entry in their observation); an agent labelled "
            "'trained among obstacles' is the from-scratch recipe's run on the moving scene (`--train`), which observes "
            "them. Compute per decision: the expert's "
            "planning, replanning and path watching per control step; an agent's forward pass per step (one CPU "
            "thread).\n\n"
            "The expert giving way to the walking worker, per episode (replans / steps out of its way / control steps "
            f"held still): {'; '.join(giving_way)}.\n")
    print(body)
    summary = {f"{label} | {scene}": per_task for (label, scene), per_task in rows.items()}
    if args.write_results:  # the table and its JSON (which experiments/summary.py reads) are one measurement
        (args.out / "summary.json").write_text(json.dumps({"command": command, "rows": summary}, indent=1) + "\n")
        update_section(RESULTS_PATH, "obstacles-zero-shot", title="Results", body=body)
        versions = {key: per_task for key, per_task in rows.items()
                    if key[0] == "planning expert" or key[0].endswith(TRAINED)}
        update_section(VERSIONS_PATH, "obstacle-versions", title="Generalization", body=(
            "## Every version trained among obstacles\n\n"
            "Each snapshot of experiments/obstacles.py SHOWN, the moving scene (the expert beside them; every scene "
            "below); the versions: OBSTACLE_REWARDS there. RESULTS shows today's version's.\n\n"
            f"{table(versions, TRAIN_SCENE)}\n\n"
            "<details><summary>Every scene</summary>\n\n"
            f"Command: `{command}`\n\n{table(versions)}\n\n</details>\n"))
        print(f"wrote {RESULTS_PATH}, {VERSIONS_PATH} and {args.out / 'summary.json'}")
    return summary


if __name__ == "__main__":
    main(tyro.cli(Args))
