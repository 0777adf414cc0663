"""Evaluate a trained agent: pick and place success (Wilson 95% intervals), return, length.

    python scripts/evaluate.py --checkpoint assets/checkpoints/general_agent.pt --env-id Flooring-v1 --episodes 100
    python scripts/evaluate.py --all --episodes 100 --json outputs/eval/general.json     # Table II
    python scripts/evaluate.py --all --steps 50000                 # the paper's protocol: 50k steps per task
    python scripts/evaluate.py --all --episodes 10 --video-dir outputs/videos             # one video per task

Episode i of a task runs from an ordinary reset with seed `--seed + i` (physx_cpu, one env per
worker process, deterministic actions: the policy's mean), at the curriculum stage given (cp4 by
default, Table I). Training never resets with seeds at or above 1,000,000 (ppo.py's and the
demonstrations' seeds lie below), the default `--seed`. Return is the extrinsic (sparse,
Algorithm 1) return. The checkpoint must fit the env: observation and action sizes and the
control mode it was trained in.

One loop runs the episodes of both (`run_episodes`): scripts/evaluate.py's, one env per worker
process, and ppo.py's evaluation during training (`evaluate_envs`), on its vector envs of either backend.
"""

from __future__ import annotations

import itertools
import json
import math
import multiprocessing as mp
import os
import shlex
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from tqdm import tqdm

from baselines import cli
from baselines.ppo.checkpoints import load_checkpoint, load_policy
from baselines.ppo.start_states import GOAL_SLOTS
from ms_construction.assets import sha256
from ms_construction.curriculum import FINAL_STAGE, STAGE_NAMES, stage_tolerances
from ms_construction.envs import ENV_IDS, PAPER_TASK_ENV_IDS
from ms_construction.envs.construction_env import ConstructionTaskEnv
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.reporting import update_section
from ms_construction.rollout import rollout

DEFAULT_CHECKPOINT = Path("assets/checkpoints/general_agent.pt")
RESULTS_PATH = Path("docs/RESULTS.md")
EXPERT_RESULTS = Path("docs/data/expert_results.json")
"""what `scripts/run_expert.py --write-results` writes beside its table in docs/RESULTS.md."""
PAPER_TABLE_II = {  # the paper's general agent at cp4: pick %, place %
    "CeilingInstallation-v1": (84.55, 68.04),
    "WindowInstallation-v1": (95.32, 84.82),
    "Flooring-v1": (88.43, 85.17),
}
PAPER_CONTROL_GROUPS = {  # the paper's control groups 4.1 / 4.2 / 4.3 (cp4 from the first step): pick %, place %
    "CeilingInstallation-v1": (63.00, 0.21),
    "WindowInstallation-v1": (62.89, 0.30),
    "Flooring-v1": (64.72, 4.45),
}


