"""Curiosity (ICM, Pathak et al. 2017) computed as ML-Agents computes it, the paper's toolkit.

ML-Agents' curiosity reward signal (its `CuriosityRewardProvider` and `CuriosityNetwork`):
- an encoder phi (the reward signal's `network_settings`: two layers of 128 units, Swish, on the raw
  observation), an inverse model (a from phi(s), phi(s'); one hidden layer of 256) and a forward
  model (phi(s') from phi(s), a; one hidden layer of 256);
- the reward of a transition is the forward model's raw error, 0.5 * sum((f(phi(s), a) - phi(s'))^2),
  capped at 1 / strength and multiplied by the strength (so at most 1), and 0 until the module has
  been updated once. It is not divided by any running statistic: as the forward model learns the
  states the agent keeps visiting, the reward there fades;
- the loss is 10 * (0.2 * forward loss + 0.8 * inverse loss), and the encoder learns from both;
- the signal has its own discount and its own value head, and ignores episode ends (ppo.py).

`normalize=True` is this project's earlier variant, kept as an option and labelled as ours: the
error is divided by its running standard deviation and not capped, so the bonus never fades.
"""

from __future__ import annotations

import torch
import torch.nn as nn

LOSS_SCALE = 10.0
"""ML-Agents multiplies the curiosity loss by 10."""
MODES = ("none", "icm", "icm_normalized")
"""ppo.py's `--curiosity`: none; ML-Agents' ICM (its own value head and discount); ours, normalized and added to
the extrinsic reward. This module alone says what each mode means (the functions below)."""


def value_heads(mode: str) -> int:
    """Value heads a learner with curiosity `mode` needs: two (extrinsic, curiosity) for ML-Agents' curiosity,
    which has its own discount and ignores episode ends; one otherwise."""
    return 2 if mode == "icm" else 1


def joins_extrinsic_reward(mode: str) -> bool:
    """Whether the curiosity reward is added to the extrinsic one (our normalized variant) rather than learnt
    by its own value head."""
    return mode == "icm_normalized"


def make_icm(mode: str, obs_dim: int, act_dim: int, args) -> "ICM | None":
    """The ICM module of `mode` with ppo.py's `args` (strength, sizes, forward weight), or None without curiosity."""
    if mode == "none":
        return None
    if mode not in MODES:
        raise ValueError(f"curiosity {mode!r}: use one of {', '.join(MODES)}")
    return ICM(obs_dim, act_dim, args.icm.icm_strength, args.icm.icm_feature_dim, args.icm.icm_hidden_size, args.icm.icm_forward_weight,
               normalize=joins_extrinsic_reward(mode))


def _mlp(sizes: list[int]) -> nn.Sequential:
    """Linear layers of `sizes`, Swish between them (not after the last)."""
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes, sizes[1:])):
        layers.append(nn.Linear(n_in, n_out))
        if i < len(sizes) - 2:
            layers.append(nn.SiLU())
    return nn.Sequential(*layers)


class ICM(nn.Module):
    """Intrinsic Curiosity Module: encoder phi, inverse model, forward model, and its reward.

    Args:
        obs_dim, act_dim: sizes of the raw observation and the action.
        strength: the reward signal's strength (ML-Agents' `strength`; the paper gives none, its toolkit's
            example configuration uses 0.02).
        encoding_size: size of phi(s) and of the encoder's layers (ML-Agents: the reward signal's
            `network_settings.hidden_units`, 128 unless set; its older `encoding_size` sets the same).
        hidden: width of the inverse and forward models' hidden layer (ML-Agents: 256).
        forward_weight: the forward loss's share of the loss (ML-Agents: 0.2).
        normalize: ours, not ML-Agents': divide the error by its running std, no cap (see the module docstring).
    """

    def __init__(self, obs_dim: int, act_dim: int, strength: float, encoding_size: int = 128, hidden: int = 256,
                 forward_weight: float = 0.2, normalize: bool = False):
        super().__init__()
        if not strength > 0:
            raise ValueError(f"curiosity strength must be positive, got {strength}")
        self.strength, self.forward_weight, self.normalize = strength, forward_weight, normalize
        self.encoder = nn.Sequential(_mlp([obs_dim, encoding_size, encoding_size]), nn.SiLU())
        self.inverse = _mlp([2 * encoding_size, hidden, act_dim])
        self.forward_model = _mlp([encoding_size + act_dim, hidden, encoding_size])
        self.register_buffer("updated", torch.tensor(False))
        self.register_buffer("error_mean", torch.zeros(()))  # running statistics of the error (normalize=True)
        self.register_buffer("error_var", torch.ones(()))
        self.register_buffer("error_count", torch.tensor(1e-4))

    def forward_error(self, obs: torch.Tensor, next_obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """0.5 * sum((f(phi(s), a) - phi(s'))^2) per transition; gradients reach the encoder through both sides."""
        pred = self.forward_model(torch.cat([self.encoder(obs), action], -1))
        return 0.5 * ((pred - self.encoder(next_obs)) ** 2).sum(-1)

    def losses(self, obs: torch.Tensor, next_obs: torch.Tensor, action: torch.Tensor) -> dict[str, torch.Tensor]:
        """`loss` (what the optimizer minimizes) and its parts `forward` and `inverse`, means over the batch."""
        phi, phi_next = self.encoder(obs), self.encoder(next_obs)
        forward = (0.5 * ((self.forward_model(torch.cat([phi, action], -1)) - phi_next) ** 2).sum(-1)).mean()
        inverse = ((self.inverse(torch.cat([phi, phi_next], -1)) - action) ** 2).sum(-1).mean()
        loss = LOSS_SCALE * (self.forward_weight * forward + (1 - self.forward_weight) * inverse)
        return dict(loss=loss, forward=forward, inverse=inverse)

    def update(self, optimizer: torch.optim.Optimizer, obs, next_obs, action, max_grad_norm=None) -> dict[str, float]:
        """One optimizer step on a minibatch; the losses, detached."""
        parts = self.losses(obs, next_obs, action)
        optimizer.zero_grad()
        parts["loss"].backward()
        if max_grad_norm is not None:
            nn.utils.clip_grad_norm_(self.parameters(), max_grad_norm)
        optimizer.step()
        self.updated.fill_(True)
        return {k: v.detach() for k, v in parts.items()}

    @torch.no_grad()
    def intrinsic_reward(self, obs: torch.Tensor, next_obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """The curiosity reward of each transition (see the module docstring)."""
        err = self.forward_error(obs, next_obs, action)
        if self.normalize:
            self._update_error_stats(err)
            return self.strength * err / torch.sqrt(self.error_var + 1e-8)
        return self.strength * torch.clamp(err, max=1.0 / self.strength) * self.updated.float()

    def _update_error_stats(self, x: torch.Tensor) -> None:
        mean, var, n = x.mean(), x.var(unbiased=False), x.numel()
        delta, total = mean - self.error_mean, self.error_count + n
        self.error_mean += delta * n / total
        self.error_var.copy_((self.error_var * self.error_count + var * n + delta**2 * self.error_count * n / total) / total)
        self.error_count.fill_(total)
