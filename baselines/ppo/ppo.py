"""PPO with a curiosity bonus (ICM) and the paper's tolerance curriculum, for the construction tasks.

In the shape of ManiSkill's PPO baseline (CleanRL style: read top to bottom); its one `Args` dataclass
(the command line; the run's fields at the top, PPO's in `args.ppo`, curiosity's in `args.icm`, the curriculum's
in `args.stages`, warm starts' in `args.warm`, start states' in `args.starts`) is in args.py, the networks in networks.py, the update (GAE and the clipped objective) in
update.py, ICM in curiosity.py, checkpoints and the CSV log in checkpoints.py, the evaluation in evaluation.py.
Additions: `--curiosity icm` (Pathak et al. 2017), `--curriculum
cp1 cp2 cp3 cp4` (Table I of the paper, each stage inheriting every parameter of the previous one),
the tasks' default reward (normalized_dense; the paper's setting passes `--reward-mode sparse`), atomic checkpoints and exact `--resume`, a CSV
log per run.
Observations are normalized (running mean and variance, in the checkpoint) and their quaternions
fed as rotation-matrix columns. Fine-tuning a warm start (our recipe for the general agent,
experiments/general_agent.py): `--checkpoint` from baselines/ppo/bc.py, `--freeze-obs-norm`,
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

import functools
import math
import random
import shutil
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

import gymnasium as gym
import numpy as np
import torch
import torch.optim as optim
import tyro
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

from baselines.ppo.args import Args, resolve_defaults, validate
from baselines.ppo.checkpoints import (CSVLog, Progress, check_fit, load_checkpoint, make_agent, policy_env_kwargs,
                                       restore_rng, save_checkpoint, StopRequest, value_heads, with_obstacle_inputs,
                                       with_path_offset_inputs)
from baselines.ppo.curiosity import ICM, make_icm
from baselines.ppo.evaluation import evaluate_envs, failed_ends, finished_episodes, reset
from baselines.ppo.networks import Agent
from baselines.ppo.update import adam, hold_log_std_floor, ppo_update, signal_advantages
from baselines.ppo.start_states import GOAL_SLOTS, StartFromStates, failure_task_weights, widen_near_goal, widen_reach_starts
from ms_construction.envs.start_states import NearGoalTimeLimit
from ms_construction.parameters import ELEMENT_KINDS, PAPER_KINDS
from ms_construction.vector_env import CPUVectorEnv

Envs = Union[CPUVectorEnv, ManiSkillVectorEnv]
"""a batch of envs with same-step resets and torch tensors in and out, on either backend."""


# ------------------------------------------------------------------------------------------------- #
# Environments
# ------------------------------------------------------------------------------------------------- #
def env_kinds(env_id: str) -> tuple[str, ...]:
    """The task types the env `env_id` samples (ELEMENT_KINDS order): the per-type options and columns are theirs."""
    from mani_skill.utils.registration import REGISTERED_ENVS

    return REGISTERED_ENVS[env_id].cls.TASKS


def make_envs(args: Args, num_envs: int, device: torch.device, eval_mode: bool = False,
              video_dir: Optional[Path] = None) -> Envs:
    """`num_envs` envs with same-step resets and torch tensors in and out: worker processes on
    physx_cpu (one env each), ManiSkillVectorEnv on physx_cuda. With `video_dir`, evaluation videos."""
    kwargs = dict(obs_mode="state", reward_mode=args.reward_mode, render_mode="rgb_array" if video_dir else None)
    kwargs.update(policy_env_kwargs(args.flat()))
    if args.obstacles is not None:
        kwargs["obstacles"] = args.obstacles
    if args.task_weights is not None and not eval_mode:
        kwargs["task_weights"] = dict(zip(PAPER_KINDS, args.task_weights))  # the general task's three types
    if args.starts.goal_slot_weights is not None and not eval_mode:
        w = args.starts.goal_slot_weights
        kwargs["goal_slot_weights"] = {kind: w[3 * k:3 * k + 3] for k, kind in enumerate(PAPER_KINDS)}
    if args.starts.reach_start_share and not eval_mode:
        kwargs["reach_start_share"] = args.starts.reach_start_share
    # near-goal starts are set (and left off in evaluation) by set_near_goal_starts; this applies their time limit
    wrappers = (NearGoalTimeLimit,) if args.starts.near_goal_max_steps is not None and not eval_mode else ()
    if args.sim_backend == "physx_cpu":
        if args.starts.start_states and not eval_mode:
            wrappers += (functools.partial(StartFromStates, bank=args.starts.start_states, share=args.starts.start_states_share,
                                           keep_clock=args.starts.start_states_keep_clock),)
        return CPUVectorEnv(args.env_id, num_envs, kwargs, device=device, video_dir=video_dir, wrappers=wrappers)
    env = gym.make(args.env_id, num_envs=num_envs, sim_backend=args.sim_backend, **kwargs)
    for wrap in wrappers:
        env = wrap(env)
    if video_dir is not None:
        from mani_skill.utils.wrappers import RecordEpisode

        env = RecordEpisode(env, str(video_dir), save_trajectory=False, video_fps=20, max_steps_per_video=args.num_eval_steps)
    partial = args.eval_partial_reset if eval_mode else args.partial_reset
    return ManiSkillVectorEnv(env, num_envs, ignore_terminations=not partial, record_metrics=True)


def call_task(envs: Envs, name: str, *args) -> None:
    """The task's method `name(*args)` in every env of `envs` (set_curriculum_stage, set_near_goal_starts,
    set_task_weights)."""
    if isinstance(envs, CPUVectorEnv):
        envs.call(name, *args)
    else:
        getattr(envs.unwrapped, name)(*args)


def set_curriculum_stage(envs: Envs, stage: str) -> None:
    """Every env of `envs` to the tolerances of `stage` (Table I)."""
    call_task(envs, "set_curriculum_stage", stage)


# ------------------------------------------------------------------------------------------------- #
# Curriculum
# ------------------------------------------------------------------------------------------------- #
def should_promote(args: Args, progress: Progress) -> Optional[str]:
    """Why the current stage ends now ('steps' or 'success'), or None."""
    if progress.stage_index >= len(args.stages.curriculum) - 1:
        return None
    in_stage = progress.global_step - progress.stage_start_step
    if in_stage >= args.stages.stage_timesteps:
        return "steps"
    if (in_stage >= args.stages.min_stage_timesteps and progress.smoothed_success is not None
            and progress.smoothed_success >= args.stages.promote_success):
        return "success"
    return None


SCHEDULE_FLOORS = dict(learning_rate=1e-10, clip_coef=0.1, ent_coef=1e-5)
"""where ML-Agents' linear schedules end (its learning rate, epsilon and beta)."""


