"""Curiosity: the Intrinsic Curiosity Module (Pathak et al. 2017), ppo.py's `--curiosity icm`."""

from __future__ import annotations

import torch
import torch.nn as nn

from baselines.ppo.networks import RunningMeanStd, mlp


class ICM(nn.Module):
    """Intrinsic Curiosity Module: encoder phi, inverse model (a from phi(s), phi(s')), forward
    model (phi(s') from phi(s), a). The encoder learns from the inverse loss only, so phi keeps what
    the agent's actions change; the forward model's error on it is the curiosity."""

    def __init__(self, obs_dim: int, act_dim: int, feature_dim: int, hidden: int):
        super().__init__()
        self.encoder = mlp(obs_dim, feature_dim, hidden, out_std=1.0, act=nn.ELU)
        self.inverse = mlp(2 * feature_dim, act_dim, hidden, out_std=1.0, act=nn.ELU)
        self.forward_model = mlp(feature_dim + act_dim, feature_dim, hidden, out_std=1.0, act=nn.ELU)
        self.error_stats = RunningMeanStd()

    def forward_error(self, obs, next_obs, action) -> torch.Tensor:
        """Per-transition forward-model error in feature space (features held fixed)."""
        phi, phi_next = self.encoder(obs).detach(), self.encoder(next_obs).detach()
        pred = self.forward_model(torch.cat([phi, action], -1))
        return 0.5 * ((pred - phi_next) ** 2).sum(-1)

    def losses(self, obs, next_obs, action) -> tuple[torch.Tensor, torch.Tensor]:
        phi, phi_next = self.encoder(obs), self.encoder(next_obs)
        inverse_loss = ((self.inverse(torch.cat([phi, phi_next], -1)) - action) ** 2).sum(-1).mean()
        return self.forward_error(obs, next_obs, action).mean(), inverse_loss

    @torch.no_grad()
    def intrinsic_reward(self, obs, next_obs, action, strength: float) -> torch.Tensor:
        err = self.forward_error(obs, next_obs, action)
        self.error_stats.update(err)
        return strength * err / torch.sqrt(self.error_stats.var + 1e-8)
