"""Simulation speed of the construction tasks against ManiSkill's PickCube-v1, same process, same run.

    python scripts/benchmark.py                     # prints the table and writes docs/BENCHMARKS.md
    python scripts/benchmark.py --steps 500 --no-write

Setting: physx_cpu, one env, state observations, pd_joint_delta_pos, dense reward, uniform random
actions, reset when an episode ends. Repeats alternate between the reference and each task so slow
drifts of the machine hit both; the figure is the median over repeats. The "held" column is the
same task with the element held by the plate for the whole run (the grasp's per-substep tracking).

GPU section (only where CUDA is there; skipped, with a message, on a CPU-only machine):

    python scripts/benchmark.py --no-cpu            # the GPU figures only (docs: gpu-simulation-speed)

physx_cuda steps/s of each task and of PickCube-v1 on the same GPU at 256, 1024 and 4096 envs with
state observations (also with the element held in every env), and at 256 envs with the 128x128 rgb
camera; and a CPU-GPU parity check: a scripted grasp and carry (IK targets, pd_joint_pos) is run on
physx_cpu, then its actions are replayed on physx_cuda from the same state, and the task logic (grasp
step, held flag, success) and the element's pose are compared. Each measurement runs in its own
process, so a crash or a timeout costs only that measurement.
"""

from __future__ import annotations

import fcntl
import gc
import json
import multiprocessing as mp
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import gymnasium as gym
import numpy as np
import torch
import tyro
from tqdm import tqdm

from ms_construction.envs import ENV_IDS
from ms_construction.reporting import update_section

REFERENCE = "PickCube-v1"


@dataclass
class Args:
    steps: int = 1000
    """env steps per measurement."""
    repeats: int = 3
    """measurements per env (median reported)."""
    write: bool = True
    """write docs/BENCHMARKS.md."""
    out: Path = Path("docs/BENCHMARKS.md")
    cpu: bool = True
    """run the CPU section (physx_cpu, one env)."""
    gpu: bool = True
    """run the GPU section when CUDA is there (physx_cuda)."""
    gpu_state: bool = True
    """measure the state-observation GPU steps/s."""
    gpu_envs: tuple[int, ...] = (256, 1024, 4096)
    """num_envs of the state-observation GPU measurements."""
    gpu_steps: int = 100
    """timed steps per GPU measurement (after a few warm-up steps; no resets in between)."""
    gpu_rgb_envs: int = 256
    """num_envs of the rgb-camera GPU measurement (0: skip it)."""
    gpu_parity: bool = True
    """run the CPU-GPU parity check."""
    gpu_timeout: float = 600.0
    """seconds one GPU measurement process may take."""
    gpu_parallel: int = 1
    """GPU measurement processes at a time: above 1, envs are built (CPU work) side by side while the
    timed steps still never overlap (a lock); saves wall time on a many-core machine."""
    gpu_ppo_iterations: int = 5
    """timed PPO iterations on physx_cuda (scripts/benchmark_training.py's measurement; 0: skip)."""
    gpu_json: Optional[Path] = None
    """also write the GPU results (raw) to this JSON file."""
    gpu_png_dir: Optional[Path] = None
    """save one rgb observation (env 0) of each env here."""
    gpu_from_json: Optional[Path] = None
    """write the GPU section from results saved earlier with --gpu-json (no measurement)."""


def make(env_id: str):
    return gym.make(env_id, num_envs=1, obs_mode="state", control_mode="pd_joint_delta_pos",
                    reward_mode="dense", sim_backend="physx_cpu", render_mode=None)


def steps_per_second(env, steps: int, seed: int, held: bool = False) -> float:
    u = env.unwrapped

    def hold():
        if held:
            state = u.get_state_dict()
            state["task"]["held"][:] = True
            u.set_state_dict(state)

    env.reset(seed=seed)
    hold()
    gen = torch.Generator().manual_seed(seed)
    low = torch.as_tensor(env.action_space.low)
    high = torch.as_tensor(env.action_space.high)
    actions = low + (high - low) * torch.rand((steps, *low.shape), generator=gen)
    t0 = time.perf_counter()
    for i in range(steps):
        _, _, term, trunc, _ = env.step(actions[i])
        if bool(term.any() or trunc.any()):
            env.reset()
            hold()
    return steps / (time.perf_counter() - t0)


