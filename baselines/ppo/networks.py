"""The learner's networks: the Gaussian policy and value (`Agent`), its observation features and
normalization, and the MLP they and ICM (baselines/ppo/curiosity.py) are built of."""

from __future__ import annotations

from typing import Optional

import numpy as np
import torch
import torch.nn as nn
from torch.distributions.normal import Normal

from ms_construction.envs.state_layout import STATE_START
from ms_construction.rotations import qconj, qmat, qmul


def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


def mlp(n_in: int, n_out: int, hidden: int, out_std: float = np.sqrt(2), act=nn.Tanh, layers: int = 3) -> nn.Sequential:
    """`layers` hidden layers of `hidden` units (orthogonal init, as CleanRL's), then the output layer."""
    sizes = [n_in] + [hidden] * layers
    body = [m for a, b in zip(sizes, sizes[1:]) for m in (layer_init(nn.Linear(a, b)), act())]
    return nn.Sequential(*body, layer_init(nn.Linear(hidden, n_out), std=out_std))


class RunningMeanStd(nn.Module):
    """Running mean and variance (parallel algorithm) of samples of `shape` (a scalar by default),
    kept as buffers so checkpoints hold them."""

    def __init__(self, shape: tuple[int, ...] = ()):
        super().__init__()
        self.register_buffer("mean", torch.zeros(shape))
        self.register_buffer("var", torch.ones(shape))
        self.register_buffer("count", torch.tensor(1e-4))

    def update(self, x: torch.Tensor) -> None:
        x = x.reshape(-1, *self.mean.shape)
        batch_mean, batch_var, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = batch_mean - self.mean, self.count + n
        self.mean += delta * n / total
        self.var = (self.var * self.count + batch_var * n + delta**2 * self.count * n / total) / total
        self.count = total


def rotation_features(x: torch.Tensor, quat_starts: tuple[int, ...]) -> torch.Tensor:
    """`x` [..., obs_dim] with each quaternion [w, x, y, z] starting at one of `quat_starts` replaced
    by the first two columns of its rotation matrix: 6 numbers that change continuously with the
    rotation, where a quaternion jumps between q and -q (the plate's flips about w = 0 when it
    faces down; Zhou et al. 2019, on the continuity of rotation representations)."""
    quat_idx, order = _feature_layout(tuple(quat_starts), x.shape[-1], x.device)
    # one qmat call for all quaternions and one gather into place: inference runs this every env step
    cols = qmat(x[..., quat_idx].unflatten(-1, (len(quat_starts), 4)))[..., :, :2].flatten(-3)
    return torch.cat([x, cols], -1)[..., order]


_layouts: dict = {}


def _feature_layout(quat_starts: tuple[int, ...], obs_dim: int, device: torch.device):
    """(indices of the quaternions' numbers in x, order of [x, rotation columns] in the features)."""
    key = (quat_starts, obs_dim, device)
    if key not in _layouts:
        order, last = [], 0
        for i, s in enumerate(quat_starts):
            order += list(range(last, s)) + list(range(obs_dim + 6 * i, obs_dim + 6 * i + 6))
            last = s + 4
        order += list(range(last, obs_dim))
        quat_idx = [s + j for s in quat_starts for j in range(4)]
        _layouts[key] = (torch.tensor(quat_idx, device=device), torch.tensor(order, device=device))
    return _layouts[key]


class CanonicalReach:
    """Until the grasp, a mirrored window's goal orientation as it is: every opening's is the same, and the mirror
    turns it half a turn about the window's normal, which matters to the installation only. The tasks measure a
    mirrored slot's joint moves until the grasp as its twin's mirror image (`plate_turn`), so the reach and the grasp
    of a mirrored opening see what those of the opening it mirrors see.

    With `held_half_turn`, once the window is held, the goal's orientation as it is too, and joint 6, the plate and
    the window turned half a turn about the plate's axis: a window is a box, so this is a state of the twin opening
    (the joint moves unchanged), and its installation is the twin's, joint 6 included. The half turn the carry must
    add then shows at the grasp, above the staging table, where the wrist turns freely, not at the opening."""

    def __init__(self, grasped_index: int, goal_quat_start: int, held_half_turn: bool = False,
                 tcp_quat_start: int = 0, obj_quat_start: int = 0, roll_index: int = 5):
        self.grasped_index, self.goal_quat = grasped_index, slice(goal_quat_start, goal_quat_start + 4)
        self.held_half_turn = held_half_turn
        self.tcp_quat = slice(tcp_quat_start, tcp_quat_start + 4)
        self.obj_quat = slice(obj_quat_start, obj_quat_start + 4)
        self.roll_index = roll_index

    def __call__(self, x, mirrored):
        """`mirrored` (x times the mirror's signs) with the goal's orientation of `x` put back where not grasped (and,
        with `held_half_turn`, where grasped, with the half turn)."""
        out = mirrored.clone()
        out[..., self.goal_quat] = x[..., self.goal_quat]
        held = x[..., self.grasped_index] > 0.5
        if not self.held_half_turn:
            return torch.where(held[..., None], mirrored, out)
        turned = out.clone()
        tcp = mirrored[..., self.tcp_quat]
        half = torch.zeros_like(tcp)
        half[..., 3] = 1.0  # half a turn about z
        turned_tcp = qmul(tcp, half)  # about the plate's own axis
        turned[..., self.tcp_quat] = turned_tcp
        turned[..., self.obj_quat] = qmul(qmul(turned_tcp, qconj(tcp)), mirrored[..., self.obj_quat])
        turned[..., self.roll_index] = mirrored[..., self.roll_index] - np.pi
        return torch.where(held[..., None], turned, out)


