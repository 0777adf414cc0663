"""ppo.py's arguments: one `Args` dataclass, the run's fields at its top level (as ManiSkill's and CleanRL's) and
the rest in nested groups: `args.ppo` (the update, advantages and networks), `args.icm` (curiosity),
`args.stages` (the tolerance curriculum), `args.warm` (warm starts and residuals) and `args.starts` (start
states). tyro reads it as ppo.py's command line with one flag per field and no group prefix (`--gamma`,
`--near-goal-share`), as before the groups; a checkpoint keeps the args as one flat dict (`Args.flat`,
`Args.of`), so every checkpoint reads as before. Also the checks and machine-dependent defaults applied to it
before a run starts."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Iterator, Literal, Optional, get_args, get_origin, get_type_hints

import torch
import tyro

from baselines import cli
from ms_construction.curriculum import STAGE_NAMES
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.envs import ENV_IDS

ControlMode = Literal["pd_joint_delta_pos", "pd_joint_pos", "pd_joint_target_delta_pos", "pd_ee_delta_pos",
                      "pd_ee_delta_pose", "pd_ee_target_delta_pose"]
"""the construction arm's controllers (its `_controller_configs`)."""
RewardMode = Literal["sparse", "dense", "normalized_dense"]


@dataclass
class RunArgs:
    """The run: its name, seed and files, the task and its envs, the budget, evaluation and checkpoints."""

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
    extend: bool = False
    """with --resume: continue to this command's --total-timesteps and --curriculum (which must start
    with the run's own stages) instead of the run's own, e.g. to take a finished run further."""
    log_dir: str = "runs"
    """where run folders go."""
    env_id: str = "ConstructionPickPlace-v1"
    """the environment: the general task or one of the single tasks (ms_construction.envs.ENV_IDS)."""
    control_mode: ControlMode = "pd_joint_delta_pos"
    """the arm's controller."""
    reward_mode: RewardMode = "normalized_dense"
    """normalized_dense (the tasks' default, as ManiSkill's PPO trains on its tasks' default), dense, or sparse (the
    paper's Algorithm 1, which its setting passes)."""
    sim_backend: Literal["auto", "physx_cpu", "physx_cuda"] = "auto"
    """physx_cuda when a GPU is there (auto), else physx_cpu."""
    total_timesteps: int = 8_000_000
    """total env steps of training (the paper: 2M per curriculum stage)."""
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
    eval_freq: int = 10
    """evaluate every this many iterations (and at stage ends)."""
    checkpoint_freq: int = 10
    """write a checkpoint every this many iterations (and at stage changes, the end, and Ctrl-C)."""
    obstacles: Optional[Literal["static", "moving"]] = None
    """the tasks' `obstacles` option (a site that changes), in training and evaluation; the policy observes them
    (`obs_obstacles`), and a checkpoint of it acts on any site with that entry (zeros without obstacles)."""
    obs_elapsed_time: bool = False
    """append the episode's elapsed steps / 250 to the observation (the tasks' `obs_elapsed_time`), in training
    and evaluation: a policy that knows how much of the step limit is left can hurry. A residual's base (trained
    without it) does not see it."""
    obs_install_offset: bool = False
    """append the joint move to the nearest installation configuration (the tasks' `obs_install_offset`: IK of
    the goal pose, what the dense reward's carry term measures) to the observation, in training and evaluation."""
    obs_path_offset: bool = False
    """append the joint move to the point a little ahead along the start path (the tasks' `obs_path_offset`: what
    the dense reward measures the carry along) to the observation, in training and evaluation. A run from
    `--checkpoint` of a policy without it gets zero weights on it: the policy acts as before until it learns to read it."""
    task_weights: Optional[tuple[float, float, float]] = None
    """the general task's sampling weights of ceiling, window and flooring in the training envs (None: uniform;
    `1 2 1`: window installation half the episodes); evaluation always samples uniformly."""
    failure_task_weights: int = 0
    """if > 0, instead of `task_weights`: after each iteration the training envs sample each task type with weight
    0.1 + the share of its last this-many training episodes from ordinary resets that did not place (kept in
    checkpoints): more of what the policy fails, so that one task type's gains do not go unnoticed as another's losses."""


