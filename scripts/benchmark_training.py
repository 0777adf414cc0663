"""Training throughput of the PPO learner: env steps per second, rollouts and updates included.

    python scripts/benchmark_training.py                  # writes its section of docs/BENCHMARKS.md
    python scripts/benchmark_training.py --iterations 2 --no-write

Runs baselines/ppo/ppo.py with its defaults for the machine (physx_cpu: one env process per core,
250 steps per env per rollout; physx_cuda when a GPU is there: 512 envs x 50 steps), without and with
ICM, for a few iterations after one warm-up iteration; no evaluation, no checkpoints.
"""

import dataclasses
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from baselines.ppo import ppo  # noqa: E402
from ms_construction.reporting import update_section  # noqa: E402


@dataclass
class Args:
    env_id: str = "ConstructionPickPlace-v1"
    iterations: int = 4
    """timed PPO iterations per configuration (after one warm-up iteration)."""
    write: bool = True
    out: Path = Path("docs/BENCHMARKS.md")


def measure(args: Args, curiosity: str, backend: str, log_dir: str) -> tuple[float, ppo.Args]:
    run = ppo.Args(env_id=args.env_id, curiosity=curiosity, sim_backend=backend, save_model=False, eval_freq=10**9,
                   curriculum=("cp1",), exp_name=f"bench_{curiosity}_{backend}", log_dir=log_dir)
    warm_up = ppo.setup(dataclasses.replace(run, total_timesteps=1))  # one iteration: start-up, first update
    ppo.train(warm_up)
    batch = warm_up.args.num_envs * warm_up.args.num_steps
    tr = ppo.setup(dataclasses.replace(run, total_timesteps=batch * args.iterations))
    t0 = time.perf_counter()
    progress = ppo.train(tr)
    return progress.global_step / (time.perf_counter() - t0), tr.args


def main(args: Args) -> None:
    backends = ["physx_cpu"] + (["physx_cuda"] if torch.cuda.is_available() else [])
    rows = []
    with tempfile.TemporaryDirectory() as log_dir:
        for backend in backends:
            for curiosity in ("none", "icm"):
                sps, run = measure(args, curiosity, backend, log_dir)
                device = torch.cuda.get_device_name(0) if backend == "physx_cuda" else f"{os.cpu_count()}-core CPU"
                rows.append(f"| {backend} ({device}) | {curiosity} | {run.num_envs} x {run.num_steps} | {sps:.0f} |")
                print(rows[-1], flush=True)
    table = "\n".join(["| backend | curiosity | envs x steps per rollout | env steps/s (updates included) |",
                       "|---|---|---|---|", *rows])
    print(table)
    if args.write:
        cmd = "python scripts/benchmark_training.py" + ("" if args.iterations == 4 else f" --iterations {args.iterations}")
        update_section(args.out, "training-throughput", title="Benchmarks", body=(
            "## PPO training throughput\n\n"
            f"Command: `{cmd}`\n\n"
            f"{args.env_id}, sparse reward, pd_joint_delta_pos, the learner's defaults for each backend, "
            f"{args.iterations} timed iterations after a warm-up.\n\n{table}\n"
        ))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main(tyro.cli(Args))