def stage_schedule(args: Args, progress: Progress) -> Args:
    """`args` with the learning rate, clip and entropy coefficients of ML-Agents' linear schedules at
    this point of the current stage (--stage-schedules): from their values to SCHEDULE_FLOORS over
    --stage-timesteps, restarting at every stage."""
    frac = 1.0 - min(1.0, (progress.global_step - progress.stage_start_step) / args.stages.stage_timesteps)
    return args.replace(**{k: (getattr(args.ppo, k) - floor) * frac + floor for k, floor in SCHEDULE_FLOORS.items()})



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
            if tuple(args.stages.curriculum[:len(saved["curriculum"])]) != tuple(saved["curriculum"]):
                raise SystemExit(f"--extend: --curriculum {' '.join(args.stages.curriculum)} must start with the run's own stages "
                                 f"({' '.join(saved['curriculum'])})")
            extended = dict(total_timesteps=args.total_timesteps, curriculum=tuple(args.stages.curriculum))
        args = Args.of(**{**saved, "resume": args.resume, "curriculum": tuple(saved["curriculum"]), **extended})
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
    elif args.warm.residual_of:
        base = load_checkpoint(args.warm.residual_of, "--residual-of")
        base_args = base["args"]
        if base.get("base_args") is not None:  # a refined agent as the base: its own base's args go with it
            if base_args.get("obs_elapsed_time"):
                raise SystemExit(f"--residual-of {args.warm.residual_of}: a residual that sees the elapsed time cannot be "
                                 "another residual's base; give one trained without --obs-elapsed-time")
            base_args = {**base_args, "base_args": base["base_args"]}
        check_fit(base, args.warm.residual_of, args.env_id, obs_dim - int(args.obs_elapsed_time), act_dim, args.control_mode)
    else:
        base_args = None
    agent = make_agent(args, obs_dim, act_dim, base_args).to(device)
    if base is not None:
        agent.base.load_state_dict(base["agent"])
    optimizer = adam([p for p in agent.parameters() if p.requires_grad], lr=args.ppo.learning_rate, eps=1e-5)
    icm, icm_optimizer = make_icm(args.icm.curiosity, obs_dim, act_dim, args), None
    if icm is not None:
        icm = icm.to(device)
        icm_optimizer = adam(icm.parameters(), lr=args.icm.icm_learning_rate)

    progress = Progress()
    if init is not None and args.obs_path_offset and not init["args"].get("obs_path_offset"):
        init = with_path_offset_inputs(init, args.checkpoint)
    if init is not None and args.obstacles and not init["args"].get("obstacles"):
        init = with_obstacle_inputs(init, args.checkpoint)
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
    hold_log_std_floor(agent, args)
    return Run(args, eval_envs, agent, optimizer, icm, icm_optimizer, progress, base_args)


