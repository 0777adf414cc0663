"""A residual policy on a frozen base policy (ResiP, Ankile et al. 2024): PPO learns a small Gaussian
correction to the actions of a behaviour clone, which stays as it is.

The policy's mean is `base(x) + scale * residual(z, base(x))`, where z is the observation as the base
normalizes it (its rotation features and frozen statistics), and its standard deviation is
`scale * exp(log_std)`. The residual's output layer starts at zero, so before any update the policy's
deterministic action is exactly the clone's; the critic sees the same inputs. To PPO it is an Agent
like any other (same methods), so rollouts, updates, checkpoints and evaluation do not change.

With `time_input` the observation ends with the episode's elapsed time (the tasks' `obs_elapsed_time`):
the residual and the critic see it, the base (trained without it) sees the observation without it. A
correction that knows how much of the step limit is left can hurry a late episode, and a critic that
knows it can value an episode the limit will cut (ppo.py's `--bootstrap-at-done terminated`).

A ResidualAgent can itself be the base of another (a second round of refinement on a refined agent):
as a base it offers what an Agent offers a residual, `normalize` and `actor_mean` of the normalized
observation, so the corrections add up; a base that sees the time cannot (its `actor_mean` would need it).
"""

from __future__ import annotations

import torch
import torch.nn as nn
from torch.distributions.normal import Normal

from baselines.ppo.networks import Agent, mlp


class ResidualAgent(nn.Module):
    """`base` (frozen) plus a learnt correction; see the module docstring.

    Args:
        base: the base policy (its weights are never updated; its observation statistics stay).
        hidden: width of the residual's and the critic's hidden layers.
        scale: the correction's scale in action units (ResiP: 0.1), so that the residual's own
            outputs and noise live on the scale of the other networks'.
        init_log_std: the correction's log standard deviation before scaling, at the start.
        value_heads: the critic's outputs (one per reward signal).
        time_input: the observation's last entry is the elapsed time, for the residual and the critic only.
    """

    def __init__(self, base: Agent, hidden: int, scale: float = 0.1, init_log_std: float = -0.5, value_heads: int = 1,
                 time_input: bool = False):
        super().__init__()
        self.base = base.requires_grad_(False)
        act_dim = base.actor_logstd.shape[-1]
        in_dim = base.obs_rms.mean.shape[0] + act_dim + int(time_input)
        self.scale, self.time_input = scale, time_input
        self.residual_mean = mlp(in_dim, act_dim, hidden)
        nn.init.zeros_(self.residual_mean[-1].weight)
        nn.init.zeros_(self.residual_mean[-1].bias)
        self.actor_logstd = nn.Parameter(torch.full((1, act_dim), init_log_std))
        self.critic = mlp(in_dim, value_heads, hidden, out_std=1.0)

    @property
    def obs_rms(self):
        return self.base.obs_rms

    def features(self, x):
        return self.base.features(x[..., :-1] if self.time_input else x)

    def normalize(self, x):
        """The observation as the innermost base normalizes it (without the time entry)."""
        return self.base.normalize(x[..., :-1] if self.time_input else x)

    def actor_mean(self, z):
        """The policy's mean from a normalized observation: what a residual on this agent adds its correction to."""
        if self.time_input:
            raise ValueError("a residual that sees the elapsed time cannot be another residual's base")
        with torch.no_grad():
            base_action = self.base.actor_mean(z)
        return base_action + self.scale * self.residual_mean(torch.cat([z, base_action], -1))

    def _inputs_and_mean(self, x):
        with torch.no_grad():
            z = self.normalize(x)
            base_action = self.base.actor_mean(z)
        inputs = torch.cat([z, base_action, x[..., -1:]] if self.time_input else [z, base_action], -1)
        return inputs, base_action + self.scale * self.residual_mean(inputs)

    def _std(self, mean):
        return self.scale * torch.exp(self.actor_logstd.expand_as(mean))

    def correction(self, x):
        """The residual's output before scaling (zero at the start): what --residual-l2-coef keeps small."""
        return self.residual_mean(self._inputs_and_mean(x)[0])

    def get_value(self, x):
        return self.critic(self._inputs_and_mean(x)[0])

    def get_action(self, x, deterministic=False):
        _, mean = self._inputs_and_mean(x)
        return mean if deterministic else torch.normal(mean, self._std(mean))

    def get_action_and_value(self, x, action=None):
        inputs, mean = self._inputs_and_mean(x)
        probs = Normal(mean, self._std(mean))
        if action is None:
            action = probs.sample()
        return action, probs.log_prob(action).sum(1), probs.entropy().sum(1), self.critic(inputs)
