"""Speed of the construction tasks and of their learner, on CPU and GPU; writes docs/BENCHMARKS.md.

    python scripts/benchmark.py                     # CPU sections, and the GPU section where CUDA is there
    python scripts/benchmark.py --steps 300 --rounds 2 --no-write
    python scripts/benchmark.py --no-cpu            # the GPU section only
    python scripts/benchmark.py --no-cpu --no-gpu --obstacles   # the obstacle scenes' section only
    python scripts/benchmark.py --workers 16 --trainings free-none free-recipe free-recipe-cuda \
        --cpu-section cpu-speed-16-cores            # a larger machine's CPU figures, beside this one's

CPU (physx_cpu, state observations, pd_joint_delta_pos, uniform random actions):

- one env in this process: each task against ManiSkill's PickCube-v1 (dense reward), with and
  without the element held by the plate (the grasp's per-substep tracking; most of every real
  pick-carry-place episode); and with rgb observations (the 128x128 camera rendered every step, on
  sapien's CUDA device where there is one, else on the CPU's Vulkan);
- env processes: ms_construction.vector_env.CPUVectorEnv (one env per process, the first in the
  learner's) with 1, 2 and 4 envs: PickCube-v1, the general task (also with every env in a worker
  process, the layout before env 0 moved into the learner's, as a reference in the same round), the
  general task with the element held, and
  baselines/ppo/ppo.py training on the same number of processes (its env steps/s with the PPO update
  included; the learner's defaults but for the number of envs), free-running and held, ICM off and
  on, and the from-scratch recipe (`--trainings`; `-cuda`: its learner on the GPU), against those
  processes simulating alone: the share of the simulator's speed the learner keeps;
- peak host memory: the resident set of this process and of each env worker process;
- among obstacles (`--obstacles`, its own section): one env with the recipe's training kwargs on the site as built,
  with static and moving obstacles and the mixed scene the runs among obstacles train on, a reset every few steps as
  in a trained agent's episodes.

Each figure is the median over rounds that alternate between the things compared, so the drifts of
a shared machine hit them all alike.

GPU (physx_cuda, where CUDA is there; skipped with a message otherwise): steps/s of each task and of
PickCube-v1 at 256, 1024 and 4096 envs with state observations (also with the element held in every
env) and at 256 envs with the 128x128 rgb camera, with ratios to PickCube-v1 on the same GPU; a
CPU-GPU parity check of a scripted grasp and carry; PPO's env steps/s on physx_cuda. Each GPU
measurement runs in a fresh process: physx_cuda keeps one GPU system per process, and a crash or a
hang then costs that measurement only.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import platform
import queue
import resource
import statistics
import sys
import tempfile
import time
import traceback
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import gymnasium as gym
import numpy as np
import torch
import tyro
from tqdm import tqdm

from ms_construction.envs import ENV_IDS
from ms_construction.envs.construction_env import default_render_backend
from ms_construction.reporting import update_section
from ms_construction.vector_env import CPUVectorEnv

REFERENCE = "PickCube-v1"
GENERAL = "ConstructionPickPlace-v1"
"""the task the general agent trains on: the vectorized and training measurements use it."""


TRAINING = (("free", "none"), ("free", "icm"), ("held", "none"), ("held", "icm"), ("free", "recipe"), ("free", "sac"))
"""the trainings measured against the simulation alone: PPO free-running or held steps, ICM off or on (the paper's
learner: sparse reward), PPO's from-scratch recipe (experiments/from_scratch.py: the dense reward, its
observation's joint moves, near-goal starts, its rollout and update sizes), and SAC's (experiments/sac_recipe.py,
the recipe's learner: the same envs and reward, a replay buffer and its gradient steps)."""
CPU_ONLY = {"sac"}
"""trainings whose learner runs on the CPU only (baselines/sac/sac.py has no GPU learner)."""


@dataclass
class Args:
    steps: int = 1000
    """env steps per one-env measurement."""
    vector_steps: int = 300
    """steps of the vector env (each steps every worker's env) per vectorized measurement."""
    rounds: int = 3
    """alternating rounds; each figure is the median over them."""
    workers: tuple[int, ...] = (1, 2, 4)
    """env processes of the vectorized and training measurements."""
    train_iterations: int = 3
    """timed PPO iterations per training measurement (one untimed start-up iteration before them)."""
    rgb_steps: int = 200
    """env steps per rgb-camera measurement (one env; 0: skip it)."""
    trainings: tuple[str, ...] = tuple(f"{steps}-{curiosity}" for steps, curiosity in TRAINING)
    """the trainings measured against the simulation alone, each STEPS-SETTING of TRAINING (free-none, free-icm,
    held-none, held-icm, free-recipe, free-sac); with `-cuda` after a PPO one (free-recipe-cuda), the same with the
    learner on the GPU (its rollouts' forward passes and its update)."""
    cpu: bool = True
    """run the CPU sections."""
    gpu: bool = True
    """run the GPU section when CUDA is there."""
    obstacles: bool = False
    """run the obstacle scenes' section (one env, the recipe's training kwargs; section cpu-obstacles)."""
    obstacle_episode_steps: int = 25
    """env steps between the resets of the obstacle section: about a trained agent's episode among obstacles (the
    runs' progress.csv, episode_length), most of them near-goal starts."""
    gpu_envs: tuple[int, ...] = (256, 1024, 4096)
    """num_envs of the state-observation GPU measurements."""
    gpu_rgb_envs: int = 256
    """num_envs of the rgb-camera GPU measurement (0: skip it)."""
    gpu_steps: int = 100
    """timed steps per GPU measurement (after GPU_WARMUP untimed ones)."""
    gpu_timeout: float = 900.0
    """seconds one GPU measurement process may take."""
    write: bool = True
    """write the sections into --out."""
    out: Path = Path("docs/BENCHMARKS.md")
    cpu_section: str = "cpu-speed"
    """the section of --out the CPU figures replace: another machine's figures go in a section of their own beside
    this machine's (for example `cpu-speed-16-cores`)."""


def trainings(args: Args) -> list[tuple[str, str, str]]:
    """--trainings as (steps, curiosity, learner device) of TRAINING; a clear error for any other, and for a learner
    on the GPU where there is none."""
    allowed = {f"{steps}-{curiosity}{suffix}": (steps, curiosity, device) for steps, curiosity in TRAINING
               for suffix, device in (("", "cpu"), ("-cuda", "cuda")) if not (device == "cuda" and curiosity in CPU_ONLY)}
    unknown = [t for t in args.trainings if t not in allowed]
    if not args.trainings or len(set(args.trainings)) < len(args.trainings):
        raise SystemExit(f"--trainings {' '.join(args.trainings)}: give one or more, each once")
    if unknown:
        raise SystemExit(f"--trainings: unknown {', '.join(unknown)}; allowed: "
                         f"{', '.join(t for t in allowed if not t.endswith('-cuda'))}, each PPO one also with -cuda")
    if any(allowed[t][2] == "cuda" for t in args.trainings) and not torch.cuda.is_available():
        raise SystemExit("--trainings: a learner on the GPU (-cuda) needs a CUDA GPU, and this machine has none")
    return [allowed[t] for t in args.trainings]


def main(args: Args) -> None:
    trainings(args)  # a wrong --trainings stops here, not after minutes of measurements
    if args.cpu:
        body = cpu_sections(args)
        print(body)
        if args.write:
            update_section(args.out, args.cpu_section, title="Benchmarks", body=body)
            print(f"wrote {args.out}")
    if args.obstacles:
        body = obstacle_section(args)
        print(body)
        if args.write:
            update_section(args.out, "cpu-obstacles", title="Benchmarks", body=body)
            print(f"wrote {args.out}")
    if args.gpu:
        if not torch.cuda.is_available():
            print("GPU section skipped: no CUDA GPU here (physx_cuda needs one)")
            return
        body = gpu_section(args)
        print(body)
        if args.write:
            update_section(args.out, "gpu-speed", title="Benchmarks", body=body)
            print(f"wrote {args.out}")


def command(args: Args) -> str:
    """The command line that gives `args` (the defaults left out)."""
    out = []
    for name, default in vars(Args()).items():
        value = getattr(args, name)
        if value != default and name not in ("write", "out"):
            flag = "--" + name.replace("_", "-")
            if isinstance(value, bool):
                out.append(flag if value else "--no-" + name.replace("_", "-"))
            else:
                out.append(f"{flag} {' '.join(map(str, value)) if isinstance(value, tuple) else value}")
    return " ".join(["python scripts/benchmark.py", *out])


def machine() -> str:
    gpu = f", {torch.cuda.get_device_name(0)} GPU" if torch.cuda.is_available() else ", no GPU"
    return (f"{platform.machine()}, {os.cpu_count()} CPU cores{gpu}, Python {sys.version.split()[0]}, "
            f"torch {torch.__version__}, sapien {__import__('sapien').__version__}, "
            f"mani_skill {__import__('mani_skill').__version__}")


# ------------------------------------------------------------------------------------------------- #
# The element held
# ------------------------------------------------------------------------------------------------- #
class HoldElement(gym.Wrapper):
    """The element held from every reset on while `hold` is on (`set_hold`; through CPUVectorEnv.call)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.hold = False

    def set_hold(self, hold: bool) -> None:
        self.hold = hold
        if hold:
            self.env.unwrapped.set_held()

    def reset(self, **kwargs):
        out = self.env.reset(**kwargs)
        if self.hold:
            self.env.unwrapped.set_held()
        return out


class AlwaysHeld(HoldElement):
    """HoldElement, on from the start (the training envs: the learner does not know of the hold)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.hold = True


# ------------------------------------------------------------------------------------------------- #
# CPU
# ------------------------------------------------------------------------------------------------- #
CPU_KWARGS = dict(obs_mode="state", control_mode="pd_joint_delta_pos", render_mode=None)


def make(env_id: str, obs_mode: str = "state"):
    # render_backend for PickCube-v1 too: ManiSkill's own envs would warn without CUDA
    return gym.make(env_id, num_envs=1, sim_backend="physx_cpu", reward_mode="dense",
                    render_backend=default_render_backend(), **dict(CPU_KWARGS, obs_mode=obs_mode))


def steps_per_second(env, steps: int, seed: int, held: bool = False, reset_every: Optional[int] = None) -> float:
    """One env: uniform random actions from a seeded reset, a reset where an episode ends (and, with `reset_every`,
    every that many steps: episodes as long as a trained agent's)."""
    u = env.unwrapped
    env.reset(seed=seed)
    if held:
        u.set_held()
    gen = torch.Generator().manual_seed(seed)
    low = torch.as_tensor(env.action_space.low)
    high = torch.as_tensor(env.action_space.high)
    actions = low + (high - low) * torch.rand((steps, *low.shape), generator=gen)
    t0 = time.perf_counter()
    for i in range(steps):
        _, _, term, trunc, _ = env.step(actions[i])
        if bool(term.any() or trunc.any()) or (reset_every and (i + 1) % reset_every == 0):
            env.reset()
            if held:
                u.set_held()
    return steps / (time.perf_counter() - t0)


def vector_steps_per_second(envs: CPUVectorEnv, steps: int, seed: int) -> float:
    """Env steps/s (envs x vector steps per second) of uniform random actions; same-step resets."""
    envs.reset(seed=seed)
    gen = torch.Generator().manual_seed(seed)
    actions = torch.rand((steps, envs.num_envs, *envs.single_action_space.shape), generator=gen) * 2 - 1
    t0 = time.perf_counter()
    for a in actions:
        envs.step(a)
    return steps * envs.num_envs / (time.perf_counter() - t0)


@contextmanager
def held_training_envs():
    """While open, baselines/ppo/ppo.py's physx_cpu training envs hold their element from every reset
    on (its evaluation envs do not)."""
    from baselines.ppo import ppo

    make_envs = ppo.make_envs

    def held(args, num_envs, device, eval_mode=False, video_dir=None):
        if eval_mode:
            return make_envs(args, num_envs, device, eval_mode, video_dir)
        return CPUVectorEnv(args.env_id, num_envs, dict(CPU_KWARGS, reward_mode=args.reward_mode), device=device,
                            wrappers=[AlwaysHeld])

    ppo.make_envs = held
    try:
        yield
    finally:
        ppo.make_envs = make_envs


def ppo_steps_per_second(iterations: int, backend: str, num_envs: Optional[int] = None, held: bool = False,
                         curiosity: Optional[str] = None, learner: Optional[str] = None) -> dict:
    """baselines/ppo/ppo.py on GENERAL with its defaults but the paper's sparse reward (and `num_envs` and `curiosity`,
    when given), or the from-scratch recipe (`curiosity="recipe"`): the median env steps/s of `iterations` iterations
    (rollout and update; the first, start-up, iteration and the last, whose final evaluation is cut to one step, left
    out). The learner on `learner` ("cpu" or "cuda"; None: the GPU with physx_cuda, the CPU with physx_cpu, as the
    recipe trains). No checkpoints."""
    import csv

    from baselines.ppo import ppo

    from experiments.from_scratch import scratch_args

    with tempfile.TemporaryDirectory() as log_dir:
        common = dict(sim_backend=backend, cuda=learner == "cuda" if learner else backend == "physx_cuda",
                      num_eval_envs=1, num_eval_steps=1,
                      eval_freq=10**9, save_model=False, log_dir=log_dir, exp_name="benchmark")
        if curiosity == "recipe":
            run_args = scratch_args(num_envs, **common)
        else:
            run_args = ppo.Args.of(env_id=GENERAL, num_envs=num_envs, reward_mode="sparse", **common,
                                   **({} if curiosity is None else dict(curiosity=curiosity)))
        run = ppo.setup(run_args)
        run.args.total_timesteps = run.args.num_envs * run.args.num_steps * (iterations + 2)
        with held_training_envs() if held else nullcontext():
            ppo.train(run)
        with open(Path(log_dir) / "benchmark" / "progress.csv") as f:
            sps = [float(row["sps"]) for row in csv.DictReader(f)][1:-1]
    return dict(sps=statistics.median(sps), num_envs=run.args.num_envs, num_steps=run.args.num_steps,
                curiosity=run.args.icm.curiosity, reward_mode=run.args.reward_mode)


def sac_steps_per_second(rows: int, num_envs: int) -> dict:
    """SAC as the recipe trains it (experiments/sac_recipe.py `sac_args`) on `num_envs` env processes: the median env
    steps/s of `rows` progress rows (log_freq env steps each, its gradient steps included) once its buffer holds
    learning_starts transitions; the rows of its random-action start, and the one that straddles it, left out. No
    checkpoints, no evaluations. Over the same rows, where its time went (progress.csv's clock): `env_ms` per env
    step (the env steps with the actor's actions and the replay buffer), `update_ms` per gradient step, and `utd`
    its gradient steps per env step."""
    import csv

    from baselines.sac import sac
    from experiments.sac_recipe import sac_args

    with tempfile.TemporaryDirectory() as log_dir:
        a = sac_args(1, num_envs=num_envs, log_dir=log_dir, exp_name="benchmark", eval_freq=0, save_model=False)
        first = -(-a.learning_starts // a.log_freq) * a.log_freq  # the first row with gradient steps in it
        a.total_timesteps = first + rows * a.log_freq
        sac.main(a)
        with open(Path(log_dir) / "benchmark" / "progress.csv") as f:
            log = list(csv.DictReader(f))
    timed = [row for row in log if int(row["global_step"]) > first]
    start, end = log[len(log) - len(timed) - 1], log[-1]  # the clock where the timed rows begin and end
    change = {k: float(end[k]) - float(start[k]) for k in ("global_step", "env_s", "update_s", "updates")}
    return dict(sps=statistics.median(float(row["sps"]) for row in timed), num_envs=num_envs,
                env_ms=1e3 * change["env_s"] / change["global_step"],
                update_ms=1e3 * change["update_s"] / max(change["updates"], 1),
                utd=change["updates"] / change["global_step"])


def sac_table(parts: dict[int, list[dict]], alone: dict[int, list[float]]) -> str:
    """Where SAC's training time goes per env step (`sac_steps_per_second`'s clock, per round) on each number of env
    processes, and the most it could make of the env processes: with its env steps free (or hidden behind its
    gradient steps), its gradient steps alone set its pace, 1 / (gradient steps per env step x a gradient step's
    time); that ceiling over the same round's simulation alone (`alone`) is the share it could keep at most."""
    lines = ["| env processes | env steps (actions, replay buffer), ms per env step | gradient step, ms | gradient "
             "steps per env step | ms per env step | ceiling with env steps free, env steps/s | ceiling's share of "
             "simulating alone |", "|---|---|---|---|---|---|---|"]
    for n, rounds in parts.items():
        med = {k: statistics.median(r[k] for r in rounds) for k in ("env_ms", "update_ms", "utd")}
        ceiling = [1e3 / (r["utd"] * r["update_ms"]) for r in rounds]
        share = [c / a for c, a in zip(ceiling, alone[n])]
        lines.append(f"| {n} | {med['env_ms']:.2f} | {med['update_ms']:.1f} | {med['utd']:.2f} | "
                     f"{med['env_ms'] + med['utd'] * med['update_ms']:.2f} | {statistics.median(ceiling):.0f} | "
                     f"{statistics.median(share):.2f} ({min(share):.2f}-{max(share):.2f}) |")
    return "\n".join(lines)


START_UP = "start-up and shut-down"
"""the training envs made and closed: timed apart, and left out of the vector step."""


def step_parts() -> list[tuple[type, str, str]]:
    """(class, method, label) of what a training's vector step spends its time in, in the learner's process: env 0's
    step (it runs there) by part, the wait for the other env processes, the policy's forward passes, the update."""
    from baselines.ppo import networks, ppo
    from ms_construction.envs.carry_geometry import CarryGeometry
    from ms_construction.envs.construction_env import ConstructionTaskEnv

    return [(ConstructionTaskEnv, "_step_action", "env 0: action, physics substeps and the hold"),
            (ConstructionTaskEnv, "evaluate", "env 0: evaluate (placement, grasp)"),
            (ConstructionTaskEnv, "_get_obs_extra", "env 0: the task's observation"),
            (CarryGeometry, "project", "env 0: of which the start-path projection"),
            (ConstructionTaskEnv, "get_reward", "env 0: reward"),
            (ConstructionTaskEnv, "reset", "env 0: resets (start states included)"),
            (CPUVectorEnv, "_wait_for_workers", "waiting for the other env processes"),
            (networks.Agent, "get_action", "the policy's forward pass, one per vector step"),
            (ppo, "ppo_update", "PPO's update (per vector step of its rollout)"),
            (ppo, "make_envs", START_UP),
            (CPUVectorEnv, "close", START_UP),
            (ppo, "train", "the training iterations in all")]


@contextmanager
def timing(parts: list[tuple[type, str, str]], spent: dict, outer: str, inner: str, apart: str):
    """While open, the wall time of the calls of each (owner, method, label) of `parts` made within the `outer` part's
    (the whole) adds up in `spent` (seconds, by label). A call inside another part's counts as that part's (a
    reset's observation is the reset's), but for the `inner` part (reported as an "of which"), which counts inside
    any part but `apart` (the start-up: a first call's compilation is not a step's). The methods are restored at the
    end."""
    saved, active = [], []

    def timed_call(f, label, *a, **k):
        if label != outer and (outer not in active or (label == inner and apart in active)
                               or (label != inner and active[-1] != outer)):
            return f(*a, **k)
        t = time.perf_counter()
        active.append(label)
        try:
            return f(*a, **k)
        finally:
            active.pop()
            spent[label] = spent.get(label, 0.0) + time.perf_counter() - t

    try:
        for owner, name, label in parts:
            defined = next((k for k in (owner.__mro__ if isinstance(owner, type) else (owner,)) if name in vars(k)), None)
            if defined is None:
                raise AttributeError(f"{getattr(owner, '__name__', owner)} has no {name} to time")
            saved.append((owner, name, vars(defined)[name] if defined is owner else None))
            setattr(owner, name, _timed(timed_call, getattr(owner, name), label))
        yield spent
    finally:
        for owner, name, original in reversed(saved):
            if original is None:
                delattr(owner, name)
            else:
                setattr(owner, name, original)


def _timed(timed_call: Callable, f: Callable, label: str) -> Callable:
    """`f` called through `timed_call` under `label` (a plain function: bound as a method where `f` is one)."""
    def timed(*a, **k):
        return timed_call(f, label, *a, **k)
    return timed


def step_split(iterations: int, num_envs: int, curiosity: str) -> tuple[dict, int]:
    """`ppo_steps_per_second`'s training (`curiosity` "none": the paper's sparse reward; "recipe": the from-scratch
    recipe) timed by part (`step_parts`), ms per vector step over all its iterations (its envs' start-up and shut-down
    left out), and its vector steps."""
    spent: dict = {}
    parts = step_parts()
    with timing(parts, spent, outer=parts[-1][2], inner=parts[3][2], apart=START_UP):
        run = ppo_steps_per_second(iterations, "physx_cpu", num_envs, curiosity=curiosity)
    vector_steps = run["num_steps"] * (iterations + 2)
    spent[parts[-1][2]] -= spent.pop(START_UP, 0.0)
    return {label: 1e3 * spent.get(label, 0.0) / vector_steps for _, _, label in parts if label != START_UP}, vector_steps


def split_table(args: Args) -> str:
    """Where a training's vector step goes, plain PPO (sparse reward) beside the recipe, on the most env processes of
    --workers that the cores hold; the rest: the rollout's bookkeeping (buffers, episode statistics, start-state
    curricula), logs and the evaluations."""
    n = max([w for w in args.workers if w <= (os.cpu_count() or 1)] or [min(args.workers)])
    columns = {name: step_split(args.train_iterations, n, curiosity) for name, curiosity in
               (("plain PPO, sparse reward", "none"), ("the from-scratch recipe", "recipe"))}
    labels = [label for _, _, label in step_parts() if label != START_UP]
    whole, nested = labels[-1], labels[3]
    for ms, _ in columns.values():
        ms["the rest: the rollout's bookkeeping, logs, evaluations"] = ms[whole] - sum(
            v for k, v in ms.items() if k not in (whole, nested))
    rows = [*labels[:-1], "the rest: the rollout's bookkeeping, logs, evaluations", whole]
    lines = [f"| ms per vector step ({n} env processes) | " + " | ".join(columns) + " | recipe / plain |",
             "|---|" + "---|" * (len(columns) + 1)]
    for label in rows:
        plain, recipe = (ms[label] for ms, _ in columns.values())
        bold = "**" if label == whole else ""
        lines.append(f"| {bold}{label}{bold} | {plain:.2f} | {recipe:.2f} | "
                     + (f"{recipe / plain:.1f} |" if plain > 0.005 else "- |"))
    lines.append("| env steps/s it makes | " + " | ".join(f"{1e3 * n / ms[whole]:.0f}" for ms, _ in columns.values())
                 + " | |")
    return "\n".join(lines)


def worker_peak_rss_mib(envs: CPUVectorEnv) -> float:
    """The largest peak resident set (VmHWM) of the vector env's worker processes, MiB (Linux)."""
    peaks = []
    for p in envs.worker_processes:
        with open(f"/proc/{p.pid}/status") as f:
            peaks += [int(line.split()[1]) / 1024 for line in f if line.startswith("VmHWM:")]
    return max(peaks, default=0.0)


def cpu_sections(args: Args) -> str:
    from experiments.sac_recipe import sac_args

    load_before = os.getloadavg()[0]
    one_env = one_env_table(args)
    rgb = rgb_table(args) if args.rgb_steps else None
    processes, training, worker_rss, sac_split = process_table(args)
    split = split_table(args)
    learner_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return "\n".join([
        f"## CPU (physx_cpu), {os.cpu_count()} cores",
        "",
        f"Command: `{command(args)}` ({time.strftime('%Y-%m-%d %H:%M')}).",
        f"Machine: {machine()}. Load average (1 min): {load_before:.1f} when the run began, {os.getloadavg()[0]:.1f} "
        f"when it ended, on {os.cpu_count()} cores (the benchmark keeps at most its env processes and itself busy; "
        "more is other work sharing the machine).",
        "",
        "### One env",
        "",
        "State observations, pd_joint_delta_pos, dense reward, uniform random actions, one env in the benchmark's "
        f"process; each figure is the median of {args.rounds} runs of {args.steps} steps, alternating with "
        f"{REFERENCE} in the same process. \"Held\": the element held by the plate from every reset on. Target: "
        "every task at least 0.8x PickCube-v1, held too.",
        "",
        one_env,
        "",
        *([] if rgb is None else [
            "### Rendering",
            "",
            "One env as above, with rgb observations (its cameras rendered every step, "
            + ("on sapien's CUDA device" if default_render_backend() == "gpu" else "on the CPU's Vulkan")
            + f") against state observations; median of {args.rounds} runs of {args.rgb_steps} steps.",
            "",
            rgb,
            "",
        ]),
        "### Env processes",
        "",
        "ms_construction.vector_env.CPUVectorEnv: one env per process, env 0 in the learner's (this one) and the "
        "others in worker processes, same-step resets, sparse reward (the paper's; the least a step can cost), uniform random actions, "
        f"{args.vector_steps} vector steps per measurement; env steps/s = envs x vector steps per second; medians of "
        f"{args.rounds} rounds. \"Held\": the element held by the plate from every reset on (as in most steps of a "
        "trained agent). \"Every env in a worker\": the same envs with `first_env_in_process=False`, the layout "
        "before env 0 moved into the learner's process; \"gain\": env 0 in the learner's process over it, per round.",
        "",
        processes,
        "",
        "### Training against simulating alone",
        "",
        f"baselines/ppo/ppo.py training on {GENERAL}: its defaults but the paper's sparse reward, the number of envs "
        "and the curiosity, or (\"recipe\") PPO's from-scratch recipe (experiments/from_scratch.py: its dense "
        "reward, the joint moves in its observation, near-goal and reach starts, 2,000-step rollouts); "
        f"{args.train_iterations} timed iterations after an untimed one, each its rollout and its PPO update (and ICM's "
        "where on); (\"sac\") baselines/sac/sac.py as the recipe trains it now (experiments/sac_recipe.py: the same "
        f"envs and dense reward, {sac_args().utd:g} gradient steps per env step), {args.train_iterations} rows of its "
        f"progress ({sac_args().log_freq:,} env steps each) after its buffer has filled; free-running steps, or the element held in every training env from every reset on; \"learner\": where "
        "its policy's forward passes and its update run (the env processes on the CPU either way). \"Share\": "
        "training's env steps/s over those of the same processes simulating alone with the sparse reward (the table "
        f"above) in the same round; median (range) of {args.rounds} rounds that alternate between them. Target: 0.6 or "
        "more (stretch 0.8), the recipe included.",
        "",
        training,
        "",
        "### Where a training step's time goes",
        "",
        "Two of the trainings above run again, plain PPO (free-none) and the recipe (free-recipe), each timed by part "
        f"in the learner's process over its {args.train_iterations + 2} iterations: env 0 runs there, so its step is timed by part (a call inside another part counts as that "
        "part's: a reset's observation is the reset's; the projection is the part of the observation the recipe's "
        "reward shares); the other env processes step meanwhile, and the learner waits for them; then its policy's "
        "forward pass for every env, and once per rollout its update. One run of each.",
        "",
        split,
        "",
        *([] if sac_split is None else [
            "### Where SAC's training time goes",
            "",
            "SAC's training above (\"sac\"), its clock over the same progress rows (progress.csv's env_s, update_s and "
            "updates): its env steps (with the actor's actions, the replay buffer, the start-state curriculum) per env "
            "step, one gradient step (actor and twin critics, batch "
            f"{sac_args().batch_size}, {sac_args().num_layers} x {sac_args().hidden_size}, "
            f"{sac_args().torch_threads} thread), and the ceiling its gradient steps set: the env steps/s it would make "
            "if its env steps cost nothing (or ran while it updates), and that ceiling's share of the same round's "
            "simulation alone (the table above, free-running); medians (range) of the rounds.",
            "",
            sac_split,
            "",
        ]),
        f"Peak host memory (resident set): the benchmark's process (learner, its env 0 and the one-env runs) "
        f"{learner_rss:,.0f} MiB; "
        + (f"one env worker process {worker_rss:,.0f} MiB at most." if worker_rss else "no worker process (one env)."),
    ]) + "\n"


def one_env_table(args: Args) -> str:
    envs = {eid: make(eid) for eid in (REFERENCE, *ENV_IDS)}
    for env in envs.values():  # warm-up
        steps_per_second(env, 50, seed=0)
    free = {eid: [] for eid in envs}
    held = {eid: [] for eid in ENV_IDS}
    with tqdm(total=args.rounds * 3 * len(ENV_IDS), desc="one env", unit="run") as bar:
        for r in range(args.rounds):
            for eid in ENV_IDS:
                free[REFERENCE].append(steps_per_second(envs[REFERENCE], args.steps, seed=r))
                free[eid].append(steps_per_second(envs[eid], args.steps, seed=r))
                held[eid].append(steps_per_second(envs[eid], args.steps, seed=r, held=True))
                bar.update(3)
    for env in envs.values():
        env.close()
    ref = statistics.median(free[REFERENCE])
    rows = [f"| env | steps/s | ratio to {REFERENCE} | steps/s, element held | ratio, held |", "|---|---|---|---|---|"]
    for eid in ENV_IDS:
        sps, sps_held = statistics.median(free[eid]), statistics.median(held[eid])
        rows.append(f"| {eid} | {sps:.0f} | {sps / ref:.2f} | {sps_held:.0f} | {sps_held / ref:.2f} |")
    rows.append(f"| {REFERENCE} (reference) | {ref:.0f} | 1.00 | | |")
    return "\n".join(rows)


OBSTACLE_SCENES = (("the site as built (reference)", None, 1.0), ("static obstacles", "static", 1.0),
                   ("moving obstacles", "moving", 1.0), ("moving obstacles in half the episodes", "moving", 0.5))
"""the obstacle section's rows: label, the tasks' `obstacles` and `obstacle_share` (the last: the mixed scene of the
runs among obstacles, `python -m experiments.obstacles --share 0.5`)."""


def make_training_env(obstacles: Optional[str], share: float):
    """One env of SAC's recipe (experiments/sac_recipe.py) with the tasks' `obstacles` and `obstacle_share`: its
    training kwargs (dense reward, observation, obstacles observed), near-goal starts as its training draws them at
    their widest."""
    from baselines.sac import sac
    from experiments.sac_recipe import sac_args

    a = sac_args(obstacles=obstacles, obstacle_share=share)
    env = gym.make(GENERAL, num_envs=1, sim_backend="physx_cpu", render_backend=default_render_backend(),
                   **sac.env_kwargs(a, train=True))
    env.unwrapped.set_near_goal_starts(a.near_goal_share, 1.0, a.near_goal_max_steps)
    return env


def obstacle_section(args: Args) -> str:
    envs = {label: make_training_env(scene, share) for label, scene, share in OBSTACLE_SCENES}
    for env in envs.values():  # warm-up: the planners and each goal slot's path points (once per env) made
        steps_per_second(env, args.steps, 10_000, reset_every=args.obstacle_episode_steps)
    sps = {label: [] for label in envs}
    with tqdm(total=args.rounds * len(envs), desc="obstacles", unit="run") as bar:
        for r in range(args.rounds):
            for label, env in envs.items():
                sps[label].append(steps_per_second(env, args.steps, r, reset_every=args.obstacle_episode_steps))
                bar.update()
    for env in envs.values():
        env.close()
    ref = statistics.median(sps[OBSTACLE_SCENES[0][0]])
    rows = ["| scene | env steps/s | ratio to the site as built |", "|---|---|---|"]
    rows += [f"| {label} | {statistics.median(v):.0f} | {statistics.median(v) / ref:.2f} |" for label, v in sps.items()]
    from experiments.sac_recipe import sac_args

    return "\n".join([
        f"## CPU (physx_cpu), {os.cpu_count()} cores: among obstacles",
        "",
        f"Command: `{command(args)}` ({time.strftime('%Y-%m-%d %H:%M')}). Machine: {machine()}. Load average (1 min) "
        f"when it ended: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores.",
        "",
        f"One env of SAC's recipe as it trains ({GENERAL}, its dense reward and observation, near-goal starts in "
        f"{sac_args().near_goal_share:.0%} of the episodes), uniform random actions from a seeded reset, a reset every "
        f"{args.obstacle_episode_steps} steps (about a trained agent's episode among obstacles); median of "
        f"{args.rounds} runs of {args.steps} steps after a warm-up run each, alternating the scenes in the same "
        "process, beside whatever else runs on the machine (the load average above). Where the obstacles cost: an "
        "episode with them checks its goal slot's start paths against the stack and the post at its reset "
        "(`clear_paths`); every step of a scene with obstacles, the mixed one's episodes without them too, poses the "
        "worker, reads the obstacles' contacts and observes them.",
        "",
        *rows,
    ]) + "\n"


def rgb_table(args: Args) -> str:
    """One env with rgb observations (its sensor cameras rendered every step) against state observations, on the
    render backend this machine has (sapien's CUDA device, else the CPU's Vulkan)."""
    envs = {(eid, mode): make(eid, mode) for eid in (REFERENCE, GENERAL) for mode in ("state", "rgb")}
    for env in envs.values():  # warm-up
        steps_per_second(env, 10, seed=0)
    sps = {k: [] for k in envs}
    for r in tqdm(range(args.rounds), desc="rgb camera", unit="round"):
        for key, env in envs.items():
            sps[key].append(steps_per_second(env, args.rgb_steps, seed=r))
    rows = ["| env | cameras | steps/s, state | steps/s, rgb | rgb / state |", "|---|---|---|---|---|"]
    for eid in (GENERAL, REFERENCE):
        state, rgb = statistics.median(sps[eid, "state"]), statistics.median(sps[eid, "rgb"])
        cams = ", ".join(f"{c.config.width}x{c.config.height}" for c in envs[eid, "rgb"].unwrapped._sensors.values())
        rows.append(f"| {eid} | {cams} | {state:.0f} | {rgb:.0f} | {rgb / state:.2f} |")
    for env in envs.values():
        env.close()
    return "\n".join(rows)


def process_table(args: Args) -> tuple[str, str, float, Optional[str]]:
    """The env processes' steps/s simulating alone, and PPO's training steps/s on the same number of
    processes, free-running and held, ICM off and on, with its share of the simulation alone; the peak worker
    memory; SAC's split (`sac_table`) where it is measured."""
    sim_rows = [f"| env processes | {REFERENCE} | {GENERAL} | {GENERAL}, held | {GENERAL}, every env in a worker | "
                "gain: env 0 in the learner's process |", "|---|---|---|---|---|---|"]
    ppo_rows = ["| env processes | env steps | curiosity or recipe | learner | training, env steps/s | "
                "simulating alone, env steps/s | share: training / simulating alone |", "|---|---|---|---|---|---|---|"]
    worker_rss = 0.0
    measured = trainings(args)
    sac_parts: dict[int, list[dict]] = {}
    alone: dict[int, list[float]] = {}
    for n in args.workers:
        ref = CPUVectorEnv(REFERENCE, n, dict(CPU_KWARGS, reward_mode="sparse"))
        ours = CPUVectorEnv(GENERAL, n, dict(CPU_KWARGS, reward_mode="sparse"), wrappers=[HoldElement])
        apart = CPUVectorEnv(GENERAL, n, dict(CPU_KWARGS, reward_mode="sparse"), first_env_in_process=False)
        for envs in (ref, ours, apart):  # warm-up
            vector_steps_per_second(envs, 20, seed=0)
        m = {k: [] for k in ("ref", "free", "held", "apart", *measured)}
        for r in tqdm(range(args.rounds), desc=f"{n} env processes", unit="round"):
            m["ref"].append(vector_steps_per_second(ref, args.vector_steps, seed=r))
            m["apart"].append(vector_steps_per_second(apart, args.vector_steps, seed=r))
            ours.call("set_hold", False)
            m["free"].append(vector_steps_per_second(ours, args.vector_steps, seed=r))
            ours.call("set_hold", True)
            m["held"].append(vector_steps_per_second(ours, args.vector_steps, seed=r))
            for steps, curiosity, learner in measured:
                if curiosity == "sac":
                    sac_parts.setdefault(n, []).append(sac_steps_per_second(args.train_iterations, n))
                    m[steps, curiosity, learner].append(sac_parts[n][-1]["sps"])
                else:
                    m[steps, curiosity, learner].append(ppo_steps_per_second(
                        args.train_iterations, "physx_cpu", n, held=steps == "held", curiosity=curiosity,
                        learner=learner)["sps"])
            alone.setdefault(n, []).append(m["free"][-1])
        worker_rss = max(worker_rss, worker_peak_rss_mib(ours))
        for envs in (ref, ours, apart):
            envs.close()
        med = {k: statistics.median(v) for k, v in m.items()}
        gain = statistics.median(f / a for f, a in zip(m["free"], m["apart"]))
        sim_rows.append(f"| {n} | {med['ref']:.0f} | {med['free']:.0f} | {med['held']:.0f} | {med['apart']:.0f} | {gain:.2f} |")
        for steps, curiosity, learner in measured:
            # each round's training over the same round's simulation alone
            share = [t / a for t, a in zip(m[steps, curiosity, learner], m[steps])]
            ppo_rows.append(f"| {n} | {steps} | {curiosity} | {learner} | {med[steps, curiosity, learner]:.0f} | "
                            f"{med[steps]:.0f} | "
                            f"{statistics.median(share):.2f} ({min(share):.2f}-{max(share):.2f}) |")
        print("\n".join(sim_rows[-1:] + ppo_rows[-len(measured):]), flush=True)
    return ("\n".join(sim_rows), "\n".join(ppo_rows), worker_rss,
            sac_table(sac_parts, {n: alone[n] for n in sac_parts}) if sac_parts else None)


# ------------------------------------------------------------------------------------------------- #
# GPU (physx_cuda)
# ------------------------------------------------------------------------------------------------- #
GPU_WARMUP = 5
"""untimed steps before each GPU measurement (kernels compiled, buffers allocated)."""
PARITY_ENV_IDS = ("CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1", "ConstructionPickPlace-v1")


def make_gpu(env_id: str, num_envs: int, obs_mode: str = "state", **kwargs):
    return gym.make(env_id, num_envs=num_envs, obs_mode=obs_mode, control_mode="pd_joint_delta_pos",
                    reward_mode="dense", sim_backend="physx_cuda", render_mode=None, **kwargs)


def all_finite(obs) -> bool:
    if isinstance(obs, dict):
        return all(all_finite(v) for v in obs.values())
    if torch.is_tensor(obs) and obs.is_floating_point():
        return bool(torch.isfinite(obs).all())
    return True


def image_stats(obs: dict) -> dict:
    """The first camera's rgb images: per-env standard deviation of the pixels (0-255), min and
    median over envs (a flat, e.g. black, image has 0)."""
    rgb = next(iter(obs["sensor_data"].values()))["rgb"]
    std = rgb.float().reshape(len(rgb), -1).std(dim=1)
    return dict(rgb_shape=list(rgb.shape), rgb_std_min=float(std.min()), rgb_std_median=float(std.median()))


def gpu_steps_per_second(env, steps: int, seed: int, held: bool = False, warmup: int = GPU_WARMUP):
    """(env steps/s = num_envs x control steps per second, whether the last observation is finite,
    the last observation) for uniform random actions from a reset; no resets while timing."""
    u = env.unwrapped
    env.reset(seed=seed)
    if held:
        u.set_held()
    low = torch.as_tensor(env.action_space.low, device=u.device)  # the batched space: [num_envs, act]
    high = torch.as_tensor(env.action_space.high, device=u.device)
    gen = torch.Generator(device=u.device).manual_seed(seed)
    actions = low + (high - low) * torch.rand((warmup + steps, *low.shape), generator=gen, device=u.device)
    for i in range(warmup):
        env.step(actions[i])
    torch.cuda.synchronize()
    t0 = time.perf_counter()
    for i in range(warmup, warmup + steps):
        obs, *_ = env.step(actions[i])
    torch.cuda.synchronize()
    return u.num_envs * steps / (time.perf_counter() - t0), all_finite(obs), obs


def gpu_measure(env_id: str, num_envs: int, obs_mode: str, steps: int) -> dict:
    """steps/s of one env at one size (and held, for a task with state observations)."""
    env = make_gpu(env_id, num_envs, obs_mode)
    rec = {}
    rec["sps"], rec["finite"], obs = gpu_steps_per_second(env, steps, seed=0)
    if obs_mode == "rgb":
        rec.update(image_stats(obs))
    elif env_id != REFERENCE:
        rec["sps_held"], rec["finite_held"], _ = gpu_steps_per_second(env, steps, seed=0, held=True)
    env.close()
    return rec


def _call_into(q, fn: Callable, args: tuple) -> None:
    import ms_construction  # noqa: F401  (registration, in a spawned process)

    try:
        q.put(fn(*args))
    except Exception:  # noqa: BLE001  (reported to the parent, which records it)
        q.put(dict(error=traceback.format_exc(limit=-3).strip().splitlines()[-1]))


def in_fresh_process(fn: Callable, *args, timeout: float):
    """fn(*args) in a spawned process: its result, or dict(error=why) if it raised, died or timed out."""
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_call_into, args=(q, fn, args))
    p.start()
    try:
        return q.get(timeout=timeout)
    except queue.Empty:
        return dict(error=f"no result after {timeout:.0f} s" if p.is_alive() else f"process died (exit code {p.exitcode})")
    finally:
        p.kill()
        p.join()


# ---- CPU-GPU parity: a scripted grasp and carry on physx_cpu, replayed on physx_cuda ---- #
def _parity_env(env_id: str, backend: str, num_envs: int = 1):
    return gym.make(env_id, num_envs=num_envs, obs_mode="state", control_mode="pd_joint_pos", reward_mode="sparse",
                    sim_backend=backend, render_mode=None, robot_init_qpos_noise=0.0)


def _log_row(u) -> dict:
    info = u.evaluate()
    row = dict(held=u.held, first_grasp=info["first_grasp"], success=info["success"], obj=u.obj.pose.raw_pose,
               tcp=u.agent.tcp.pose.raw_pose, place_dist=info["place_dist"], place_angle=info["place_angle_deg"])
    return {k: v.detach().cpu().clone() for k, v in row.items()}


def _stack_log(rows: list[dict]) -> dict:
    return {k: torch.stack([r[k] for r in rows]).numpy() for k in rows[0]}  # [steps, num_envs, ...]


def _tree_map(x, fn):
    return {k: _tree_map(v, fn) for k, v in x.items()} if isinstance(x, dict) else fn(x)


def _parity_cpu(env_id: str, seed: int) -> dict:
    """physx_cpu, one env, pd_joint_pos: joint-space moves to IK targets (above the grasp face, down
    until the ray grasps, a pause for the pull, lift, over the goal, onto the goal): the start state,
    the actions and the per-step log (numpy, to cross processes)."""
    import sapien

    from ms_construction.kinematics import ArmIK

    env = _parity_env(env_id, "physx_cpu")
    env.reset(seed=seed)
    u = env.unwrapped
    start = _tree_map(u.get_state_dict(), lambda t: t.cpu().numpy().copy())
    ik = ArmIK(u.agent.robot)
    q = u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)
    actions, rows = [], []

    def pose(raw: torch.Tensor) -> sapien.Pose:
        t = raw[0].cpu().numpy()
        return sapien.Pose(t[:3], t[3:])

    def solve(target, what):
        sol = ik.solve(target, seeds=[q])
        if sol is None:
            raise RuntimeError(f"{env_id}: no IK solution {what}")
        return sol

    def move(q_goal, n):
        nonlocal q
        q0 = q.copy()
        for i in range(1, n + 1):
            q = q0 + (q_goal - q0) * i / n
            a = torch.tensor(q, dtype=torch.float32)
            env.step(a[None])
            actions.append(a)
            rows.append(_log_row(u))

    k = int(u.task_id[0])
    tau = float(u.tau_pick[0])
    face = pose(u.obj.pose.raw_pose) * pose(u._grasp_in_el[k:k + 1])
    move(solve(face * sapien.Pose([0, 0, -(tau + 0.15)]), "above the grasp face"), 40)
    move(solve(face * sapien.Pose([0, 0, -(tau - 0.1)]), "at the grasp face"), 20)  # grasps on the way
    move(q, 15)  # the pull onto the plate
    if not bool(u.held[0]):
        raise RuntimeError(f"{env_id}: the scripted approach did not grasp")
    tcp_at_goal = pose(u.goal_pose.raw_pose) * pose(u.hold_pose_in_tcp).inv()
    lift = pose(u.agent.tcp.pose.raw_pose)
    move(solve(sapien.Pose(lift.p + np.array([0, 0, 0.3]), lift.q), "lifting"), 30)
    move(solve(tcp_at_goal * sapien.Pose([0, 0, -0.3]), "before the goal"), 60)
    move(solve(tcp_at_goal, "at the goal"), 30)
    move(q, 10)
    env.close()
    return dict(start=start, actions=torch.stack(actions).numpy(), log=_stack_log(rows))