def main(args: Args) -> Progress:
    run = setup(args)
    if run.args.evaluate:
        stage = run.args.stages.curriculum[min(run.progress.stage_index, len(run.args.stages.curriculum) - 1)]
        set_curriculum_stage(run.eval_envs, stage)
        print({"stage": stage, **evaluate_envs(run.agent, run.eval_envs, run.args.num_eval_steps, seed=run.args.seed)})
        run.eval_envs.close()
        return run.progress
    return train(run)


@dataclass
class Rollout:
    """One iteration's samples, [num_steps, num_envs, ...]: s_t, s_{t+1} (the final observation where an episode
    ended there), a_t, r_t, whether the episode ended at t, whether it ended by termination (success or failure) and
    whether by failure (`info["fail"]`: among obstacles, a touch)."""

    obs: torch.Tensor
    next_obs: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    dones: torch.Tensor
    terminated: torch.Tensor
    failed: torch.Tensor

    @classmethod
    def zeros(cls, num_steps: int, num_envs: int, obs_dim: int, act_dim: int, device: torch.device) -> "Rollout":
        obs, steps = torch.zeros((num_steps, num_envs, obs_dim), device=device), torch.zeros((num_steps, num_envs), device=device)
        return cls(obs, torch.zeros_like(obs), torch.zeros((num_steps, num_envs, act_dim), device=device), steps,
                   torch.zeros_like(steps), torch.zeros_like(steps), torch.zeros_like(steps))


def flat(x: torch.Tensor) -> torch.Tensor:
    """[num_steps, num_envs, ...] -> [num_steps * num_envs, ...]"""
    return x.reshape(-1, *x.shape[2:])


def collect(agent: Agent, envs: Envs, buf: Rollout, next_obs: torch.Tensor, args: Args, progress: Progress,
            episodes: dict) -> torch.Tensor:
    """Fill `buf` with args.num_steps steps of every env from `next_obs` on (the policy's sampled actions), adding
    the episodes that end to `episodes` (EPISODE_STATS' keys, near-goal start, task type); the observation after."""
    for step in range(args.num_steps):
        progress.global_step += args.num_envs
        buf.obs[step] = next_obs
        # the action alone: its log-probability and value V(s_t) come in `advantages`, for the whole
        # rollout in one call (the weights do not change within it), not a network call per step
        with torch.no_grad():
            buf.actions[step] = action = agent.get_action(next_obs)
        next_obs, reward, terminations, truncations, infos = envs.step(action.clamp(-1, 1))
        buf.rewards[step] = reward * args.ppo.reward_scale
        buf.dones[step], buf.terminated[step] = (terminations | truncations).float(), terminations.float()
        buf.failed[step] = failed_ends(terminations, infos).float()
        buf.next_obs[step] = next_obs
        if "final_info" in infos:
            ep = finished_episodes(infos)
            buf.next_obs[step, ep["ended"]] = infos["final_observation"][ep["ended"]]
            for key in EPISODE_STATS.values():
                episodes[key] += ep[key][ep["ended"]].float().tolist()
            episodes["near_goal"] += ep["near_goal_start"][ep["ended"]].tolist()
            episodes["reach_start"] += ep["reach_start"][ep["ended"]].tolist()
            episodes["reach_start_grasped"] += ep["reach_start_grasped"][ep["ended"]].float().tolist()
            episodes["task_id"] += ep["task_id"][ep["ended"]].tolist()
            episodes["goal_slot"] += ep["goal_slot"][ep["ended"]].tolist()
    return next_obs