@dataclass
class Args:
    checkpoint: Path = DEFAULT_CHECKPOINT
    """a ppo.py checkpoint (or the shipped general agent)."""
    env_id: str = "ConstructionPickPlace-v1"
    """the task to evaluate on (ignored with --all)."""
    all: bool = False
    """evaluate on the three tasks (ceiling, window, flooring) and print a Table II-shaped table."""
    episodes: int = 100
    """episodes per task."""
    steps: Optional[int] = None
    """instead of --episodes: run episodes until this many env steps per task (the paper: 50000)."""
    seed: int = 1_000_000
    """seed of the first episode; the others follow."""
    curriculum_stage: str = FINAL_STAGE
    """tolerances the episodes are judged by (Table I)."""
    json: Optional[Path] = None
    """write the figures (and each episode) to this file."""
    video_dir: Optional[Path] = None
    """write a video of the first --videos episodes of every task here."""
    videos: int = 1
    """episodes per task recorded when --video-dir is given."""
    workers: int = 2
    """processes, one env each."""
    beside: tuple[str, ...] = ()
    """with --write-results: earlier agents' rows beside the table, each LABEL=JSON, a file that
    `scripts/evaluate.py --all --json` wrote (say, on the same seeds and steps)."""
    sample_actions: bool = False
    """sample each action from the policy's Gaussian (seeded by the episode's seed) instead of taking its
    mean: a diagnostic of how the policy behaves as it was trained; the published protocol is the mean."""
    max_episode_steps: Optional[int] = None
    """a diagnostic: let episodes run up to this many steps instead of the task's limit (250), to tell late
    arrivals from lost episodes; each task's results then also say what placed within the task's own limit
    (`place_success_within_limit`). The published protocol keeps the limit."""
    action_gain: float = 1.0
    """a diagnostic: multiply the policy's actions by this (then clip to [-1, 1]), to tell whether a faster policy
    would place more (the shipped agent's placed windows take 25% longer than the expert's). The published
    protocol is the policy's own actions."""
    write_results: bool = False
    """write the table (with how the agent was trained, from its checkpoint) into docs/RESULTS.md."""
    goal_slots: tuple[int, ...] = ()
    """evaluate on these goal slots only (indices 0-2, the same for every task type; default: all): the openings a
    run held out in training (ppo.py's `--goal-slot-weights` with zeros there)."""
    obstacles: Optional[str] = None
    """the tasks' `obstacles` option ('static' or 'moving'); a policy trained without them meets them blind. Each
    episode's record then says whether it collided (which ends it)."""


