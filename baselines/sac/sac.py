"""Soft actor-critic (SAC) for the construction tasks, on a CPU.

In the shape of ManiSkill's SAC baseline (examples/baselines/sac/sac.py in the mani_skill repository; CleanRL style:
one file, read top to bottom, one `Args`): a replay buffer of preallocated torch tensors, twin Q networks with
Polyak-averaged target networks, a tanh-squashed Gaussian actor, automatic entropy tuning (target entropy -act_dim),
a fixed ratio of gradient steps to env steps (`--utd`) once `--learning-starts` env steps of uniform random actions
are in the buffer. What it takes from this project (baselines/ppo), so that it compares with PPO's from-scratch
recipe (experiments/from_scratch.py `scratch_args`):

- the envs: ConstructionPickPlace-v1 on physx_cpu, one env per process (ms_construction.vector_env.CPUVectorEnv),
  state observations with the install and path offsets, the normalized_dense reward, pd_joint_delta_pos;
- the start-state curriculum: 80% of the training episodes start near the goal (the tasks' `set_near_goal_starts`),
  each task type's radius from 0.1 widened by 0.1 once 60% of its last 20 such episodes placed
  (baselines/ppo/start_states.py `widen_near_goal`), such an episode cut after 80 steps (NearGoalTimeLimit);
  evaluation resets as usual; with --near-goal-share-end (off in the recipe), a type whose radius is 1 hands its
  near-goal starts back to ordinary resets at each further promotion, down to that share;
- episode ends: success is absorbing, its reward for ever (target r / (1 - gamma), PPO's
  `success_value="absorbing"`); a failure (`info["fail"]`: among obstacles, a touch) has nothing after it (target r);
  a time limit (or the near-goal cut) bootstraps from the final observation; gamma 0.95;
- observations normalized by running statistics, quaternions fed as rotation-matrix columns (networks.py);
- progress.csv with ppo.py's columns (checkpoints.CSVLog) plus the wall time split and SAC's losses; atomic
  checkpoints (checkpoints.save_checkpoint) with the replay buffer in a file beside them, and an exact `--resume`;
- a checkpoint's `agent` entry is the actor's mean policy in the layout of PPO's Agent (tanh hidden units, mean
  bounded by tanh: `bounded_mean`), so scripts/evaluate.py (checkpoints.load_policy) evaluates a SAC checkpoint as it
  is, on the deterministic action tanh(mean).

    python baselines/sac/sac.py --exp-name sac_scratch                       # train (runs/sac_scratch/)
    python baselines/sac/sac.py --resume runs/sac_scratch/checkpoint.pt      # continue an interrupted run
    python baselines/sac/sac.py --resume runs/sac_scratch/checkpoint.pt --extend --total-timesteps 4000000
    python baselines/sac/sac.py --evaluate --checkpoint runs/sac_scratch/checkpoint.pt --eval-episodes 50
    python scripts/evaluate.py --checkpoint runs/sac_scratch/checkpoint.pt --all      # the full evaluation

Pace on this project's 2-core machine: its gradient steps, not the simulator, set it. docs/BENCHMARKS.md ("Where
SAC's training time goes", `python scripts/benchmark.py`) measures a gradient step of actor and twin critics (2 x 256,
batch 256, one thread) against its env steps, and the ceiling the defaults' `--utd 0.5` sets: with env steps that
cost nothing it could not step faster. progress.csv's env_s, update_s and update_share say where a run's wall time
went; it prints the split at its end.

Episodes restart at every checkpoint (every `--checkpoint-freq` env steps; the cut episodes are truncations, which
bootstrap), so that a run resumed from a checkpoint repeats the uninterrupted run exactly: the same env seeds, RNG
states, replay buffer and networks. A checkpoint written on Ctrl-C or SIGTERM (between checkpoints) resumes too,
with the episodes in progress cut there. Ctrl-C or SIGTERM ends a run after the iteration in progress, with a
checkpoint; a second Ctrl-C ends it at once.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import random
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Literal, NamedTuple, Optional

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
import tyro
from tqdm import tqdm

from baselines.ppo.checkpoints import (CSVLog, Progress, check_fit, insert_filled, load_checkpoint, make_agent,
                                       policy_env_kwargs, restore_rng, save_checkpoint, StopRequest)
from baselines.ppo.evaluation import evaluate_envs, failed_ends, finished_episodes, reset, run_episodes, slot_weights, summarize
from baselines.ppo.networks import RunningMeanStd, layer_init, mlp, rotation_features
from baselines.ppo.ppo import EPISODE_STATS
from baselines.ppo.start_states import GOAL_SLOTS, widen_near_goal
from baselines.ppo.update import adam
from ms_construction.curriculum import FINAL_STAGE, STAGE_NAMES
from ms_construction.envs import ENV_IDS
from ms_construction.envs.start_states import NearGoalTimeLimit
from ms_construction.envs.state_layout import STATE_QUATERNION_STARTS
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.vector_env import CPUVectorEnv


@dataclass
class Args:
    """baselines/sac/sac.py's command line: SAC on the construction tasks with PPO's from-scratch recipe's envs and
    start states (the module docstring says what each part is)."""

    # ---- the run ----
    exp_name: Optional[str] = None
    """name of this run, its folder under --log-dir (default: sac__<env id>__s<seed>)."""
    seed: int = 1
    """seed of the run: networks, random actions, replay sampling and the envs' resets."""
    torch_deterministic: bool = True
    """`torch.backends.cudnn.deterministic` (the learner runs on the CPU, which is deterministic at a fixed thread
    count)."""
    torch_threads: int = 1
    """intra-op threads of the gradient steps (the env steps always take 1: env 0 runs in the learner's process). On
    an idle 2-core machine 2 make a gradient step about a quarter faster (the env processes wait meanwhile), but
    where other work shares the cores a descheduled thread stalls every step: measured 10 to 30 times slower."""
    save_model: bool = True
    """write checkpoints (atomically) to runs/<run>/checkpoint.pt, the replay buffer beside it."""
    evaluate: bool = False
    """only evaluate --checkpoint (deterministic actions, tanh of the actor's mean) and exit."""
    checkpoint: Optional[str] = None
    """the checkpoint --evaluate evaluates."""
    init_from: Optional[str] = None
    """start from the networks of this SAC checkpoint (actor, critics, target critics, entropy coefficient and
    observation statistics; optimizers, replay buffer and progress fresh), the actor acting from the first step (no
    random actions first): a trained agent on a new setting. Where this run's observation ends with the obstacles'
    entry and the checkpoint's did not, its networks get zero weights there: they act and value as before until
    they learn to read it. A run started so resumes from its own checkpoint (--resume), which records it."""
    resume: Optional[str] = None
    """continue the run of this checkpoint exactly: its args, networks, optimizers, replay buffer, progress, RNG."""
    extend: bool = False
    """with --resume: run to this command's --total-timesteps instead of the run's own."""
    refill_lost_buffer: bool = False
    """with --resume: where the checkpoint's replay buffer is missing (a fresh machine: the buffer, about 140 MB, is not
    committed with the checkpoint), go on with an empty one, which the actor refills for --learning-starts env steps
    before the gradient steps go on (those the refill's env steps would have had are skipped, not made up in a burst).
    Not an exact resume: the checkpoint's clock records where it happened (`refilled_at`)."""
    log_dir: str = "runs"
    """where run folders go."""

    # ---- the envs (as PPO's from-scratch recipe makes them) ----
    env_id: str = "ConstructionPickPlace-v1"
    """the task: the general task or one of the single tasks (ms_construction.envs.ENV_IDS)."""
    control_mode: Literal["pd_joint_delta_pos"] = "pd_joint_delta_pos"
    """the arm's controller (joint moves, actions in [-1, 1], what the tanh-squashed actor gives)."""
    reward_mode: Literal["normalized_dense", "dense", "sparse"] = "normalized_dense"
    """the tasks' reward: normalized_dense is the dense reward / 10 (placing pays 1 a step)."""
    obs_install_offset: bool = True
    """append the joint move to the installation configuration to the observation (the tasks' `obs_install_offset`)."""
    obs_path_offset: bool = True
    """append the joint move a little ahead along the start path (the tasks' `obs_path_offset`)."""
    goal_slots: tuple[int, ...] = ()
    """the goal slots (indices, every task type) the training envs draw, the others held out (empty: all); evaluation
    during training draws every slot."""
    obstacles: Optional[Literal["static", "moving"]] = None
    """the tasks' `obstacles` option (a site that changes), in training and evaluation; the policy observes them
    (`obs_obstacles`)."""
    obstacle_share: float = 1.0
    """with `obstacles`, the share of training episodes that have them (the tasks' `obstacle_share`: a mixed scene,
    the others on the site as built); evaluation during training: all."""
    num_envs: int = 2
    """training envs, one per process (physx_cpu): one per core of the 2-core machine."""
    total_timesteps: int = 2_000_000
    """env steps of training (all envs together)."""

    # ---- Table I's tolerances ----
    curriculum: tuple[str, ...] = (FINAL_STAGE,)
    """the tolerance stages (Table I: cp1 .. cp4) the training and evaluation envs go through in order,
    `stage_timesteps` env steps each, the last to the end (default: cp4, the tasks' own, from the first step). The
    stage moves on by env steps alone, as the paper's did; the replay buffer keeps what earlier stages paid."""
    stage_timesteps: int = 500_000
    """env steps of each stage of `curriculum` but the last."""

    # ---- where training episodes start (PPO's recipe) ----
    near_goal_share: float = 0.8
    """this share of the training episodes start with the element held on a path out of its goal (the tasks'
    `set_near_goal_starts`; 0: ordinary resets only); evaluation always resets as usual."""
    near_goal_radius: float = 0.1
    """each task type's first radius (fraction of its start paths, 0: installed)..."""
    near_goal_step: float = 0.1
    """...widened by this (up to 1) once the last `near_goal_window` near-goal episodes of its type placed at least
    `near_goal_promote` of the time (baselines/ppo/start_states.py `widen_near_goal`)."""
    near_goal_promote: float = 0.6
    """success from near-goal starts that widens a task type's radius."""
    near_goal_window: int = 20
    """near-goal episodes of a task type whose success decides a widening."""
    near_goal_share_end: Optional[float] = None
    """once a task type's radius is 1, each further promotion lowers its share of near-goal starts by
    `near_goal_step`, down to this (the curriculum handing its episodes back to ordinary resets); None: the share
    stays `near_goal_share`."""
    near_goal_max_steps: Optional[int] = 80
    """a near-goal episode that has not placed within this many steps is cut (truncated; None: the task's limit)."""
    reach_start_share: float = 0.0
    """this share of the training episodes (before near-goal starts draw theirs) start with the arm a uniform fraction
    in [0, 0.75) of the joint line from its start configuration to a table grasp configuration on a turret side the
    goal slot's start paths (among obstacles, the ways clear of them) leave from, the element lying on the table (the
    tasks' `reach_start_share`); 0 in the recipe. Their episodes are counted apart from the ordinary resets."""

    # ---- SAC ----
    gamma: float = 0.95
    """discount (PPO's recipe: values of a few dozen steps; the dense reward carries the rest)."""
    tau: float = 0.005
    """Polyak step of the target critics towards the critics, every `target_network_frequency` gradient steps."""
    buffer_size: int = 300_000
    """transitions the replay buffer holds (the latest; 300,000 x 55-number observations, about 140 MB, is
    what each checkpoint writes beside itself once full)."""
    batch_size: int = 256
    """transitions per gradient step."""
    learning_starts: int = 5_000
    """env steps of uniform random actions before the first gradient step (and before the actor acts)."""
    utd: float = 0.5
    """update-to-data ratio: gradient steps per env step (all envs together), done after each iteration's env steps
    (fractions carry over to the next iteration)."""
    steps_per_env_per_iteration: int = 1
    """env steps of every env between two rounds of gradient steps (ManiSkill's `steps_per_env_per_iteration`)."""
    policy_frequency: int = 1
    """train the actor (and the entropy coefficient) every this many critic steps, that many times (TD3's delay,
    as CleanRL)."""
    target_network_frequency: int = 1
    """move the target critics every this many gradient steps."""
    policy_lr: float = 3e-4
    """Adam learning rate of the actor."""
    q_lr: float = 3e-4
    """Adam learning rate of the critics."""
    alpha: float = 0.2
    """the entropy coefficient: fixed without --autotune, its starting value with it."""
    autotune: bool = True
    """tune the entropy coefficient towards the target entropy -act_dim."""
    alpha_lr: float = 3e-4
    """Adam learning rate of log(alpha)."""
    hidden_size: int = 256
    """width of the actor's and the critics' hidden layers."""
    num_layers: int = 2
    """hidden layers of the actor and of each critic (2 x 256: a third cheaper than 3 x 256 per gradient step)."""
    q_layer_norm: bool = True
    """LayerNorm after each hidden layer of the critics (ManiSkill's SAC default)."""
    log_std_min: float = -5.0
    """the actor's log standard deviation (before tanh) lies in [log_std_min, log_std_max]..."""
    log_std_max: float = 2.0
    """...squashed there by tanh, as SpinUp and ManiSkill."""
    reward_scale: float = 1.0
    """scale of the reward the critics learn."""
    norm_obs: bool = True
    """normalize observations by their running mean and variance (updated with every collected observation, kept in
    the actor, so in the checkpoint); the buffer keeps them raw."""
    rotation_features: bool = True
    """feed each quaternion of the state (plate, goal, element) as the first two columns of its rotation matrix
    (networks.py `rotation_features`): a quaternion's sign flips mid-episode, the matrix does not."""

    # ---- logs, evaluation, checkpoints ----
    log_freq: int = 2_000
    """a progress.csv row every this many env steps (PPO's recipe: one per 2,000-step iteration)."""
    eval_freq: int = 50_000
    """evaluate the deterministic policy every this many env steps and at the end (0: never)."""
    num_eval_envs: int = 2
    """evaluation envs (one episode each per evaluation during training; their own processes)."""
    num_eval_steps: int = 250
    """steps per evaluation episode (the tasks' limit)."""
    checkpoint_freq: int = 50_000
    """write a checkpoint every this many env steps (and at the end, and on Ctrl-C); the envs restart their episodes
    there, so that a resumed run is the uninterrupted one."""
    eval_episodes: int = 20
    """--evaluate: episodes (seeds --eval-seed on, ordinary resets, sparse reward)."""
    eval_seed: int = 1_000_000
    """--evaluate: seed of the first episode (scripts/evaluate.py's: training never resets at or above it)."""

    def flat(self) -> dict:
        """What a checkpoint saves as its args: the fields, and what checkpoints.make_agent reads to build the
        actor's mean policy as PPO's Agent (`algorithm` tells the two apart)."""
        return dict(dataclasses.asdict(self), **POLICY_ARGS)