def _parity_gpu(env_id: str, seed: int, cpu_run: dict, num_envs: int) -> dict:
    """physx_cuda: the CPU run's start state in every env, then its actions open loop: the per-step log."""
    env = _parity_env(env_id, "physx_cuda", num_envs)
    env.reset(seed=seed)
    u = env.unwrapped
    u.set_state_dict(_tree_map(cpu_run["start"], lambda a: torch.as_tensor(a, device=u.device).repeat(num_envs, *[1] * (a.ndim - 1))))
    u.agent.controller.reset()
    rows = []
    for a in cpu_run["actions"]:
        env.step(torch.as_tensor(a, device=u.device)[None].repeat(num_envs, 1))
        rows.append(_log_row(u))
    env.close()
    return dict(log=_stack_log(rows))


def _angle_deg(qa: torch.Tensor, qb: torch.Tensor) -> torch.Tensor:
    """Angle (degrees) of the rotation between unit quaternions [w, x, y, z]; atan2, not acos, so that
    small angles keep their precision in float32."""
    from ms_construction.rotations import qconj, qmul

    q = qmul(qconj(qa.double()), qb.double())
    return torch.rad2deg(2 * torch.atan2(torch.linalg.norm(q[..., 1:], dim=-1), q[..., 0].abs()))