def main(args: Args) -> None:
    if args.gpu_from_json:
        body = gpu_report(json.loads(Path(args.gpu_from_json).read_text()))
        print(body)
        if args.write:
            update_section(args.out, "gpu-simulation-speed", title="Benchmarks", body=body)
            print(f"wrote {args.out}")
        return
    if args.cpu:
        cpu_main(args)
    if args.gpu:
        if torch.cuda.is_available():
            gpu_main(args)
        else:
            print("GPU section skipped: no CUDA GPU here (physx_cuda needs one)")


def cpu_main(args: Args) -> None:
    envs = {eid: make(eid) for eid in (REFERENCE, *ENV_IDS)}
    for env in envs.values():  # warm-up
        steps_per_second(env, 50, seed=0)
    results = {eid: [] for eid in envs}
    held = {eid: [] for eid in ENV_IDS}
    with tqdm(total=args.repeats * 3 * len(ENV_IDS), desc="benchmark", unit="run") as bar:
        for r in range(args.repeats):
            for eid in ENV_IDS:
                results[REFERENCE].append(steps_per_second(envs[REFERENCE], args.steps, seed=r))
                results[eid].append(steps_per_second(envs[eid], args.steps, seed=r))
                held[eid].append(steps_per_second(envs[eid], args.steps, seed=r, held=True))
                bar.update(3)
    ref = statistics.median(results[REFERENCE])
    rows = []
    for eid in ENV_IDS:
        sps, sps_held = statistics.median(results[eid]), statistics.median(held[eid])
        rows.append(f"| {eid} | {sps:.0f} | {sps / ref:.2f} | {sps_held:.0f} | {sps_held / ref:.2f} |")
    table = "\n".join(
        [f"| env | steps/s | ratio to {REFERENCE} | steps/s, element held | ratio, held |",
         "|---|---|---|---|---|", *rows, f"| {REFERENCE} (reference) | {ref:.0f} | 1.00 | | |"]
    )
    print(table)
    if args.write:
        cmd = "python scripts/benchmark.py" + ("" if args.steps == 1000 and args.repeats == 3 else f" --steps {args.steps} --repeats {args.repeats}")
        update_section(args.out, "simulation-speed", title="Benchmarks", body=(
            "## Simulation speed on CPU (physx_cpu, one process)\n\n"
            f"Command: `{cmd}`\n\n"
            "State observations, pd_joint_delta_pos, dense reward, random actions, one env; each figure is the\n"
            f"median of {args.repeats} runs of {args.steps} steps, alternating with the reference in the same process.\n"
            "Target: every task at least 0.8x PickCube-v1.\n\n"
            f"{table}\n\n"
            f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {sys.version.split()[0]}, "
            f"torch {torch.__version__}, mani_skill {__import__('mani_skill').__version__}.\n"
        ))
        print(f"wrote {args.out}")


# ------------------------------------------------------------------------------------------------- #
# GPU (physx_cuda)
# ------------------------------------------------------------------------------------------------- #
GPU_WARMUP = 5
"""untimed steps before each GPU measurement (kernels compiled, buffers allocated)."""
PARITY_ENV_IDS = ("CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1", "ConstructionPickPlace-v1")


def make_gpu(env_id: str, num_envs: int, obs_mode: str = "state", **kwargs):
    return gym.make(env_id, num_envs=num_envs, obs_mode=obs_mode, control_mode="pd_joint_delta_pos",
                    reward_mode="dense", sim_backend="physx_cuda", render_mode=None, **kwargs)


def hold_all(u) -> None:
    """Every env's element held by the plate (through the task state, as a grasp would leave it)."""
    state = u.get_state_dict()
    state["task"]["held"][:] = True
    u.set_state_dict(state)


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
    return dict(rgb_shape=list(rgb.shape), rgb_std_min=float(std.min()), rgb_std_median=float(std.median()),
                rgb_mean=float(rgb.float().mean()))


def _sync() -> None:
    if torch.cuda.is_available():
        torch.cuda.synchronize()