POLICY_ARGS = dict(algorithm="sac", bounded_mean=True, curiosity="none")
"""entries of a SAC checkpoint's args beside Args' fields: the `agent` entry is PPO's Agent with its mean bounded by
tanh and one value head (unused), which scripts/evaluate.py loads (hidden_size, num_layers, rotation_features are
fields of both)."""

CSV_FIELDS = [
    "global_step", "iteration", "stage", "episodes", "pick_success", "place_success", "extrinsic_return",
    "episode_length", "end_place_dist", "end_place_angle_deg", "held_at_end", "eval_pick_success", "eval_place_success",
    "eval_extrinsic_return", "near_goal_radius", "near_goal_episodes", "near_goal_place_success",
    "ordinary_place_success", *[f"ordinary_place_{kind}" for kind in ELEMENT_KINDS],
    *[f"ordinary_pick_{kind}" for kind in ELEMENT_KINDS], *[f"ordinary_collided_{kind}" for kind in ELEMENT_KINDS],
    *[f"near_goal_radius_{kind}" for kind in ELEMENT_KINDS], *[f"near_goal_share_{kind}" for kind in ELEMENT_KINDS],
    "reach_start_episodes", "reach_start_grasp_success",
    "sps", "wall_s", "env_s", "update_s", "eval_s", "checkpoint_s", "update_share", "updates", "buffer_fill",
    "alpha", "entropy", "qf1_loss", "qf2_loss", "q_value", "actor_loss", "alpha_loss",
]
"""progress.csv's columns: ppo.py's (the same names, so experiments/from_scratch.py's and scripts/plot_training.py's
readers read them; `place_success` is the place success of the training episodes that ended since the last row,
`stage` the tolerance stage of --curriculum, cp4 by default; `ordinary_collided_<kind>`, with --obstacles, the share
of those episodes that ended on a touch of an obstacle), then SAC's: `sps` env steps per second of wall time since the last row,
`wall_s` the run's wall time so far (resumes added up), `env_s`, `update_s`, `eval_s`, `checkpoint_s` its parts in
env steps (with the actor's actions and the buffer), gradient steps, evaluations and checkpoints, `update_share`
update_s / wall_s, `updates` gradient steps so far, `buffer_fill` transitions in the buffer; the losses are means
over the gradient steps since the last row, `entropy` the actor's -log pi of its own actions."""


