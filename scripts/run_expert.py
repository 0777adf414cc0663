"""Run the motion-planning expert on seeded episodes: pick and place success, planning time, length.

    python scripts/run_expert.py --env-id Flooring-v1 --episodes 100 --seed 0
    python scripts/run_expert.py --env-id CeilingInstallation-v1 --episodes 3 --save-trajectory --save-video
    python scripts/run_expert.py --env-id all --episodes 100 --workers 2 --write-results   # docs/RESULTS.md
    python scripts/run_expert.py --env-id Flooring-v1 --goal-slots 1 --episodes 60     # the middle recess only

Episodes use seeds seed, seed + 1, ...; physx_cpu, one env, pd_joint_pos, state observations.
Saved trajectories (ManiSkill's RecordEpisode: <out>/<env id>.expert.h5 and .json) replay from their
actions with `python scripts/replay_trajectory.py --traj-path <out>/<env id>.expert.h5`.
OMPL seeds its sampler from the clock, so a rerun may take other paths (the IK seeds are fixed).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import platform
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import gymnasium as gym
import numpy as np
import tyro
from mani_skill.utils.wrappers import RecordEpisode
from tqdm import tqdm

import ms_construction  # noqa: F401  (registration)
from baselines.ppo.evaluation import slot_weights
from ms_construction.envs import ENV_IDS
from ms_construction.planning import ExpertConfig, MotionPlanningExpert
from ms_construction.reporting import update_section
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.curriculum import FINAL_STAGE

RESULTS_PATH = Path("docs/RESULTS.md")


@dataclass
class Args:
    env_id: str = "ConstructionPickPlace-v1"
    """task to solve, or 'all' for every task (ms_construction.envs.ENV_IDS) one after the other."""
    episodes: int = 10
    """episodes per task."""
    seed: int = 0
    """seed of the first episode; the others follow."""
    curriculum_stage: str = FINAL_STAGE
    """tolerance stage of the env (cp1..cp4)."""
    obstacles: Optional[str] = None
    """the tasks' `obstacles` option: 'static' (a material stack, a scaffold post, a standing worker) or 'moving'
    (the worker walks across); the expert plans around them and replans around the walking worker."""
    goal_slots: tuple[int, ...] = ()
    """only these goal slots (openings, recesses, bays) of every task type (the tasks' `goal_slot_weights`); default:
    every one, as the tasks draw them."""
    save_trajectory: bool = False
    """record the episodes as ManiSkill trajectories (h5 + json) under --out."""
    save_video: bool = False
    """render a video of every episode under --out."""
    out: Path = Path("outputs/expert")
    """where trajectories and videos go."""
    json: Optional[Path] = None
    """write the figures (and every episode's result) to this JSON file."""
    workers: int = 1
    """processes solving episodes in parallel (one env each); recording needs 1."""
    write_results: bool = False
    """write the table into the 'Motion-planning expert' section of docs/RESULTS.md, and its JSON (the
    figures scripts/evaluate.py --write-results sets beside the general agent's) to
    docs/data/expert_results.json unless --json names another file."""
    expert: ExpertConfig = ExpertConfig()
    """the expert's settings (margins, speeds, planning time limits); the defaults are what
    docs/RESULTS.md reports."""


def make_env(env_id: str, stage: str, render: bool = False, obstacles: Optional[str] = None,
             goal_slots: tuple[int, ...] = ()):
    return gym.make(env_id, num_envs=1, obs_mode="state", control_mode="pd_joint_pos", reward_mode="sparse",
                    sim_backend="physx_cpu", curriculum_stage=stage, render_mode="rgb_array" if render else None,
                    obstacles=obstacles, goal_slot_weights=slot_weights(goal_slots))


_worker_experts: dict = {}


def _solve(job: tuple[str, str, int, ExpertConfig, Optional[str], tuple[int, ...]]) -> dict:
    """One episode in a worker process, its env and expert kept for the next one."""
    env_id, stage, seed, config, obstacles, goal_slots = job
    key = (env_id, obstacles, goal_slots)
    if key not in _worker_experts:
        _worker_experts[key] = MotionPlanningExpert(make_env(env_id, stage, obstacles=obstacles, goal_slots=goal_slots),
                                                    config)
    return _worker_experts[key].run(seed).to_dict()


def run_env(args: Args, env_id: str) -> list[dict]:
    seeds = range(args.seed, args.seed + args.episodes)
    bar = tqdm(total=args.episodes, desc=env_id, unit="ep", dynamic_ncols=True)
    results = []
    if args.workers > 1:
        with mp.get_context("spawn").Pool(args.workers) as pool:
            jobs = [(env_id, args.curriculum_stage, s, args.expert, args.obstacles, args.goal_slots) for s in seeds]
            for r in pool.imap(_solve, jobs):
                results.append(r)
                bar.update()
                bar.set_postfix(placed=sum(x["placed"] for x in results))
    else:
        env = make_env(env_id, args.curriculum_stage, render=args.save_video, obstacles=args.obstacles,
                       goal_slots=args.goal_slots)
        record = args.save_trajectory or args.save_video
        if record:
            env = RecordEpisode(env, str(args.out), save_trajectory=args.save_trajectory, save_video=args.save_video,
                                trajectory_name=f"{env_id}.expert", video_fps=env.unwrapped.control_freq,
                                save_on_reset=False, source_type="motionplanning",
                                source_desc="ms_construction mplib RRTConnect expert")
        expert = MotionPlanningExpert(env, args.expert)
        for s in seeds:
            results.append(expert.run(s).to_dict())
            if args.save_trajectory:
                env.flush_trajectory()
            if args.save_video:
                env.flush_video(name=f"{env_id}.expert.seed{s}")
            bar.update()
            bar.set_postfix(placed=sum(x["placed"] for x in results))
        expert.close()
        env.close()
    bar.close()
    return results


def summarize(results: list[dict]) -> dict:
    plan = np.array([r["planning_time"] for r in results])
    steps = np.array([r["steps"] for r in results])
    placed_steps = steps[[r["placed"] for r in results]]
    return {
        "episodes": len(results),
        "pick_success": float(np.mean([r["picked"] for r in results])),
        "place_success": float(np.mean([r["placed"] for r in results])),
        "planning_time_mean_s": float(plan.mean()),
        "planning_time_p95_s": float(np.percentile(plan, 95)),
        "episode_length_mean": float(steps.mean()),
        "placed_length_max": int(placed_steps.max()) if len(placed_steps) else None,
    }


def table(rows: list[tuple[str, dict]]) -> str:
    lines = ["| task | episodes | pick success | place success | planning time per episode, mean / p95 (s) | "
             "episode length, mean (steps) | longest placed episode (steps) |",
             "|---|---|---|---|---|---|---|"]
    for name, s in rows:
        lines.append(f"| {name} | {s['episodes']} | {s['pick_success']:.0%} | {s['place_success']:.0%} | "
                     f"{s['planning_time_mean_s']:.2f} / {s['planning_time_p95_s']:.2f} | "
                     f"{s['episode_length_mean']:.0f} | {s['placed_length_max'] if s['placed_length_max'] else '-'} |")
    return "\n".join(lines)


def rows_of(env_id: str, results: list[dict]) -> list[tuple[str, dict]]:
    """The env's row, and for the general task one row per task type it drew."""
    rows = [(env_id, summarize(results))]
    if env_id == "ConstructionPickPlace-v1":
        for kind in ELEMENT_KINDS:
            part = [r for r in results if r["task"] == kind]
            if part:
                rows.append((f"  of which {kind}", summarize(part)))
    return rows


def failure_lines(env_ids, results: dict[str, list[dict]]) -> list[str]:
    """One line per task and distinct failure, with the seeds that ended in it."""
    seeds: dict[tuple[str, str, str], list[int]] = {}
    for env_id in env_ids:
        for r in results[env_id]:
            if not r["placed"]:
                seeds.setdefault((env_id, r["task"], r["failure"]), []).append(r["seed"])
    return [f"- {env_id} ({task}), {len(s)} episode(s), seed(s) {', '.join(map(str, s))}: {failure}"
            for (env_id, task, failure), s in seeds.items()]


def main(args: Args) -> None:
    if args.workers > 1 and (args.save_trajectory or args.save_video):
        raise SystemExit("--save-trajectory/--save-video record one env: use --workers 1")
    env_ids = ENV_IDS if args.env_id == "all" else (args.env_id,)
    results = {env_id: run_env(args, env_id) for env_id in env_ids}
    rows = [row for env_id in env_ids for row in rows_of(env_id, results[env_id])]
    failures = failure_lines(env_ids, results)
    command = "python scripts/run_expert.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    print(table(rows))
    print("\n".join(failures) or "no failures")
    if args.write_results and args.json is None:
        args.json = Path("docs/data/expert_results.json")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"command": command, "curriculum_stage": args.curriculum_stage,
                                         "summary": {name.strip(): s for name, s in rows},
                                         "episodes": results}, indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.write_results:
        update_section(RESULTS_PATH, "motion-planning-expert", title="Results", body=(
            "## Motion-planning expert\n\n"
            f"Command: `{command}`\n\n"
            "`ms_construction/planning`: mplib 0.1.1 RRTConnect on the arm's URDF/SRDF and the site's coacd convex\n"
            "parts; approach, descend until grasped, lift, carry with the element in the collision model,\n"
            f"straight install. Curriculum stage {args.curriculum_stage}, physx_cpu, pd_joint_pos at 20 Hz, "
            "at most 250 steps per episode.\nPlanning time is wall time in IK, planning, time "
            "parameterization and checks.\n\n"
            f"{table(rows)}\n\n"
            "Failures:\n\n" + ("\n".join(failures) or "none") + "\n\n"
            f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {sys.version.split()[0]}, "
            f"{args.workers} worker process(es).\n"
        ))
        print(f"wrote {RESULTS_PATH}")


if __name__ == "__main__":
    main(tyro.cli(Args))
