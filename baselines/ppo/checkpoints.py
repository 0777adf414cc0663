"""A run's record: its progress, its checkpoints (one API to save and load them) and its CSV log.

A checkpoint is the dict that `save_checkpoint` writes with torch.save: the run's args, progress,
observation and action sizes, the Agent's weights (with its observation normalization), the
optimizers, ICM and the RNG states (for an exact --resume). baselines/ppo/ppo.py and bc.py write
them; `load_checkpoint` reads one for training or resuming, `load_policy` for evaluation.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import pickle
import random
import signal
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import torch
import torch.nn as nn

from baselines.ppo import curiosity
from baselines.ppo.networks import Agent, CanonicalReach, Mirror
from baselines.ppo.residual import ResidualAgent
from ms_construction.envs.carry_geometry import JOINT_MIRROR_SIGNS
from ms_construction.envs.state_layout import (
    STATE_IS_GRASPED,
    STATE_QUATERNION_STARTS,
    STATE_TASK_START,
    TASK_SLOTS_BEFORE_PANELING,
    state_mirror_signs,
)
from ms_construction.parameters import ELEMENT_KINDS, PAPER_KINDS

WHAT_A_CHECKPOINT_IS = ("a checkpoint is the .pt file that baselines/ppo/ppo.py or baselines/ppo/bc.py writes "
                        "(torch.save of a dict with args, obs_dim, act_dim and the agent's weights)")
def value_heads(args) -> int:
    """Value heads of the agent `args` (ppo.py's Args or a checkpoint's saved dict of them) describes: two
    (extrinsic, curiosity) with ML-Agents' curiosity, which has its own discount and ignores episode ends; one
    otherwise."""
    return curiosity.value_heads((args if isinstance(args, dict) else args.flat())["curiosity"])


def make_agent(args, obs_dim: int, act_dim: int, base_args: Optional[dict] = None) -> nn.Module:
    """The Agent that `args` (ppo.py's Args or a checkpoint's saved dict of them) describes; with
    `residual_of`, a ResidualAgent on a base that `base_args` (the base checkpoint's args) describes; a base that is
    itself a residual carries its own base's args under `base_args["base_args"]`."""
    get = (args if isinstance(args, dict) else args.flat()).get
    if get("residual_of"):
        if base_args is None:
            raise ValueError("a residual agent needs its base's args (the checkpoint's base_args)")
        time_input = bool(get("obs_elapsed_time", False))  # the base was trained without the time entry
        base = make_agent(base_args, obs_dim - int(time_input), act_dim, base_args.get("base_args"))
        return ResidualAgent(base, get("hidden_size"),
                             get("residual_scale"), value_heads=value_heads(args), time_input=time_input)
    starts = STATE_QUATERNION_STARTS if get("rotation_features", False) else ()
    mirror = None
    if get("mirror_twins", False):
        if act_dim != len(JOINT_MIRROR_SIGNS):
            raise ValueError(f"mirror_twins mirrors joint actions ({len(JOINT_MIRROR_SIGNS)}), not {act_dim}")
        canonical = None
        if get("mirror_canonical_reach", False):
            tcp, goal, obj = STATE_QUATERNION_STARTS
            canonical = CanonicalReach(STATE_IS_GRASPED, goal, bool(get("mirror_held_half_turn", False)), tcp, obj)
        mirror = Mirror(state_mirror_signs(obs_dim, bool(get("obstacles"))), torch.tensor(JOINT_MIRROR_SIGNS),
                        mirrored_goals(), canonical)
    return Agent(obs_dim, act_dim, get("hidden_size"), starts, value_heads(args), get("num_layers", 3),
                 bool(get("bounded_mean", False)), mirror)


REMOVED_ENV_OPTIONS = ("carry_along_paths", "reach_in_joint_space", "reach_toward_path_sides", "reach_avoids_vias",
                       "carry_counts_lag", "carry_keeps_to_vias", "install_mirror_branch", "reach_starts_to_lift")
"""task kwargs that checkpoints before 2026-11-28 saved: the first three, `carry_keeps_to_vias` and
`install_mirror_branch` became the one dense reward's measures, the rest were deleted (never adopted)."""


def mirrored_goals() -> torch.Tensor:
    """[G, 4]: of each goal slot with a mirror twin (`goal_configurations.mirror_twins`), the index of its task type's
    one-hot entry in the state observation and its goal position: where a policy with `mirror_twins` acts in the
    mirror."""
    from ms_construction.assets import load_manifest
    from ms_construction.goal_configurations import mirror_twins

    goals = load_manifest()["goal_poses"]
    rows = [[STATE_TASK_START + k, *goals[ELEMENT_KINDS[k]][slot][:3]] for k, slot in zip(*np.nonzero(mirror_twins() >= 0))]
    return torch.tensor(rows, dtype=torch.float32).reshape(-1, 4)


def upgrade_args(saved: dict) -> dict:
    """A checkpoint's saved ppo.py args under their current names and meanings, so that checkpoints
    written by earlier versions still load: `finite_horizon_gae` / `bootstrap_at_truncation` (booleans)
    became `bootstrap_at_done`, `norm_adv` a choice of where advantages are normalized, and `icm`
    meant the normalized variant (now `icm_normalized`) before ML-Agents' curiosity (with its
    `icm_gamma`) took the name; the task kwargs of REMOVED_ENV_OPTIONS are dropped."""
    args = dict(saved)
    for old in ("finite_horizon_gae", "bootstrap_at_truncation"):
        if old in args:
            args["bootstrap_at_done"] = "truncated" if args.pop(old) else "never"
    if isinstance(args.get("norm_adv"), bool):
        args["norm_adv"] = "minibatch" if args["norm_adv"] else "none"
    if args.get("curiosity") == "icm" and "icm_gamma" not in args:
        args["curiosity"] = "icm_normalized"
    if "mirror_windows" in args:  # the mirror of every slot with a twin, named for the one site's windows until 2026-11-28
        args["mirror_twins"] = args.pop("mirror_windows")
    for option in REMOVED_ENV_OPTIONS:  # the dense reward's options, now its only way (or deleted)
        args.pop(option, None)
    if args.get("base_args") is not None:  # a refined agent's base that is itself a residual (ppo.py --residual-of)
        args["base_args"] = upgrade_args(args["base_args"])
    return args


class StopRequest:
    """Ctrl-C or SIGTERM while a run trains: made before the loop (it installs the handlers), it is true once asked,
    the loop (`while ... and not stop`) ends after the iteration under way and `report` saves a checkpoint; a second
    Ctrl-C ends it at once (KeyboardInterrupt, which the loop catches: that iteration is lost, the last checkpoint
    stands). `restore` (in the loop's `finally`) puts the previous handlers back."""

    def __init__(self) -> None:
        self.signals: list[int] = []
        self._handlers = {signum: signal.signal(signum, self._ask) for signum in (signal.SIGINT, signal.SIGTERM)}

    def __bool__(self) -> bool:
        return bool(self.signals)

    def _ask(self, signum, _frame) -> None:
        self.signals.append(signum)
        signal.signal(signal.SIGINT, signal.default_int_handler)

    def restore(self) -> None:
        for signum, handler in self._handlers.items():
            signal.signal(signum, handler)

    def report(self, interrupted: bool, progress: Progress, save, save_model: bool, resume: str) -> None:
        """After the loop: where a signal stopped it, `save()` the checkpoint; say how to resume either way."""
        if interrupted:
            print(f"interrupted during iteration {progress.iteration}, which is lost; resume from the last checkpoint "
                  f"with: {resume}", file=sys.stderr)
        elif self.signals:
            save()
            saved = f"checkpoint saved; resume with: {resume}" if save_model else "no checkpoint (--no-save-model)"
            print(f"stopped by {signal.Signals(self.signals[0]).name} at step {progress.global_step} (iteration "
                  f"{progress.iteration}): {saved}", file=sys.stderr)

    def exit(self) -> None:
        """End the process as the signal asked (exit status 128 + its number), if one did."""
        if self.signals:
            raise SystemExit(128 + self.signals[0])


@dataclass
class Progress:
    """Where a run is; saved in checkpoints."""

    global_step: int = 0
    iteration: int = 0
    stage_index: int = 0
    stage_start_step: int = 0
    smoothed_success: Optional[float] = None
    stage_changes: list = field(default_factory=list)
    """(global_step, stage) at every stage start."""
    near_goal_radius: Optional[list] = None
    """the start-state curriculum's radius now per task type (ELEMENT_KINDS order; --near-goal-share); None before
    it starts."""
    near_goal_share: Optional[list] = None
    """the share of training episodes that start near the goal now per task type (--near-goal-share, lowered by
    --near-goal-share-end's rule); None before it starts."""
    near_goal_recent: Optional[list] = None
    """per task type, whether each of its latest near-goal episodes placed (the window a widening looks at)."""
    ordinary_recent: Optional[list] = None
    """per task type, whether each of its latest episodes from ordinary resets placed (--failure-task-weights)."""
    reach_start_radius: Optional[list] = None
    """the reach starts' radius now per goal slot (task type * 3 + slot; --reach-start-radius); None before they
    start."""
    reach_start_recent: Optional[list] = None
    """per goal slot, whether each of its latest reach-start episodes grasped from the side it started on."""


def save_checkpoint(path: Path, args, progress: Progress, agent: Agent, optimizer, icm, icm_optimizer,
                    obs_dim: int, act_dim: int, **extra) -> None:
    """Write atomically (a temporary file in the same folder, then a rename); `extra` entries (e.g.
    bc.py's record of its demonstrations) are stored beside the run's state."""
    state = dict(
        args=args.flat(), progress=dataclasses.asdict(progress), obs_dim=obs_dim, act_dim=act_dim,
        task_slots=len(ELEMENT_KINDS), agent=agent.state_dict(), optimizer=None if optimizer is None else optimizer.state_dict(),
        icm=None if icm is None else icm.state_dict(),
        icm_optimizer=None if icm_optimizer is None else icm_optimizer.state_dict(),
        rng=dict(python=random.getstate(), numpy=np.random.get_state(), torch=torch.get_rng_state(),
                 cuda=torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None),
        **extra,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


def restore_rng(rng: dict) -> None:
    """The random generators (Python, numpy, torch, CUDA) as `save_checkpoint` saved them, for an exact resume."""
    random.setstate(rng["python"])
    np.random.set_state(rng["numpy"])
    torch.set_rng_state(rng["torch"])
    if rng["cuda"] is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(rng["cuda"])


def load_checkpoint(path, option: str = "--checkpoint", env_id: Optional[str] = None, obs_dim: Optional[int] = None,
                    act_dim: Optional[int] = None, control_mode: Optional[str] = None) -> dict:
    """The checkpoint at `path` (given as `option`), its args under their current names. With
    `env_id` and its observation and action sizes (and control mode), a checkpoint that does not fit
    them is refused. Every refusal is one line (SystemExit) that names the file."""
    if not Path(path).is_file():
        raise SystemExit(f"{option}: checkpoint not found: {path}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
    except (pickle.UnpicklingError, zipfile.BadZipFile, EOFError, RuntimeError, ValueError, OSError) as e:
        raise SystemExit(f"{option}: {path} is not a checkpoint, or a truncated one ({type(e).__name__}); "
                         f"{WHAT_A_CHECKPOINT_IS}") from None
    missing = [k for k in ("agent", "obs_dim", "act_dim", "args") if not isinstance(ckpt, dict) or k not in ckpt]
    if missing:
        raise SystemExit(f"{option}: {path} is not a checkpoint (missing {', '.join(missing)}); {WHAT_A_CHECKPOINT_IS}")
    ckpt["args"] = upgrade_args(ckpt["args"])
    if ckpt.get("base_args") is not None:
        ckpt["base_args"] = upgrade_args(ckpt["base_args"])
    ckpt = with_task_slots(ckpt)
    if obs_dim is not None:
        check_fit(ckpt, path, env_id, obs_dim, act_dim, control_mode)
    return ckpt


def check_fit(ckpt: dict, path, env_id: str, obs_dim: int, act_dim: int, control_mode: Optional[str] = None) -> None:
    """Refuse `ckpt` if it was made for other observation or action sizes than `env_id`'s here, or
    (given one) another control mode."""
    if (ckpt["obs_dim"], ckpt["act_dim"]) != (obs_dim, act_dim):
        raise SystemExit(
            f"checkpoint {path} does not fit {env_id}: it was trained with observations of size {ckpt['obs_dim']} and "
            f"actions of size {ckpt['act_dim']} (env {ckpt['args']['env_id']}, control mode "
            f"{ckpt['args']['control_mode']}); {env_id} in {control_mode} with state observations has {obs_dim} and "
            f"{act_dim}. Use the checkpoint's control mode and state observations.")
    if control_mode is not None and ckpt["args"]["control_mode"] != control_mode:
        raise SystemExit(f"checkpoint {path} was trained in control mode {ckpt['args']['control_mode']}, "
                         f"not {control_mode}: use --control-mode {ckpt['args']['control_mode']}")


def insert_filled(t: torch.Tensor, dim: int, at: int, fill: float, n: int = 1) -> torch.Tensor:
    """`t` with `n` slices of `fill` inserted before index `at` along `dim` (a network's input widened by new
    observation entries: zero weights, neutral statistics)."""
    shape = list(t.shape)
    shape[dim] = n
    return torch.cat([t.narrow(dim, 0, at), torch.full(shape, fill, dtype=t.dtype), t.narrow(dim, at, t.shape[dim] - at)], dim)


def _feature_index(args: dict, obs_dim: int, index: int) -> int:
    """Where observation entry `index` is among the features of the Agent `args` describes (`rotation_features`
    puts six numbers where each quaternion's four were)."""
    from baselines.ppo.networks import _feature_layout

    if not args.get("rotation_features"):
        return index
    _, order = _feature_layout(tuple(STATE_QUATERNION_STARTS), obs_dim, torch.device("cpu"))
    return order.tolist().index(index)


def _widen_policy(agent: dict, prefix: str, args: dict, base_args: Optional[dict], obs_dim: int, index: int,
                  widened: dict) -> int:
    """Give the policy under `prefix` in `agent` (a state dict, changed in place) a zero input for new observation
    entry `index` (obs_dim: the observation's size with it); returns where the entry is among its innermost Agent's
    features. `widened` collects {parameter name: column inserted}."""
    if args.get("residual_of"):
        time_input = int(bool(args.get("obs_elapsed_time")))
        at = _widen_policy(agent, prefix + "base.", base_args, base_args.get("base_args"), obs_dim - time_input,
                           index, widened)
    else:
        at = _feature_index(args, obs_dim, index)
        for key, fill in (("obs_rms.mean", 0.0), ("obs_rms.var", 1.0)):
            agent[prefix + key] = insert_filled(agent[prefix + key], 0, at, fill)
    for key in ("critic.0.weight", "actor_mean.0.weight", "residual_mean.0.weight"):
        if prefix + key in agent:
            agent[prefix + key] = insert_filled(agent[prefix + key], 1, at, 0.0)
            widened[prefix + key] = at
    return at


def _widen_adam(state: dict, names: list[str], widened: dict) -> dict:
    """An Adam state dict whose parameters (named `names`, in the optimizer's order) gained the `widened` columns:
    zero moments there (a zero input's weight has had zero gradient), so the next steps are those it would take."""
    state = {**state, "state": dict(state["state"])}
    for i, name in enumerate(names):
        if name in widened and i in state["state"]:
            moments = dict(state["state"][i])
            for key in ("exp_avg", "exp_avg_sq"):
                moments[key] = insert_filled(moments[key], 1, widened[name], 0.0)
            state["state"][i] = moments
    return state


def _progress_per_task_type(progress: Optional[dict], args: dict) -> Optional[dict]:
    """A saved Progress whose per-task-type (and per-goal-slot) lists were of the paper's three task types, with
    entries for the new ones where their curricula would start (the radius the run started its own at, empty windows)."""
    from baselines.ppo.start_states import GOAL_SLOTS

    if progress is None:
        return None
    progress, old, new = dict(progress), len(PAPER_KINDS), len(ELEMENT_KINDS)
    for key, per, fill in (("near_goal_radius", 1, args.get("near_goal_radius")), ("near_goal_recent", 1, None),
                           ("ordinary_recent", 1, None), ("reach_start_radius", GOAL_SLOTS, args.get("reach_start_radius")),
                           ("reach_start_recent", GOAL_SLOTS, None)):
        if progress.get(key) is not None and len(progress[key]) == old * per:
            progress[key] = list(progress[key]) + [[] if fill is None else fill for _ in range((new - old) * per)]
    return progress


def with_task_slots(ckpt: dict) -> dict:
    """`ckpt` for today's observation, whose task one-hot has a slot per task type of ELEMENT_KINDS: a checkpoint
    saved before paneling became the fourth type (its one-hot had TASK_SLOTS_BEFORE_PANELING slots) gets a zero
    input weight for the new slot in the first layer of every network that reads the observation (policy, value,
    a residual's base, curiosity's encoder), statistics of mean 0 and variance 1 for it, and zero optimizer moments
    there. It acts, values and trains on the paper's three task types exactly as before (the slot is 0 in all of
    them, and an input that is always 0 gets no gradient); on paneling, its task input is all zeros."""
    if ckpt.get("task_slots", TASK_SLOTS_BEFORE_PANELING) == len(ELEMENT_KINDS):
        return ckpt
    index, obs_dim = STATE_TASK_START + TASK_SLOTS_BEFORE_PANELING, ckpt["obs_dim"] + 1
    agent, widened = dict(ckpt["agent"]), {}
    _widen_policy(agent, "", ckpt["args"], ckpt.get("base_args"), obs_dim, index, widened)
    out = {**ckpt, "agent": agent, "obs_dim": obs_dim, "task_slots": len(ELEMENT_KINDS),
           "progress": _progress_per_task_type(ckpt.get("progress"), ckpt["args"])}
    if ckpt.get("optimizer") is not None:
        net = make_agent(ckpt["args"], obs_dim, ckpt["act_dim"], ckpt.get("base_args"))
        names = [name for name, p in net.named_parameters() if p.requires_grad]
        out["optimizer"] = _widen_adam(ckpt["optimizer"], names, widened)
    if ckpt.get("icm") is not None:
        icm = dict(ckpt["icm"])
        first = "encoder.0.0.weight"  # the encoder's first layer: the ICM's first parameter, as in its optimizer
        icm[first] = insert_filled(icm[first], 1, index, 0.0)
        out["icm"] = icm
        if ckpt.get("icm_optimizer") is not None:
            out["icm_optimizer"] = _widen_adam(ckpt["icm_optimizer"], [first], {first: index})
    return out


PATH_OFFSET_SIZE = 6
"""numbers the tasks' `obs_path_offset` appends (a joint move)."""


def with_path_offset_inputs(ckpt: dict, path) -> dict:
    """`ckpt` (a plain policy trained without `obs_path_offset`) for a run that adds the path offset to the observation
    (after the install offset, before the elapsed time), as `_with_new_inputs` adds inputs (a joint move in rad)."""
    at = ckpt["agent"]["obs_rms.mean"].shape[0] - int(bool(ckpt["args"].get("obs_elapsed_time")))
    return _with_new_inputs(ckpt, path, at, PATH_OFFSET_SIZE, "obs_path_offset", "the path-offset inputs")


def with_obstacle_inputs(ckpt: dict, path) -> dict:
    """`ckpt` (a plain policy trained on a site without obstacles) for a run among them (`obstacles`), whose
    observation ends with the obstacles' entry (OBSTACLE_OBS_SIZE numbers, after everything else), as
    `_with_new_inputs` adds inputs: it acts as it did blind until the run learns to read them. The run's `obstacles`
    says which scene; the checkpoint's args gain `obstacles` = "static" until the run saves its own."""
    from ms_construction.envs.obstacles import OBSTACLE_OBS_SIZE

    at = ckpt["agent"]["obs_rms.mean"].shape[0]
    return _with_new_inputs(ckpt, path, at, OBSTACLE_OBS_SIZE, "obstacles", "the obstacle inputs", value="static")


def _with_new_inputs(ckpt: dict, path, at: int, size: int, flag: str, what: str, value=True) -> dict:
    """A copy of `ckpt` (a plain policy) whose observation gains `size` inputs at index `at`: the first layers of its
    policy and value get zero weights for them and its observation statistics a mean of 0 and a variance of 1 there,
    so that it acts and values as before whatever they say; its args gain `flag` = `value`. `path` names it in
    errors."""
    args = ckpt["args"]
    if args.get("residual_of") or ckpt.get("icm") is not None:
        raise SystemExit(f"--checkpoint {path}: only a plain policy without curiosity gains {what}")
    agent = dict(ckpt["agent"])
    for key, fill in (("obs_rms.mean", 0.0), ("obs_rms.var", 1.0)):
        v = agent[key]
        agent[key] = torch.cat([v[:at], torch.full((size,), fill, dtype=v.dtype), v[at:]])
    for key in ("critic.0.weight", "actor_mean.0.weight"):
        w = agent[key]
        agent[key] = torch.cat([w[:, :at], torch.zeros(w.shape[0], size, dtype=w.dtype), w[:, at:]], 1)
    return {**ckpt, "agent": agent, "obs_dim": ckpt["obs_dim"] + size, "args": {**args, flag: value}}


def policy_env_kwargs(args: dict) -> dict:
    """The env kwargs that a checkpoint's policy (its saved `args`) acts in, beside obs_mode="state": its control
    mode and the observation's optional entries (install offset, path offset, elapsed time, obstacles) it was trained
    with: `obs_obstacles=True` for a policy trained among obstacles (`obstacles`), whatever site it acts on
    (scripts/evaluate.py passes `obs_obstacles=False` otherwise, so a policy trained without them meets them blind)."""
    return dict(control_mode=args["control_mode"],
                **{k: True for k in ("obs_install_offset", "obs_path_offset", "obs_elapsed_time") if args.get(k)},
                **({"obs_obstacles": True} if args.get("obstacles") else {}))


def load_policy(path, env_id: str) -> tuple[Agent, dict]:
    """The checkpoint's Agent (in eval mode) and the env kwargs it acts in (`policy_env_kwargs`: pass them to
    gym.make with obs_mode="state"), after checking that it fits `env_id`'s observations there."""
    import gymnasium as gym

    ckpt = load_checkpoint(path)
    env_kwargs = policy_env_kwargs(ckpt["args"])
    control_mode = env_kwargs["control_mode"]
    env = gym.make(env_id, obs_mode="state", num_envs=1, sim_backend="physx_cpu", **env_kwargs)
    obs_dim, act_dim = env.observation_space.shape[-1], env.action_space.shape[-1]
    env.close()
    check_fit(ckpt, path, env_id, obs_dim, act_dim, control_mode)
    agent = make_agent(ckpt["args"], ckpt["obs_dim"], ckpt["act_dim"], ckpt.get("base_args"))
    try:
        agent.load_state_dict(ckpt["agent"])
    except RuntimeError as e:
        raise SystemExit(f"checkpoint {path}: its weights do not fit the policy network ({e})") from None
    return agent.eval(), env_kwargs


def average_checkpoints(paths: list, out: Path) -> dict:
    """The policy whose weights are the mean of the checkpoints' at `paths` (snapshots of one run: same
    networks, same frozen parts), written to `out`, with the last checkpoint's other entries and
    `averaged_from` naming the snapshots. The weights that every snapshot shares (a residual's frozen
    base, frozen observation statistics) must be equal in all of them, and are kept as they are."""
    ckpts = [load_checkpoint(p) for p in paths]
    last = ckpts[-1]["agent"]
    for p, c in zip(paths, ckpts):
        if c["agent"].keys() != last.keys() or any(c["agent"][k].shape != v.shape for k, v in last.items()):
            raise SystemExit(f"{p}: its networks differ from {paths[-1]}'s; average snapshots of one run")
    frozen = {k for k in last if k.startswith("base.") or k.startswith("obs_rms.")}
    for k in frozen:
        if not all(torch.equal(c["agent"][k], last[k]) for c in ckpts):
            raise SystemExit(f"{k} differs between the snapshots: they are not of one run with that part frozen")
    agent = {k: v if k in frozen or not v.is_floating_point() else sum(c["agent"][k] for c in ckpts) / len(ckpts)
             for k, v in last.items()}
    averaged = dict(ckpts[-1], agent=agent, averaged_from=[str(p) for p in paths])
    torch.save(averaged, out)
    return averaged


CSV_FIELDS = [
    "global_step", "iteration", "stage", "episodes", "pick_success", "place_success", "extrinsic_return",
    "intrinsic_return", "episode_length", "eval_pick_success", "eval_place_success", "eval_extrinsic_return",
    "smoothed_eval_success", "sps", "learning_rate", "value_loss", "policy_loss", "entropy", "approx_kl",
    "icm_forward_loss", "icm_inverse_loss", "bc_loss", "clip_coef", "ent_coef", "end_place_dist",
    "end_place_angle_deg", "held_at_end", "near_goal_radius", "near_goal_episodes", "near_goal_place_success",
    "ordinary_place_success", "ordinary_place_ceiling", "ordinary_place_window", "ordinary_place_flooring",
    "near_goal_radius_ceiling", "near_goal_radius_window", "near_goal_radius_flooring",
    "task_weight_ceiling", "task_weight_window", "task_weight_flooring", "mean_saturation",
    "reach_start_episodes", "reach_start_grasp_success",
    "reach_start_radius_ceiling0", "reach_start_radius_ceiling1", "reach_start_radius_ceiling2",
    "reach_start_radius_window0", "reach_start_radius_window1", "reach_start_radius_window2",
    "reach_start_radius_flooring0", "reach_start_radius_flooring1", "reach_start_radius_flooring2",
    "ordinary_pick_ceiling", "ordinary_pick_window", "ordinary_pick_flooring",
    # the fourth task type's, after the paper's three so that the columns of earlier runs keep their places
    "ordinary_place_paneling", "ordinary_pick_paneling", "near_goal_radius_paneling", "task_weight_paneling",
    "reach_start_radius_paneling0", "reach_start_radius_paneling1", "reach_start_radius_paneling2",
    # --near-goal-share-end's shares, newer still (plain names: scripts/plot_training.py reads this list as a literal)
    "near_goal_share_ceiling", "near_goal_share_window", "near_goal_share_flooring", "near_goal_share_paneling",
]
"""`end_*` and `held_at_end`: where the iteration's training episodes ended (mean place distance in m and
angle error in degrees to the goal at the last step, share with the element held), what a run that
places nothing still shows. `near_goal_*`: the start-state curriculum's radius (the mean of the task types', and each one's) and its episodes
(--near-goal-share);
`ordinary_place_success`: the place success of the other training episodes, those from ordinary resets (neither
near-goal nor reach starts; in probes AC to AE the reach starts counted among them), and
`ordinary_place_<task>` the same per task type, `ordinary_pick_<task>` their pick success (grasped at least once: a
near-goal start counts as picked from its first step, so `pick_success` alone hides the grasps a policy learnt); `task_weight_<task>`: the training envs' sampling probability of each
task type from the next iteration on (--failure-task-weights); `mean_saturation`: the penalty of
--mean-saturation-coef before its weight (the bounded mean's squared excess before tanh, summed over the action
dimensions it penalizes); `reach_start_*`: the reach starts' episodes, the share that grasped from the side they
started on, and each goal slot's radius (`reach_start_radius_window2`: the window opening at y = +0.85;
--reach-start-radius)."""


class CSVLog:
    """Appends one row per iteration (the columns `fields`: ppo.py's CSV_FIELDS by default); on resume, drops rows
    past the checkpoint's step."""

    def __init__(self, path: Path, resume_step: Optional[int], fields: Sequence[str] = CSV_FIELDS):
        self.path, self.fields = path, list(fields)
        if resume_step is not None and path.exists():
            with open(path) as f:
                rows = [r for r in csv.DictReader(f) if int(r["global_step"]) <= resume_step]
            self._write(rows, "w")
        else:
            self._write([], "w")

    def _write(self, rows, mode):
        with open(self.path, mode, newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.fields, extrasaction="ignore")
            if mode == "w":
                w.writeheader()
            w.writerows(rows)

    def append(self, row: dict) -> None:
        self._write([{k: row.get(k, "") for k in self.fields}], "a")