def gpu_steps_per_second(env, steps: int, seed: int, held: bool = False, warmup: int = GPU_WARMUP):
    """(env steps/s = num_envs x control steps per second, whether the last observation is finite,
    the last observation) for uniform random actions from a reset; no resets while timing."""
    u = env.unwrapped
    env.reset(seed=seed)
    if held:
        hold_all(u)
    low = torch.as_tensor(env.action_space.low, device=u.device)  # the batched space: [num_envs, act]
    high = torch.as_tensor(env.action_space.high, device=u.device)
    gen = torch.Generator(device=u.device).manual_seed(seed)
    actions = low + (high - low) * torch.rand((warmup + steps, *low.shape), generator=gen, device=u.device)
    for i in range(warmup):
        env.step(actions[i])
    _sync()
    t0 = time.perf_counter()
    for i in range(warmup, warmup + steps):
        obs, *_ = env.step(actions[i])
    _sync()
    dt = time.perf_counter() - t0
    return u.num_envs * steps / dt, all_finite(obs), obs


@contextmanager
def exclusive(lock_path: Optional[str]):
    """Hold an exclusive lock on `lock_path` (nothing when None): timed parts of parallel processes
    never overlap."""
    if lock_path is None:
        yield
        return
    with open(lock_path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _gpu_worker(kind: str, env_id: str, counts: tuple, steps: int, seed: int, path: str, png_dir: Optional[str],
                lock_path: Optional[str] = None):
    """One process: the measurements of one env at each of `counts`, a JSON line each in `path`."""
    import ms_construction  # noqa: F401  (registration, in a spawned process)

    for n in counts:
        rec, env = dict(kind=kind, env_id=env_id, num_envs=n), None
        try:
            t0 = time.perf_counter()
            env = make_gpu(env_id, n, obs_mode="state" if kind == "state" else "rgb")
            rec["make_s"] = round(time.perf_counter() - t0, 2)
            with exclusive(lock_path):
                t0 = time.perf_counter()
                env.reset(seed=seed)
                _sync()
                rec["reset_s"] = round(time.perf_counter() - t0, 3)
                rec["sps"], rec["finite"], obs = gpu_steps_per_second(env, steps, seed)
                if kind == "rgb":
                    rec.update(image_stats(obs))
                    if png_dir:
                        from PIL import Image

                        rgb = next(iter(obs["sensor_data"].values()))["rgb"][0].cpu().numpy()
                        Image.fromarray(rgb).save(Path(png_dir) / f"rgb_{env_id}.png")
                elif env_id != REFERENCE:
                    rec["sps_held"], rec["finite_held"], _ = gpu_steps_per_second(env, steps, seed, held=True)
                    rec["held_fraction_at_end"] = float(env.unwrapped.held.float().mean())
            if torch.cuda.is_available():
                free, total = torch.cuda.mem_get_info()
                rec["gpu_mem_used_gib"] = round((total - free) / 2**30, 2)
        except Exception as e:  # noqa: BLE001  (recorded, and the next count still runs)
            rec["error"] = f"{type(e).__name__}: {e}"
        with open(path, "a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps(rec), flush=True)
        if env is not None:
            env.close()
        del env
        gc.collect()
        if torch.cuda.is_available():
            torch.cuda.empty_cache()


def run_in_process(target, args: tuple, timeout: float) -> Optional[str]:
    """target(*args) in a fresh (spawned) process: None, or why it failed."""
    p = mp.get_context("spawn").Process(target=target, args=args)
    p.start()
    p.join(timeout)
    if p.is_alive():
        p.kill()
        p.join()
        return f"timed out after {timeout:.0f} s"
    return None if p.exitcode == 0 else f"process died (exit code {p.exitcode})"


def gpu_measure(kind: str, env_id: str, counts: tuple, steps: int, timeout: float, seed: int = 0,
                png_dir: Optional[str] = None, lock_path: Optional[str] = None) -> list[dict]:
    """The measurements of `_gpu_worker`; a count whose process crashed or timed out is recorded with
    its error and the remaining counts get a fresh process."""
    out, remaining = [], list(counts)
    while remaining:
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "rec.jsonl")
            err = run_in_process(_gpu_worker, (kind, env_id, tuple(remaining), steps, seed, path, png_dir, lock_path),
                                 timeout)
            recs = [json.loads(line) for line in open(path)] if os.path.exists(path) else []
        out += recs
        done = {r["num_envs"] for r in recs}
        remaining = [n for n in remaining if n not in done]
        if err and remaining:
            out.append(dict(kind=kind, env_id=env_id, num_envs=remaining[0], error=err))
            print(json.dumps(out[-1]), flush=True)
            remaining = remaining[1:]
        elif err:
            break
    return out


# ---- CPU-GPU parity: a scripted grasp and carry on physx_cpu, replayed on physx_cuda ---- #
def _parity_env(env_id: str, backend: str, num_envs: int = 1):
    return gym.make(env_id, num_envs=num_envs, obs_mode="state", control_mode="pd_joint_pos", reward_mode="sparse",
                    sim_backend=backend, render_mode=None, robot_init_qpos_noise=0.0)


def _log_row(u) -> dict:
    info = u.evaluate()
    row = dict(held=u.held, first_grasp=info["first_grasp"], success=info["success"], obj=u.obj.pose.raw_pose,
               tcp=u.agent.tcp.pose.raw_pose, place_dist=info["place_dist"], place_angle=info["place_angle_deg"])
    return {k: v.detach().cpu().clone() for k, v in row.items()}  # (.cpu() of a CPU tensor is no copy)


def _stack_log(rows: list[dict]) -> dict:
    return {k: torch.stack([r[k] for r in rows]) for k in rows[0]}  # [steps, num_envs, ...]


def _tree_map(x, fn):
    return {k: _tree_map(v, fn) for k, v in x.items()} if isinstance(x, dict) else fn(x)


def _parity_cpu(env_id: str, seed: int, path: str) -> None:
    """physx_cpu, one env, pd_joint_pos: joint-space moves to IK targets (above the grasp face, down
    until the ray grasps, a pause for the pull, lift, over the goal, onto the goal). Saves the start
    state, the actions and the per-step log."""
    import sapien

    import ms_construction  # noqa: F401
    from ms_construction.kinematics import ArmIK

    env = _parity_env(env_id, "physx_cpu")
    env.reset(seed=seed)
    u = env.unwrapped
    start = _tree_map(u.get_state_dict(), lambda t: t.clone().cpu())
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
    torch.save(dict(start=start, actions=torch.stack(actions), log=_stack_log(rows)), path)
    env.close()


def _parity_gpu(env_id: str, seed: int, path_in: str, path_out: str, num_envs: int) -> None:
    """physx_cuda: the CPU run's start state in every env, then its actions open loop."""
    import ms_construction  # noqa: F401

    data = torch.load(path_in, weights_only=False)
    env = _parity_env(env_id, "physx_cuda", num_envs)
    env.reset(seed=seed)
    u = env.unwrapped
    u.set_state_dict(_tree_map(data["start"], lambda t: t.to(u.device).repeat(num_envs, *[1] * (t.ndim - 1))))
    u.agent.controller.reset()
    rows = []
    for a in data["actions"]:
        env.step(a.to(u.device)[None].repeat(num_envs, 1))
        rows.append(_log_row(u))
    torch.save(dict(log=_stack_log(rows)), path_out)
    env.close()


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
    """CPU run and GPU replay (each in its own process) and their differences: steps of the grasp
    and of success on each backend, steps where the held flag differs, and the element's position (m)
    and rotation (degrees) differences, the maximum before the grasp, while held and at the end.
    `gpu_spread_*`: the largest difference between GPU envs that got the same state and actions."""
    rec: dict = dict(env_id=env_id, seed=seed, gpu_envs=num_envs)
    with tempfile.TemporaryDirectory() as tmp:
        cpu_path, gpu_path = os.path.join(tmp, "cpu.pt"), os.path.join(tmp, "gpu.pt")
        err = run_in_process(_parity_cpu, (env_id, seed, cpu_path), timeout)
        if err is None and os.path.exists(cpu_path):
            err = run_in_process(_parity_gpu, (env_id, seed, cpu_path, gpu_path, num_envs), timeout)
        if err or not os.path.exists(gpu_path):
            rec["error"] = err or "no result"
            return rec
        c = torch.load(cpu_path, weights_only=False)["log"]
        g = torch.load(gpu_path, weights_only=False)["log"]
    rec.update(parity_diff(c, g))
    return rec


def parity_diff(c: dict, g: dict) -> dict:
    """The differences between a CPU log `c` (env 0) and a GPU log `g` (env 0; and its spread over envs)."""
    c0 = {k: v[:, 0] for k, v in c.items()}
    g0 = {k: v[:, 0] for k, v in g.items()}
    dp = torch.linalg.norm(c0["obj"][:, :3] - g0["obj"][:, :3], dim=-1)
    da = _angle_deg(c0["obj"][:, 3:], g0["obj"][:, 3:])
    dtcp = torch.linalg.norm(c0["tcp"][:, :3] - g0["tcp"][:, :3], dim=-1)
    grasp_c, grasp_g = _first(c0["held"]), _first(g0["held"])
    before = slice(0, min(x for x in (grasp_c, grasp_g, len(dp)) if x is not None))
    held_both = c0["held"] & g0["held"]
    return dict(
        steps=len(dp),
        grasp_step_cpu=grasp_c, grasp_step_gpu=grasp_g,
        success_step_cpu=_first(c0["success"]), success_step_gpu=_first(g0["success"]),
        held_mismatch_steps=int((c0["held"] != g0["held"]).sum()),
        success_mismatch_steps=int((c0["success"] != g0["success"]).sum()),
        pos_diff_max_before_grasp=float(dp[before].max()) if before.stop > 0 else 0.0,
        pos_diff_max_held=float(dp[held_both].max()) if held_both.any() else None,
        pos_diff_max=float(dp.max()), pos_diff_final=float(dp[-1]),
        angle_diff_max_deg=float(da.max()), angle_diff_final_deg=float(da[-1]),
        tcp_pos_diff_max=float(dtcp.max()),
        place_dist_final_cpu=float(c0["place_dist"][-1]), place_dist_final_gpu=float(g0["place_dist"][-1]),
        place_angle_final_cpu=float(c0["place_angle"][-1]), place_angle_final_gpu=float(g0["place_angle"][-1]),
        gpu_spread_pos_max=float(torch.linalg.norm(g["obj"][..., :3] - g["obj"][:, :1, :3], dim=-1).max()),
        gpu_spread_held_mismatch=int((g["held"] != g["held"][:, :1]).sum()),
    )


# ---- PPO on physx_cuda (scripts/benchmark_training.py's measurement) ---- #
def _ppo_worker(curiosity: str, iterations: int, path: str) -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("benchmark_training", Path(__file__).with_name("benchmark_training.py"))
    bt = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bt)
    with tempfile.TemporaryDirectory() as log_dir:
        sps, run = bt.measure(bt.Args(iterations=iterations, write=False), curiosity, "physx_cuda", log_dir)
    with open(path, "w") as f:
        json.dump(dict(curiosity=curiosity, sps=sps, num_envs=run.num_envs, num_steps=run.num_steps,
                       env_id=run.env_id, iterations=iterations), f)


