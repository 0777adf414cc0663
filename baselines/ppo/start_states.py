"""Training episodes that start where a policy failed: a bank of its states, and the wrapper that resets
a share of episodes into them.

A behaviour clone that places 96-99% teaches PPO little from ordinary resets: most episodes succeed
the same way. `collect_failure_states` runs the policy deterministically on training seeds and, where
an episode does not place, keeps the env states a few steps before the element came closest to its
goal (where the policy went wrong, as the expert takeovers of ms_construction/planning/demos.py
choose them). `StartFromStates` (a worker-side wrapper, see CPUVectorEnv's `wrappers`) resets a share
of episodes into a state drawn from that bank. An env state does not hold the episode's clock (ManiSkill's
elapsed steps), so by default the episode then has its whole time limit again; with `keep_clock` it goes
on from the step the state was taken at, so that a failure that was a late arrival stays one (most failed
windows are: docs/experiments/general_agent.md). Evaluation never uses it.

The other start states need no policy: near-goal starts (the tasks' `set_near_goal_starts`, the element held on
a path out of its goal, up to a radius per task type); `widen_near_goal` is ppo.py's rule for widening those radii,
and `failure_task_weights` its rule for sampling more of the task types whose ordinary episodes fail.

    python -m baselines.ppo.start_states --checkpoint assets/checkpoints/general_agent_clone_direct.pt --episodes 1500 \\
        --out runs/failure_states.pt
"""

from __future__ import annotations

import multiprocessing as mp
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import gymnasium as gym
import numpy as np
import torch
import tyro
from tqdm import tqdm

from baselines.ppo.args import Args as PPOArgs
from baselines.ppo.checkpoints import Progress, load_policy
from ms_construction.parameters import ELEMENT_KINDS, PAPER_KINDS
from ms_construction.rollout import policy_episode

FIRST_SEED = 430_000
"""training seeds of the bank's episodes: below the validation (500,000) and test (1,000,000) seeds, apart from
the demonstrations' and takeovers' (experiments/general_agent.py)."""


def _to_cpu(x):
    return {k: _to_cpu(v) for k, v in x.items()} if isinstance(x, dict) else x.detach().cpu().clone()


_worker: dict = {}


def _failure_states(job: tuple) -> dict:
    """One deterministic episode of the policy; the states `offsets` steps before the element's
    closest approach to its goal if it did not place (found by replaying the episode's actions from
    its seeded reset, which physx_cpu reproduces: cheaper than saving every step's state)."""
    checkpoint, env_id, seed, offsets, task_kwargs = job
    torch.set_num_threads(1)
    if "env" not in _worker:
        agent, env_kwargs = load_policy(Path(checkpoint), env_id)
        _worker.update(agent=agent, env=gym.make(env_id, obs_mode="state", reward_mode="sparse", num_envs=1,
                                                   sim_backend="physx_cpu", **env_kwargs, **(task_kwargs or {})))
    agent, env = _worker["agent"], _worker["env"]
    episode = policy_episode(agent, env, seed)
    actions, placed, task_id = episode.actions, episode.placed, int(episode.info["task_id"][0])
    kept, elapsed = [], []
    if not placed:
        wanted = steps_before_closest(episode.place_dist, offsets)
        env.reset(seed=seed)
        for t in range(wanted[-1] + 1):  # the state at step t is the one after t actions
            if t in wanted:
                kept.append(_to_cpu(env.unwrapped.get_state_dict()))
                elapsed.append(t)
            if t < wanted[-1]:
                env.step(actions[t])
    return dict(seed=seed, task_id=task_id, placed=placed, states=kept, elapsed=elapsed)


def steps_before_closest(dists: list[float], offsets: tuple[int, ...]) -> list[int]:
    """The steps (actions taken) `offsets` before the one after which the element was closest to its goal."""
    closest = int(np.argmin(dists)) + 1  # dists[i] is measured after action i, in the state at step i + 1
    return sorted({max(0, closest + k) for k in offsets})


