"""One episode of a policy in one env (num_envs=1): the policy's mean, actions clipped to the bounds, from a
seeded reset to the episode's end. Finding where a policy fails (baselines/ppo/start_states.py) and the
expert's takeovers from those places (planning/demos.py) run it; evaluation runs many episodes at once on a
vector env (baselines/ppo/evaluation.py, `run_episodes`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym
import torch


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


@torch.no_grad()
def policy_episode(policy, env: gym.Env, seed: int, keep_states: bool = False) -> Episode:
    """Run `policy` (anything with `get_action(obs, deterministic)`) deterministically in `env` from
    `env.reset(seed=seed)` until the episode terminates or is truncated."""
    obs, _ = env.reset(seed=seed)
    episode = Episode([], [], {})
    while True:
        if keep_states:
            episode.states.append(env.unwrapped.get_state_dict())
        episode.actions.append(policy.get_action(obs.float(), deterministic=True).clamp(-1, 1))
        obs, _, terminated, truncated, episode.info = env.step(episode.actions[-1])
        episode.place_dist.append(float(episode.info["place_dist"][0]))
        if bool(terminated[0]) or bool(truncated[0]):
            return episode