@dataclass
class PPOArgs:
    """PPO: the update, the advantages and the networks."""

    learning_rate: float = 3e-4
    """Adam learning rate of policy and value."""
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
    mirror_twins: bool = False
    """act on an episode whose goal slot is the mirror image, in the arm's plane of symmetry y = 0, of another slot of
    its task type (`goal_configurations.mirror_twins`: a slot at y > 0 with a twin at its mirror image; on the shipped
    site the window openings at y = +0.85 and -0.85) as on its twin's: the networks see the mirrored state
    (`state_mirror_signs`) and the action is mirrored back (JOINT_MIRROR_SIGNS). The table lies at y = 0, so a slot
    reached from the turret's +pi side is met as its twin reached from -pi. A window's head stays up, so in the
    mirror it must be installed turned half a turn on the plate: a goal orientation of its own, left to reward
    (probe AJ learnt it from near-goal starts, not the grasp before it). Joint control only."""
    mirror_canonical_reach: bool = False
    """with `mirror_twins`, until the grasp the networks see a mirrored window's goal orientation as it is (the same
    at every opening; the mirror turns it half a turn): the tasks' measures of a mirrored slot (`plate_turn`) make the reach and the grasp of the
    opening at y = +0.85 then see what those of the one at -0.85 see, the plate's roll not mattering to them; after
    the grasp the honest mirror, where the carry turns the element half a turn more."""
    mirror_held_half_turn: bool = False
    """with `mirror_canonical_reach`, once the window is held the networks see the goal's orientation as it is too,
    and joint 6, the plate and the window turned half a turn about the plate's axis: a window is a box, so that is
    a state of the mirrored opening, installed where it is; the carry's extra half turn then shows right after the
    grasp, above the staging table, instead of at the opening."""
    bounded_mean: bool = False
    """squash the policy's mean into the action bounds by tanh: an unbounded mean can drift past them, where
    every draw clips to the same action, the advantages cannot tell draws apart and the mean stays there (the
    from-scratch runs' joints driven to their limits)."""
    mean_saturation_coef: float = 0.0
    """with `bounded_mean`, a penalty of this weight on the square of how far each of the mean's values before tanh
    lies beyond +-`mean_saturation_bound`: where it is far past, tanh's slope is nil and PPO cannot move the mean
    (the from-scratch policy's turret, pinned at -10 there, turned every window toward the same side of the table
    whatever the reward said); 0: off."""
    mean_saturation_bound: float = 2.0
    """where `mean_saturation_coef`'s penalty begins on the mean's values before tanh: at 2 tanh is 0.96 of the action
    bound and its slope 0.07 (1e-8 at 10); at 1, 0.76 and 0.42."""
    mean_saturation_joints: Optional[tuple[int, ...]] = None
    """the action dimensions (0-based) `mean_saturation_coef` penalizes; None: all. The turret alone (0) leaves the
    other joints' means, which a policy drives at full speed on every task, as they are (probe AD, which penalized
    all six, lost its ceiling panels)."""
    log_std_floor: Optional[float] = None
    """a floor under the policy's log standard deviation on `log_std_floor_joints`, raised to it at the start and held
    after every optimizer step (update.py): the from-scratch policy's turret spread shrank to 0.10 around a mean at
    tanh's end and an entropy bonus on all six joints did not widen it (probes AF, AG); None: off."""
    log_std_floor_joints: Optional[tuple[int, ...]] = None
    """the action dimensions (0-based) `log_std_floor` holds; None: all."""


@dataclass
class CuriosityArgs:
    """The curiosity bonus (ICM, baselines/ppo/curiosity.py)."""

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


@dataclass
class CurriculumArgs:
    """The tolerance curriculum (Table I): its stages and when a stage ends."""

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
    stage_schedules: bool = False
    """ML-Agents' linear schedules, restarted at every curriculum stage (as when each stage is a run that
    inherits the last): over a stage's --stage-timesteps the learning rate falls to 1e-10, the clip
    coefficient to 0.1 and the entropy coefficient to 1e-5."""


@dataclass
class WarmStartArgs:
    """A warm start (a behaviour clone's weights, a behaviour-cloning term) or a residual on a frozen base."""

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
    residual_of: Optional[str] = None
    """a checkpoint (a behaviour clone, or a refined agent: a residual on a residual) that stays frozen as the base
    policy; PPO learns a correction added to its actions (baselines/ppo/residual.py, ResiP). Its observation
    statistics stay too."""
    residual_scale: float = 0.1
    """the correction's scale in action units."""
    residual_l2_coef: float = 0.0
    """weight of the correction's mean square (before scaling) in the policy loss: an anchor at the clone,
    so that the residual moves only where the advantages keep asking it to."""