def command_of(args: Args) -> str:
    """The `python scripts/evaluate.py` command that makes `args` (the checkpoint and the first seed always, other
    flags where they differ from the defaults, so that a later change of a default does not change what a recorded
    command runs), so that an evaluation run from code (experiments/) writes down the command a reader can run, not
    its caller's argv."""
    values = {f.name: getattr(args, f.name) for f in fields(Args)}
    defaults = {f.name: getattr(Args(), f.name) for f in fields(Args)}
    return shlex.join(["python", "scripts/evaluate.py", *cli.flags(values, defaults, always=("checkpoint", "seed"))])


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score 95% interval of a binomial proportion."""
    if n == 0:
        return (float("nan"), float("nan"))
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def reset(envs, seed: int) -> torch.Tensor:
    """Reset every env of a vector env, env i with seed `seed + i`; the first observations."""
    obs, _ = envs.reset(seed=[seed + i for i in range(envs.num_envs)])
    return obs


def finished_episodes(infos: dict) -> dict:
    """The episodes that ended in a vector env's step (its info has "final_info"): per env, whether
    its episode ended (`ended`), and the ended episodes' place success, pick success, return and length,
    and where they ended: place distance and angle error to the goal, whether the element was held."""
    fin = infos["final_info"]
    return dict(ended=infos["_final_info"], success=fin["episode"]["success_once"], picked=fin["picked"],
                ep_return=fin["episode"]["return"], ep_length=fin["episode"]["episode_len"],
                end_place_dist=fin["place_dist"], end_place_angle_deg=fin["place_angle_deg"], held_at_end=fin["is_grasped"],
                task_id=fin["task_id"], goal_slot=fin["goal_slot"], collided=fin.get("fail", torch.zeros_like(fin["task_id"], dtype=torch.bool)), near_goal_start=fin.get("near_goal_start", torch.zeros_like(fin["task_id"], dtype=torch.bool)),
                reach_start=fin.get("reach_start", torch.zeros_like(fin["task_id"], dtype=torch.bool)),
                reach_start_grasped=fin.get("reach_start_grasped", torch.zeros_like(fin["task_id"], dtype=torch.bool)))


def failed_ends(terminations: torch.Tensor, infos: dict) -> torch.Tensor:
    """[num_envs] bool: the episodes of a vector env's step that ended by failure (ManiSkill's `info["fail"]`: among
    obstacles, a touch of one), not by success. The learners value such an end as nothing after it, where success
    is absorbing (it pays its reward for ever): a touch valued like success would pay the touching step's reward
    for ever."""
    fin = infos.get("final_info", {})
    if "fail" not in fin:
        return torch.zeros_like(terminations, dtype=torch.bool)
    return terminations.bool() & fin["fail"].to(terminations.device).bool()


def run_episodes(agent, envs, num_steps: int, seed: int, deterministic: bool = True) -> list[dict]:
    """The one evaluation loop, for ppo.py's evaluation during training and scripts/evaluate.py's seeded
    episodes: `rollout` of every env of `envs` (a vector env of either backend, or ManiSkillVectorEnv without auto
    reset) from a reset with seed `seed + i`, the policy's mean (or samples from its Gaussian) until each env's
    first episode has ended or `num_steps` have passed. A record per ended episode, in env order;
    `policy_time_s` is each episode's share of the policy's forward passes."""
    n = envs.num_envs
    records: list[Optional[dict]] = [None] * n
    policy_time = 0.0
    for step in itertools.islice(rollout(agent, envs, seed, deterministic), num_steps):
        policy_time += step.policy_time_s / n
        infos = step.info
        if "final_info" not in infos:  # an env that does not reset on its own reports its end in the step's info
            done = (step.terminated | step.truncated).cpu()
            if not done.any():
                continue
            infos = dict(final_info=infos, _final_info=done)
        ep = {k: v.cpu() for k, v in finished_episodes(infos).items()}
        for i in map(int, ep["ended"].nonzero()[:, 0]):
            if records[i] is None:
                records[i] = dict(seed=seed + i, task_id=int(ep["task_id"][i]), goal_slot=int(ep["goal_slot"][i]),
                                  picked=bool(ep["picked"][i]),
                                  placed=bool(ep["success"][i]), ret=float(ep["ep_return"][i]), length=int(ep["ep_length"][i]),
                                  policy_time_s=policy_time, final_place_dist=float(ep["end_place_dist"][i]),
                                  final_place_angle_deg=float(ep["end_place_angle_deg"][i]), held_at_end=bool(ep["held_at_end"][i]),
                                  collided=bool(ep["collided"][i]))
        if all(r is not None for r in records):
            break
    return [r for r in records if r is not None]


def evaluate_envs(agent, envs, num_steps: int, seed: int) -> dict:
    """ppo.py's evaluation during training (`run_episodes` on its evaluation envs, deterministic policy):
    the first episode of every env: pick and place success, return."""
    episodes = run_episodes(agent, envs, num_steps, seed)
    mean = lambda key: float(np.mean([e[key] for e in episodes])) if episodes else float("nan")  # noqa: E731
    return dict(eval_pick_success=mean("picked"), eval_place_success=mean("placed"), eval_extrinsic_return=mean("ret"),
                eval_episodes=len(episodes))


_worker: dict = {}


class Gain:
    """A policy whose actions are `gain` times another's (--action-gain)."""

    def __init__(self, agent, gain: float):
        self.agent, self.gain = agent, gain

    def get_action(self, x, deterministic=False):
        return self.gain * self.agent.get_action(x, deterministic=deterministic)