def gpu_ppo(curiosity: str, iterations: int, timeout: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "ppo.json")
        err = run_in_process(_ppo_worker, (curiosity, iterations, path), timeout)
        if os.path.exists(path):
            return json.load(open(path))
    return dict(curiosity=curiosity, error=err or "no result")


# ---- the section ---- #
def gpu_device_info() -> dict:
    info = dict(name=torch.cuda.get_device_name(0),
                memory_gib=round(torch.cuda.get_device_properties(0).total_memory / 2**30, 1),
                torch=torch.__version__, mani_skill=__import__("mani_skill").__version__,
                sapien=__import__("sapien").__version__, python=sys.version.split()[0])
    try:
        smi = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total,driver_version", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=30).stdout.strip()
        info["nvidia_smi"] = smi.splitlines()[0] if smi else ""
    except (OSError, subprocess.SubprocessError):
        info["nvidia_smi"] = ""
    return info


def _command() -> str:
    """This run's command line, less the output paths."""
    argv, out, skip = sys.argv[1:], [], False
    for a in argv:
        if skip:
            skip = False
            continue
        if a.split("=")[0] in ("--gpu-json", "--gpu-png-dir", "--out"):
            skip = "=" not in a
            continue
        out.append(a)
    return " ".join(["python scripts/benchmark.py", *out])