class Mirror(nn.Module):
    """The mirror image of chosen states (a task whose site is symmetric in a plane): `observation` mirrors the
    observations `applies` to by `obs_signs`, `action` the actions taken in them by `action_signs`. The signs are
    buffers outside the state dict: they follow from the observation's layout, not from training."""

    def __init__(self, obs_signs: torch.Tensor, action_signs: torch.Tensor, goals: torch.Tensor,
                 canonical_reach: Optional[CanonicalReach] = None, goal_start: int = STATE_START["goal_pose"]):
        super().__init__()
        self.register_buffer("obs_signs", obs_signs.float(), persistent=False)
        self.register_buffer("action_signs", action_signs.float(), persistent=False)
        self.register_buffer("goals", goals.float(), persistent=False)
        self.goal = slice(goal_start, goal_start + 3)
        self.canonical_reach = canonical_reach

    def applies(self, x):
        """[...] bool; the observations whose task one-hot entry and goal position are those of a row of `goals` [G, 4]
        (task entry, goal x, y, z: the slots met as their twin's mirror image)."""
        task = torch.gather(x, -1, self.goals[:, 0].long().expand(*x.shape[:-1], -1)) > 0.5  # [..., G]
        at = (x[..., None, self.goal] - self.goals[:, 1:]).abs().amax(-1) < 1e-3
        return (task & at).any(-1)

    def observation(self, x):
        mirrored = x * self.obs_signs
        if self.canonical_reach is not None:
            mirrored = self.canonical_reach(x, mirrored)
        return torch.where(self.applies(x)[..., None], mirrored, x)

    def action(self, x, a):
        """`a` chosen on `observation(x)`, in the env's frame."""
        return torch.where(self.applies(x)[..., None], a * self.action_signs, a)


class Agent(nn.Module):
    """Gaussian policy and value on observation features (`rotation_features` for the quaternions
    at `quat_starts`) normalized by `obs_rms` (running mean and variance, clipped to +-10 as
    gymnasium's NormalizeObservation does; raw until it has seen data). With `bounded_mean` the policy's
    mean is squashed into the action bounds [-1, 1] by tanh (the draws around it are clipped by the learner); with
    `mirror` the networks see the mirror image of the states it applies to, and act in it."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int, quat_starts: tuple[int, ...] = (), value_heads: int = 1,
                 layers: int = 3, bounded_mean: bool = False, mirror: Optional[Mirror] = None):
        super().__init__()
        self.quat_starts = tuple(quat_starts)
        self.mirror = mirror
        feature_dim = obs_dim + 2 * len(self.quat_starts)
        self.obs_rms = RunningMeanStd((feature_dim,))
        # one value per reward signal (ML-Agents' value heads): extrinsic, and curiosity's where it has its own
        self.critic = mlp(feature_dim, value_heads, hidden, out_std=1.0, layers=layers)
        self.actor_mean = mlp(feature_dim, act_dim, hidden, out_std=0.01 * np.sqrt(2), layers=layers)
        if bounded_mean:  # within the action bounds: a mean past them, where every draw clips alike, gets no gradient
            self.actor_mean.append(nn.Tanh())
        self.actor_logstd = nn.Parameter(torch.ones(1, act_dim) * -0.5)

    def features(self, x):
        if self.mirror is not None:
            x = self.mirror.observation(x)
        return rotation_features(x, self.quat_starts) if self.quat_starts else x

    def _act(self, x, mean):
        """The policy's mean in the env's frame (mirrored back where `mirror` mirrored the state)."""
        return mean if self.mirror is None else self.mirror.action(x, mean)

    def normalize(self, x):
        x = self.features(x)
        if float(self.obs_rms.count) < 1:
            return x
        return ((x - self.obs_rms.mean) / torch.sqrt(self.obs_rms.var + 1e-8)).clamp(-10, 10)

    def get_value(self, x):
        return self.critic(self.normalize(x))

    def mean_before_tanh(self, x):
        """The bounded mean's values before its tanh (x: observations), in the env's frame."""
        return self._act(x, self.actor_mean[:-1](self.normalize(x)))

    def get_action(self, x, deterministic=False):
        """The policy's mean, or a draw from it (the draw `get_action_and_value` makes, without building a
        Normal: its argument checks cost more than the networks at a rollout step's batch of a few envs)."""
        mean = self._act(x, self.actor_mean(self.normalize(x)))
        if deterministic:
            return mean
        return torch.normal(mean, torch.exp(self.actor_logstd.expand_as(mean)))

    def get_action_and_value(self, x, action=None):
        z = self.normalize(x)
        mean = self._act(x, self.actor_mean(z))  # a sign flip per dimension: the same Gaussian's density, mirrored
        probs = Normal(mean, torch.exp(self.actor_logstd.expand_as(mean)))
        if action is None:
            action = probs.sample()
        return action, probs.log_prob(action).sum(1), probs.entropy().sum(1), self.critic(z)