@dataclass
class StartStateArgs:
    """Where training episodes start: a bank of states where a policy failed, or near the goal (reverse curriculum)."""

    start_states: Optional[str] = None
    """a bank of env states (baselines/ppo/start_states.py, where a policy failed) that a share of the
    training episodes start from; evaluation always resets as usual. physx_cpu only."""
    start_states_share: float = 0.5
    """the share of training episodes that start from the bank."""
    start_states_keep_clock: bool = False
    """an episode started from the bank goes on from the elapsed steps its state was taken at (a failure that ran
    out of time stays one) instead of getting the whole step limit again; the bank must hold them (a bank of
    start_states.py collected since it keeps them)."""
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
    near_goal_share_end: Optional[float] = None
    """once a task type's radius is 1, each further promotion lowers its share of near-goal starts by
    `near_goal_step`, down to this (the curriculum handing its episodes back to ordinary resets); None: the share
    stays `near_goal_share`."""
    near_goal_max_steps: Optional[int] = None
    """a near-goal episode that has not placed within this many steps is truncated (None: the task's step limit)."""
    goal_slot_weights: Optional[tuple[float, ...]] = None
    """nine weights >= 0: the goal slots' sampling weights in training, three per task type (ceiling, window,
    flooring; the tasks' `goal_slot_weights`), e.g. 1 1 1 1 1 4 1 1 1 to train the window opening at y = +0.85 more;
    evaluation always draws them uniformly."""
    reach_start_share: float = 0.0
    """this share of the training episodes start with the arm part of the way from its start configuration to a table
    grasp configuration on a turret side the goal slot's start paths leave from, the element lying on the table (the
    tasks' `reach_start_share`: the start-state curriculum's first stretch); evaluation always resets as usual."""
    reach_start_radius: Optional[float] = None
    """reach starts as the start-state curriculum carried back through the grasp (the tasks' `set_reach_starts`):
    each goal slot's starts on the reach path's last this much of its length (0: right above the element, about to
    grasp it; 1: anywhere from the reset on), widened by `near_goal_step` once the last `near_goal_window` reach-start
    episodes of the slot grasped their element from the turret side they started on at least `near_goal_promote` of
    the time. None: the fixed reach starts above."""
    reach_start_tasks: Optional[tuple[str, ...]] = None
    """with `reach_start_radius`, the task types whose resets reach starts draw from (None: all): the others keep
    their ordinary resets (a task whose policy already grasps from the side its paths leave from learns nothing
    from them, and its reach from the reset goes untrained)."""


_GROUP = tyro.conf.OmitArgPrefixes  # a group's fields keep their flat flags: --gamma, not --ppo.gamma


@dataclass
class Args(RunArgs):
    """ppo.py's command line, one flag per field (`--seed`, `--gamma`, `--icm-strength`, ...): the run's fields, then
    PPO's, curiosity's, the curriculum's, the warm start's and the start states', each group a nested dataclass."""

    ppo: Annotated[PPOArgs, _GROUP] = field(default_factory=PPOArgs)
    """PPO: the update, the advantages and the networks."""
    icm: Annotated[CuriosityArgs, _GROUP] = field(default_factory=CuriosityArgs)
    """the curiosity bonus (ICM)."""
    stages: Annotated[CurriculumArgs, _GROUP] = field(default_factory=CurriculumArgs)
    """the tolerance curriculum (Table I)."""
    warm: Annotated[WarmStartArgs, _GROUP] = field(default_factory=WarmStartArgs)
    """a warm start or a residual on a frozen base."""
    starts: Annotated[StartStateArgs, _GROUP] = field(default_factory=StartStateArgs)
    """where training episodes start."""

    @classmethod
    def of(cls, **values: Any) -> "Args":
        """Args from flat field names (`Args.of(gamma=0.95, near_goal_share=0.8)`, a checkpoint's saved dict): each
        goes to its group; the rest keep their defaults. An unknown name is refused as a dataclass would."""
        return cls().replace(**values)

    def replace(self, **values: Any) -> "Args":
        """A copy with these fields (flat names) replaced, as `dataclasses.replace` but across the groups."""
        unknown = sorted(set(values) - set(GROUP_OF))
        if unknown:
            raise TypeError(f"Args has no field(s) {', '.join(unknown)}")
        groups = {g: dataclasses.replace(getattr(self, g), **{k: v for k, v in values.items() if GROUP_OF[k] == g})
                  for g in GROUPS}
        return dataclasses.replace(self, **{k: v for k, v in values.items() if GROUP_OF[k] is None}, **groups)

    def flat(self) -> dict:
        """Every field by its flat name (what a checkpoint saves as its args)."""
        return {f.name: getattr(self if g is None else getattr(self, g), f.name) for g, f in flat_fields()}