def update_batch(run: Run, buf: Rollout, next_obs: torch.Tensor, episodes: dict, intrinsic_running: torch.Tensor) -> dict:
    """The rollout as PPO's update batch: log-probabilities and values of the whole rollout, curiosity's reward
    (each finished episode's intrinsic return into `episodes`, `intrinsic_running` carrying the rest across
    rollouts), and GAE's advantages and returns, one value head per reward signal."""
    args, agent, heads = run.args, run.agent, value_heads(run.args)
    num_steps, num_envs = buf.rewards.shape
    with torch.no_grad():
        _, logprobs, _, values = agent.get_action_and_value(flat(buf.obs), flat(buf.actions))
    values = values.view(num_steps, num_envs, heads)
    intrinsic = torch.zeros_like(buf.rewards)
    if run.icm is not None:
        intrinsic = run.icm.intrinsic_reward(flat(buf.obs), flat(buf.next_obs), flat(buf.actions)).view_as(buf.rewards)
        for step in range(num_steps):  # intrinsic return of each finished episode
            intrinsic_running += intrinsic[step]
            ended = buf.dones[step].bool()
            episodes["intrinsic_return"] += intrinsic_running[ended].tolist()
            intrinsic_running[ended] = 0
    with torch.no_grad():
        next_value = agent.get_value(next_obs)
        # V(last observation) where an episode ended and bootstraps (see bootstrap_mask)
        v_final = agent.get_value(flat(buf.next_obs)).view(num_steps, num_envs, heads)
        advantages, returns = signal_advantages(args, buf.rewards, intrinsic, values, next_value, v_final, buf.dones,
                                                buf.terminated, buf.failed)
    return dict(obs=flat(buf.obs), next_obs=flat(buf.next_obs), actions=flat(buf.actions), logprobs=logprobs.reshape(-1),
                advantages=advantages.reshape(-1), returns=returns.reshape(-1, heads), values=values.reshape(-1, heads))


def episode_columns(args: Args, progress: Progress, episodes: dict, envs: Envs) -> dict:
    """progress.csv's columns of the iteration's finished episodes: EPISODE_STATS' means, ordinary resets' place
    success per task type, the near-goal starts' and the reach starts' (whose radii this widens where they placed,
    or grasped from the side they started on, often enough)."""
    row = {}
    if episodes["success"]:
        row.update({column: float(np.mean(episodes[key])) for column, key in EPISODE_STATS.items()})
        if episodes["intrinsic_return"]:
            row["intrinsic_return"] = float(np.mean(episodes["intrinsic_return"]))
    near, reach = np.asarray(episodes["near_goal"], dtype=bool), np.asarray(episodes["reach_start"], dtype=bool)
    placed, task = np.asarray(episodes["success"], dtype=float), np.asarray(episodes["task_id"], dtype=int)
    ordinary = ~near & ~reach
    picked = np.asarray(episodes["picked"], dtype=float)
    for k, kind in enumerate(ELEMENT_KINDS):
        if ((task == k) & ordinary).any():
            row[f"ordinary_place_{kind}"] = float(placed[(task == k) & ordinary].mean())
            row[f"ordinary_pick_{kind}"] = float(picked[(task == k) & ordinary].mean())
    kinds = env_kinds(args.env_id)
    if args.failure_task_weights:
        weights = failure_task_weights(args, progress, task[ordinary].tolist(), placed[ordinary].tolist(),
                                       [ELEMENT_KINDS.index(kind) for kind in kinds])
        call_task(envs, "set_task_weights", dict(zip(kinds, weights)))
        row.update({f"task_weight_{kind}": w for kind, w in zip(kinds, weights)})
    if args.starts.near_goal_share > 0:
        radii = [progress.near_goal_radius[ELEMENT_KINDS.index(kind)] for kind in kinds]
        row.update(near_goal_radius=float(np.mean(radii)), near_goal_episodes=int(near.sum()),
                   near_goal_place_success=float(placed[near].mean()) if near.any() else float("nan"),
                   ordinary_place_success=float(placed[ordinary].mean()) if ordinary.any() else float("nan"),
                   **{f"near_goal_radius_{kind}": r for kind, r in zip(ELEMENT_KINDS, progress.near_goal_radius)},
                   **{f"near_goal_share_{kind}": s for kind, s in zip(ELEMENT_KINDS, progress.near_goal_share)})
        if widen_near_goal(args, progress, task[near].tolist(), placed[near].tolist()):
            call_task(envs, "set_near_goal_starts", tuple(progress.near_goal_share), tuple(progress.near_goal_radius),
                      args.starts.near_goal_max_steps)
    if args.starts.reach_start_radius is not None:
        grasped = np.asarray(episodes["reach_start_grasped"], dtype=float)
        slot = task * GOAL_SLOTS + np.asarray(episodes["goal_slot"], dtype=int)
        row.update(reach_start_episodes=int(reach.sum()),
                   reach_start_grasp_success=float(grasped[reach].mean()) if reach.any() else float("nan"),
                   **{f"reach_start_radius_{kind}{s}": progress.reach_start_radius[k * GOAL_SLOTS + s]
                      for k, kind in enumerate(ELEMENT_KINDS) for s in range(GOAL_SLOTS)})
        if widen_reach_starts(args, progress, slot[reach].tolist(), grasped[reach].tolist()):
            call_task(envs, "set_reach_starts", reach_start_shares(args), tuple(progress.reach_start_radius))
    return row


