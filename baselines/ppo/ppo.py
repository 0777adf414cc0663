"""PPO with a curiosity bonus (ICM) and the paper's tolerance curriculum, for the construction tasks.

In the shape of ManiSkill's PPO baseline (CleanRL style: read top to bottom, one `Args` dataclass);
the networks are in networks.py, the update (GAE and the clipped objective) in update.py, ICM in
curiosity.py, checkpoints and the CSV log in checkpoints.py, the evaluation in evaluation.py. Additions: `--curiosity icm` (Pathak et al. 2017), `--curriculum
cp1 cp2 cp3 cp4` (Table I of the paper, each stage inheriting every parameter of the previous one),
sparse reward by default (the paper's Algorithm 1), atomic checkpoints and exact `--resume`, a CSV
log per run.
Observations are normalized (running mean and variance, in the checkpoint) and their quaternions
fed as rotation-matrix columns. Fine-tuning a warm start (our recipe for the general agent,
scripts/train_general_agent.py): `--checkpoint` from baselines/ppo/bc.py, `--freeze-obs-norm`,
`--critic-warmup-iterations`, and a behaviour-cloning term on demonstrations (`--demos`, `--bc-coef`).

    python baselines/ppo/ppo.py --env-id ConstructionPickPlace-v1 --curriculum cp1 cp2 cp3 cp4 --curiosity icm
    python baselines/ppo/ppo.py --resume runs/<run>/checkpoint.pt            # continue an interrupted run
    python baselines/ppo/ppo.py --evaluate --checkpoint runs/<run>/checkpoint.pt --env-id Flooring-v1
    python scripts/evaluate.py --checkpoint runs/<run>/checkpoint.pt --all     # the full evaluation

CPU path (physx_cpu, one env per process): ms_construction.vector_env.CPUVectorEnv, env worker
processes behind ManiSkillVectorEnv's interface (same-step resets, torch tensors). GPU path
(physx_cuda): ManiSkillVectorEnv. `--sim-backend auto` picks by what the machine has. Ctrl-C or
SIGTERM ends a run after the iteration in progress, with a checkpoint (a second Ctrl-C ends it at once).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import random
import shutil
import signal
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional, Union, get_args, get_origin, get_type_hints

import gymnasium as gym
import numpy as np
import torch
import torch.optim as optim
import tyro
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

from baselines.ppo.checkpoints import (CSVLog, Progress, check_fit, load_checkpoint, make_agent, restore_rng, save_checkpoint,
                                       value_heads)
from baselines.ppo.curiosity import ICM, make_icm
from baselines.ppo.evaluation import evaluate_envs, finished_episodes, reset
from baselines.ppo.networks import Agent
from baselines.ppo.update import adam, ppo_update, signal_advantages
from baselines.ppo.start_states import StartFromStates
from ms_construction.curriculum import STAGE_NAMES
from ms_construction.envs import ENV_IDS
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.vector_env import CPUVectorEnv

ControlMode = Literal["pd_joint_delta_pos", "pd_joint_pos", "pd_joint_target_delta_pos", "pd_ee_delta_pos",
                      "pd_ee_delta_pose", "pd_ee_target_delta_pose"]
"""the construction arm's controllers (its `_controller_configs`)."""
RewardMode = Literal["sparse", "dense", "normalized_dense"]
Envs = Union[CPUVectorEnv, ManiSkillVectorEnv]
"""a batch of envs with same-step resets and torch tensors in and out, on either backend."""


