"""PPO's update on one rollout: advantages (GAE, with the choice of which episode ends bootstrap) and
the clipped objective, with Adam fused. ppo.py's training loop calls them once per iteration."""

from __future__ import annotations

from collections import defaultdict
from typing import Optional

import numpy as np
import torch
import torch.nn as nn
import torch.optim as optim

from baselines.ppo.curiosity import ICM, joins_extrinsic_reward
from baselines.ppo.networks import Agent


def bootstrap_mask(terminated: torch.Tensor, truncated: torch.Tensor, bootstrap_at_done: str) -> torch.Tensor:
    """1 where an episode ended ([steps, envs]) and bootstraps with the value of its last observation."""
    ends = {"always": terminated + truncated, "truncated": truncated, "terminated": terminated,
            "never": torch.zeros_like(truncated)}
    return ends[bootstrap_at_done].clamp(max=1)


def gae(rewards: torch.Tensor, values: torch.Tensor, next_value: torch.Tensor, final_values: torch.Tensor,
        dones: torch.Tensor, gamma: float, gae_lambda: float) -> torch.Tensor:
    """Generalized advantage estimates of a rollout ([steps, envs]): `values` V(s_t), `next_value`
    V(s) after the last step, `final_values` the value an episode that ended at step t bootstraps with
    (V of its last observation where it does, see `bootstrap_mask`, else 0), `dones` where episodes ended."""
    advantages = torch.zeros_like(rewards)
    lastgaelam = torch.zeros_like(next_value)
    for t in reversed(range(len(rewards))):
        boot = next_value if t == len(rewards) - 1 else values[t + 1]
        v = torch.where(dones[t].bool(), final_values[t], boot)
        delta = rewards[t] + gamma * v - values[t]
        lastgaelam = delta + gamma * gae_lambda * (1 - dones[t]) * lastgaelam
        advantages[t] = lastgaelam
    return advantages


