"""Record the planning expert's demonstrations in the learner's control mode (pd_joint_delta_pos).

    python scripts/collect_demos.py --episodes 600 --workers 2 --out outputs/demos/general.npz

Seeds seed, seed + 1, ... of the general task (each episode draws ceiling, window or flooring); every
other episode runs with DART noise (`--noise`) on the executed actions, the clean ones recorded
(ms_construction/planning/demos.py, which does the work). Only placed episodes are kept. The file (numpy .npz: obs,
actions, sparse rewards, episode index, task, seed, noise per step) is rewritten atomically every `--save-every`
episodes, so an interrupted collection keeps what it had; `--resume` continues it.
With `--policy CHECKPOINT` the policy runs each episode first; where it fails, the expert takes over
from the states it led to, and those takeovers are recorded (DAgger-style data on the policy's own states):
    python scripts/collect_demos.py --policy runs/general_agent/bc/checkpoint.pt --env-id WindowInstallation-v1 \
        --seed 400000 --episodes 500 --out outputs/demos/window_takeovers.npz
Seeds used for demonstrations must not overlap the evaluation seeds (scripts/evaluate.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional

import tyro

from baselines.ppo.checkpoints import load_policy
from ms_construction.planning.demos import demo_expert_config, record_demos
from ms_construction.curriculum import FINAL_STAGE


@dataclass
class Args:
    env_id: str = "ConstructionPickPlace-v1"
    """task the expert solves (the general task draws the three types)."""
    episodes: int = 600
    """episodes to run (failed ones are counted and dropped)."""
    seed: int = 100_000
    """seed of the first episode (scripts/evaluate.py uses seeds from 1000000 on)."""
    noise: float = 0.1
    """std of the DART noise on the executed delta actions (in action units: 0.1 = 0.01 rad) of every
    other episode; the rest run clean."""
    curriculum_stage: str = FINAL_STAGE
    """tolerance stage the expert places at."""
    workers: int = 2
    """processes, one env and expert each."""
    out: Path = Path("outputs/demos/general.npz")
    """the demonstrations file."""
    save_every: int = 50
    """rewrite the file after this many episodes."""
    resume: bool = False
    """continue the seeds of an existing --out file."""
    policy: Optional[Path] = None
    """a policy checkpoint (ppo.py / bc.py): record instead the expert's takeovers of the episodes this
    policy fails, from the states it led to (DAgger-style; ms_construction/planning/demos.py)."""
    branch_preference: Literal["nearest", "fixed"] = "nearest"
    """the expert's choice among several ways to reach a configuration (ExpertConfig.branch_preference): `nearest`
    to the arm (the shipped clone's demonstrations) or `fixed`, the same way for the same goal slot every time."""
    demo_pace: Literal["slow", "fast"] = "slow"
    """the expert's speed (ms_construction/planning/demos.py DEMO_PACES): `slow`, every joint at 0.55 of its
    limits (the shipped clones' demonstrations), or `fast`, as quick as the delta actions allow with room to spare."""
    direct_paths: bool = False
    """the expert takes a straight (or one-corner) joint path wherever one is free, RRTConnect only elsewhere
    (ExpertConfig.direct_first): the same start and goal give the same motion, where RRTConnect's paths wander
    differently every time and a clone averages them (docs/experiments/general_agent.md, 'the quick one-way expert')."""


def main(args: Args) -> None:
    record_demos(args.out, args.episodes, env_id=args.env_id, seed=args.seed, noise=args.noise,
                 curriculum_stage=args.curriculum_stage, workers=args.workers, save_every=args.save_every,
                 resume=args.resume, policy=args.policy, load_policy=load_policy,
                 expert=demo_expert_config(args.branch_preference, args.demo_pace, args.direct_paths))


if __name__ == "__main__":
    main(tyro.cli(Args))
