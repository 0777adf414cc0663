"""What held the window opening at y = +0.85 back: the carry distance a window for it sees from the turret's -pi side
(the side the general agent grasps windows from), at the paths' deviation weight and with `carry_keeps_to_vias`,
written into the experiment page.

    python -m experiments.via_landscape                       # the campaign's checkpoint, 4 episodes
    python -m experiments.via_landscape --checkpoint runs/probes/probeAA_keeps_to_vias/checkpoint.pt

Two tables: along that opening's -pi start paths (IK and the planned via alone: the table end, the lift, the via,
and 60% of the straight joint line from the lift to the back-off out of the opening, which cuts across the detour into
the wall between the openings); and along a policy's own carries of that opening's windows from ordinary resets
(seeds SEED on: neither the validation nor the test seeds; the policy's mean), both measures on the same states.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import tyro

SLOT = 2
"""the window opening at y = +0.85."""
SIDE = 1
"""the turret's -pi side, in StartPaths' layout."""
SEED = 3_000_000
"""the first seed of the policy's episodes."""
CUT = 0.6
"""how far along the straight joint line from the lift to the back-off the cut-across point lies."""
PAGE = Path("docs/experiments/from_scratch.md")
SECTION = "via-landscape"


def _env(keeps: bool, **kwargs):
    import gymnasium as gym

    import ms_construction  # noqa: F401  (registration)

    return gym.make("WindowInstallation-v1", obs_mode="state", reward_mode="dense", carry_along_paths=True,
                    carry_keeps_to_vias=keeps, **kwargs)


def _measure(u, qs, keeps: bool) -> list[float]:
    """The carry distance at each joint configuration of `qs` [m, 6], the env's hold and grasp side as they are."""
    import torch

    u.carry_keeps_to_vias = keeps
    out = []
    for q in qs:
        u.agent.robot.set_qpos(torch.as_tensor(np.asarray(q)[None], dtype=torch.float32))
        out.append(float(u.carry_distance()[0]))
    return out


def path_table() -> str:
    """Along each -pi start path of that opening: its table end, lift, via, back-off, and the cut-across point."""
    from ms_construction.goal_configurations import start_paths
    from ms_construction.parameters import ELEMENT_KINDS

    paths, w = start_paths(), ELEMENT_KINDS.index("window")
    env = _env(False)
    env.reset(seed=0)
    u = env.unwrapped
    u.set_held(True)
    u.goal_slot[:], u.carry_side[:] = SLOT, SIDE
    lines = ["| installation configuration | measure | table end | lift | via | back-off | cut across, "
             f"{CUT:.0%} of the way from the lift to the back-off |", "|---|---|---|---|---|---|---|"]
    for c in range(paths.waypoints.shape[2]):
        wp = paths.waypoints[w, SLOT, c, SIDE].astype(np.float64)
        points = [wp[4], wp[3], wp[2], wp[1], wp[3] + CUT * (wp[1] - wp[3])]
        for keeps in (False, True):
            d = _measure(u, points, keeps)
            lines.append(f"| {c} | {'carry_keeps_to_vias' if keeps else 'deviation weight ' + format(u.PATH_DEVIATION_WEIGHT, 'g')} | "
                         + " | ".join(f"{x:.1f}" for x in d) + " |")
    env.close()
    return "\n".join(lines)


def policy_table(checkpoint: Path, episodes: int) -> str:
    """A policy's episodes at that opening from ordinary resets: where its carry went and how far each measure said
    it was from its goal at the grasp, at its least and at the end."""
    import torch

    from baselines.ppo.checkpoints import load_checkpoint, load_policy
    from ms_construction.rollout import rollout

    agent, kwargs = load_policy(checkpoint, "ConstructionPickPlace-v1")
    kwargs = {k: v for k, v in kwargs.items() if k not in ("obs_mode", "reward_mode", "carry_keeps_to_vias")}
    keeps_in_obs = bool(load_checkpoint(checkpoint)["args"].get("carry_keeps_to_vias"))  # its path offset's measure
    env = _env(keeps_in_obs, **kwargs)
    u = env.unwrapped
    lines = ["| seed | placed | grasped from | turret at the grasp / end (rad) | carry distance at the grasp / least / end, "
             f"deviation weight {u.PATH_DEVIATION_WEIGHT:g} (rad) | the same with carry_keeps_to_vias (rad) |",
             "|---|---|---|---|---|---|"]
    seed, done = SEED, 0
    while done < episodes:
        env.reset(seed=seed)
        if int(u.goal_slot[0]) == SLOT:
            qs = []
            for step in rollout(agent, env, seed):
                if bool(step.info["is_grasped"][0]):
                    qs.append(u.agent.robot.get_qpos()[0].clone())
                if bool(step.terminated[0]) or bool(step.truncated[0]):
                    break
            placed = "yes" if bool(step.info["success"][0]) else "no"
            if qs:
                side = {0: "+pi", 1: "-pi"}.get(int(u.carry_side[0]), "-")
                cells = []
                for keeps in (False, True):
                    d = _measure(u, torch.stack(qs).numpy(), keeps)
                    cells.append(f"{d[0]:.1f} / {min(d):.1f} / {d[-1]:.1f}")
                u.carry_keeps_to_vias = keeps_in_obs
                lines.append(f"| {seed} | {placed} | {side} | {float(qs[0][0]):.2f} / {float(qs[-1][0]):.2f} | "
                             f"{cells[0]} | {cells[1]} |")
            else:
                lines.append(f"| {seed} | {placed} | not grasped | - | - | - |")
            done += 1
        seed += 1
    env.close()
    return "\n".join(lines)


@dataclass
class Args:
    checkpoint: Optional[Path] = None
    """the policy whose carries are measured (default: the from-scratch campaign's checkpoint)."""
    episodes: int = 4
    """its episodes at that opening."""
    write: bool = True
    """write the tables into the experiment page's generated section."""


def main(args: Args) -> None:
    from baselines.ppo.checkpoints import load_checkpoint
    from experiments.from_scratch import scratch_runs

    if args.episodes < 1:
        raise SystemExit(f"--episodes {args.episodes}: give at least 1")
    run = scratch_runs()[0]
    ckpt = args.checkpoint or Path(run.args.log_dir) / run.args.exp_name / "checkpoint.pt"
    if not Path(ckpt).is_file():
        raise SystemExit(f"--checkpoint {ckpt}: no such file")
    step = load_checkpoint(ckpt)["progress"]["global_step"]
    command = ("python -m experiments.via_landscape" + (f" --checkpoint {args.checkpoint}" if args.checkpoint else "")
               + (f" --episodes {args.episodes}" if args.episodes != Args.episodes else ""))
    body = (f"Command: `{command}` (IK and the planned via alone; then the policy at {ckpt} "
            f"(its run's {step:,} env steps), its mean, from ordinary resets, seeds {SEED:,} on).\n\n"
            + path_table() + "\n\n" + policy_table(Path(ckpt), args.episodes))
    print(body)
    if args.write:
        from ms_construction.reporting import update_section

        update_section(PAGE, SECTION, body, "Learning from reward alone: the experiment")


if __name__ == "__main__":
    main(tyro.cli(Args))