def _first(flags: torch.Tensor) -> Optional[int]:
    idx = torch.nonzero(flags).flatten()
    return int(idx[0]) if len(idx) else None


def parity(env_id: str, seed: int = 0, num_envs: int = 2, timeout: float = 300.0) -> dict:
    """CPU run and GPU replay (each in a fresh process) and their differences: steps of the grasp and
    of success on each backend, steps where the held flag differs, and the element's position (m)
    and rotation (degrees) differences, the maximum before the grasp, while held and at the end.
    `gpu_spread_*`: the largest difference between GPU envs that got the same state and actions."""
    rec: dict = dict(env_id=env_id, seed=seed, gpu_envs=num_envs)
    cpu_run = in_fresh_process(_parity_cpu, env_id, seed, timeout=timeout)
    gpu_run = cpu_run if "error" in cpu_run else in_fresh_process(_parity_gpu, env_id, seed, cpu_run, num_envs,
                                                                  timeout=timeout)
    if "error" in gpu_run:
        return {**rec, "error": gpu_run["error"]}
    as_torch = lambda log: {k: torch.as_tensor(v) for k, v in log.items()}  # noqa: E731
    return {**rec, **parity_diff(as_torch(cpu_run["log"]), as_torch(gpu_run["log"]))}


def parity_diff(c: dict, g: dict) -> dict:
    """The differences between a CPU log `c` (env 0) and a GPU log `g` (env 0; and its spread over envs)."""
    c0 = {k: v[:, 0] for k, v in c.items()}
    g0 = {k: v[:, 0] for k, v in g.items()}
    dp = torch.linalg.norm(c0["obj"][:, :3] - g0["obj"][:, :3], dim=-1)
    da = _angle_deg(c0["obj"][:, 3:], g0["obj"][:, 3:])
    grasp_c, grasp_g = _first(c0["held"]), _first(g0["held"])
    before = slice(0, min(x for x in (grasp_c, grasp_g, len(dp)) if x is not None))
    held_both = c0["held"] & g0["held"]
    return dict(
        steps=len(dp),
        grasp_step_cpu=grasp_c, grasp_step_gpu=grasp_g,
        success_step_cpu=_first(c0["success"]), success_step_gpu=_first(g0["success"]),
        held_mismatch_steps=int((c0["held"] != g0["held"]).sum()),
        pos_diff_max_before_grasp=float(dp[before].max()) if before.stop > 0 else 0.0,
        pos_diff_max_held=float(dp[held_both].max()) if held_both.any() else None,
        pos_diff_max=float(dp.max()), pos_diff_final=float(dp[-1]),
        angle_diff_max_deg=float(da.max()),
        gpu_spread_pos_max=float(torch.linalg.norm(g["obj"][..., :3] - g["obj"][:, :1, :3], dim=-1).max()),
        gpu_spread_held_mismatch=int((g["held"] != g["held"][:, :1]).sum()),
    )


