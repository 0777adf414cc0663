"""How many ways the planning expert solves a task, and where an agent fails: per goal slot, the distinct
arm configurations the expert's placed episodes end in (IK branches) and which way its base joint turns to
reach the element, from the trajectories that scripts/run_expert.py --save-trajectory writes; beside them,
the agent's failed episodes per goal slot, from JSONs of scripts/evaluate.py.

    python scripts/run_expert.py --env-id WindowInstallation-v1 --episodes 30 --seed 500000 --save-trajectory --out outputs/expert_modes
    python -m experiments.expert_modes --traj outputs/expert_modes/WindowInstallation-v1.expert.h5 \
        --agent 'shipped agent=docs/data/general_agent_eval_50k.json' --write-results

A behaviour clone of demonstrations that reach the same goal in several joint configurations learns their
average where they part, an arm configuration between two branches. Two configurations are the same branch
when no joint differs by more than --tol.
"""

from __future__ import annotations

import functools

import json
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import h5py
import numpy as np
import tyro

from baselines.ppo.evaluation import read_labelled
from ms_construction.reporting import update_section

ARM = "construction_arm"
QPOS = slice(13, 19)  # an articulation's state: root pose (7), root velocities (6), qpos (6), qvel (6)


@dataclass
class Args:
    traj: tuple[Path, ...]
    """.h5 files of scripts/run_expert.py --save-trajectory (one task each, named <env id>.expert.h5)."""
    tol: float = 0.5
    """radians: configurations whose joints all lie within this of a branch's first one belong to it."""
    agent: tuple[str, ...] = ()
    """LABEL=JSON ...: an agent's episodes (a JSON of scripts/evaluate.py, with --all or for this task), whose
    failures are counted per goal slot (each episode's slot read from a reset with its seed)."""
    json: Optional[Path] = None
    """write the branches, turns and failures to this file."""
    write_results: bool = False
    """write the table into the section `expert-modes` of docs/experiments/general_agent.md."""
    results: Path = Path("docs/experiments/general_agent.md")


def branches(configs: list[np.ndarray], tol: float) -> list[dict]:
    """Greedy clusters of joint configurations (first come, first representative): each with its count."""
    found: list[dict] = []
    for q in configs:
        for b in found:
            if np.max(np.abs(q - b["q"])) <= tol:
                b["count"] += 1
                break
        else:
            found.append(dict(q=q, count=1))
    return [dict(q=[round(float(x), 2) for x in b["q"]], count=b["count"]) for b in found]


def modes(path: Path, tol: float) -> dict:
    """Per goal slot of the placed episodes: the branches of the final arm configuration, and the
    side the base joint turned to (the sign of its largest excursion)."""
    slots: dict[int, dict] = {}
    with h5py.File(path, "r") as f:
        for key in sorted(f, key=lambda k: int(k.split("_")[1])):
            ep = f[key]
            if not bool(np.asarray(ep["success"])[-1]):
                continue
            q = np.asarray(ep["env_states"]["articulations"][ARM])[:, QPOS]
            slot = int(np.asarray(ep["env_states"]["task"]["goal_slot"]).reshape(-1)[-1])
            s = slots.setdefault(slot, dict(finals=[], turns={"+": 0, "-": 0}))
            s["finals"].append(q[-1])
            s["turns"]["+" if q[np.argmax(np.abs(q[:, 0])), 0] > 0 else "-"] += 1
    return {str(slot): dict(episodes=len(s["finals"]), final_branches=branches(s["finals"], tol), base_turn=s["turns"])
            for slot, s in sorted(slots.items())}


@functools.lru_cache(maxsize=None)
def goal_slots(env_id: str, seeds: tuple[int, ...]) -> tuple[int, ...]:
    """The goal slot a reset of `env_id` with each seed draws (for episode records from before 2026-11-27, which do
    not name theirs)."""
    import gymnasium as gym

    import ms_construction  # noqa: F401  (registers the tasks)

    env = gym.make(env_id, obs_mode="state", num_envs=1, sim_backend="physx_cpu")
    slots = []
    for seed in seeds:
        env.reset(seed=seed)
        slots.append(int(env.unwrapped.goal_slot.item()))
    env.close()
    return tuple(slots)


def failures_by_slot(env_id: str, episodes: list[dict]) -> dict[str, list[int]]:
    """Per goal slot: [episodes, failed] of an agent's evaluated episodes (the slot its record names, or `goal_slots`)."""
    slots = [e["goal_slot"] for e in episodes] if all("goal_slot" in e for e in episodes) else \
        goal_slots(env_id, tuple(e["seed"] for e in episodes))
    counts: dict[str, list[int]] = {}
    for slot, e in zip(slots, episodes):
        c = counts.setdefault(str(slot), [0, 0])
        c[0] += 1
        c[1] += not e["placed"]
    return dict(sorted(counts.items()))


def placed_per_slot(env_id: str, episodes: list[dict]) -> str:
    """'105/106, 104/109, 1/128': placed/episodes per goal slot, slot 0 first. Where one slot fails while its
    neighbours place, the policy has not learnt that slot's way in."""
    return ", ".join(f"{n - failed}/{n}" for n, failed in failures_by_slot(env_id, episodes).values())


def report(env_id: str, result: dict, failed: dict[str, dict], tol: float) -> str:
    lines = [f"{env_id}: per goal slot, the arm configurations the expert's placed episodes end in (joints in rad; "
             f"the same configuration within {tol} rad), the side its base joint turned to on the way, and the "
             "failed episodes of each agent (failed / episodes):", "",
             "| " + " | ".join(["goal slot", "expert episodes", "expert's final arm configurations", "base turned + / -",
                                *failed]) + " |", "|---" * (4 + len(failed)) + "|"]
    for slot, s in result.items():
        configs = "<br>".join(f"{b['count']} x {b['q']}" for b in s["final_branches"])
        cells = [slot, str(s["episodes"]), configs, f"{s['base_turn']['+']} / {s['base_turn']['-']}",
                 *("{1} / {0}".format(*f.get(slot, [0, 0])) for f in failed.values())]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(args: Args) -> dict:
    for path in args.traj:
        if not path.is_file():
            raise SystemExit(f"--traj {path}: no such file (write one with scripts/run_expert.py --save-trajectory)")
    agents = read_labelled(args.agent, "--agent")
    out, tables = {}, []
    for path in args.traj:
        env_id = path.name.split(".")[0]
        result = modes(path, args.tol)
        missing = [label for label, a in agents.items() if env_id not in a["tasks"]]
        if missing:
            raise SystemExit(f"--agent: the JSON of {', '.join(missing)} holds no episodes of {env_id}")
        failed = {label: failures_by_slot(env_id, a["tasks"][env_id]["episode_results"]) for label, a in agents.items()}
        out[env_id] = dict(traj=str(path), slots=result, failed_by_slot=failed)
        tables.append(report(env_id, result, failed, args.tol))
    command = "python -m experiments.expert_modes " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    body = f"Command: `{command}`\n\n" + "\n\n".join(tables)
    print(body)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(dict(tol=args.tol, tasks=out), indent=1) + "\n")
    if args.write_results:
        update_section(args.results, "expert-modes", title="Results",
                       body="## Where the general agent fails: the expert's several ways\n\n" + body)
    return out


if __name__ == "__main__":
    main(tyro.cli(Args))
