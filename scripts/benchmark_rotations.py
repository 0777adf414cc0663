"""Our quaternion helpers (ms_construction/rotations.py) against ManiSkill's, per call.

    python scripts/benchmark_rotations.py            # writes its section of docs/BENCHMARKS.md
    python scripts/benchmark_rotations.py --no-write

The task computes its grasp, hold, evaluation, observations and rewards with these helpers every
control step; on physx_cpu a batch is one env, so a helper's cost is its number of small tensor ops.
Each pair is timed in the same process, interleaved (best of `repeats` rounds of `number` calls),
at batch 1 (physx_cpu) and `gpu_batch` (as on physx_cuda, here on the CPU). The ratio is
ManiSkill's time over ours; tests/test_rotations.py checks that both compute the same.
"""

from __future__ import annotations

import platform
import sys
import timeit
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro
from mani_skill.utils.geometry import rotation_conversions as rc
from mani_skill.utils.structs import Pose

from ms_construction import rotations as r
from ms_construction.reporting import update_section


@dataclass
class Args:
    batches: tuple[int, ...] = (1, 1024)
    """batch sizes timed."""
    number: int = 2000
    """calls per timing round."""
    repeats: int = 5
    """timing rounds; the best counts (the least disturbed by other work)."""
    write: bool = True
    """write the table into docs/BENCHMARKS.md."""
    doc: Path = Path("docs/BENCHMARKS.md")


def pairs(n: int) -> dict:
    """name -> (ours, ManiSkill's) as zero-argument calls on random unit quaternions / poses."""
    g = torch.Generator().manual_seed(0)
    q1, q2 = (torch.nn.functional.normalize(torch.randn(n, 4, generator=g), dim=-1) for _ in range(2))
    p1, p2 = torch.cat([torch.randn(n, 3, generator=g), q1], -1), torch.cat([torch.randn(n, 3, generator=g), q2], -1)
    v = torch.randn(n, 3, generator=g)
    return {
        "qmul / quaternion_raw_multiply": (lambda: r.qmul(q1, q2), lambda: rc.quaternion_raw_multiply(q1, q2)),
        "qconj / quaternion_invert": (lambda: r.qconj(q1), lambda: rc.quaternion_invert(q1)),
        "qrot / quaternion_apply": (lambda: r.qrot(q1, v), lambda: rc.quaternion_apply(q1, v)),
        "qmat / quaternion_to_matrix": (lambda: r.qmat(q1), lambda: rc.quaternion_to_matrix(q1)),
        "quat_to_rotvec / quaternion_to_axis_angle": (
            lambda: r.quat_to_rotvec(q1), lambda: rc.quaternion_to_axis_angle(rc.standardize_quaternion(q1))),
        "pose_mul / Pose * Pose": (lambda: r.pose_mul(p1, p2), lambda: (Pose.create(p1) * Pose.create(p2)).raw_pose),
        "pose_inv / Pose.inv": (lambda: r.pose_inv(p1), lambda: Pose.create(p1).inv().raw_pose),
    }


def main(args: Args) -> str:
    torch.set_num_threads(1)
    rows = []
    for n in args.batches:
        for name, (ours, theirs) in pairs(n).items():
            t_ours, t_theirs = [], []
            for _ in range(args.repeats):  # interleaved: a drift of the machine hits both
                t_ours.append(timeit.timeit(ours, number=args.number) / args.number)
                t_theirs.append(timeit.timeit(theirs, number=args.number) / args.number)
            a, b = min(t_ours), min(t_theirs)
            rows.append(f"| {n} | {name} | {a * 1e6:.1f} | {b * 1e6:.1f} | {b / a:.2f} |")
    command = "python scripts/benchmark_rotations.py" + (" " + " ".join(sys.argv[1:]) if sys.argv[1:] else "")
    body = "\n".join([
        "## Quaternion helpers: ours against ManiSkill's",
        "",
        f"`{command}` on {platform.processor() or platform.machine()}, torch {torch.__version__}, one thread. "
        "Microseconds per call (best of the rounds); ratio = ManiSkill's / ours (above 1: ours faster). "
        "The task keeps its own helpers where the ratio at batch 1 (physx_cpu) is above 1; "
        "tests/test_rotations.py checks that both compute the same.",
        "",
        "| batch | ours / ManiSkill's | ours (us) | ManiSkill (us) | ratio |",
        "|---|---|---|---|---|",
        *rows,
    ])
    print(body)
    if args.write:
        update_section(args.doc, "rotations", body, "Benchmarks")
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
