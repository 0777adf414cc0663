"""Training throughput of the PPO learner: env steps per second, rollouts and updates included.

    python scripts/benchmark_training.py                  # writes its section of docs/BENCHMARKS.md
    python scripts/benchmark_training.py --iterations 2 --no-write

Runs baselines/ppo/ppo.py with its defaults for the machine (physx_cpu: one env process per core,
250 steps per env per rollout; physx_cuda when a GPU is there: 512 envs x 50 steps), without and with
ICM: the median of a few iterations' env steps/s (rollout + update), start-up and the final
evaluation left out; no checkpoints.
"""

import csv
import os
import statistics
import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro

from baselines.ppo import ppo
from ms_construction.reporting import update_section


@dataclass
class Args:
    env_id: str = "ConstructionPickPlace-v1"
    iterations: int = 5
    """timed PPO iterations per configuration (a start-up and a final-evaluation iteration come on top)."""
    write: bool = True
    out: Path = Path("docs/BENCHMARKS.md")


def measure(args: Args, curiosity: str, backend: str, log_dir: str) -> tuple[float, ppo.Args]:
    """Median env steps/s of the run's iterations, the first (start-up) and last (final evaluation)
    left out; each iteration's time covers its rollout and its update."""
    run = ppo.Args(env_id=args.env_id, curiosity=curiosity, sim_backend=backend, save_model=False, eval_freq=10**9,
                   curriculum=("cp1",), exp_name=f"bench_{curiosity}_{backend}", log_dir=log_dir)
    tr = ppo.setup(run)
    tr.args.total_timesteps = tr.args.num_envs * tr.args.num_steps * (args.iterations + 2)
    ppo.train(tr)
    with open(Path(log_dir) / run.exp_name / "progress.csv") as f:
        sps = [float(row["sps"]) for row in csv.DictReader(f)][1:-1]
    return statistics.median(sps), tr.args


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
        cmd = "python scripts/benchmark_training.py" + ("" if args.iterations == 5 else f" --iterations {args.iterations}")
        update_section(args.out, "training-throughput", title="Benchmarks", body=(
            "## PPO training throughput\n\n"
            f"Command: `{cmd}`\n\n"
            f"{args.env_id}, sparse reward, pd_joint_delta_pos, the learner's defaults for each backend, "
            f"median over {args.iterations} iterations (rollout + PPO and ICM updates; start-up and evaluation excluded).\n\n{table}\n"
        ))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main(tyro.cli(Args))