# ---- the section ---- #
def _ratio(x: Optional[float], ref: Optional[float]) -> str:
    return f"{x:,.0f} ({x / ref:.2f}x)" if x is not None and ref else (f"{x:,.0f}" if x is not None else "failed")


def gpu_section(args: Args) -> str:
    envs = (*ENV_IDS, REFERENCE)
    state = {}
    for n in args.gpu_envs:
        for eid in envs:
            state[eid, n] = in_fresh_process(gpu_measure, eid, n, "state", args.gpu_steps, timeout=args.gpu_timeout)
            print(eid, n, state[eid, n], flush=True)
    rgb = {}
    if args.gpu_rgb_envs:
        for eid in envs:
            rgb[eid] = in_fresh_process(gpu_measure, eid, args.gpu_rgb_envs, "rgb", args.gpu_steps, timeout=args.gpu_timeout)
            print(eid, "rgb", rgb[eid], flush=True)
    par = [parity(eid, timeout=args.gpu_timeout) for eid in PARITY_ENV_IDS]
    ppo_run = in_fresh_process(ppo_steps_per_second, args.train_iterations, "physx_cuda", timeout=args.gpu_timeout)

    name = torch.cuda.get_device_name(0)
    lines = ["## GPU (physx_cuda)", "", f"Command: `{command(args)}` ({time.strftime('%Y-%m-%d %H:%M')}).",
             f"GPU: {name}, {torch.cuda.get_device_properties(0).total_memory / 2**30:.0f} GiB; {machine()}.", "",
             f"Env steps/s (num_envs x control steps per second), uniform random actions, pd_joint_delta_pos, dense "
             f"reward, {GPU_WARMUP} untimed steps then {args.gpu_steps} timed ones from a reset, one fresh process "
             f"per measurement; in brackets the ratio to {REFERENCE} at the same num_envs (target: at least 0.5x at "
             "4096 envs). \"Held\": every env's element held by the plate for the whole run.", "",
             "| env | " + " | ".join(f"{n} envs" for n in args.gpu_envs) + " | "
             + " | ".join(f"held, {n} envs" for n in args.gpu_envs) + " |", "|---|" + "---|" * (2 * len(args.gpu_envs))]
    for eid in envs:
        ref = [None if eid == REFERENCE else state[REFERENCE, n].get("sps") for n in args.gpu_envs]
        cells = [_ratio(state[eid, n].get("sps"), r) for n, r in zip(args.gpu_envs, ref)]
        held = ["" if eid == REFERENCE else _ratio(state[eid, n].get("sps_held"), r) for n, r in zip(args.gpu_envs, ref)]
        lines.append(f"| {eid} | " + " | ".join(cells + held) + " |")
    lines += [f"\n{eid} at {n} envs failed: {r['error']}" for (eid, n), r in state.items() if "error" in r]
    if rgb:
        lines += ["", f"rgb observations (the 128x128 camera), {args.gpu_rgb_envs} envs; image std: the pixel standard "
                  "deviation (0-255) of each env's image, the smallest over the envs (a flat image has 0):", "",
                  "| env | steps/s | image std, min over envs |", "|---|---|---|"]
        for eid in envs:
            r, ref = rgb[eid], None if eid == REFERENCE else rgb[REFERENCE].get("sps")
            std = f"{r['rgb_std_min']:.1f}" if "rgb_std_min" in r else r.get("error", "")
            lines.append(f"| {eid} | {_ratio(r.get('sps'), ref)} | {std} |")
    lines += ["", "CPU-GPU parity: a scripted grasp and carry (pd_joint_pos moves to IK targets: above the grasp face, "
              "down until the ray grasps, lift, to the goal) on physx_cpu, its actions replayed open loop on physx_cuda "
              "from the CPU run's start state (2 GPU envs, same state and actions). Steps count from 0; differences "
              "are the element's position (m) and rotation (degrees), CPU against GPU env 0.", "",
              "| env | steps | grasp step CPU / GPU | success step CPU / GPU | held differs (steps) | max pos diff "
              "before grasp | max pos diff while held | max pos diff | final pos diff | max angle diff | GPU envs "
              "spread |", "|---|" + "---|" * 10]
    for r in par:
        if "error" in r:
            lines.append(f"| {r['env_id']} | failed: {r['error']} |" + " |" * 9)
            continue
        held = "n/a" if r["pos_diff_max_held"] is None else f"{r['pos_diff_max_held']:.4f}"
        lines.append(f"| {r['env_id']} | {r['steps']} | {r['grasp_step_cpu']} / {r['grasp_step_gpu']} | "
                     f"{r['success_step_cpu']} / {r['success_step_gpu']} | {r['held_mismatch_steps']} | "
                     f"{r['pos_diff_max_before_grasp']:.4f} | {held} | {r['pos_diff_max']:.4f} | "
                     f"{r['pos_diff_final']:.4f} | {r['angle_diff_max_deg']:.2f} | {r['gpu_spread_pos_max']:.4f} |")
    lines += ["", f"PPO on physx_cuda: baselines/ppo/ppo.py on {GENERAL} with its GPU defaults, the median env steps/s "
              f"of {args.train_iterations} iterations, rollout and update (and ICM's) included: "
              + (f"failed: {ppo_run['error']}" if "error" in ppo_run else
                 f"{ppo_run['sps']:,.0f} env steps/s ({ppo_run['num_envs']} envs x {ppo_run['num_steps']} steps per "
                 f"rollout, curiosity {ppo_run['curiosity']}, {ppo_run['reward_mode']} reward).")]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main(tyro.cli(Args))