def collect_failure_states(checkpoint: Path, episodes: int, env_id: str = "ConstructionPickPlace-v1",
                           seed: int = FIRST_SEED, offsets: tuple[int, ...] = (-30, -10), workers: int = 2,
                           env_kwargs: Optional[dict] = None) -> dict:
    """The bank: states of the failed episodes among `episodes` (see `_failure_states`), each with the
    episode's elapsed steps when it was taken, and counts. `env_kwargs`: more of the task's kwargs for the episodes
    (say, `goal_slot_weights` that draw some goal slots only)."""
    if not offsets or max(offsets) > 0:
        raise ValueError(f"offsets {offsets}: steps at or before (<= 0) the closest approach, at least one")
    jobs = [(str(checkpoint), env_id, seed + i, offsets, env_kwargs) for i in range(episodes)]
    bank, elapsed, failed, per_task = [], [], 0, np.zeros((len(ELEMENT_KINDS), 2), dtype=int)  # per task: episodes, failures
    with mp.get_context("spawn").Pool(workers) as pool:
        bar = tqdm(pool.imap(_failure_states, jobs), total=episodes, desc="failure states", unit="ep")
        for r in bar:
            per_task[r["task_id"], 0] += 1
            if not r["placed"]:
                failed += 1
                per_task[r["task_id"], 1] += 1
                bank += r["states"]
                elapsed += r["elapsed"]
            bar.set_postfix(failed=failed)
    return dict(states=bank, elapsed=elapsed, env_id=env_id, checkpoint=str(checkpoint), episodes=episodes, failed=failed,
                per_task=per_task.tolist(), offsets=list(offsets), first_seed=seed)


class StartFromStates(gym.Wrapper):
    """Resets a share of episodes into a state drawn from a bank (`collect_failure_states`'s file);
    with `keep_clock` the episode's elapsed steps are those of the state's own episode, not 0.
    Wraps a ManiSkill env of one env (physx_cpu); picklable as `functools.partial(StartFromStates,
    bank=..., share=...)` for CPUVectorEnv's workers."""

    def __init__(self, env: gym.Env, bank: str, share: float, keep_clock: bool = False):
        super().__init__(env)
        if not 0 <= share <= 1:
            raise ValueError(f"share of episodes started from the bank must lie in [0, 1], got {share}")
        saved = torch.load(bank, map_location="cpu", weights_only=False)
        self.states, self.elapsed = saved["states"], saved.get("elapsed")
        if not self.states:
            raise ValueError(f"{bank}: the bank holds no states")
        if keep_clock and (self.elapsed is None or len(self.elapsed) != len(self.states)):
            raise ValueError(f"{bank}: the bank holds no elapsed steps for its states (collected before banks kept "
                             "them): collect it again to keep the clock")
        self.share, self.keep_clock, self.rng = share, keep_clock, np.random.default_rng()

    def reset(self, **kwargs):
        if kwargs.get("seed") is not None:  # a seeded reset (each worker its own seed) seeds the draws too
            self.rng = np.random.default_rng([int(np.ravel(kwargs["seed"])[0]), 7])
        obs, info = self.env.reset(**kwargs)
        if self.rng.random() >= self.share:
            return obs, info
        u, i = self.env.unwrapped, self.rng.integers(len(self.states))
        u.set_state_dict(self.states[i])
        if self.keep_clock:  # the tensor ManiSkill's step limit and the tasks' obs_elapsed_time read
            u.elapsed_steps.fill_(int(self.elapsed[i]))
        return u.get_obs(), u.get_info()


def widen_near_goal(args: PPOArgs, progress: Progress, task_ids: list[int], placed: list[float]) -> bool:
    """Record the near-goal episodes that ended (their task types and whether they placed) and widen each task
    type's radius whose last --near-goal-window episodes placed often enough (--near-goal-promote). Once a type's
    radius is 1, with --near-goal-share-end, each such promotion lowers its share of near-goal starts by
    --near-goal-step instead, down to that end: its starts cover the whole way to the goal, and the reverse curriculum
    hands its episodes back to ordinary resets, the start distribution it is for (Florensa et al. 2017). Whether any
    radius or share changed. The windows are part of the progress: a resumed run goes on with them."""
    end, share = args.starts.near_goal_share_end, progress.near_goal_share

    def hand_back(k: int) -> bool:
        if end is None or share[k] <= end:
            return False
        share[k] = round(max(end, share[k] - args.starts.near_goal_step), 6)
        return True

    return _widen(args, progress.near_goal_radius, progress.near_goal_recent, task_ids, placed, hand_back)


