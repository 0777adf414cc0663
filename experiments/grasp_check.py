"""Does a policy grasp its element when it starts on the way to it? Each policy from reach starts (the start-state
curriculum's: `set_reach_starts`, the arm on the last `radius` of the joint path down to the element, on a turret side
the goal slot's start paths leave from) at a few radii, per task type: how many episodes grasp the element within
--max-steps steps from the turret side the start was on (as the training's curriculum counts them), and how many from
the other side. Radius 0 starts with the plate at the element (the grasp is made at the first step); 1 anywhere on
the way from the reset's configuration.

    python -m experiments.grasp_check --policy s1=campaign/scratch_s1/candidates/candidate_10000000.pt \\
        s2=campaign/scratch_s2/checkpoint.pt

It tells a policy that has not learnt to grasp an element type (its reach-start radius stuck near 0 in training)
from one that grasps it from anywhere, and how close a start must be. Episodes: seeds from SEED (neither the test
seeds nor the snapshot rule's validation seeds), the policy's mean action. Writes JSON and the table of
docs/experiments/from_scratch.md's grasp-check section.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import tyro
from tqdm import tqdm

from baselines.ppo.checkpoints import load_checkpoint, load_policy
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section
from ms_construction.rollout import rollout

SEED = 700_000
PAGE = Path("docs/experiments/from_scratch.md")


@dataclass
class Args:
    policy: tuple[str, ...]
    """LABEL=CHECKPOINT, one per policy (a run's checkpoint or a snapshot), all after one --policy."""
    radii: tuple[float, ...] = (0.0, 0.1, 0.2, 0.5, 1.0)
    """reach-start radii, each in [0, 1]."""
    episodes: int = 8
    """episodes per policy, task type and radius."""
    max_steps: int = 60
    """steps an episode has to grasp its element."""
    out: Path = Path("docs/data/from_scratch/grasp_check.json")
    """where the counts go (JSON)."""
    write: bool = True
    """write `out` and the experiment page's section."""


def parse_policies(specs: tuple[str, ...]) -> dict[str, Path]:
    out = {}
    for spec in specs:
        label, sep, path = spec.partition("=")
        if not sep or not label or not path or " " in label:
            raise SystemExit(f"--policy {spec!r}: give LABEL=CHECKPOINT (a label without spaces), for example "
                             "s2=campaign/scratch_s2/checkpoint.pt")
        if label in out:
            raise SystemExit(f"--policy: the label {label!r} is given twice; give each policy its own")
        if not Path(path).is_file():
            raise SystemExit(f"--policy {spec!r}: no file {path}")
        out[label] = Path(path)
    return out


def grasps(path: Path, env_id: str, radius: float, episodes: int, max_steps: int) -> tuple[int, int]:
    """Episodes of the policy at `path` on `env_id` from reach starts at `radius` that grasp within `max_steps`: (from
    the turret side the start was on, as the training's curriculum counts them; from the other side)."""
    agent, env_kwargs = load_policy(path, env_id)
    env = gym.make(env_id, obs_mode="state", num_envs=1, sim_backend="physx_cpu", **env_kwargs)
    env.unwrapped.set_reach_starts(1.0, radius)
    on_side = other_side = 0
    for i in range(episodes):
        for t, step in enumerate(rollout(agent, env, SEED + i)):
            if bool(env.unwrapped.picked[0]):
                side = bool(step.info["reach_start_grasped"][0])
                on_side, other_side = on_side + side, other_side + (not side)
                break
            if t + 1 >= max_steps or bool(step.terminated[0] | step.truncated[0]):
                break
    env.close()
    return on_side, other_side


def cell(grasped: tuple[int, int], episodes: int) -> str:
    on_side, other_side = grasped
    return f"{on_side} / {episodes}" + (f" (+{other_side} from the other side)" if other_side else "")


def command(args: Args) -> str:
    """The command line that gives `args` (the defaults left out)."""
    out = ["python -m experiments.grasp_check --policy", *args.policy]
    for name, default in vars(Args(policy=())).items():
        value = getattr(args, name)
        if name not in ("policy", "write", "out") and value != default:
            out.append(f"--{name.replace('_', '-')} " + (" ".join(map(str, value)) if isinstance(value, tuple) else str(value)))
    return " ".join(out)


def main(args: Args) -> dict:
    if not all(0 <= r <= 1 for r in args.radii):
        raise SystemExit(f"--radii {args.radii}: each radius lies in [0, 1]")
    policies = parse_policies(args.policy)
    env_ids = list(PAPER_TASK_ENV_IDS.values())
    steps = {label: load_checkpoint(p)["progress"]["global_step"] for label, p in policies.items()}
    result = {"seed": SEED, "episodes": args.episodes, "max_steps": args.max_steps, "radii": list(args.radii),
              "policies": {label: dict(checkpoint=str(p), env_steps=steps[label]) for label, p in policies.items()},
              "grasped_on_side": {}, "grasped_other_side": {}}
    table = ["| policy | its env steps | task | " + " | ".join(f"radius {r:g}" for r in args.radii) + " |",
             "|---|---|---|" + "---|" * len(args.radii)]
    with tqdm(total=len(policies) * len(env_ids) * len(args.radii), desc="grasp check", unit="cell") as bar:
        for label, path in policies.items():
            for env_id in env_ids:
                counts = []
                for radius in args.radii:
                    counts.append(grasps(path, env_id, radius, args.episodes, args.max_steps))
                    bar.update()
                result["grasped_on_side"].setdefault(label, {})[env_id] = [c[0] for c in counts]
                result["grasped_other_side"].setdefault(label, {})[env_id] = [c[1] for c in counts]
                table.append(f"| {label} ({path}) | {steps[label]:,} | {env_id} | "
                             + " | ".join(cell(c, args.episodes) for c in counts) + " |")
    print("\n".join(table))
    if args.write:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")
        update_section(PAGE, "grasp-check", "\n".join([
            f"Command: `{command(args)}`. Episodes that grasp within {args.max_steps} steps from reach starts at each "
            f"radius, from the turret side the start was on (as the training's curriculum counts them; grasps from "
            f"the other side in brackets), out of {args.episodes}; seeds from {SEED:,}, the policy's mean; radius 0: "
            "the plate at the element, 1: anywhere on the way from the reset's configuration.", "", *table]),
            "From scratch")
    return result


if __name__ == "__main__":
    main(tyro.cli(Args))