def signal_advantages(args, rewards: torch.Tensor, intrinsic: torch.Tensor, values: torch.Tensor,
                      next_value: torch.Tensor, final_values: torch.Tensor, dones: torch.Tensor,
                      terminated: torch.Tensor, failed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The advantages [steps, envs] and the value heads' returns [steps, envs, heads] of a rollout, one GAE per
    reward signal with the settings of `args` (ppo.py's Args): the extrinsic signal (`rewards`, plus the
    `intrinsic` reward for `icm_normalized`) with `gamma`, bootstrapping at the episode ends
    `bootstrap_at_done` names; with `icm` (ML-Agents' curiosity, two value heads) the intrinsic signal too,
    with `icm_gamma` and a bootstrap at every episode end (curiosity ignores them). `values`, `next_value` and
    `final_values` hold one column per head; the advantage is the mean of the signals' (ML-Agents). With
    `success_value="absorbing"` an episode that ended by success and bootstraps there (dense rewards) takes the
    value of staying in its last state for ever, its reward / (1 - gamma), not the critic's guess: the critic
    never trains on a state after success (the env resets), and a guess below that lets holding near the goal
    outvalue placing. An episode that ended by failure (`failed`, among `terminated`: a touch of an obstacle) has
    nothing after it on the extrinsic signal, whatever `bootstrap_at_done` says."""
    truncated = dones - terminated
    extrinsic = rewards + intrinsic if joins_extrinsic_reward(args.icm.curiosity) else rewards
    if args.ppo.success_value == "absorbing":
        final_values = final_values.clone()
        success = terminated.bool() & ~failed.bool()
        final_values[..., 0] = torch.where(success, extrinsic / (1 - args.ppo.gamma), final_values[..., 0])
    extrinsic_mask = bootstrap_mask(terminated, truncated, args.ppo.bootstrap_at_done) * (1 - failed)
    signals = [(extrinsic, args.ppo.gamma, extrinsic_mask)]
    if values.shape[-1] == 2:
        signals.append((intrinsic, args.icm.icm_gamma, dones))
    advantages = torch.stack([gae(r, values[..., h], next_value[:, h], final_values[..., h] * mask, dones, gamma,
                                  args.ppo.gae_lambda) for h, (r, gamma, mask) in enumerate(signals)], -1)
    return advantages.mean(-1), advantages + values


def hold_log_std_floor(agent: Agent, args) -> None:
    """Raise the policy's log standard deviation to `args.ppo.log_std_floor` where it lies below, on
    `args.ppo.log_std_floor_joints` (all when None); nothing when the floor is off."""
    if args.ppo.log_std_floor is None:
        return
    joints = list(args.ppo.log_std_floor_joints or range(agent.actor_logstd.shape[-1]))
    with torch.no_grad():
        agent.actor_logstd[:, joints] = agent.actor_logstd[:, joints].clamp(min=args.ppo.log_std_floor)


def ppo_update(agent: Agent, optimizer: optim.Optimizer, batch: dict, args, icm: Optional[ICM] = None,
               icm_optimizer: Optional[optim.Optimizer] = None, demos: Optional[tuple] = None,
               value_only: bool = False) -> dict[str, float]:
    """PPO's clipped update on one rollout, with the settings of `args` (ppo.py's Args): `batch` holds obs,
    next_obs, actions, logprobs and advantages, flat over steps and envs, and returns and values [batch,
    value heads] (the value loss is the mean of the heads'). `args.ppo.update_epochs` epochs of
    `args.ppo.num_minibatches` shuffled minibatches (numpy's RNG), stopping after an epoch whose last minibatch's approximate KL
    exceeds `args.ppo.target_kl`; ICM learns on the same minibatches. `demos` (obs, actions) add a
    behaviour-cloning term, `args.warm.residual_l2_coef` a pull of a residual agent's correction towards zero,
    `args.ppo.mean_saturation_coef` a pull of the bounded mean's values before tanh back within
    +-`args.ppo.mean_saturation_bound` (`log_std_floor` holds the spread after every step); `value_only` trains
    the critic alone (the warm-up). The mean of each loss."""
    batch_size = len(batch["obs"])
    minibatch_size = batch_size // args.ppo.num_minibatches
    b_inds = np.arange(batch_size)
    advantages = batch["advantages"]
    if args.ppo.norm_adv == "batch":
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    losses = defaultdict(list)  # tensors, read once at the end: a .item() per loss per minibatch costs more
    for _epoch in range(args.ppo.update_epochs):
        np.random.shuffle(b_inds)
        for start in range(0, batch_size, minibatch_size):
            mb = torch.from_numpy(b_inds[start:start + minibatch_size]).to(batch["obs"].device)
            obs, actions = batch["obs"][mb], batch["actions"][mb]
            _, newlogprob, entropy, newvalue = agent.get_action_and_value(obs, actions)
            logratio = newlogprob - batch["logprobs"][mb]
            ratio = logratio.exp()
            with torch.no_grad():
                approx_kl = ((ratio - 1) - logratio).mean()
            mb_adv = advantages[mb]
            if args.ppo.norm_adv == "minibatch":
                mb_adv = (mb_adv - mb_adv.mean()) / (mb_adv.std() + 1e-8)
            pg_loss = torch.max(-mb_adv * ratio, -mb_adv * torch.clamp(ratio, 1 - args.ppo.clip_coef, 1 + args.ppo.clip_coef)).mean()
            mb_ret = batch["returns"][mb]
            if args.ppo.clip_vloss:
                mb_val = batch["values"][mb]
                v_clipped = mb_val + torch.clamp(newvalue - mb_val, -args.ppo.clip_coef, args.ppo.clip_coef)
                v_loss = 0.5 * torch.max((newvalue - mb_ret) ** 2, (v_clipped - mb_ret) ** 2).mean()
            else:
                v_loss = 0.5 * ((newvalue - mb_ret) ** 2).mean()
            entropy_loss = entropy.mean()
            loss = pg_loss - args.ppo.ent_coef * entropy_loss + v_loss * args.ppo.vf_coef
            if args.ppo.mean_saturation_coef > 0:
                beyond = (agent.mean_before_tanh(obs).abs() - args.ppo.mean_saturation_bound).clamp(min=0)
                if args.ppo.mean_saturation_joints is not None:
                    beyond = beyond[:, list(args.ppo.mean_saturation_joints)]
                saturation = beyond.pow(2).sum(-1).mean()
                loss = loss + args.ppo.mean_saturation_coef * saturation
                losses["mean_saturation"].append(saturation.detach())
            if demos is not None and args.warm.bc_coef > 0:
                d = torch.randint(len(demos[0]), (len(mb),), device=mb.device)
                bc_loss = ((agent.actor_mean(agent.normalize(demos[0][d])) - demos[1][d]) ** 2).mean()
                loss = loss + args.warm.bc_coef * bc_loss
                losses["bc_loss"].append(bc_loss.detach())
            if args.warm.residual_l2_coef > 0:
                l2 = agent.correction(obs).pow(2).sum(-1).mean()
                loss = loss + args.warm.residual_l2_coef * l2
                losses["residual_l2"].append(l2.detach())
            if value_only:
                loss = v_loss * args.ppo.vf_coef
            optimizer.zero_grad()
            loss.backward()
            if args.ppo.max_grad_norm is not None:
                nn.utils.clip_grad_norm_(agent.parameters(), args.ppo.max_grad_norm)
            optimizer.step()
            hold_log_std_floor(agent, args)
            if icm is not None:
                icm_losses = icm.update(icm_optimizer, obs, batch["next_obs"][mb], actions)
                losses["icm_forward_loss"].append(icm_losses["forward"])
                losses["icm_inverse_loss"].append(icm_losses["inverse"])
            losses["value_loss"].append(v_loss.detach())
            losses["policy_loss"].append(pg_loss.detach())
            losses["entropy"].append(entropy_loss.detach())
            losses["approx_kl"].append(approx_kl)
        if args.ppo.target_kl is not None and approx_kl > args.ppo.target_kl:
            break
    return {k: torch.stack(v).double().mean().item() for k, v in losses.items()}


def adam(params, lr: float, eps: float = 1e-8) -> optim.Optimizer:
    """Adam as the policy and ICM learn with it, fused (one kernel for all tensors per step): at minibatches
    of a few dozen samples the default's loop over tensors costs about a fifth of the update."""
    return optim.Adam(params, lr=lr, eps=eps, fused=True)