def validate(args: Args) -> None:
    """Refuse, before anything starts, what the run would otherwise fail on (or silently do wrong) later."""
    if args.env_id not in ENV_IDS:
        raise SystemExit(f"--env-id {args.env_id}: use one of {', '.join(ENV_IDS)}")
    if any(not 0 <= s < GOAL_SLOTS for s in args.goal_slots) or len(set(args.goal_slots)) != len(args.goal_slots):
        raise SystemExit(f"--goal-slots {' '.join(map(str, args.goal_slots))}: give distinct indices in "
                         f"0..{GOAL_SLOTS - 1}")
    if args.evaluate:
        if not args.checkpoint:
            raise SystemExit("--evaluate evaluates --checkpoint: give one")
        if args.eval_episodes < 1 or args.num_eval_envs < 1 or args.num_eval_steps < 1:
            raise SystemExit("--evaluate: --eval-episodes, --num-eval-envs and --num-eval-steps must be positive")
        return
    if args.checkpoint:
        raise SystemExit("--checkpoint is what --evaluate evaluates; to continue a run use --resume")
    if args.extend and not args.resume:
        raise SystemExit("--extend continues a run: give --resume")
    if args.utd <= 0:
        raise SystemExit(f"--utd {args.utd}: gradient steps per env step must be > 0")
    if args.batch_size < 1 or args.buffer_size < 1:
        raise SystemExit(f"--batch-size {args.batch_size} and --buffer-size {args.buffer_size} must be positive")
    if args.batch_size > args.buffer_size:
        raise SystemExit(f"--batch-size {args.batch_size} is larger than the replay buffer (--buffer-size "
                         f"{args.buffer_size}): a batch would repeat transitions; give a larger buffer or a smaller "
                         "batch")
    if not args.batch_size <= args.learning_starts <= args.buffer_size:
        raise SystemExit(f"--learning-starts {args.learning_starts}: the first gradient step needs a batch's worth of "
                         f"transitions (--batch-size {args.batch_size}) and at most a full buffer "
                         f"(--buffer-size {args.buffer_size})")
    if not 0 < args.gamma < 1:
        raise SystemExit(f"--gamma {args.gamma}: a discount in (0, 1) (success is worth its reward / (1 - gamma))")
    if not 0 < args.tau <= 1:
        raise SystemExit(f"--tau {args.tau}: the target critics' Polyak step lies in (0, 1]")
    if args.log_std_min >= args.log_std_max:
        raise SystemExit(f"--log-std-min {args.log_std_min} must lie below --log-std-max {args.log_std_max}")
    if args.alpha <= 0:
        raise SystemExit(f"--alpha {args.alpha}: the entropy coefficient must be > 0")
    for name in ("num_envs", "torch_threads", "total_timesteps", "steps_per_env_per_iteration", "policy_frequency",
                 "target_network_frequency", "hidden_size", "num_layers", "log_freq", "checkpoint_freq",
                 "near_goal_window", "num_eval_steps"):
        if getattr(args, name) < 1:
            raise SystemExit(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}")
    for name in ("policy_lr", "q_lr", "alpha_lr", "reward_scale"):
        if getattr(args, name) <= 0:
            raise SystemExit(f"--{name.replace('_', '-')} must be > 0, got {getattr(args, name)}")
    if args.eval_freq < 0 or args.num_eval_envs < 0 or (args.eval_freq > 0 and args.num_eval_envs < 1):
        raise SystemExit(f"--eval-freq {args.eval_freq} (0: never) with --num-eval-envs {args.num_eval_envs} >= 1")
    for name in ("near_goal_share", "near_goal_radius", "near_goal_promote", "reach_start_share"):
        if not 0 <= getattr(args, name) <= 1:
            raise SystemExit(f"--{name.replace('_', '-')} must lie in [0, 1], got {getattr(args, name)}")
    if args.near_goal_share_end is not None and not 0 <= args.near_goal_share_end <= args.near_goal_share:
        raise SystemExit(f"--near-goal-share-end {args.near_goal_share_end}: a share in [0, --near-goal-share "
                         f"({args.near_goal_share})]")
    if not 0 < args.near_goal_step <= 1:
        raise SystemExit(f"--near-goal-step {args.near_goal_step} must lie in (0, 1]")
    if args.near_goal_max_steps is not None and args.near_goal_max_steps < 1:
        raise SystemExit(f"--near-goal-max-steps {args.near_goal_max_steps}: a positive step count or None")
    if not args.curriculum or any(stage not in STAGE_NAMES for stage in args.curriculum):
        raise SystemExit(f"--curriculum {' '.join(args.curriculum)}: give stages among {', '.join(STAGE_NAMES)}")
    if args.stage_timesteps < 1:
        raise SystemExit(f"--stage-timesteps {args.stage_timesteps} must be positive")
    if not 0 < args.obstacle_share <= 1 or (args.obstacle_share < 1 and args.obstacles is None):
        raise SystemExit(f"--obstacle-share {args.obstacle_share}: the share of training episodes with obstacles, in "
                         "(0, 1], below 1 only with --obstacles static or moving")


# ------------------------------------------------------------------------------------------------- #
# Environments
# ------------------------------------------------------------------------------------------------- #
def env_kwargs(args: Args, train: bool = True) -> dict:
    """gym.make's kwargs of the training (or evaluation) envs: PPO's from-scratch recipe's observation, reward and
    controller (checkpoints.policy_env_kwargs reads the same fields off a checkpoint's args), the site's obstacles,
    and in training the goal slots drawn and the share of episodes with obstacles."""
    kwargs = dict(obs_mode="state", reward_mode=args.reward_mode, **policy_env_kwargs(args.flat()))
    if args.obstacles is not None:
        kwargs["obstacles"] = args.obstacles
        if train and args.obstacle_share < 1.0:
            kwargs["obstacle_share"] = args.obstacle_share
    if train and args.goal_slots:
        kwargs["goal_slot_weights"] = slot_weights(args.goal_slots)
    if train and args.reach_start_share:
        kwargs["reach_start_share"] = args.reach_start_share
    return kwargs


