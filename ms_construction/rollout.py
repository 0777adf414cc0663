"""Rolling a policy out: the one loop that evaluation (baselines/ppo/evaluation.py, `run_episodes`, many
episodes at once on a vector env), finding where a policy fails (baselines/ppo/start_states.py) and the
expert's takeovers from those places (planning/demos.py, both through `policy_episode`) step a policy with.

`rollout` yields one `Step` per env step from a seeded reset and leaves to its caller when to stop;
`policy_episode` runs one env's (num_envs=1) episode to its end."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Iterator, Optional

import gymnasium as gym
import torch


@dataclass
class Step:
    action: torch.Tensor
    """the actions taken (one row per env), as the env got them: the policy's, clipped to [-1, 1]."""
    terminated: torch.Tensor
    truncated: torch.Tensor
    info: dict
    """the step's info."""
    policy_time_s: float
    """the wall time of the policy's forward pass for this step (all envs)."""
    state: Optional[dict] = None
    """the env's state before the action (with `keep_states`)."""


@torch.no_grad()
def rollout(policy, env: gym.Env, seed: int, deterministic: bool = True, keep_states: bool = False) -> Iterator[Step]:
    """Step `policy` (anything with `get_action(obs, deterministic)`) in `env` (a ManiSkill env or vector env of n
    envs, either backend), env i reset with seed `seed + i`: its mean, or draws from its Gaussian, clipped to the
    action bounds. Yields a `Step` per env step, for as long as the caller iterates."""
    n = env.num_envs if hasattr(env, "num_envs") else env.unwrapped.num_envs
    obs, _ = env.reset(seed=[seed + i for i in range(n)])
    while True:
        state = env.unwrapped.get_state_dict() if keep_states else None
        t = time.perf_counter()
        action = policy.get_action(obs.float(), deterministic=deterministic).clamp(-1, 1)
        policy_time = time.perf_counter() - t
        obs, _, terminated, truncated, info = env.step(action)
        yield Step(action, terminated, truncated, info, policy_time, state)


@dataclass
class Episode:
    actions: list[torch.Tensor]
    """the actions taken, as the env got them."""
    place_dist: list[float]
    """the element's distance from its goal after each action (m)."""
    info: dict
    """the last step's info."""
    states: list[dict] = field(default_factory=list)
    """the env's state before each action (with `keep_states`)."""

    @property
    def placed(self) -> bool:
        return bool(self.info["success"][0])


def policy_episode(policy, env: gym.Env, seed: int, keep_states: bool = False) -> Episode:
    """`rollout` of `policy`'s mean in `env` (num_envs=1) from `env.reset(seed=seed)` until the episode
    terminates or is truncated."""
    episode = Episode([], [], {})
    for step in rollout(policy, env, seed, keep_states=keep_states):
        if keep_states:
            episode.states.append(step.state)
        episode.actions.append(step.action)
        episode.info = step.info
        episode.place_dist.append(float(step.info["place_dist"][0]))
        if bool(step.terminated[0]) or bool(step.truncated[0]):
            return episode
    raise AssertionError("unreachable: rollout never ends by itself")