def episode_job(job: tuple) -> dict:
    """One seeded episode in a worker process (env and policy kept for the next job)."""
    import gymnasium as gym
    from mani_skill.utils.gym_utils import find_max_episode_steps_value
    from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

    checkpoint, env_id, stage, seed, video_dir, sample, max_steps, gain, obstacles, goal_slots = job
    torch.set_num_threads(1)
    key = (checkpoint, env_id, video_dir is not None, max_steps, obstacles, goal_slots)
    if key not in _worker:
        for _, old in _worker.values():
            old.close()
        _worker.clear()
        agent, env_kwargs = load_policy(Path(checkpoint), env_id)
        env = gym.make(env_id, obs_mode="state", reward_mode="sparse", num_envs=1, sim_backend="physx_cpu",
                       curriculum_stage=stage, render_mode="rgb_array" if video_dir else None, obstacles=obstacles,
                       goal_slot_weights=slot_weights(goal_slots), **{"obs_obstacles": False, **env_kwargs},
                       **({"max_episode_steps": max_steps} if max_steps else {}))
        if video_dir:
            from mani_skill.utils.wrappers import RecordEpisode

            env = RecordEpisode(env, str(video_dir), save_trajectory=False, save_on_reset=False, video_fps=20)
        # no auto reset: the episode's last frame ends the video, and no reset is wasted after it
        _worker[key] = (agent, ManiSkillVectorEnv(env, 1, auto_reset=False, record_metrics=True))
    agent, env = _worker[key]
    torch.manual_seed(seed)
    policy = agent if gain == 1 else Gain(agent, gain)
    [episode] = run_episodes(policy, env, find_max_episode_steps_value(env._env), seed, deterministic=not sample)
    if video_dir:
        env.call("flush_video", f"{env_id}_seed{seed}")  # (call's own first parameter is `name`)
    return episode


def slot_weights(goal_slots: tuple[int, ...]) -> Optional[dict]:
    """The tasks' `goal_slot_weights` that draw only `goal_slots` of every task type (None: all)."""
    if not goal_slots:
        return None
    return {kind: [float(i in goal_slots) for i in range(GOAL_SLOTS)] for kind in ELEMENT_KINDS}


def training_slot_weights(goal_slots: tuple[int, ...]) -> Optional[tuple[float, ...]]:
    """ppo.py's `--goal-slot-weights` that train on `goal_slots` of every paper task type only (None: all)."""
    if not goal_slots:
        return None
    return tuple(float(i in goal_slots) for _ in PAPER_TASK_ENV_IDS for i in range(GOAL_SLOTS))


def summarize(episodes: list[dict]) -> dict:
    n = len(episodes)
    by_slot = {}
    for e in episodes:
        by_slot.setdefault(e["goal_slot"], []).append(e["placed"])
    picks, places = sum(e["picked"] for e in episodes), sum(e["placed"] for e in episodes)
    return dict(
        episodes=n, steps=int(sum(e["length"] for e in episodes)),
        pick_success=picks / n, pick_success_ci95=wilson(picks, n),
        place_success=places / n, place_success_ci95=wilson(places, n),
        mean_return=float(np.mean([e["ret"] for e in episodes])),
        mean_length=float(np.mean([e["length"] for e in episodes])),
        policy_time_per_episode_s=float(np.mean([e["policy_time_s"] for e in episodes])),
        place_success_by_goal_slot={slot: float(np.mean(p)) for slot, p in sorted(by_slot.items())},
    )