def reach_start_shares(args: Args) -> tuple[float, ...]:
    """The reach starts' share per task type (ELEMENT_KINDS order): --reach-start-share for --reach-start-tasks, 0 for
    the rest."""
    tasks = args.starts.reach_start_tasks
    return tuple(args.starts.reach_start_share if tasks is None or kind in tasks else 0.0 for kind in ELEMENT_KINDS)


def promote(run: Run, envs: Envs) -> str:
    """Move the run to its next curriculum stage, in the training and evaluation envs; the new stage."""
    progress = run.progress
    progress.stage_index += 1
    progress.stage_start_step = progress.global_step
    progress.smoothed_success = None
    stage = run.args.stages.curriculum[progress.stage_index]
    progress.stage_changes.append((progress.global_step, stage))
    for e in (envs, run.eval_envs):
        set_curriculum_stage(e, stage)
    return stage


def train(run: Run) -> Progress:
    """The PPO loop, from where `run` is to the end of its budget; returns where the run ended.

    Ctrl-C or SIGTERM ends the run after the iteration in progress: it saves the checkpoint, closes the
    envs and exits (SystemExit, status 128 + the signal's number) with one line that says how to resume.
    A second Ctrl-C (a KeyboardInterrupt) ends it at once, dropping the iteration in progress: the last
    checkpoint stands."""
    args, agent, progress = run.args, run.agent, run.progress
    device = next(agent.parameters()).device
    run_dir = checkpoint_path(args).parent
    envs = make_envs(args, args.num_envs, device)
    batch_size = args.num_envs * args.num_steps
    num_iterations = math.ceil(args.total_timesteps / batch_size)
    stage = args.stages.curriculum[progress.stage_index]
    if not progress.stage_changes:
        progress.stage_changes.append((0, stage))
    for e in (envs, run.eval_envs):
        set_curriculum_stage(e, stage)
    if args.starts.near_goal_share > 0:
        if progress.near_goal_radius is None:
            progress.near_goal_radius = [args.starts.near_goal_radius] * len(ELEMENT_KINDS)
            progress.near_goal_recent = [[] for _ in ELEMENT_KINDS]
        if progress.near_goal_share is None:  # also a checkpoint saved before the share was part of the progress
            progress.near_goal_share = [args.starts.near_goal_share] * len(ELEMENT_KINDS)
        call_task(envs, "set_near_goal_starts", tuple(progress.near_goal_share), tuple(progress.near_goal_radius),
                  args.starts.near_goal_max_steps)
    if args.starts.reach_start_radius is not None:
        if progress.reach_start_radius is None:
            progress.reach_start_radius = [args.starts.reach_start_radius] * (len(ELEMENT_KINDS) * GOAL_SLOTS)
            progress.reach_start_recent = [[] for _ in progress.reach_start_radius]
        call_task(envs, "set_reach_starts", reach_start_shares(args), tuple(progress.reach_start_radius))
    if args.failure_task_weights:  # where the run left them (uniform at its start)
        kinds = env_kinds(args.env_id)
        weights = failure_task_weights(args, progress, [], [], [ELEMENT_KINDS.index(kind) for kind in kinds])
        call_task(envs, "set_task_weights", dict(zip(kinds, weights)))

    run_dir.mkdir(parents=True, exist_ok=True)
    writer = SummaryWriter(str(run_dir))
    if not args.resume:
        writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + "\n".join(f"|{k}|{v}|" for k, v in args.flat().items()))
    log = CSVLog(run_dir / "progress.csv", progress.global_step if args.resume else None)

    demos = None
    if args.warm.demos:
        files = [np.load(path) for path in args.warm.demos]
        demos = tuple(torch.as_tensor(np.concatenate([f[k] for f in files]), dtype=torch.float32, device=device)
                      for k in ("obs", "actions"))
    buf = Rollout.zeros(args.num_steps, args.num_envs, run.obs_dim, run.act_dim, device)
    intrinsic_running = torch.zeros(args.num_envs, device=device)

    stop = StopRequest()
    interrupted = False
    next_obs = reset(envs, seed=args.seed + progress.iteration * 1000)
    bar = tqdm(total=args.total_timesteps, initial=min(progress.global_step, args.total_timesteps), unit="step",
               desc=f"{args.exp_name} [{stage}]", dynamic_ncols=True)
    try:
        while progress.iteration < num_iterations and not stop:
            progress.iteration += 1
            t0 = time.time()
            if args.ppo.anneal_lr:
                run.optimizer.param_groups[0]["lr"] = args.ppo.learning_rate * (1.0 - (progress.iteration - 1.0) / num_iterations)
            update_args = args
            if args.stages.stage_schedules:
                update_args = stage_schedule(args, progress)
                run.optimizer.param_groups[0]["lr"] = update_args.ppo.learning_rate
            episodes = defaultdict(list)
            next_obs = collect(agent, envs, buf, next_obs, args, progress, episodes)
            batch = update_batch(run, buf, next_obs, episodes, intrinsic_running)
            losses = ppo_update(agent, run.optimizer, batch, update_args, run.icm, run.icm_optimizer, demos,
                                value_only=progress.iteration <= args.warm.critic_warmup_iterations)
            # statistics change after the update, so that each update sees its rollout's normalization
            if args.ppo.norm_obs and not args.warm.freeze_obs_norm and not args.warm.residual_of:
                agent.obs_rms.update(agent.features(batch["obs"]))

            # ---- logs, evaluation, curriculum ----
            sps = batch_size / (time.time() - t0)
            row = dict(global_step=progress.global_step, iteration=progress.iteration, stage=stage, sps=round(sps, 1),
                       learning_rate=run.optimizer.param_groups[0]["lr"], episodes=len(episodes["success"]),
                       clip_coef=update_args.ppo.clip_coef, ent_coef=update_args.ppo.ent_coef)
            row.update(losses)
            row.update(episode_columns(args, progress, episodes, envs))
            if progress.iteration % args.eval_freq == 0 or progress.iteration == num_iterations:
                result = evaluate_envs(agent, run.eval_envs, args.num_eval_steps, seed=args.seed + 10_000 + progress.iteration)
                s, a = result["eval_place_success"], args.stages.success_smoothing
                if not math.isnan(s):
                    progress.smoothed_success = s if progress.smoothed_success is None else a * s + (1 - a) * progress.smoothed_success
                row.update(result, smoothed_eval_success=progress.smoothed_success)
            promotion = should_promote(args, progress)
            for key, value in row.items():
                if isinstance(value, (int, float)) and key not in ("global_step", "iteration"):
                    writer.add_scalar(f"charts/{key}", value, progress.global_step)
            log.append(row)
            if promotion:
                stage = promote(run, envs)
                writer.add_text("curriculum", f"step {progress.global_step}: promoted to {stage} ({promotion})", progress.global_step)
                tqdm.write(f"step {progress.global_step}: promoted to {stage} ({promotion})")
                bar.set_description(f"{args.exp_name} [{stage}]")
            bar.update(min(batch_size, args.total_timesteps - bar.n))
            bar.set_postfix(sps=f"{sps:.0f}", place=row.get("place_success", float("nan")), pick=row.get("pick_success", float("nan")))
            if promotion or progress.iteration % args.checkpoint_freq == 0 or progress.iteration == num_iterations:
                run.save()
            if promotion and args.save_model:  # the policy at the end of each stage, kept to be evaluated (at cp4)
                ended = f"checkpoint_stage{progress.stage_index}_{args.stages.curriculum[progress.stage_index - 1]}.pt"
                shutil.copyfile(checkpoint_path(args), checkpoint_path(args).with_name(ended))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        stop.restore()
        bar.close()
        envs.close()
        run.eval_envs.close()
        writer.close()
    stop.report(interrupted, progress, run.save, args.save_model,
                f"python baselines/ppo/ppo.py --resume {checkpoint_path(args)}")
    stop.exit()
    return progress


if __name__ == "__main__":
    main(tyro.cli(Args))