def gpu_main(args: Args) -> None:
    results: dict = dict(date=time.strftime("%Y-%m-%d"), command=_command(), device=gpu_device_info(),
                         steps=args.gpu_steps, warmup=GPU_WARMUP, parallel=args.gpu_parallel,
                         state=[], rgb=[], parity=[], ppo=[])
    print(f"GPU: {results['device']}", flush=True)

    def save():
        if args.gpu_json:
            Path(args.gpu_json).parent.mkdir(parents=True, exist_ok=True)
            Path(args.gpu_json).write_text(json.dumps(results, indent=1))

    png_dir = str(args.gpu_png_dir) if args.gpu_png_dir else None
    if png_dir:
        Path(png_dir).mkdir(parents=True, exist_ok=True)
    jobs = []
    if args.gpu_state and args.gpu_envs:
        jobs += [("state", eid, tuple(args.gpu_envs)) for eid in (REFERENCE, *ENV_IDS)]
    if args.gpu_rgb_envs:
        jobs += [("rgb", eid, (args.gpu_rgb_envs,)) for eid in (REFERENCE, *ENV_IDS)]
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(max(1, args.gpu_parallel)) as pool:
        lock = os.path.join(tmp, "gpu.lock") if args.gpu_parallel > 1 else None
        futures = {pool.submit(gpu_measure, kind, eid, counts, args.gpu_steps, args.gpu_timeout, 0, png_dir, lock): kind
                   for kind, eid, counts in jobs}
        for fut in as_completed(futures):
            results[futures[fut]] += fut.result()
            save()
        if args.gpu_parity:  # not timed: side by side
            futures = [pool.submit(parity, eid, 0, 2, args.gpu_timeout) for eid in PARITY_ENV_IDS]
            for fut in futures:
                results["parity"].append(fut.result())
                print(json.dumps(results["parity"][-1]), flush=True)
                save()
    if args.gpu_ppo_iterations:
        for curiosity in ("none", "icm"):
            results["ppo"].append(gpu_ppo(curiosity, args.gpu_ppo_iterations, args.gpu_timeout))
            print(json.dumps(results["ppo"][-1]), flush=True)
            save()
    body = gpu_report(results)
    print(body)
    if args.write:
        update_section(args.out, "gpu-simulation-speed", title="Benchmarks", body=body)
        print(f"wrote {args.out}")