def evaluate(args: Args, env_id: str, pool) -> dict:
    """Episodes of `env_id` until --episodes (or --steps) are done; their summary and list."""
    by_steps = args.steps is not None
    target = args.steps if by_steps else args.episodes
    bar = tqdm(total=target, desc=env_id, unit="step" if by_steps else "ep", dynamic_ncols=True)
    episodes: list[dict] = []
    progress = lambda: sum(e["length"] for e in episodes) if by_steps else len(episodes)  # noqa: E731

    def job(i: int, video: bool) -> tuple:
        return (str(args.checkpoint), env_id, args.curriculum_stage, args.seed + i, str(args.video_dir) if video else None,
                args.sample_actions, args.max_episode_steps, args.action_gain, args.obstacles, args.goal_slots)

    for i in range(min(args.videos, target) if args.video_dir else 0):  # the recorded episodes come first
        episodes.append(pool.apply(episode_job, (job(i, True),)))
        bar.update(min(target, progress()) - bar.n)
    while progress() < target:
        # in batches, so that no worker runs past the target; by steps, as many episodes as still fit
        left = target - progress()
        batch = len(episodes) + (left if not by_steps else max(args.workers, left // 250 + 1))
        for e in pool.imap(episode_job, [job(i, False) for i in range(len(episodes), batch)]):
            if progress() >= target:
                break
            episodes.append(e)
            bar.update(min(target, progress()) - bar.n)
            bar.set_postfix(placed=f"{sum(x['placed'] for x in episodes)}/{len(episodes)}")
    bar.close()
    within = {}
    if args.max_episode_steps:
        limit = ConstructionTaskEnv.MAX_EPISODE_STEPS
        within = dict(task_step_limit=limit, max_episode_steps=args.max_episode_steps, place_success_within_limit=sum(
            e["placed"] and e["length"] <= limit for e in episodes) / len(episodes))
    return dict(env_id=env_id, **summarize(episodes), **within, episode_results=episodes)


def failures(episodes: list[dict], stage: str = FINAL_STAGE) -> list[dict]:
    """The failed episodes, each with its kind at the stage's tolerances (Table I; cp4: 0.10 m, 20 degrees)
    and its distance and angle at the end. Kinds: dropped (the element not on the plate at the end); short
    (further from the goal than the tolerance, turned within it: on course, late or stopped); short and turned
    (off by both: lost on the way); turned (near enough, turned further than the tolerance).
    Collisions are not told apart: an element stopped by the structure ends as one of the others."""
    tol = stage_tolerances(stage)

    def kind(e: dict) -> str:
        if not e["held_at_end"]:
            return "dropped"
        short, turned = e["final_place_dist"] > tol["place"], e["final_place_angle_deg"] > tol["angle_deg"]
        return "short and turned" if short and turned else "short" if short else "turned"

    return [dict(seed=e["seed"], kind=kind(e), dist=round(e["final_place_dist"], 3),
                 angle_deg=round(e["final_place_angle_deg"], 1)) for e in episodes if not e["placed"]]


def kinds(failed: list[dict]) -> str:
    """'8 short (0.18-1.93 m), 2 short and turned (1-2.1 m, 72-156 deg), 1 turned (25-25 deg)': per kind of
    `failures`, the count and the range of its error."""
    def span(of: list[dict], key: str, unit: str) -> str:
        return f"{min(f[key] for f in of):g}-{max(f[key] for f in of):g} {unit}"

    parts = []
    for kind in ("short", "short and turned", "turned", "dropped"):
        of = [f for f in failed if f["kind"] == kind]
        if of:
            errors = ([span(of, "dist", "m")] if kind != "turned" else []) + \
                     ([span(of, "angle_deg", "deg")] if "turned" in kind else [])
            parts.append(f"{len(of)} {kind} ({', '.join(errors)})")
    return ", ".join(parts) or "none"


def pct(p: float, ci: tuple[float, float]) -> str:
    return f"{100 * p:.1f} [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]"


def table(results: dict[str, dict], expert: Optional[dict[str, str]] = None) -> str:
    """Table II's shape: per task, ours (pick, place with 95% intervals) beside the paper's general
    agent (and the planning expert's place success, when given)."""
    extra = " expert place |" if expert else ""
    lines = ["| task | episodes | pick success % [95% CI] | place success % [95% CI] | paper pick % | paper place % |"
             + extra + " mean return | mean length |", "|---|---|---|---|---|---|---|---|" + ("---|" if expert else "")]
    for env_id, r in results.items():
        paper = PAPER_TABLE_II.get(env_id, ("-", "-"))
        lines.append(f"| {env_id} | {r['episodes']} | {pct(r['pick_success'], r['pick_success_ci95'])} | "
                     f"{pct(r['place_success'], r['place_success_ci95'])} | {paper[0]} | {paper[1]} |"
                     + (f" {expert.get(env_id, '-')} |" if expert else "")
                     + f" {r['mean_return']:.2f} | {r['mean_length']:.0f} |")
    return "\n".join(lines)


def expert_place_success(path: Path = EXPERT_RESULTS) -> dict[str, str]:
    """The planning expert's place success per task ("97% of 100"), from the JSON that
    scripts/run_expert.py writes (its summary per task); none where that file is missing."""
    if not path.is_file():
        return {}
    summary = json.loads(path.read_text())["summary"]
    return {env_id: f"{s['place_success']:.0%} of {s['episodes']}" for env_id, s in summary.items()
            if env_id in PAPER_TABLE_II}


def main(args: Args) -> dict[str, dict]:
    env_ids = tuple(PAPER_TASK_ENV_IDS.values()) if args.all else (args.env_id,)
    if not args.all and args.env_id not in ENV_IDS:
        raise SystemExit(f"--env-id {args.env_id}: unknown; allowed: {', '.join(ENV_IDS)}")
    if args.curriculum_stage not in STAGE_NAMES:
        raise SystemExit(f"--curriculum-stage {args.curriculum_stage}: use one of {', '.join(STAGE_NAMES)}")
    if any(not 0 <= s < GOAL_SLOTS for s in args.goal_slots) or len(set(args.goal_slots)) != len(args.goal_slots):
        raise SystemExit(f"--goal-slots {' '.join(map(str, args.goal_slots))}: give distinct indices in 0..{GOAL_SLOTS - 1}")
    if args.episodes < 1 or (args.steps is not None and args.steps < 1) or args.workers < 1:
        raise SystemExit("--episodes, --steps and --workers must be positive")
    if args.action_gain <= 0 or (args.action_gain != 1 and args.write_results):
        raise SystemExit(f"--action-gain {args.action_gain}: a positive diagnostic; the published table (--write-results) "
                         "takes the policy's own actions")
    if (args.goal_slots or args.obstacles) and args.write_results:
        raise SystemExit("--goal-slots and --obstacles evaluate other episodes than the published table's "
                         "(--write-results): write their JSON (--json) and report it where it belongs")
    if args.sample_actions and args.write_results:
        raise SystemExit("--sample-actions is a diagnostic: the published table (--write-results) takes the policy's mean")
    if args.max_episode_steps is not None and (args.max_episode_steps < 1 or args.write_results or args.steps is not None):
        raise SystemExit(f"--max-episode-steps {args.max_episode_steps}: a positive diagnostic with --episodes; the published "
                         "table (--write-results) and the paper's protocol (--steps) keep the task's limit")
    beside = read_beside(args.beside)
    for env_id in env_ids:  # a checkpoint that does not fit fails here, before any worker starts
        load_policy(args.checkpoint, env_id)
    results = {}
    with mp.get_context("spawn").Pool(args.workers) as pool:
        for env_id in env_ids:
            results[env_id] = evaluate(args, env_id, pool)
    print(table(results))
    for env_id, r in results.items():
        if "place_success_within_limit" in r:
            print(f"{env_id}: placed {r['place_success_within_limit']:.1%} within the task's {r['task_step_limit']} steps, "
                  f"{r['place_success']:.1%} within {r['max_episode_steps']}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        command = command_of(args)
        out = results[env_ids[0]] if len(env_ids) == 1 else {"tasks": results}
        args.json.write_text(json.dumps({"command": command, "checkpoint": str(args.checkpoint),
                                         "checkpoint_sha256": sha256(args.checkpoint),
                                         "curriculum_stage": args.curriculum_stage,
                                         "sample_actions": args.sample_actions, "action_gain": args.action_gain, **out}, indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.video_dir:
        print(f"videos: {args.video_dir.resolve()}")
    if args.write_results:
        write_results(args, results, beside)
    return results


def read_labelled(specs: tuple[str, ...], option: str) -> dict[str, dict]:
    """LABEL=JSON ... (the command-line `option` that gave them): each label's file, command and per-task
    results, from a JSON that scripts/evaluate.py --json wrote (with --all, or of one task)."""
    out = {}
    for spec in specs:
        label, _, path = spec.partition("=")
        data = json.loads(Path(path).read_text()) if label and path and Path(path).is_file() else {}
        if "tasks" not in data and "place_success" not in data:
            raise SystemExit(f"{option} {spec}: use LABEL=JSON, a file that scripts/evaluate.py --json wrote")
        out[label] = dict(path=path, command=data.get("command", "?"), tasks=task_results(data))
    return out


def task_results(data: dict) -> dict[str, dict]:
    """Each task's results (by env id) in what `main` wrote with --json: {"tasks": ...} with --all, one task's
    results at the top level otherwise."""
    return data["tasks"] if "tasks" in data else {data["env_id"]: data}


def read_beside(specs: tuple[str, ...]) -> dict[str, dict]:
    """--beside LABEL=JSON ...: each label's per-task results (`read_labelled`)."""
    return read_labelled(specs, "--beside")


def beside_table(beside: dict[str, dict]) -> str:
    """Each earlier agent's row per task, pick and place with 95% intervals."""
    lines = ["| agent | task | episodes | pick success % [95% CI] | place success % [95% CI] |", "|---|---|---|---|---|"]
    for label, b in beside.items():
        for env_id, r in b["tasks"].items():
            lines.append(f"| {label} | {env_id} | {r['episodes']} | {pct(r['pick_success'], r['pick_success_ci95'])} | "
                         f"{pct(r['place_success'], r['place_success_ci95'])} |")
    return "\n".join(lines)


def write_results(args: Args, results: dict[str, dict], beside: Optional[dict[str, dict]] = None) -> None:
    """The general agent's section of docs/RESULTS.md: our Table II and the checkpoint's training record."""
    campaign = load_checkpoint(args.checkpoint).get("campaign", {})
    command = command_of(args)
    lines = ["## The general agent (our recipe)", "", f"Command: `{command}`", "",
             f"One policy (`{args.checkpoint}`, {args.checkpoint.stat().st_size / 1e6:.1f} MB) on the three tasks at "
             f"{args.curriculum_stage}; deterministic actions; ordinary seeded resets, seeds {args.seed} on "
             "(never used in training); physx_cpu, pd_joint_delta_pos at 20 Hz, at most 250 steps per episode. "
             "The paper's columns are its general agent at cp4 (Table II); the expert's, the motion-planning "
             "expert's (its own section on this page).", "", table(results, expert_place_success()), ""]
    policy_ms = 1000 * np.mean([r["policy_time_per_episode_s"] for r in results.values()])
    lines += [f"Compute per episode: the policy's forward passes take {policy_ms:.0f} ms per episode on one CPU "
              "thread (mean over the three tasks), against the planning expert's planning time per episode in "
              "the table above; both also spend the same simulation time. Load average when the evaluation ended: "
              f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (other work on the machine slows both).", ""]
    if beside:
        lines += ["Beside it, earlier agents on the same protocol (" + "; ".join(
            f"{label}: `{b['command']}`, {b['path']}" for label, b in beside.items()) + "):", "", beside_table(beside), ""]
    rows = {"this agent": results, **{label: b["tasks"] for label, b in (beside or {}).items()}}
    lines += [f"Failures by kind ({args.curriculum_stage} tolerances: short of the goal, short and turned, turned, dropped; "
              "`failures` in baselines/ppo/evaluation.py), with the range of the distance or angle at the end:", "",
              "| agent | " + " | ".join(results) + " |", "|---|" + "---|" * len(results)]
    lines += [f"| {label} | " + " | ".join(kinds(failures(tasks[e]["episode_results"], args.curriculum_stage)) if e in tasks
                                            else "-" for e in results) + " |" for label, tasks in rows.items()]
    lines.append("")
    if campaign:
        # the command as the checkpoint's record holds it, from when it ran: a module since moved keeps its old name
        lines += ["Training (the command recorded when it ran: `" + campaign["command"] + "`):", ""]
        lines += [f"- {k}: {v}" for k, v in campaign["record"].items()]
        lines.append("")
    update_section(RESULTS_PATH, "general-agent", title="Results", body="\n".join(lines))
    print(f"wrote {RESULTS_PATH}")