GROUPS = {"ppo": PPOArgs, "icm": CuriosityArgs, "stages": CurriculumArgs, "warm": WarmStartArgs, "starts": StartStateArgs}
"""Args' nested groups: attribute name and dataclass."""


def flat_fields() -> Iterator[tuple[Optional[str], dataclasses.Field]]:
    """(group or None for the run's own, field) of every field of Args, in the command line's order."""
    for f in dataclasses.fields(RunArgs):
        yield None, f
    for g, cls in GROUPS.items():
        for f in dataclasses.fields(cls):
            yield g, f


GROUP_OF = {f.name: g for g, f in flat_fields()}
"""flat field name: its group (None: the run's own)."""


def validate(args: Args) -> None:
    """Refuse, before anything starts, what the run would otherwise fail on later (often in the env
    worker processes, with their tracebacks)."""
    if args.env_id not in ENV_IDS:
        raise SystemExit(f"--env-id {args.env_id}: use one of {', '.join(ENV_IDS)}")
    values = args.flat()
    for g, f in flat_fields():  # Args built in code are not checked by tyro
        hint = get_type_hints(RunArgs if g is None else GROUPS[g])[f.name]
        allowed = get_args(hint) if get_origin(hint) is Literal else ()
        if allowed and values[f.name] not in allowed:
            raise SystemExit(f"--{f.name.replace('_', '-')} {values[f.name]}: use one of {', '.join(allowed)}")
    for name in ("residual_of", "start_states"):
        if values[name] is not None and not Path(values[name]).is_file():
            raise SystemExit(f"--{name.replace('_', '-')}: no such file: {values[name]}")
    if args.warm.residual_l2_coef and not args.warm.residual_of:
        raise SystemExit("--residual-l2-coef weighs a residual's correction: give --residual-of")
    if args.warm.residual_of and args.warm.bc_coef > 0:
        raise SystemExit("--bc-coef works on the policy's own weights; a residual agent (--residual-of) has none to pull")
    if args.task_weights is not None and (args.env_id != "ConstructionPickPlace-v1" or min(args.task_weights) < 0
                                          or sum(args.task_weights) <= 0):
        raise SystemExit(f"--task-weights {args.task_weights}: three weights >= 0, not all 0 (ceiling, window, flooring), "
                         "of the general task ConstructionPickPlace-v1 only")
    if args.failure_task_weights < 0 or (args.failure_task_weights and (args.task_weights is not None
                                                                      or args.env_id != "ConstructionPickPlace-v1")):
        raise SystemExit(f"--failure-task-weights {args.failure_task_weights}: a window of episodes (> 0; 0: off), of the "
                         "general task ConstructionPickPlace-v1 only, without --task-weights")
    gsw = args.starts.goal_slot_weights
    if gsw is not None and (len(gsw) != 9 or min(gsw) < 0 or any(sum(gsw[i:i + 3]) <= 0 for i in (0, 3, 6))):
        raise SystemExit(f"--goal-slot-weights {' '.join(map(str, gsw))}: nine weights >= 0, three per task type "
                         "(ceiling, window, flooring), not all 0 within a type")
    if args.ppo.mean_saturation_coef < 0 or (args.ppo.mean_saturation_coef > 0 and not args.ppo.bounded_mean):
        raise SystemExit(f"--mean-saturation-coef {args.ppo.mean_saturation_coef}: a weight >= 0 on the mean's values "
                         "before tanh, with --bounded-mean")
    if args.ppo.mirror_twins and (args.control_mode != "pd_joint_delta_pos" or args.warm.residual_of):
        raise SystemExit("--mirror-twins mirrors the joints' actions of a plain policy: with --control-mode "
                         "pd_joint_delta_pos and without --residual-of")
    if args.ppo.mirror_canonical_reach and not args.ppo.mirror_twins:
        raise SystemExit("--mirror-canonical-reach changes what the mirror shows: give --mirror-twins too")
    if args.ppo.mirror_held_half_turn and not args.ppo.mirror_canonical_reach:
        raise SystemExit("--mirror-held-half-turn goes on from what --mirror-canonical-reach shows: give it too")
    if args.ppo.mean_saturation_bound <= 0:
        raise SystemExit(f"--mean-saturation-bound {args.ppo.mean_saturation_bound}: a value > 0 before tanh")
    for flag, joints, needs, has in (("--mean-saturation-joints", args.ppo.mean_saturation_joints,
                                      "--mean-saturation-coef > 0", bool(args.ppo.mean_saturation_coef)),
                                     ("--log-std-floor-joints", args.ppo.log_std_floor_joints, "--log-std-floor",
                                      args.ppo.log_std_floor is not None)):
        if joints is not None and (not joints or min(joints) < 0 or len(set(joints)) != len(joints) or not has):
            raise SystemExit(f"{flag} {' '.join(map(str, joints or ()))}: distinct action dimensions >= 0 "
                             f"(0: the turret), with {needs}")
    radius = args.starts.reach_start_radius
    if radius is not None and (not 0 <= radius <= 1 or not args.starts.reach_start_share):
        raise SystemExit(f"--reach-start-radius {radius}: a fraction in [0, 1] of the reach path, with --reach-start-share "
                         "> 0")
    tasks = args.starts.reach_start_tasks
    if tasks is not None and (radius is None or not tasks or any(t not in ELEMENT_KINDS for t in tasks)):
        raise SystemExit(f"--reach-start-tasks {' '.join(tasks)}: task types among {', '.join(ELEMENT_KINDS)}, with "
                         "--reach-start-radius")
    for name in ("near_goal_share", "near_goal_radius", "near_goal_promote", "reach_start_share"):
        if not 0 <= values[name] <= 1:
            raise SystemExit(f"--{name.replace('_', '-')} must lie in [0, 1], got {values[name]}")
    end = args.starts.near_goal_share_end
    if end is not None and not 0 <= end <= values["near_goal_share"]:
        raise SystemExit(f"--near-goal-share-end {end}: a share in [0, --near-goal-share "
                         f"({values['near_goal_share']})]")
    if not 0 <= args.starts.start_states_share <= 1:
        raise SystemExit(f"--start-states-share must lie in [0, 1], got {args.starts.start_states_share}")
    if args.starts.start_states_keep_clock and not args.starts.start_states:
        raise SystemExit("--start-states-keep-clock: give the bank (--start-states)")
    if args.starts.start_states and args.sim_backend == "physx_cuda":
        raise SystemExit("--start-states: physx_cpu only (the bank is restored in the env worker processes)")
    missing = [p for p in args.warm.demos if not Path(p).is_file()]
    if missing:
        raise SystemExit(f"--demos: no such file(s): {', '.join(missing)} (record them with scripts/collect_demos.py)")
    bad = [s for s in args.stages.curriculum if s not in STAGE_NAMES]
    if bad or not args.stages.curriculum:
        raise SystemExit(f"--curriculum {' '.join(args.stages.curriculum)}: stages must be among {', '.join(STAGE_NAMES)}")
    for name in ("total_timesteps", "stage_timesteps", "num_minibatches", "update_epochs", "eval_freq", "checkpoint_freq"):
        if values[name] <= 0:
            raise SystemExit(f"--{name.replace('_', '-')} must be positive, got {values[name]}")


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
        args.exp_name = f"{args.env_id}__{args.icm.curiosity}__{'-'.join(args.stages.curriculum)}__s{args.seed}"
    if args.ppo.bootstrap_at_done is None:
        args.ppo.bootstrap_at_done = "truncated" if args.reward_mode == "sparse" else "always"


def command_line(args: Args) -> list[str]:
    """ppo.py's flags that build `args` (those that differ from the defaults), so that a run configured in code
    (experiments/) can be written down as one `python baselines/ppo/ppo.py ...` command."""
    return cli.flags(args.flat(), Args().flat())