def _fmt(x: Optional[float], ref: Optional[float] = None, rec: Optional[dict] = None) -> str:
    if x is None:
        return "failed" if rec and "error" in rec else "-"
    return f"{x:,.0f}" + (f" ({x / ref:.2f}x)" if ref else "")


def gpu_report(results: dict) -> str:
    """The markdown of the GPU section, from `gpu_main`'s results (also as saved with --gpu-json)."""
    dev, command = results["device"], results.get("command", "python scripts/benchmark.py --no-cpu")
    state = {(r["env_id"], r["num_envs"]): r for r in results["state"]}
    counts = sorted({r["num_envs"] for r in results["state"]})
    ref = {n: state.get((REFERENCE, n), {}).get("sps") for n in counts}
    lines = [
        "## Simulation speed on GPU (physx_cuda)",
        "",
        f"Command: `{command}` (measured {results['date']}).",
        "",
        f"GPU: {dev.get('nvidia_smi') or dev['name']}; torch {dev['torch']}, sapien {dev['sapien']}, "
        f"mani_skill {dev['mani_skill']}, Python {dev['python']}.",
        "",
        f"Env steps/s (num_envs x control steps per second), uniform random actions, pd_joint_delta_pos, dense "
        f"reward, {results['warmup']} warm-up steps then {results['steps']} timed steps from a reset, one process per "
        f"env{' (up to %d processes building envs side by side, the timed steps never overlapping)' % results['parallel'] if results.get('parallel', 1) > 1 else ''}; in brackets the ratio to {REFERENCE} at the same num_envs on the same GPU (target: at least 0.5x "
        "at 4096 envs). \"Held\": every env's element held by the plate for the whole run.",
    ]
    if counts:
        lines += ["", "State observations:", "",
                  "| env | " + " | ".join(f"{n} envs" for n in counts) + " | " + " | ".join(f"held, {n} envs" for n in counts) + " |",
                  "|---|" + "---|" * (2 * len(counts))]
        for eid in (*ENV_IDS, REFERENCE):
            recs = [state.get((eid, n), {}) for n in counts]
            cells = [_fmt(r.get("sps"), ref[n] if eid != REFERENCE else None, r) for n, r in zip(counts, recs)]
            held = ["" if eid == REFERENCE else _fmt(r.get("sps_held"), ref[n], r) for n, r in zip(counts, recs)]
            lines.append(f"| {eid}{' (reference)' if eid == REFERENCE else ''} | " + " | ".join(cells + held) + " |")
        errors = [r for r in results["state"] if "error" in r]
        for r in errors:
            lines.append(f"\n{r['env_id']} at {r['num_envs']} envs failed: {r['error']}")
        mk = [r for r in results["state"] if "make_s" in r and r["num_envs"] == max(counts)]
        if mk:
            mem = ", ".join(f"{r['env_id']} {r['gpu_mem_used_gib']:.1f} GiB" for r in mk if "gpu_mem_used_gib" in r)
            mem = f"; GPU memory in use after the run: {mem}" if mem and results.get("parallel", 1) == 1 else ""
            lines += ["", f"At {max(counts)} envs, env creation (gym.make) took: "
                      + ", ".join(f"{r['env_id']} {r['make_s']:.0f} s" for r in mk) + mem + "."]
    if results.get("rgb"):
        rgb = {r["env_id"]: r for r in results["rgb"]}
        n = results["rgb"][0]["num_envs"]
        r0 = rgb.get(REFERENCE, {}).get("sps")
        lines += ["", f"rgb observations (the 128x128 base camera), {n} envs; image std: the pixel standard "
                  "deviation (0-255) of each env's image, its minimum over the envs (0 would be a flat image):", "",
                  "| env | steps/s | image std, min over envs |", "|---|---|---|"]
        for eid in (*ENV_IDS, REFERENCE):
            r = rgb.get(eid, {})
            std = f"{r['rgb_std_min']:.1f}" if "rgb_std_min" in r else r.get("error", "")
            lines.append(f"| {eid}{' (reference)' if eid == REFERENCE else ''} | "
                         f"{_fmt(r.get('sps'), r0 if eid != REFERENCE else None, r)} | {std} |")
    if results.get("parity"):
        lines += ["", "CPU-GPU parity: a scripted grasp and carry (pd_joint_pos moves to IK targets: above the grasp "
                  "face, down until the ray grasps, lift, to the goal) run on physx_cpu, its actions replayed open loop "
                  "on physx_cuda from the CPU run's start state (2 GPU envs, same state and actions). Steps count from 0; "
                  "differences are the element's position (m) and rotation (degrees), CPU against GPU env 0.", "",
                  "| env | steps | grasp step CPU / GPU | success step CPU / GPU | held differs (steps) | "
                  "max pos diff before grasp | max pos diff while held | max pos diff | final pos diff | "
                  "max angle diff | GPU envs spread |", "|---|" + "---|" * 10]
        for r in results["parity"]:
            if "error" in r:
                lines.append(f"| {r['env_id']} | failed: {r['error']} |" + " |" * 9)
                continue
            held = "n/a" if r["pos_diff_max_held"] is None else f"{r['pos_diff_max_held']:.4f}"
            lines.append(
                f"| {r['env_id']} | {r['steps']} | {r['grasp_step_cpu']} / {r['grasp_step_gpu']} | "
                f"{r['success_step_cpu']} / {r['success_step_gpu']} | {r['held_mismatch_steps']} | "
                f"{r['pos_diff_max_before_grasp']:.4f} | {held} | {r['pos_diff_max']:.4f} | {r['pos_diff_final']:.4f} | "
                f"{r['angle_diff_max_deg']:.2f} | {r['gpu_spread_pos_max']:.4f} |")
    if results.get("ppo"):
        lines += ["", "PPO on physx_cuda (baselines/ppo/ppo.py, its GPU defaults, sparse reward, curriculum stage cp1; "
                  "scripts/benchmark_training.py's measurement: the median env steps/s of the timed iterations, rollout "
                  "and PPO (and ICM) updates included, start-up and final evaluation left out):", "",
                  "| env | curiosity | envs x steps per rollout | env steps/s (updates included) |", "|---|---|---|---|"]
        for r in results["ppo"]:
            if "error" in r:
                lines.append(f"| | {r['curiosity']} | | failed: {r['error']} |")
            else:
                lines.append(f"| {r['env_id']} | {r['curiosity']} | {r['num_envs']} x {r['num_steps']} | {r['sps']:,.0f} |")
    return "\n".join(lines) + "\n"

if __name__ == "__main__":
    main(tyro.cli(Args))