@dataclass
class Args:
    exp_name: Optional[str] = None
    """name of this run (default: env id, curiosity, curriculum and seed)."""
    seed: int = 1
    """seed of the experiment."""
    torch_deterministic: bool = True
    """`torch.backends.cudnn.deterministic`."""
    cuda: bool = True
    """use CUDA for the networks when it is available."""
    capture_video: bool = False
    """save evaluation videos to `runs/<run>/videos` (offscreen, CPU or GPU)."""
    save_model: bool = True
    """write checkpoints (atomically) to `runs/<run>/checkpoint.pt`."""
    evaluate: bool = False
    """only evaluate `--checkpoint` and exit."""
    checkpoint: Optional[str] = None
    """initial weights (policy, value, ICM) from this checkpoint; a fresh run otherwise."""
    resume: Optional[str] = None
    """continue the interrupted run of this checkpoint: same run folder, stage, step count, optimizer, RNG."""
    log_dir: str = "runs"
    """where run folders go."""

    env_id: str = "ConstructionPickPlace-v1"
    """the environment: the general task or one of the three single tasks (ms_construction.envs.ENV_IDS)."""
    control_mode: ControlMode = "pd_joint_delta_pos"
    """the arm's controller."""
    reward_mode: RewardMode = "sparse"
    """sparse (the paper's Algorithm 1), dense or normalized_dense."""
    sim_backend: Literal["auto", "physx_cpu", "physx_cuda"] = "auto"
    """physx_cuda when a GPU is there (auto), else physx_cpu."""
    total_timesteps: int = 8_000_000
    """total env steps of training (the paper: 2M per curriculum stage)."""
    learning_rate: float = 3e-4
    """Adam learning rate of policy and value."""
    num_envs: Optional[int] = None
    """parallel training envs (default: one per CPU core on physx_cpu, 512 on physx_cuda)."""
    num_eval_envs: Optional[int] = None
    """parallel evaluation envs (default: 2 on physx_cpu, 16 on physx_cuda)."""
    partial_reset: bool = True
    """reset each env when its episode ends (success ends an episode)."""
    eval_partial_reset: bool = False
    """GPU evaluation: reset envs that finish early (off: each env runs one full-length episode)."""
    num_steps: Optional[int] = None
    """steps per env per rollout (default: 250 on physx_cpu, 50 on physx_cuda)."""
    num_eval_steps: int = 250
    """steps per evaluation (one episode per env)."""
    anneal_lr: bool = False
    """anneal the learning rate linearly to 0."""
    gamma: float = 0.99
    """discount (long horizon: the sparse reward comes once, up to 250 steps away)."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    num_minibatches: int = 8
    """minibatches per update epoch."""
    update_epochs: int = 4
    """epochs per rollout."""
    norm_adv: Literal["minibatch", "batch", "none"] = "minibatch"
    """normalize advantages per minibatch (CleanRL's, ManiSkill's), once over the whole update batch
    (ML-Agents'), or not at all."""
    clip_coef: float = 0.2
    """PPO clip coefficient."""
    clip_vloss: bool = False
    """clip the value loss."""
    ent_coef: float = 0.0
    """entropy bonus coefficient."""
    vf_coef: float = 0.5
    """value loss coefficient."""
    max_grad_norm: Optional[float] = 0.5
    """gradient clipping of policy and value (None: none, as ML-Agents)."""
    target_kl: Optional[float] = 0.1
    """stop an update early when the approximate KL exceeds this."""
    reward_scale: float = 1.0
    """scale of the extrinsic reward."""
    eval_freq: int = 10
    """evaluate every this many iterations (and at stage ends)."""
    bootstrap_at_done: Optional[Literal["always", "truncated", "terminated", "never"]] = None
    """which episode ends bootstrap with the value of their last observation. `truncated`: episodes cut
    by the time limit (they did not end there); success is an end with nothing after it. `always`
    (ManiSkill's PPO default, its name): every end, success included, so that a success state counts
    as one that keeps paying what it paid; the dense rewards are made for it (see the task card).
    `terminated`: success only; the time limit is an end like any other, which only a policy that sees
    the time (--obs-elapsed-time) can value right: an episode cut short of its goal loses what placing
    would have paid. `never`: no end. Default: `always` with the dense rewards, `truncated` with sparse (ML-Agents',
    which bootstraps interrupted episodes only)."""
    success_value: Literal["absorbing", "critic"] = "absorbing"
    """what an episode that ends by success bootstraps with, where it does (--bootstrap-at-done always or
    terminated): `absorbing`, the success step's reward for ever (reward / (1 - gamma)), as the task card defines
    success; `critic`, the critic's value of the last observation (ManiSkill's PPO), a guess about a state it
    never trains on."""
    hidden_size: int = 256
    """width of the policy and value networks."""
    num_layers: int = 3
    """hidden layers of the policy and value networks (ML-Agents' default: 2)."""
    norm_obs: bool = True
    """normalize observations by their running mean and variance (kept in the checkpoint), as CleanRL's
    continuous-control PPO does (with gymnasium's NormalizeObservation)."""
    rotation_features: bool = True
    """feed the networks each quaternion of the state (plate, goal, element) as the first two columns
    of its rotation matrix: a quaternion's sign can flip mid-episode, the matrix cannot."""
    freeze_obs_norm: bool = False
    """keep the normalization statistics as they are (those of a --checkpoint's behaviour cloning)."""
    demos: tuple[str, ...] = ()
    """demonstration files (scripts/collect_demos.py) for a behaviour-cloning term in the policy loss
    (as DAPG, Rajeswaran et al. 2018): keeps a warm-started policy near the expert while PPO refines it."""
    bc_coef: float = 0.0
    """weight of that term: mean squared error of the policy's mean on a demonstration minibatch."""
    critic_warmup_iterations: int = 0
    """the first iterations of a run (counted from 1) update the value function only: with a
    warm-started policy (--checkpoint), the critic first learns that policy's returns, so the policy's
    first steps follow advantages that mean something."""
    checkpoint_freq: int = 10
    """write a checkpoint every this many iterations (and at stage changes, the end, and Ctrl-C)."""
    extend: bool = False
    """with --resume: continue to this command's --total-timesteps and --curriculum (which must start
    with the run's own stages) instead of the run's own, e.g. to take a finished run further."""
    stage_schedules: bool = False
    """ML-Agents' linear schedules, restarted at every curriculum stage (as when each stage is a run that
    inherits the last): over a stage's --stage-timesteps the learning rate falls to 1e-10, the clip
    coefficient to 0.1 and the entropy coefficient to 1e-5."""

    residual_of: Optional[str] = None
    """a checkpoint (a behaviour clone, or a refined agent: a residual on a residual) that stays frozen as the base
    policy; PPO learns a correction added to its actions (baselines/ppo/residual.py, ResiP). Its observation
    statistics stay too."""
    residual_scale: float = 0.1
    """the correction's scale in action units."""
    residual_l2_coef: float = 0.0
    """weight of the correction's mean square (before scaling) in the policy loss: an anchor at the clone,
    so that the residual moves only where the advantages keep asking it to."""
    start_states: Optional[str] = None
    """a bank of env states (baselines/ppo/start_states.py, where a policy failed) that a share of the
    training episodes start from; evaluation always resets as usual. physx_cpu only."""
    start_states_share: float = 0.5
    """the share of training episodes that start from the bank."""
    start_states_keep_clock: bool = False
    """an episode started from the bank goes on from the elapsed steps its state was taken at (a failure that ran
    out of time stays one) instead of getting the whole step limit again; the bank must hold them (a bank of
    start_states.py collected since it keeps them)."""
    obs_elapsed_time: bool = False
    """append the episode's elapsed steps / 250 to the observation (the tasks' `obs_elapsed_time`), in training
    and evaluation: a policy that knows how much of the step limit is left can hurry. A residual's base (trained
    without it) does not see it."""
    task_weights: Optional[tuple[float, float, float]] = None
    """the general task's sampling weights of ceiling, window and flooring in the training envs (None: uniform;
    `1 2 1`: window installation half the episodes); evaluation always samples uniformly."""

    near_goal_share: float = 0.0
    """the start-state curriculum (reverse curriculum generation, Florensa et al. 2017; no demonstrations): this
    share of the training episodes start with the element held on a collision-free path out of its goal (the
    tasks' `set_near_goal_starts`), at most `near_goal_radius` of the path's length out; evaluation always
    resets as usual."""
    near_goal_radius: float = 0.1
    """the curriculum's first radius (fraction of a start path, 0: installed), one per task type..."""
    near_goal_step: float = 0.1
    """...each widened by this (up to 1) once the last `near_goal_window` near-goal episodes of its task type placed
    at least `near_goal_promote` of the time (the window then starts again)."""
    near_goal_promote: float = 0.6
    """success from near-goal starts that widens a task type's radius."""
    near_goal_window: int = 20
    """near-goal episodes of a task type whose success decides a widening."""

    curiosity: Literal["none", "icm", "icm_normalized"] = "icm"
    """intrinsic reward (baselines/ppo/curiosity.py): `icm` as ML-Agents computes it (the forward model's
    raw error x strength, capped at 1, with its own value head and discount, ignoring episode ends);
    `icm_normalized`, ours: the error divided by its running std, added to the extrinsic reward;
    or none (plain PPO)."""
    icm_strength: float = 0.02
    """curiosity's strength. ML-Agents documents 1.0 as its default (typical 0.001 to 0.1) and uses 0.02
    in its example configuration with curiosity; we keep that 0.02."""
    icm_gamma: float = 0.99
    """discount of the curiosity reward (its own value head; ML-Agents' default)."""
    icm_forward_weight: float = 0.2
    """beta: ICM loss = 10 ((1 - beta) inverse loss + beta forward loss) (ML-Agents)."""
    icm_feature_dim: int = 128
    """size of ICM's feature space phi(s) and of its encoder's layers (ML-Agents: 128)."""
    icm_hidden_size: int = 256
    """width of ICM's forward and inverse models (ML-Agents: 256)."""
    icm_learning_rate: float = 3e-4
    """Adam learning rate of ICM."""

    curriculum: tuple[str, ...] = STAGE_NAMES
    """tolerance stages in order (Table I); one stage, e.g. `cp4`, trains without a curriculum."""
    stage_timesteps: int = 2_000_000
    """promote to the next stage after this many env steps in a stage (the paper: 2M)."""
    min_stage_timesteps: int = 500_000
    """promote early only after this many steps in the stage..."""
    promote_success: float = 0.9
    """...when the smoothed evaluation place success reaches this (above 1 disables it)."""
    success_smoothing: float = 0.5
    """weight of the newest evaluation in the smoothed success (exponential moving average)."""


# ------------------------------------------------------------------------------------------------- #
# Environments
# ------------------------------------------------------------------------------------------------- #
def make_envs(args: Args, num_envs: int, device: torch.device, eval_mode: bool = False,
              video_dir: Optional[Path] = None) -> Envs:
    """`num_envs` envs with same-step resets and torch tensors in and out: worker processes on
    physx_cpu (one env each), ManiSkillVectorEnv on physx_cuda. With `video_dir`, evaluation videos."""
    kwargs = dict(obs_mode="state", control_mode=args.control_mode, reward_mode=args.reward_mode,
                  render_mode="rgb_array" if video_dir else None)
    if args.obs_elapsed_time:
        kwargs["obs_elapsed_time"] = True
    if args.task_weights is not None and not eval_mode:
        kwargs["task_weights"] = dict(zip(ELEMENT_KINDS, args.task_weights))
    if args.sim_backend == "physx_cpu":
        wrappers = ()
        if args.start_states and not eval_mode:
            wrappers = (functools.partial(StartFromStates, bank=args.start_states, share=args.start_states_share,
                                          keep_clock=args.start_states_keep_clock),)
        return CPUVectorEnv(args.env_id, num_envs, kwargs, device=device, video_dir=video_dir, wrappers=wrappers)
    env = gym.make(args.env_id, num_envs=num_envs, sim_backend=args.sim_backend, **kwargs)
    if video_dir is not None:
        from mani_skill.utils.wrappers import RecordEpisode

        env = RecordEpisode(env, str(video_dir), save_trajectory=False, video_fps=20, max_steps_per_video=args.num_eval_steps)
    partial = args.eval_partial_reset if eval_mode else args.partial_reset
    return ManiSkillVectorEnv(env, num_envs, ignore_terminations=not partial, record_metrics=True)


def call_task(envs: Envs, name: str, *args) -> None:
    """The task's method `name(*args)` in every env of `envs` (set_curriculum_stage, set_near_goal_starts)."""
    if isinstance(envs, CPUVectorEnv):
        envs.call(name, *args)
    else:
        getattr(envs.unwrapped, name)(*args)


def set_curriculum_stage(envs: Envs, stage: str) -> None:
    """Every env of `envs` to the tolerances of `stage` (Table I)."""
    call_task(envs, "set_curriculum_stage", stage)


def widen_near_goal(args: Args, progress: Progress, task_ids: list[int], placed: list[float]) -> bool:
    """Record the near-goal episodes that ended (their task types and whether they placed) and widen each task
    type's radius whose last --near-goal-window episodes placed often enough (--near-goal-promote); whether any
    radius widened. The windows are part of the progress: a resumed run goes on with them."""
    widened = set()  # the rest of this iteration's episodes of a widened type started at the old radius
    for k, ok in zip(task_ids, placed):
        if k in widened:
            continue
        window = progress.near_goal_recent[k]
        window.append(float(ok))
        del window[:-args.near_goal_window]
        if len(window) == args.near_goal_window and np.mean(window) >= args.near_goal_promote and progress.near_goal_radius[k] < 1:
            progress.near_goal_radius[k] = round(min(1.0, progress.near_goal_radius[k] + args.near_goal_step), 6)
            window.clear()
            widened.add(k)
    return bool(widened)


# ------------------------------------------------------------------------------------------------- #
# Curriculum and arguments
# ------------------------------------------------------------------------------------------------- #
def should_promote(args: Args, progress: Progress) -> Optional[str]:
    """Why the current stage ends now ('steps' or 'success'), or None."""
    if progress.stage_index >= len(args.curriculum) - 1:
        return None
    in_stage = progress.global_step - progress.stage_start_step
    if in_stage >= args.stage_timesteps:
        return "steps"
    if (in_stage >= args.min_stage_timesteps and progress.smoothed_success is not None
            and progress.smoothed_success >= args.promote_success):
        return "success"
    return None


SCHEDULE_FLOORS = dict(learning_rate=1e-10, clip_coef=0.1, ent_coef=1e-5)
"""where ML-Agents' linear schedules end (its learning rate, epsilon and beta)."""


def stage_schedule(args: Args, progress: Progress) -> Args:
    """`args` with the learning rate, clip and entropy coefficients of ML-Agents' linear schedules at
    this point of the current stage (--stage-schedules): from their values to SCHEDULE_FLOORS over
    --stage-timesteps, restarting at every stage."""
    frac = 1.0 - min(1.0, (progress.global_step - progress.stage_start_step) / args.stage_timesteps)
    return dataclasses.replace(args, **{k: (getattr(args, k) - floor) * frac + floor for k, floor in SCHEDULE_FLOORS.items()})


def validate(args: Args) -> None:
    """Refuse, before anything starts, what the run would otherwise fail on later (often in the env
    worker processes, with their tracebacks)."""
    if args.env_id not in ENV_IDS:
        raise SystemExit(f"--env-id {args.env_id}: use one of {', '.join(ENV_IDS)}")
    hints = get_type_hints(Args)
    for f in dataclasses.fields(Args):  # Args built in code are not checked by tyro
        allowed = get_args(hints[f.name]) if get_origin(hints[f.name]) is Literal else ()
        if allowed and getattr(args, f.name) not in allowed:
            raise SystemExit(f"--{f.name.replace('_', '-')} {getattr(args, f.name)}: use one of {', '.join(allowed)}")
    for name in ("residual_of", "start_states"):
        if getattr(args, name) is not None and not Path(getattr(args, name)).is_file():
            raise SystemExit(f"--{name.replace('_', '-')}: no such file: {getattr(args, name)}")
    if args.residual_l2_coef and not args.residual_of:
        raise SystemExit("--residual-l2-coef weighs a residual's correction: give --residual-of")
    if args.residual_of and args.bc_coef > 0:
        raise SystemExit("--bc-coef works on the policy's own weights; a residual agent (--residual-of) has none to pull")
    if args.task_weights is not None and (args.env_id != "ConstructionPickPlace-v1" or min(args.task_weights) < 0
                                          or sum(args.task_weights) <= 0):
        raise SystemExit(f"--task-weights {args.task_weights}: three weights >= 0, not all 0 (ceiling, window, flooring), "
                         "of the general task ConstructionPickPlace-v1 only")
    for name in ("near_goal_share", "near_goal_radius", "near_goal_promote"):
        if not 0 <= getattr(args, name) <= 1:
            raise SystemExit(f"--{name.replace('_', '-')} must lie in [0, 1], got {getattr(args, name)}")
    if not 0 <= args.start_states_share <= 1:
        raise SystemExit(f"--start-states-share must lie in [0, 1], got {args.start_states_share}")
    if args.start_states_keep_clock and not args.start_states:
        raise SystemExit("--start-states-keep-clock: give the bank (--start-states)")
    if args.start_states and args.sim_backend == "physx_cuda":
        raise SystemExit("--start-states: physx_cpu only (the bank is restored in the env worker processes)")
    missing = [p for p in args.demos if not Path(p).is_file()]
    if missing:
        raise SystemExit(f"--demos: no such file(s): {', '.join(missing)} (record them with scripts/collect_demos.py)")
    bad = [s for s in args.curriculum if s not in STAGE_NAMES]
    if bad or not args.curriculum:
        raise SystemExit(f"--curriculum {' '.join(args.curriculum)}: stages must be among {', '.join(STAGE_NAMES)}")
    for name in ("total_timesteps", "stage_timesteps", "num_minibatches", "update_epochs", "eval_freq", "checkpoint_freq"):
        if getattr(args, name) <= 0:
            raise SystemExit(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}")


def resolve_defaults(args: Args) -> None:
    """Fill in the defaults that depend on the machine (in `args`, so that checkpoints keep them)."""
    if args.sim_backend == "auto":
        args.sim_backend = "physx_cuda" if torch.cuda.is_available() else "physx_cpu"
    gpu = args.sim_backend == "physx_cuda"
    if args.num_envs is None:
        args.num_envs = 512 if gpu else (os.cpu_count() or 1)
    if args.num_eval_envs is None:
        args.num_eval_envs = 16 if gpu else 2
    if args.num_steps is None:
        args.num_steps = 50 if gpu else 250
    if args.exp_name is None:
        args.exp_name = f"{args.env_id}__{args.curiosity}__{'-'.join(args.curriculum)}__s{args.seed}"
    if args.bootstrap_at_done is None:
        args.bootstrap_at_done = "truncated" if args.reward_mode == "sparse" else "always"


# ------------------------------------------------------------------------------------------------- #
# Training
# ------------------------------------------------------------------------------------------------- #
EPISODE_STATS = dict(pick_success="picked", place_success="success", extrinsic_return="ep_return", episode_length="ep_length",
                     end_place_dist="end_place_dist", end_place_angle_deg="end_place_angle_deg", held_at_end="held_at_end")
"""progress.csv's columns of the training episodes that ended in an iteration (their means), from
`finished_episodes`' keys."""


def checkpoint_path(args: Args) -> Path:
    """The run's checkpoint (the one resumed from, when resuming); its other files sit beside it."""
    return Path(args.resume) if args.resume else Path(args.log_dir) / args.exp_name / "checkpoint.pt"


@dataclass
class Run:
    """A run between iterations, as `setup` builds or restores it: its arguments (machine defaults
    filled in), networks, optimizers and progress, which its checkpoint saves, and its evaluation envs."""

    args: Args
    eval_envs: Envs
    agent: Agent
    optimizer: optim.Optimizer
    icm: Optional[ICM]
    icm_optimizer: Optional[optim.Optimizer]
    progress: Progress
    base_args: Optional[dict] = None
    """a residual agent's base policy's args (saved with the checkpoint, which holds the base's weights)."""

    @property
    def obs_dim(self) -> int:
        return int(np.prod(self.eval_envs.single_observation_space.shape))

    @property
    def act_dim(self) -> int:
        return int(np.prod(self.eval_envs.single_action_space.shape))

    def save(self) -> None:
        if self.args.save_model:
            save_checkpoint(checkpoint_path(self.args), self.args, self.progress, self.agent, self.optimizer, self.icm,
                            self.icm_optimizer, self.obs_dim, self.act_dim, base_args=self.base_args)


def setup(args: Args) -> Run:
    """Build (or, with --resume, restore) a run: args, seeds, evaluation envs, networks, optimizers, progress."""
    resume = load_checkpoint(args.resume, "--resume") if args.resume else None
    init = load_checkpoint(args.checkpoint) if args.checkpoint and resume is None else None
    if resume is not None:
        saved, extended = resume["args"], {}
        if args.extend:
            if tuple(args.curriculum[:len(saved["curriculum"])]) != tuple(saved["curriculum"]):
                raise SystemExit(f"--extend: --curriculum {' '.join(args.curriculum)} must start with the run's own stages "
                                 f"({' '.join(saved['curriculum'])})")
            extended = dict(total_timesteps=args.total_timesteps, curriculum=tuple(args.curriculum))
        args = Args(**{**saved, "resume": args.resume, "curriculum": tuple(saved["curriculum"]), **extended})
    validate(args)
    resolve_defaults(args)

    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")
    if args.sim_backend == "physx_cpu":
        # the env processes own the cores; a multi-threaded learner would fight them for every step
        torch.set_num_threads(1)

    eval_envs = make_envs(args, args.num_eval_envs, device, eval_mode=True,
                          video_dir=checkpoint_path(args).parent / "videos" if args.capture_video else None)
    obs_dim = int(np.prod(eval_envs.single_observation_space.shape))
    act_dim = int(np.prod(eval_envs.single_action_space.shape))

    base = None  # a residual run's base policy: its checkpoint when the run starts, its args since
    if resume is not None or init is not None:
        base_args = (resume or init).get("base_args")
    elif args.residual_of:
        base = load_checkpoint(args.residual_of, "--residual-of")
        base_args = base["args"]
        if base.get("base_args") is not None:  # a refined agent as the base: its own base's args go with it
            if base_args.get("obs_elapsed_time"):
                raise SystemExit(f"--residual-of {args.residual_of}: a residual that sees the elapsed time cannot be "
                                 "another residual's base; give one trained without --obs-elapsed-time")
            base_args = {**base_args, "base_args": base["base_args"]}
        check_fit(base, args.residual_of, args.env_id, obs_dim - int(args.obs_elapsed_time), act_dim, args.control_mode)
    else:
        base_args = None
    agent = make_agent(args, obs_dim, act_dim, base_args).to(device)
    if base is not None:
        agent.base.load_state_dict(base["agent"])
    optimizer = adam([p for p in agent.parameters() if p.requires_grad], lr=args.learning_rate, eps=1e-5)
    icm, icm_optimizer = make_icm(args.curiosity, obs_dim, act_dim, args), None
    if icm is not None:
        icm = icm.to(device)
        icm_optimizer = adam(icm.parameters(), lr=args.icm_learning_rate)

    progress = Progress()
    for ckpt, path in ((resume, args.resume), (init, args.checkpoint)):
        if ckpt is not None:
            check_fit(ckpt, path, args.env_id, obs_dim, act_dim, args.control_mode)
    if resume is not None:
        agent.load_state_dict(resume["agent"])
        optimizer.load_state_dict(resume["optimizer"])
        if icm is not None:
            icm.load_state_dict(resume["icm"])
            icm_optimizer.load_state_dict(resume["icm_optimizer"])
        progress = Progress(**resume["progress"])
        restore_rng(resume["rng"])
    elif init is not None:
        agent.load_state_dict(init["agent"])
        if icm is not None and init["icm"] is not None:
            icm.load_state_dict(init["icm"])
        if args.evaluate:
            progress = Progress(**init["progress"])
    return Run(args, eval_envs, agent, optimizer, icm, icm_optimizer, progress, base_args)


def main(args: Args) -> Progress:
    run = setup(args)
    if run.args.evaluate:
        stage = run.args.curriculum[min(run.progress.stage_index, len(run.args.curriculum) - 1)]
        set_curriculum_stage(run.eval_envs, stage)
        print({"stage": stage, **evaluate_envs(run.agent, run.eval_envs, run.args.num_eval_steps, seed=run.args.seed)})
        run.eval_envs.close()
        return run.progress
    return train(run)


def train(run: Run) -> Progress:
    """The PPO loop, from where `run` is to the end of its budget; returns where the run ended.

    Ctrl-C or SIGTERM ends the run after the iteration in progress: it saves the checkpoint, closes the
    envs and exits (SystemExit, status 128 + the signal's number) with one line that says how to resume.
    A second Ctrl-C (a KeyboardInterrupt) ends it at once, dropping the iteration in progress: the last
    checkpoint stands."""
    args, agent, icm, progress = run.args, run.agent, run.icm, run.progress
    device = next(agent.parameters()).device
    run_dir = checkpoint_path(args).parent
    envs = make_envs(args, args.num_envs, device)
    batch_size = args.num_envs * args.num_steps
    num_iterations = math.ceil(args.total_timesteps / batch_size)
    stage = args.curriculum[progress.stage_index]
    if not progress.stage_changes:
        progress.stage_changes.append((0, stage))
    for e in (envs, run.eval_envs):
        set_curriculum_stage(e, stage)
    if args.near_goal_share > 0:
        if progress.near_goal_radius is None:
            progress.near_goal_radius = [args.near_goal_radius] * len(ELEMENT_KINDS)
            progress.near_goal_recent = [[] for _ in ELEMENT_KINDS]
        call_task(envs, "set_near_goal_starts", args.near_goal_share, tuple(progress.near_goal_radius))

    run_dir.mkdir(parents=True, exist_ok=True)
    writer = SummaryWriter(str(run_dir))
    if not args.resume:
        writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + "\n".join(f"|{k}|{v}|" for k, v in vars(args).items()))
    log = CSVLog(run_dir / "progress.csv", progress.global_step if args.resume else None)

    demos = None
    if args.demos:
        files = [np.load(path) for path in args.demos]
        demos = tuple(torch.as_tensor(np.concatenate([f[k] for f in files]), dtype=torch.float32, device=device)
                      for k in ("obs", "actions"))

    obs_buf = torch.zeros((args.num_steps, args.num_envs, run.obs_dim), device=device)
    next_obs_buf = torch.zeros_like(obs_buf)  # s_{t+1}: the final observation where an episode ended
    actions = torch.zeros((args.num_steps, args.num_envs, run.act_dim), device=device)
    rewards = torch.zeros((args.num_steps, args.num_envs), device=device)
    dones = torch.zeros_like(rewards)
    terminated = torch.zeros_like(rewards)
    heads = value_heads(args)
    intrinsic_running = torch.zeros(args.num_envs, device=device)

    stop: list[int] = []  # the signal that asked the run to end

    def request_stop(signum, _frame):
        stop.append(signum)
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a second Ctrl-C ends the run at once

    handlers = {signum: signal.signal(signum, request_stop) for signum in (signal.SIGINT, signal.SIGTERM)}
    interrupted = False
    next_obs = reset(envs, seed=args.seed + progress.iteration * 1000)
    bar = tqdm(total=args.total_timesteps, initial=min(progress.global_step, args.total_timesteps), unit="step",
               desc=f"{args.exp_name} [{stage}]", dynamic_ncols=True)
    try:
        while progress.iteration < num_iterations and not stop:
            progress.iteration += 1
            t0 = time.time()
            if args.anneal_lr:
                run.optimizer.param_groups[0]["lr"] = args.learning_rate * (1.0 - (progress.iteration - 1.0) / num_iterations)
            update_args = args
            if args.stage_schedules:
                update_args = stage_schedule(args, progress)
                run.optimizer.param_groups[0]["lr"] = update_args.learning_rate
            episodes = defaultdict(list)

            # ---- rollout ----
            for step in range(args.num_steps):
                progress.global_step += args.num_envs
                obs_buf[step] = next_obs
                # the action alone: its log-probability and value V(s_t) come below, for the whole
                # rollout in one call (the weights do not change within it), not a network call per step
                with torch.no_grad():
                    actions[step] = action = agent.get_action(next_obs)
                next_obs, reward, terminations, truncations, infos = envs.step(action.clamp(-1, 1))
                rewards[step] = reward * args.reward_scale
                dones[step], terminated[step] = (terminations | truncations).float(), terminations.float()
                next_obs_buf[step] = next_obs
                if "final_info" in infos:
                    ep = finished_episodes(infos)
                    next_obs_buf[step, ep["ended"]] = infos["final_observation"][ep["ended"]]
                    for key in EPISODE_STATS.values():
                        episodes[key] += ep[key][ep["ended"]].float().tolist()
                    episodes["near_goal"] += ep["near_goal_start"][ep["ended"]].tolist()
                    episodes["task_id"] += ep["task_id"][ep["ended"]].tolist()

            # ---- log-probabilities and values, and the intrinsic reward, on the whole rollout ----
            flat = lambda x: x.reshape(-1, *x.shape[2:])  # noqa: E731
            with torch.no_grad():
                _, logprobs, _, values = agent.get_action_and_value(flat(obs_buf), flat(actions))
            logprobs, values = logprobs.view(args.num_steps, args.num_envs), values.view(args.num_steps, args.num_envs, heads)
            intrinsic = torch.zeros_like(rewards)
            if icm is not None:
                intrinsic = icm.intrinsic_reward(flat(obs_buf), flat(next_obs_buf), flat(actions)).view_as(rewards)
                # intrinsic return of each finished episode (carried across rollouts)
                for step in range(args.num_steps):
                    intrinsic_running += intrinsic[step]
                    ended = dones[step].bool()
                    episodes["intrinsic_return"] += intrinsic_running[ended].tolist()
                    intrinsic_running[ended] = 0

            # ---- GAE, one value head per reward signal ----
            with torch.no_grad():
                next_value = agent.get_value(next_obs)
                # V(last observation) where an episode ended and bootstraps (see bootstrap_mask)
                v_final = agent.get_value(flat(next_obs_buf)).view(args.num_steps, args.num_envs, heads)
                advantages, returns = signal_advantages(args, rewards, intrinsic, values, next_value, v_final, dones,
                                                        terminated)

            # ---- update ----
            batch = dict(obs=flat(obs_buf), next_obs=flat(next_obs_buf), actions=flat(actions),
                         logprobs=logprobs.reshape(-1), advantages=advantages.reshape(-1),
                         returns=returns.reshape(-1, heads), values=values.reshape(-1, heads))
            losses = ppo_update(agent, run.optimizer, batch, update_args, run.icm, run.icm_optimizer, demos,
                                value_only=progress.iteration <= args.critic_warmup_iterations)
            # statistics change after the update, so that each update sees its rollout's normalization
            if args.norm_obs and not args.freeze_obs_norm and not args.residual_of:
                agent.obs_rms.update(agent.features(batch["obs"]))

            # ---- logs, evaluation, curriculum ----
            sps = batch_size / (time.time() - t0)
            row = dict(global_step=progress.global_step, iteration=progress.iteration, stage=stage, sps=round(sps, 1),
                       learning_rate=run.optimizer.param_groups[0]["lr"], episodes=len(episodes["success"]),
                       clip_coef=update_args.clip_coef, ent_coef=update_args.ent_coef)
            row.update(losses)
            if episodes["success"]:
                row.update({column: float(np.mean(episodes[key])) for column, key in EPISODE_STATS.items()})
                if episodes["intrinsic_return"]:
                    row["intrinsic_return"] = float(np.mean(episodes["intrinsic_return"]))
            near = np.asarray(episodes["near_goal"], dtype=bool)
            placed, task = np.asarray(episodes["success"], dtype=float), np.asarray(episodes["task_id"], dtype=int)
            for k, kind in enumerate(ELEMENT_KINDS):
                if ((task == k) & ~near).any():
                    row[f"ordinary_place_{kind}"] = float(placed[(task == k) & ~near].mean())
            if args.near_goal_share > 0:
                row.update(near_goal_radius=float(np.mean(progress.near_goal_radius)), near_goal_episodes=int(near.sum()),
                           near_goal_place_success=float(placed[near].mean()) if near.any() else float("nan"),
                           ordinary_place_success=float(placed[~near].mean()) if (~near).any() else float("nan"),
                           **{f"near_goal_radius_{kind}": r for kind, r in zip(ELEMENT_KINDS, progress.near_goal_radius)})
                if widen_near_goal(args, progress, task[near].tolist(), placed[near].tolist()):
                    call_task(envs, "set_near_goal_starts", args.near_goal_share, tuple(progress.near_goal_radius))
            if progress.iteration % args.eval_freq == 0 or progress.iteration == num_iterations:
                result = evaluate_envs(agent, run.eval_envs, args.num_eval_steps, seed=args.seed + 10_000 + progress.iteration)
                s, a = result["eval_place_success"], args.success_smoothing
                if not math.isnan(s):
                    progress.smoothed_success = s if progress.smoothed_success is None else a * s + (1 - a) * progress.smoothed_success
                row.update(result, smoothed_eval_success=progress.smoothed_success)
            promotion = should_promote(args, progress)
            for key, value in row.items():
                if isinstance(value, (int, float)) and key not in ("global_step", "iteration"):
                    writer.add_scalar(f"charts/{key}", value, progress.global_step)
            log.append(row)
            if promotion:
                progress.stage_index += 1
                progress.stage_start_step = progress.global_step
                progress.smoothed_success = None
                stage = args.curriculum[progress.stage_index]
                progress.stage_changes.append((progress.global_step, stage))
                for e in (envs, run.eval_envs):
                    set_curriculum_stage(e, stage)
                writer.add_text("curriculum", f"step {progress.global_step}: promoted to {stage} ({promotion})", progress.global_step)
                tqdm.write(f"step {progress.global_step}: promoted to {stage} ({promotion})")
                bar.set_description(f"{args.exp_name} [{stage}]")
            bar.update(min(batch_size, args.total_timesteps - bar.n))
            bar.set_postfix(sps=f"{sps:.0f}", place=row.get("place_success", float("nan")), pick=row.get("pick_success", float("nan")))
            if promotion or progress.iteration % args.checkpoint_freq == 0 or progress.iteration == num_iterations:
                run.save()
            if promotion and args.save_model:  # the policy at the end of each stage, kept to be evaluated (at cp4)
                ended = f"checkpoint_stage{progress.stage_index}_{args.curriculum[progress.stage_index - 1]}.pt"
                shutil.copyfile(checkpoint_path(args), checkpoint_path(args).with_name(ended))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
        bar.close()
        envs.close()
        run.eval_envs.close()
        writer.close()
    resume = f"python baselines/ppo/ppo.py --resume {checkpoint_path(args)}"
    if interrupted:
        print(f"interrupted during iteration {progress.iteration}, which is lost; resume from the last checkpoint "
              f"with: {resume}", file=sys.stderr)
    elif stop:
        run.save()
        saved = f"checkpoint saved; resume with: {resume}" if args.save_model else "no checkpoint (--no-save-model)"
        print(f"stopped by {signal.Signals(stop[0]).name} after iteration {progress.iteration} "
              f"(step {progress.global_step}): {saved}", file=sys.stderr)
    if stop:
        raise SystemExit(128 + stop[0])
    return progress


if __name__ == "__main__":
    main(tyro.cli(Args))