def make_envs(args: Args, num_envs: int, train: bool = True) -> CPUVectorEnv:
    """`num_envs` envs on physx_cpu, one per process; training envs cut near-goal episodes after
    --near-goal-max-steps (NearGoalTimeLimit; the starts themselves are set by `set_near_goal_starts`)."""
    wrappers = (NearGoalTimeLimit,) if train and args.near_goal_share > 0 and args.near_goal_max_steps else ()
    return CPUVectorEnv(args.env_id, num_envs, env_kwargs(args, train), device="cpu", wrappers=wrappers)


def stage_at(args: Args, global_step: int) -> str:
    """The tolerance stage of --curriculum the run is in at `global_step`: by env steps alone, so a resumed run is in
    the stage the uninterrupted one was."""
    return args.curriculum[min(global_step // args.stage_timesteps, len(args.curriculum) - 1)]


def set_near_goal_starts(args: Args, envs: CPUVectorEnv, progress: Progress) -> None:
    envs.call("set_near_goal_starts", tuple(progress.near_goal_share), tuple(progress.near_goal_radius),
              args.near_goal_max_steps)


def segment_seed(args: Args, global_step: int) -> int:
    """The seed the envs reset with at the start of the checkpoint interval holding `global_step` (env i: + i)."""
    return args.seed + 1000 * (global_step // args.checkpoint_freq)


# ------------------------------------------------------------------------------------------------- #
# Networks
# ------------------------------------------------------------------------------------------------- #
class Actor(nn.Module):
    """Tanh-squashed Gaussian policy on normalized observation features (`rotation_features` of the quaternions at
    `quat_starts`, then `obs_rms`, clipped to +-10: exactly PPO's Agent.normalize). Its network is PPO's policy MLP
    (networks.mlp, tanh hidden units) with twice the outputs: the mean, then the log standard deviation, both before
    the tanh squash; the deterministic action is tanh(mean)."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int, layers: int, quat_starts: tuple[int, ...] = (),
                 log_std_min: float = -5.0, log_std_max: float = 2.0):
        super().__init__()
        self.act_dim, self.quat_starts = act_dim, tuple(quat_starts)
        self.log_std_min, self.log_std_max = log_std_min, log_std_max
        feature_dim = obs_dim + 2 * len(self.quat_starts)
        self.obs_rms = RunningMeanStd((feature_dim,))
        self.net = mlp(feature_dim, 2 * act_dim, hidden, out_std=0.01, act=nn.Tanh, layers=layers)

    def features(self, x: torch.Tensor) -> torch.Tensor:
        return rotation_features(x, self.quat_starts) if self.quat_starts else x

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """The networks' input (the critics' too) for observations `x`."""
        x = self.features(x)
        if float(self.obs_rms.count) < 1:
            return x
        return ((x - self.obs_rms.mean) / torch.sqrt(self.obs_rms.var + 1e-8)).clamp(-10, 10)

    def mean_log_std(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, log_std = self.net(z).split(self.act_dim, -1)
        log_std = self.log_std_min + 0.5 * (self.log_std_max - self.log_std_min) * (torch.tanh(log_std) + 1)
        return mean, log_std

    def sample(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparameterized draw a = tanh(u), u ~ N(mean, std), and its log-probability log pi(a|z) (the Gaussian's,
        less log |da/du| = log(1 - tanh(u)^2), written stably as 2 (log 2 - u - softplus(-2u)))."""
        mean, log_std = self.mean_log_std(z)
        eps = torch.randn_like(mean)
        u = mean + log_std.exp() * eps
        log_prob = (-0.5 * eps.pow(2) - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        log_prob = log_prob - (2 * (math.log(2) - u - F.softplus(-2 * u))).sum(-1)
        return torch.tanh(u), log_prob

    def get_action(self, x: torch.Tensor, deterministic: bool = False) -> torch.Tensor:
        """The policy interface of the project's rollouts (ms_construction.rollout, evaluation.run_episodes): actions
        for observations `x`, tanh(mean) or a draw."""
        z = self.normalize(x)
        if deterministic:
            return torch.tanh(self.mean_log_std(z)[0])
        return self.sample(z)[0]


def q_mlp(n_in: int, hidden: int, layers: int, layer_norm: bool) -> nn.Sequential:
    """`layers` hidden ReLU layers of `hidden` units (with LayerNorm before each ReLU if `layer_norm`), one output."""
    sizes, body = [n_in] + [hidden] * layers, []
    for a, b in zip(sizes, sizes[1:]):
        body += [layer_init(nn.Linear(a, b))] + ([nn.LayerNorm(b)] if layer_norm else []) + [nn.ReLU()]
    return nn.Sequential(*body, layer_init(nn.Linear(hidden, 1), std=1.0))


class TwinQ(nn.Module):
    """Two soft Q networks Q(z, a) on the actor's normalized features `z` and actions `a`."""

    def __init__(self, feature_dim: int, act_dim: int, hidden: int, layers: int, layer_norm: bool):
        super().__init__()
        self.q1 = q_mlp(feature_dim + act_dim, hidden, layers, layer_norm)
        self.q2 = q_mlp(feature_dim + act_dim, hidden, layers, layer_norm)

    def forward(self, z: torch.Tensor, a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        za = torch.cat([z, a], -1)
        return self.q1(za).squeeze(-1), self.q2(za).squeeze(-1)


def ppo_agent(args: Args, actor: Actor, obs_dim: int, act_dim: int) -> nn.Module:
    """The actor's deterministic policy tanh(mean) as PPO's Agent (checkpoints.make_agent of the checkpoint's args:
    `bounded_mean`, the actor's width, depth and features), its observation statistics and policy weights copied
    (the mean's rows of the output layer); its value head and log-std are unused placeholders. What a checkpoint
    holds as `agent`, for scripts/evaluate.py and the other tools that load PPO checkpoints."""
    with torch.random.fork_rng(devices=[]):  # its throwaway initialization leaves the run's random numbers alone
        agent = make_agent(args.flat(), obs_dim, act_dim)
    with torch.no_grad():
        agent.obs_rms.load_state_dict(actor.obs_rms.state_dict())
        last = len(actor.net) - 1
        for i, layer in enumerate(actor.net):
            if isinstance(layer, nn.Linear):
                rows = slice(0, act_dim) if i == last else slice(None)
                agent.actor_mean[i].weight.copy_(layer.weight[rows])
                agent.actor_mean[i].bias.copy_(layer.bias[rows])
    return agent


# ------------------------------------------------------------------------------------------------- #
# Replay buffer
# ------------------------------------------------------------------------------------------------- #
class Batch(NamedTuple):
    obs: torch.Tensor
    next_obs: torch.Tensor
    """the observation after the action: where the episode ended there, its final observation (not the reset's)."""
    actions: torch.Tensor
    rewards: torch.Tensor
    terminated: torch.Tensor
    """bool: the episode ended there (success or failure); truncations are not marked (they bootstrap)."""
    failed: torch.Tensor
    """bool: of those, the ones that ended by failure (`info["fail"]`): nothing after it; the others, success,
    absorbing."""


class ReplayBuffer:
    """The latest `size` transitions of every env in preallocated tensors, used as a ring."""

    KEYS = Batch._fields

    def __init__(self, size: int, obs_dim: int, act_dim: int):
        self.size, self.pos, self.count = size, 0, 0
        self.obs, self.next_obs = torch.zeros(size, obs_dim), torch.zeros(size, obs_dim)
        self.actions, self.rewards = torch.zeros(size, act_dim), torch.zeros(size)
        self.terminated = torch.zeros(size, dtype=torch.bool)
        self.failed = torch.zeros(size, dtype=torch.bool)

    def add(self, *transitions: torch.Tensor) -> None:
        """One step of every env: obs, next_obs, actions, rewards, terminated, failed, each [num_envs, ...]."""
        n = len(transitions[0])
        idx = (self.pos + torch.arange(n)) % self.size
        for key, value in zip(self.KEYS, transitions):
            getattr(self, key)[idx] = value
        self.pos, self.count = (self.pos + n) % self.size, min(self.size, self.count + n)

    def sample(self, batch_size: int) -> Batch:
        """`batch_size` transitions drawn uniformly (with replacement; torch's RNG)."""
        idx = torch.randint(self.count, (batch_size,))
        return Batch(*(getattr(self, key)[idx] for key in self.KEYS))

    def state_dict(self) -> dict:
        """The filled part only (copies: torch.save of a slice would write the whole preallocated tensor)."""
        filled = {key: getattr(self, key)[:self.count].clone() if self.count < self.size else getattr(self, key)
                  for key in self.KEYS}
        return dict(size=self.size, pos=self.pos, count=self.count, **filled)

    def load_state_dict(self, state: dict) -> None:
        if state["size"] != self.size:
            raise SystemExit(f"the saved replay buffer holds {state['size']} transitions, this run's {self.size}")
        self.pos, self.count = state["pos"], state["count"]
        for key in self.KEYS:
            if key == "failed" and key not in state:  # a buffer saved before failures were told apart: none marked
                self.failed.zero_()
                continue
            getattr(self, key)[:self.count] = state[key]


# ------------------------------------------------------------------------------------------------- #
# The update
# ------------------------------------------------------------------------------------------------- #
def soft_q_target(rewards: torch.Tensor, terminated: torch.Tensor, failed: torch.Tensor, next_q: torch.Tensor,
                  next_log_pi: torch.Tensor, alpha: torch.Tensor, gamma: float) -> torch.Tensor:
    """The critics' target y for transitions (s, a, r, s'): r + gamma (min Q'(s', a') - alpha log pi(a'|s')) with
    a' ~ pi(s'), where the episode goes on or was cut by a time limit (s' its final observation); r / (1 - gamma)
    where it ended by success: the success state is absorbing and pays its reward for ever (PPO's
    `success_value="absorbing"`), not the critic's guess about a state it never trains on; r where it ended by
    failure (`failed`, a touch of an obstacle): nothing after it."""
    return torch.where(failed, rewards, torch.where(terminated, rewards / (1 - gamma),
                                                    rewards + gamma * (next_q - alpha * next_log_pi)))


@dataclass
class Learner:
    """SAC's networks and optimizers."""

    actor: Actor
    critics: TwinQ
    critics_target: TwinQ
    actor_optimizer: torch.optim.Optimizer
    q_optimizer: torch.optim.Optimizer
    log_alpha: torch.Tensor
    alpha_optimizer: Optional[torch.optim.Optimizer]
    target_entropy: float

    @classmethod
    def make(cls, args: Args, obs_dim: int, act_dim: int) -> "Learner":
        quat_starts = STATE_QUATERNION_STARTS if args.rotation_features else ()
        actor = Actor(obs_dim, act_dim, args.hidden_size, args.num_layers, quat_starts, args.log_std_min,
                      args.log_std_max)
        feature_dim = actor.obs_rms.mean.shape[0]
        critics = TwinQ(feature_dim, act_dim, args.hidden_size, args.num_layers, args.q_layer_norm)
        critics_target = copy.deepcopy(critics).requires_grad_(False)
        log_alpha = torch.tensor(math.log(args.alpha), requires_grad=args.autotune)
        return cls(actor, critics, critics_target, adam(actor.parameters(), lr=args.policy_lr),
                   adam(critics.parameters(), lr=args.q_lr), log_alpha,
                   adam([log_alpha], lr=args.alpha_lr) if args.autotune else None, -float(act_dim))

    def state_dict(self) -> dict:
        return dict(actor=self.actor.state_dict(), critics=self.critics.state_dict(),
                    critics_target=self.critics_target.state_dict(), actor_optimizer=self.actor_optimizer.state_dict(),
                    q_optimizer=self.q_optimizer.state_dict(), log_alpha=self.log_alpha.detach().clone(),
                    alpha_optimizer=None if self.alpha_optimizer is None else self.alpha_optimizer.state_dict())

    def load_state_dict(self, state: dict) -> None:
        for key in ("actor", "critics", "critics_target", "actor_optimizer", "q_optimizer"):
            getattr(self, key).load_state_dict(state[key])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        if self.alpha_optimizer is not None:
            self.alpha_optimizer.load_state_dict(state["alpha_optimizer"])


def sac_update(learner: Learner, batch: Batch, args: Args, update_index: int) -> dict[str, torch.Tensor]:
    """One gradient step of the critics on `batch` (raw observations, normalized here with the current statistics),
    every `policy_frequency`-th one as many steps of the actor and the entropy coefficient, every
    `target_network_frequency`-th one a Polyak step of the target critics; the losses (detached tensors)."""
    actor, critics = learner.actor, learner.critics
    alpha = learner.log_alpha.detach().exp()
    z, z_next = actor.normalize(batch.obs), actor.normalize(batch.next_obs)
    with torch.no_grad():
        next_actions, next_log_pi = actor.sample(z_next)
        next_q = torch.min(*learner.critics_target(z_next, next_actions))
        y = soft_q_target(batch.rewards, batch.terminated, batch.failed, next_q, next_log_pi, alpha, args.gamma)
    q1, q2 = critics(z, batch.actions)
    qf1_loss, qf2_loss = F.mse_loss(q1, y), F.mse_loss(q2, y)
    learner.q_optimizer.zero_grad()
    (qf1_loss + qf2_loss).backward()
    learner.q_optimizer.step()
    out = dict(qf1_loss=qf1_loss.detach(), qf2_loss=qf2_loss.detach(), q_value=q1.detach().mean())

    if update_index % args.policy_frequency == 0:
        critics.requires_grad_(False)  # the actor's loss needs gradients through the critics, not of their weights
        for _ in range(args.policy_frequency):
            pi, log_pi = actor.sample(z)
            actor_loss = (alpha * log_pi - torch.min(*critics(z, pi))).mean()
            learner.actor_optimizer.zero_grad()
            actor_loss.backward()
            learner.actor_optimizer.step()
            out.update(actor_loss=actor_loss.detach(), entropy=-log_pi.detach().mean())
            if learner.alpha_optimizer is not None:
                alpha_loss = -(learner.log_alpha.exp() * (log_pi.detach() + learner.target_entropy)).mean()
                learner.alpha_optimizer.zero_grad()
                alpha_loss.backward()
                learner.alpha_optimizer.step()
                alpha = learner.log_alpha.detach().exp()
                out["alpha_loss"] = alpha_loss.detach()
        critics.requires_grad_(True)

    if update_index % args.target_network_frequency == 0:
        with torch.no_grad():
            for target, online in zip(learner.critics_target.parameters(), critics.parameters()):
                target.lerp_(online, args.tau)
    out["alpha"] = alpha
    return out


def updates_due(args: Args, global_step: int) -> int:
    """Gradient steps a run has made by env step `global_step`: `utd` per env step after --learning-starts."""
    return math.floor(args.utd * max(0, global_step - args.learning_starts) + 1e-9)


# ------------------------------------------------------------------------------------------------- #
# The run: setup, checkpoints
# ------------------------------------------------------------------------------------------------- #
@dataclass
class Clock:
    """Gradient steps made and where the run's wall time went (seconds; resumes add up); saved in checkpoints."""

    updates: int = 0
    wall_s: float = 0.0
    env_s: float = 0.0
    update_s: float = 0.0
    eval_s: float = 0.0
    checkpoint_s: float = 0.0
    evaluations: int = 0
    skipped_updates: int = 0
    """gradient steps not made while a lost replay buffer refilled (--refill-lost-buffer)."""
    refilled_at: list = dataclasses.field(default_factory=list)
    """env steps at which the run went on with an empty replay buffer (--refill-lost-buffer)."""
    refill_until: int = 0
    """env step until which the latest refill runs without gradient steps."""


@dataclass
class Run:
    """A run between iterations, as `setup` builds or restores it; its checkpoint saves all but the envs."""

    args: Args
    envs: CPUVectorEnv
    eval_envs: Optional[CPUVectorEnv]
    obs_dim: int
    act_dim: int
    learner: Learner
    buffer: ReplayBuffer
    progress: Progress
    clock: Clock
    buffer_file: Optional[str] = None
    """the replay buffer file the run's checkpoint names (beside it)."""

    @property
    def path(self) -> Path:
        """The run's checkpoint (the one resumed from, when resuming); progress.csv and the buffer sit beside it."""
        if self.args.resume:
            return Path(self.args.resume)
        return Path(self.args.log_dir) / self.args.exp_name / "checkpoint.pt"

    def save(self) -> None:
        """The checkpoint, atomically, after the replay buffer it names (its own file beside it, also written
        atomically, `replay_buffer_<step>.pt`); the previous buffer file goes once the new checkpoint is in place."""
        if not self.args.save_model:
            return
        t = time.perf_counter()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        buffer_file = f"replay_buffer_{self.progress.global_step}.pt"
        tmp = self.path.with_name(buffer_file + ".tmp")
        torch.save(self.buffer.state_dict(), tmp)
        os.replace(tmp, self.path.with_name(buffer_file))
        agent = ppo_agent(self.args, self.learner.actor, self.obs_dim, self.act_dim)
        save_checkpoint(self.path, self.args, self.progress, agent, None, None, None, self.obs_dim, self.act_dim,
                        sac=self.learner.state_dict(), clock=dataclasses.asdict(self.clock), replay_buffer=buffer_file)
        if self.buffer_file not in (None, buffer_file):
            self.path.with_name(self.buffer_file).unlink(missing_ok=True)
        self.buffer_file = buffer_file
        self.clock.checkpoint_s += time.perf_counter() - t


def load_sac_checkpoint(path: str, option: str) -> dict:
    """A SAC checkpoint (checkpoints.load_checkpoint, which refuses what is no checkpoint); a PPO one is refused."""
    ckpt = load_checkpoint(path, option)
    if ckpt["args"].get("algorithm") != "sac":
        raise SystemExit(f"{option}: {path} is not a SAC checkpoint (baselines/sac/sac.py writes those); "
                         "a PPO checkpoint continues with baselines/ppo/ppo.py")
    return ckpt


def resumed_args(args: Args, saved: dict) -> Args:
    """--resume's args: the run's own, with this command's --total-timesteps where --extend asks for it."""
    known = {f.name for f in dataclasses.fields(Args)}
    resumed = Args(**{k: v for k, v in saved.items() if k in known})
    resumed.resume, resumed.extend, resumed.evaluate, resumed.checkpoint = args.resume, args.extend, False, None
    if args.extend:
        resumed.total_timesteps = args.total_timesteps
    return resumed


def setup(args: Args) -> Run:
    """Build (or, with --resume, restore) a run: args, envs, seeds, networks, optimizers, replay buffer, progress."""
    resume = load_sac_checkpoint(args.resume, "--resume") if args.resume else None
    refill = False
    if resume is not None:
        refill_asked = args.refill_lost_buffer
        args = resumed_args(args, resume["args"])
        buffer_path = Path(args.resume).with_name(resume["replay_buffer"])
        refill = not buffer_path.is_file()
        if refill and not refill_asked:
            raise SystemExit(f"--resume {args.resume}: its replay buffer {buffer_path} is missing (a checkpoint's "
                             "buffer is written beside it: move or copy the two together; or give --refill-lost-buffer "
                             "to go on with an empty one, an inexact resume)")
    validate(args)
    if args.exp_name is None:
        args.exp_name = f"sac__{args.env_id}__s{args.seed}"
    # the envs first: the random numbers below are the run's, whatever making an env draws
    envs = make_envs(args, args.num_envs)
    eval_envs = make_envs(args, args.num_eval_envs, train=False) if args.eval_freq > 0 else None
    obs_dim, act_dim = envs.single_observation_space.shape[-1], envs.single_action_space.shape[-1]
    space = envs.single_action_space
    try:
        if not (np.all(space.low == -1) and np.all(space.high == 1)):
            raise SystemExit(f"{args.control_mode}: the actor's tanh gives actions in [-1, 1], the env's are {space}")
        if resume is not None:
            check_fit(resume, args.resume, args.env_id, obs_dim, act_dim, args.control_mode)
    except SystemExit:
        close(envs, eval_envs)
        raise
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    # a layer's random init is drawn in chunks, one per thread: the run's thread count, not the machine's cores
    torch.set_num_threads(args.torch_threads)

    learner = Learner.make(args, obs_dim, act_dim)
    if args.init_from and resume is None:
        try:
            start_from(learner, load_sac_checkpoint(args.init_from, "--init-from"), args)
        except SystemExit:
            close(envs, eval_envs)
            raise
    run = Run(args, envs, eval_envs, obs_dim, act_dim, learner, ReplayBuffer(args.buffer_size, obs_dim, act_dim),
              Progress(), Clock())
    if resume is not None:
        learner.load_state_dict(resume["sac"])
        run.progress, run.clock = Progress(**resume["progress"]), Clock(**resume["clock"])
        if refill:
            run.clock.refilled_at.append(run.progress.global_step)
            run.clock.refill_until = run.progress.global_step + args.learning_starts
            print(f"--refill-lost-buffer: {buffer_path} is missing; the actor refills an empty buffer for "
                  f"{args.learning_starts:,} env steps before the gradient steps go on")
        else:
            run.buffer.load_state_dict(torch.load(buffer_path, map_location="cpu", weights_only=False))
            run.buffer_file = resume["replay_buffer"]
        restore_rng(resume["rng"])
    return run


def start_from(learner: Learner, ckpt: dict, args: Args) -> None:
    """`learner`'s networks, entropy coefficient and observation statistics from the SAC checkpoint `ckpt`
    (--init-from). A run among obstacles from a checkpoint trained without them: the obstacles' entry ends the
    observation, so its OBSTACLE_OBS_SIZE features follow the checkpoint's; the actor's and the critics' first layers
    get zero weights on them (the critics' before the action's columns) and the statistics a mean of 0 and a variance
    of 1, so the networks compute what the checkpoint's did, whatever the obstacles' entry says."""
    from ms_construction.envs.obstacles import OBSTACLE_OBS_SIZE

    state, saved = ckpt["sac"], ckpt["args"]
    if "critics" not in state:
        raise SystemExit(f"--init-from {args.init_from}: it keeps the actor alone (a policy shipped before its critics "
                         "were kept with it); give a run's checkpoint, which keeps them")
    old, new = state["actor"]["obs_rms.mean"].shape[0], learner.actor.obs_rms.mean.shape[0]
    if ckpt["act_dim"] != learner.actor.act_dim or saved["control_mode"] != args.control_mode:
        raise SystemExit(f"--init-from {args.init_from}: its actions ({ckpt['act_dim']}, {saved['control_mode']}) are "
                         f"not this run's ({learner.actor.act_dim}, {args.control_mode})")
    gained = new - old
    if gained and not (gained == OBSTACLE_OBS_SIZE and args.obstacles and not saved.get("obstacles")):
        raise SystemExit(f"--init-from {args.init_from}: its networks read {old} features, this run's {new}; only the "
                         f"obstacles' entry ({OBSTACLE_OBS_SIZE}) may be new (a run with --obstacles from a checkpoint "
                         "trained without them)")
    actor = dict(state["actor"])
    critics = {key: dict(state[key]) for key in ("critics", "critics_target")}
    if gained:
        for key, fill in (("obs_rms.mean", 0.0), ("obs_rms.var", 1.0)):
            actor[key] = insert_filled(actor[key], 0, old, fill, gained)
        actor["net.0.weight"] = insert_filled(actor["net.0.weight"], 1, old, 0.0, gained)
        for nets in critics.values():
            for q in ("q1", "q2"):
                nets[f"{q}.0.weight"] = insert_filled(nets[f"{q}.0.weight"], 1, old, 0.0, gained)
    try:
        learner.actor.load_state_dict(actor)
        learner.critics.load_state_dict(critics["critics"])
        learner.critics_target.load_state_dict(critics["critics_target"])
    except RuntimeError as e:
        raise SystemExit(f"--init-from {args.init_from}: its networks are not this run's shape (--hidden-size, "
                         f"--num-layers, --q-layer-norm): {e}") from None
    with torch.no_grad():
        learner.log_alpha.copy_(state["log_alpha"])


def acts_at_random(args: Args, global_step: int) -> bool:
    """Whether the run's actions at `global_step` are uniform random (before --learning-starts, unless the actor
    starts trained: --init-from)."""
    return global_step < args.learning_starts and not args.init_from


def close(*envs: Optional[CPUVectorEnv]) -> None:
    for e in envs:
        if e is not None:
            e.close()


# ------------------------------------------------------------------------------------------------- #
# Training
# ------------------------------------------------------------------------------------------------- #
def collect(run: Run, envs: CPUVectorEnv, obs: torch.Tensor, episodes: dict) -> torch.Tensor:
    """`steps_per_env_per_iteration` steps of every env from `obs` into the replay buffer (uniform random actions
    before --learning-starts, the actor's draws after), the episodes that end added to `episodes` (EPISODE_STATS'
    keys, near-goal start, task type, a touch of an obstacle); the observation statistics updated with the
    observations acted on. The observation after."""
    args, actor, progress = run.args, run.learner.actor, run.progress
    seen = []
    for _ in range(args.steps_per_env_per_iteration):
        if acts_at_random(args, progress.global_step):
            actions = torch.rand(args.num_envs, run.act_dim) * 2 - 1
        else:
            with torch.no_grad():
                actions = actor.get_action(obs)
        next_obs, reward, terminated, _truncated, infos = envs.step(actions)
        progress.global_step += args.num_envs
        final_obs, failed = next_obs, failed_ends(terminated, infos)
        if "final_info" in infos:
            ep = finished_episodes(infos)
            ended = ep["ended"]
            final_obs = next_obs.clone()
            final_obs[ended] = infos["final_observation"][ended]
            for key in EPISODE_STATS.values():
                episodes[key] += ep[key][ended].float().tolist()
            episodes["near_goal"] += ep["near_goal_start"][ended].tolist()
            episodes["reach_start"] += ep["reach_start"][ended].tolist()
            episodes["reach_start_grasped"] += ep["reach_start_grasped"][ended].float().tolist()
            episodes["task_id"] += ep["task_id"][ended].tolist()
            episodes["collided"] += ep["collided"][ended].tolist()
        run.buffer.add(obs, final_obs, actions, reward * args.reward_scale, terminated, failed)
        seen.append(obs)
        obs = next_obs
    if args.norm_obs:
        actor.obs_rms.update(actor.features(torch.cat(seen)))
    return obs


def widen_starts(run: Run, envs: CPUVectorEnv, episodes: dict) -> None:
    """The start-state curriculum after an iteration: its near-goal episodes into each task type's window, and the
    radii that widen (`widen_near_goal`, PPO's rule, which reads near_goal_window, _promote and _step off
    `args.starts`: here Args' own fields) set in the envs."""
    near = [i for i, n in enumerate(episodes["near_goal"]) if n]
    tasks, placed = [episodes["task_id"][i] for i in near], [episodes["success"][i] for i in near]
    if near and widen_near_goal(SimpleNamespace(starts=run.args), run.progress, tasks, placed):
        set_near_goal_starts(run.args, envs, run.progress)


def episode_columns(args: Args, progress: Progress, episodes: dict) -> dict:
    """progress.csv's columns of the episodes that ended since the last row (ppo.py's names): EPISODE_STATS' means,
    the place and pick success of ordinary resets (per task type; with --obstacles, the share that touched one too),
    the place success of near-goal starts, and the radii now; with --reach-start-share, how many episodes started on
    the way to the element and the share of them grasped from the side they started on."""
    row = {}
    if episodes["success"]:
        row.update({column: float(np.mean(episodes[key])) for column, key in EPISODE_STATS.items()})
    near, placed = np.asarray(episodes["near_goal"], dtype=bool), np.asarray(episodes["success"], dtype=float)
    task, picked = np.asarray(episodes["task_id"], dtype=int), np.asarray(episodes["picked"], dtype=float)
    reach = np.asarray(episodes.get("reach_start") or [False] * len(near), dtype=bool)
    ordinary = ~near & ~reach
    collided = np.asarray(episodes.get("collided") or [False] * len(near), dtype=bool)
    for k, kind in enumerate(ELEMENT_KINDS):
        if ((task == k) & ordinary).any():
            row[f"ordinary_place_{kind}"] = float(placed[(task == k) & ordinary].mean())
            row[f"ordinary_pick_{kind}"] = float(picked[(task == k) & ordinary].mean())
            if args.obstacles is not None:
                row[f"ordinary_collided_{kind}"] = float(np.mean(collided[(task == k) & ordinary]))
    if args.reach_start_share > 0:
        grasped = np.asarray(episodes["reach_start_grasped"], dtype=float)
        row.update(reach_start_episodes=int(reach.sum()),
                   reach_start_grasp_success=float(grasped[reach].mean()) if reach.any() else float("nan"))
    if args.near_goal_share > 0:
        row.update(near_goal_radius=float(np.mean(progress.near_goal_radius)), near_goal_episodes=int(near.sum()),
                   near_goal_place_success=float(placed[near].mean()) if near.any() else float("nan"),
                   ordinary_place_success=float(placed[ordinary].mean()) if ordinary.any() else float("nan"),
                   **{f"near_goal_radius_{kind}": r for kind, r in zip(ELEMENT_KINDS, progress.near_goal_radius)},
                   **{f"near_goal_share_{kind}": s for kind, s in zip(ELEMENT_KINDS, progress.near_goal_share)})
    return row


def progress_row(run: Run, since: dict, episodes: dict, losses: dict, stage: str) -> dict:
    """progress.csv's row: where the run is, its pace since the last row (`since`: that row's step and wall time) and
    where its wall time went, the means of the losses and the episodes' columns since then (at `stage`'s
    tolerances, the stage the run is in)."""
    progress, clock = run.progress, run.clock
    sps = (progress.global_step - since["step"]) / max(clock.wall_s - since["wall"], 1e-9)
    row = dict(global_step=progress.global_step, iteration=progress.iteration, stage=stage,
               episodes=len(episodes["success"]), updates=clock.updates, buffer_fill=run.buffer.count,
               sps=round(sps, 1), update_share=round(clock.update_s / max(clock.wall_s, 1e-9), 3))
    row.update({k: round(getattr(clock, k), 2) for k in ("wall_s", "env_s", "update_s", "eval_s", "checkpoint_s")})
    row.update({k: torch.stack(v).double().mean().item() for k, v in losses.items()})
    row.update(episode_columns(run.args, progress, episodes))
    return row


def crossed(step: int, before: int, every: int) -> bool:
    """Whether the env steps from `before` to `step` passed a multiple of `every`."""
    return every > 0 and step // every > before // every


def train(run: Run) -> Progress:
    """SAC from where `run` is to --total-timesteps; where the run ended.

    Each iteration: the envs in the tolerance stage of --curriculum for its env steps (`stage_at`), then
    `steps_per_env_per_iteration` steps of every env, then the gradient steps due (`utd` per env step
    since --learning-starts), the start-state curriculum, a progress.csv row every --log-freq env steps, an
    evaluation every --eval-freq, a checkpoint every --checkpoint-freq (where the envs restart their episodes).
    Ctrl-C or SIGTERM ends the run after the iteration in progress with a checkpoint (SystemExit, status 128 + the
    signal's number); a second Ctrl-C ends it at once, the last checkpoint standing."""
    args, learner, progress, clock = run.args, run.learner, run.progress, run.clock
    envs, eval_envs = run.envs, run.eval_envs
    run.path.parent.mkdir(parents=True, exist_ok=True)
    if args.near_goal_share > 0:
        if progress.near_goal_radius is None:
            progress.near_goal_radius = [args.near_goal_radius] * len(ELEMENT_KINDS)
            progress.near_goal_recent = [[] for _ in ELEMENT_KINDS]
        if progress.near_goal_share is None:  # also a checkpoint saved before the share was part of the progress
            progress.near_goal_share = [args.near_goal_share] * len(ELEMENT_KINDS)
        set_near_goal_starts(args, envs, progress)
    log = CSVLog(run.path.with_name("progress.csv"), progress.global_step if args.resume else None, fields=CSV_FIELDS)
    stage = None  # the tolerance stage the envs are in: set before the first step, again where it changes

    stop = StopRequest()
    interrupted = False
    obs = reset(envs, segment_seed(args, progress.global_step))
    logged = dict(step=progress.global_step, wall=clock.wall_s)  # where the last row was
    episodes, losses = defaultdict(list), defaultdict(list)
    bar = tqdm(total=args.total_timesteps, initial=min(progress.global_step, args.total_timesteps), unit="step",
               desc=args.exp_name, dynamic_ncols=True)
    try:
        while progress.global_step < args.total_timesteps and not stop:
            progress.iteration += 1
            before = progress.global_step
            if stage_at(args, before) != stage:
                stage = stage_at(args, before)
                for e in (envs, eval_envs):
                    if e is not None:
                        e.call("set_curriculum_stage", stage)
            t0 = time.perf_counter()
            new = defaultdict(list)
            torch.set_num_threads(1)  # env 0 runs in this process: its small tensor ops gain nothing from threads
            obs = collect(run, envs, obs, new)
            widen_starts(run, envs, new)
            for key, values in new.items():
                episodes[key] += values
            t1 = time.perf_counter()
            torch.set_num_threads(args.torch_threads)
            if progress.global_step < clock.refill_until:  # a lost buffer refilling: no gradient steps, no backlog
                clock.skipped_updates = updates_due(args, progress.global_step) - clock.updates
            for _ in range(updates_due(args, progress.global_step) - clock.updates - clock.skipped_updates):
                clock.updates += 1
                for key, value in sac_update(learner, run.buffer.sample(args.batch_size), args, clock.updates).items():
                    losses[key].append(value)
            t2 = time.perf_counter()
            clock.env_s += t1 - t0
            clock.update_s += t2 - t1
            clock.wall_s += t2 - t0
            row = {}
            done = progress.global_step >= args.total_timesteps
            if eval_envs is not None and (crossed(progress.global_step, before, args.eval_freq) or done):
                clock.evaluations += 1
                row.update(evaluate_envs(learner.actor, eval_envs, args.num_eval_steps,
                                         seed=args.seed + 10_000 + 100 * clock.evaluations))
                clock.eval_s += time.perf_counter() - t2
            if crossed(progress.global_step, before, args.log_freq) or done or row:
                t = time.perf_counter()
                clock.wall_s += t - t2
                row.update(progress_row(run, logged, episodes, losses, stage))
                log.append(row)
                bar.set_postfix(sps=row["sps"], updates=f"{row['update_share']:.0%}",
                                place=row.get("place_success", float("nan")),
                                near=row.get("near_goal_place_success", float("nan")))
                logged = dict(step=progress.global_step, wall=clock.wall_s)
                episodes, losses = defaultdict(list), defaultdict(list)
                clock.wall_s += time.perf_counter() - t
            bar.update(min(progress.global_step, args.total_timesteps) - bar.n)
            if crossed(progress.global_step, before, args.checkpoint_freq) or done:
                t = time.perf_counter()
                run.save()
                if not done:  # the next checkpoint interval starts from seeded resets (see the module docstring)
                    obs = reset(envs, segment_seed(args, progress.global_step))
                clock.wall_s += time.perf_counter() - t
    except KeyboardInterrupt:
        interrupted = True
    finally:
        stop.restore()
        bar.close()
        close(envs, eval_envs)
    stop.report(interrupted, progress, run.save, args.save_model, f"python baselines/sac/sac.py --resume {run.path}")
    print(time_split(clock, progress.global_step), file=sys.stderr)
    stop.exit()
    return progress


def time_split(clock: Clock, global_step: int) -> str:
    """Where the run's wall time went, in one line."""
    wall = max(clock.wall_s, 1e-9)
    parts = ", ".join(f"{name} {getattr(clock, key):.0f} s ({getattr(clock, key) / wall:.0%})" for name, key in
                      (("env steps", "env_s"), ("updates", "update_s"), ("evaluation", "eval_s"),
                       ("checkpoints", "checkpoint_s")))
    return (f"{global_step} env steps, {clock.updates} gradient steps in {clock.wall_s:.0f} s "
            f"({global_step / wall:.0f} env steps/s): {parts}")


# ------------------------------------------------------------------------------------------------- #
# Evaluation
# ------------------------------------------------------------------------------------------------- #
def actor_of(ckpt: dict) -> Actor:
    """The actor of a SAC checkpoint (`load_sac_checkpoint`), in eval mode."""
    saved = resumed_args(Args(), ckpt["args"])
    quat_starts = STATE_QUATERNION_STARTS if saved.rotation_features else ()
    actor = Actor(ckpt["obs_dim"], ckpt["act_dim"], saved.hidden_size, saved.num_layers, quat_starts,
                  saved.log_std_min, saved.log_std_max)
    actor.load_state_dict(ckpt["sac"]["actor"])
    return actor.eval()


def evaluate(args: Args) -> dict:
    """--evaluate: --eval-episodes episodes of --checkpoint's deterministic policy on --env-id from ordinary resets with
    seeds --eval-seed on (sparse reward: the return counts placements), in the env kwargs it was trained with; the
    summary (evaluation.summarize: pick and place success with Wilson 95% intervals, return, length)."""
    validate(args)
    ckpt = load_sac_checkpoint(args.checkpoint, "--checkpoint")
    actor = actor_of(ckpt)
    torch.set_num_threads(1)
    kwargs = dict(obs_mode="state", reward_mode="sparse", **policy_env_kwargs(ckpt["args"]))
    envs = CPUVectorEnv(args.env_id, min(args.num_eval_envs, args.eval_episodes), kwargs, device="cpu")
    try:
        check_fit(ckpt, args.checkpoint, args.env_id, envs.single_observation_space.shape[-1],
                  envs.single_action_space.shape[-1], kwargs["control_mode"])
        episodes, seed = [], args.eval_seed
        while len(episodes) < args.eval_episodes:
            episodes += run_episodes(actor, envs, args.num_eval_steps, seed)
            seed += envs.num_envs
    finally:
        envs.close()
    result = dict(env_id=args.env_id, checkpoint=args.checkpoint, global_step=ckpt["progress"]["global_step"],
                  **summarize(episodes[:args.eval_episodes]))
    print(result)
    return result


def main(args: Args):
    if args.evaluate:
        return evaluate(args)
    return train(setup(args))


if __name__ == "__main__":
    main(tyro.cli(Args))
