"""Simulation speed of the construction tasks against ManiSkill's PickCube-v1, same process, same run.

    python scripts/benchmark.py                     # prints the table and writes docs/BENCHMARKS.md
    python scripts/benchmark.py --steps 500 --no-write

Setting: physx_cpu, one env, state observations, pd_joint_delta_pos, dense reward, uniform random
actions, reset when an episode ends. Repeats alternate between the reference and each task so slow
drifts of the machine hit both; the figure is the median over repeats. The "held" column is the
same task with the element held by the plate for the whole run (the grasp's per-substep tracking).
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
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

if __name__ == "__main__":
    main(tyro.cli(Args))