GOAL_SLOTS = 3
"""goal slots per task type (the tasks' goal tables): the reach starts widen per slot."""


def widen_reach_starts(args: PPOArgs, progress: Progress, slots: list[int], grasped: list[float]) -> bool:
    """The same rule for the reach starts' radii (--reach-start-radius), one per goal slot (`slots`: task type *
    GOAL_SLOTS + goal slot), on whether each reach-start episode grasped its element from the turret side it started
    on: a slot reached from the side the policy does not grasp from widens on its own grasps alone."""
    return _widen(args, progress.reach_start_radius, progress.reach_start_recent, slots, grasped)


def _widen(args: PPOArgs, radius: list, recent: list, keys: list[int], ok: list[float],
           beyond: Callable[[int], bool] = lambda k: False) -> bool:
    """The widening rule; a key whose radius is already 1 is promoted by `beyond(key)` (whether it changed
    anything)."""
    widened = set()  # the rest of this iteration's episodes of a widened key started at the old radius
    for k, good in zip(keys, ok):
        if k in widened:
            continue
        window = recent[k]
        window.append(float(good))
        del window[:-args.starts.near_goal_window]
        if len(window) == args.starts.near_goal_window and np.mean(window) >= args.starts.near_goal_promote:
            if radius[k] < 1:
                radius[k] = round(min(1.0, radius[k] + args.starts.near_goal_step), 6)
            elif not beyond(k):
                continue
            window.clear()
            widened.add(k)
    return bool(widened)


FAILURE_WEIGHT_FLOOR = 0.1
"""--failure-task-weights: a task type that placed every recent episode still weighs this (it is still trained)."""


def failure_task_weights(args: PPOArgs, progress: Progress, task_ids: list[int], placed: list[float],
                         kinds: Sequence[int] = tuple(range(len(PAPER_KINDS)))) -> list[float]:
    """Record the ordinary-reset episodes that ended (their task types and whether they placed) and return the
    sampling probabilities of the task types `kinds` (task ids: those the env samples, the paper's three by default):
    FAILURE_WEIGHT_FLOOR + each one's failure rate over its last --failure-task-weights episodes (a type with none
    yet counts as failing all), normalized. The windows are part of the progress: a resumed run goes on with them."""
    window = args.failure_task_weights
    if progress.ordinary_recent is None:
        progress.ordinary_recent = [[] for _ in ELEMENT_KINDS]
    for k, ok in zip(task_ids, placed):
        recent = progress.ordinary_recent[k]
        recent.append(float(ok))
        del recent[:-window]
    recents = [progress.ordinary_recent[k] for k in kinds]
    weights = [FAILURE_WEIGHT_FLOOR + (1.0 - float(np.mean(r)) if r else 1.0) for r in recents]
    return [w / sum(weights) for w in weights]


@dataclass
class Args:
    checkpoint: Path
    """the policy whose failures start the episodes (a behaviour clone)."""
    out: Path
    """where the bank goes (torch file)."""
    episodes: int = 1500
    """deterministic episodes of the policy on training seeds."""
    offsets: tuple[int, ...] = (-30, -10)
    """steps before (negative) the element's closest approach to its goal at which a failed episode's states are kept."""
    env_id: str = "ConstructionPickPlace-v1"
    seed: int = FIRST_SEED
    workers: int = 2


if __name__ == "__main__":
    a = tyro.cli(Args)
    result = collect_failure_states(a.checkpoint, a.episodes, a.env_id, a.seed, a.offsets, a.workers)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(result, a.out)
    print(f"{result['failed']} of {a.episodes} episodes failed (per task [episodes, failures]: {result['per_task']}); "
          f"{len(result['states'])} states in {a.out}")
