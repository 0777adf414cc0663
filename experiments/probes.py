"""The from-scratch work's short probes (Flooring-v1 first): what each changed, and what its curve showed.

    python -m experiments.probes            # the table into docs/experiments/from_scratch.md, from the CSVs

Each probe is a ppo.py run of a few hundred thousand env steps; its progress.csv is kept in
docs/data/from_scratch/probes/<name>.csv (copy it there from runs/probes/<name>/ when it ends). The table
reports, over the last fifth of each probe's iterations, the means of its training episodes: pick success,
place success of ordinary resets and of near-goal starts, the start radius reached, and where the element
ended (m from its goal).
"""

from __future__ import annotations

import csv
import math
import shlex
from pathlib import Path

from ms_construction.reporting import update_section

PROBE_DIR = Path("docs/data/from_scratch/probes")
PAGE = Path("docs/experiments/from_scratch.md")
COMMON = ("python baselines/ppo/ppo.py --env-id Flooring-v1 --curiosity none --curriculum cp4 --num-steps 1000 "
          "--log-dir runs/probes --eval-freq 5")


def _recipe(**overrides) -> str:
    """The ppo.py command of the from-scratch recipe (experiments/from_scratch.py, 2 envs) with `overrides`, as a probe
    (each probe names the recipe's settings it ran without, so that its command stays its own as the recipe moves on)."""
    from baselines.ppo.args import command_line
    from experiments.from_scratch import scratch_args

    args = scratch_args(2, log_dir="runs/probes", eval_freq=50, total_timesteps=600_000, **overrides)
    return "python baselines/ppo/ppo.py " + shlex.join(command_line(args))


PROBES = {
    "probeA_floor_jointcarry": ("the new dense reward (joint-space carry), ppo.py's dense defaults (gamma 0.99, 4 x 4 "
                                "minibatches, bootstrap with the critic at success)",
                                "--reward-mode dense --num-minibatches 4 --total-timesteps 300000"),
    "probeB_floor_neargoal": ("A + half the episodes from near-goal starts (paths to a lift 0.25 m above the table)",
                              "--reward-mode dense --num-minibatches 4 --total-timesteps 300000 --near-goal-share 0.5 "
                              "--success-value critic"),
    "probeC_floor_neargoal_absorbing": ("B + success valued as absorbing (its reward for ever) instead of the critic's guess",
                                        "--reward-mode dense --num-minibatches 4 --total-timesteps 300000 "
                                        "--near-goal-share 0.5"),
    "probeD_floor_ng_norm_g95_e8": ("C + normalized_dense, gamma 0.95, 8 epochs of 8 minibatches; paths with a raised "
                                    "corner to a lift 0.5 m up",
                                    "--reward-mode normalized_dense --gamma 0.95 --update-epochs 8 --num-minibatches 8 "
                                    "--total-timesteps 300000 --near-goal-share 0.5"),
    "probeE_floor_ng_table": ("D + the start paths go on down to the element lying on the table (radius 1: just grasped)",
                              "--reward-mode normalized_dense --gamma 0.95 --update-epochs 8 --num-minibatches 8 "
                              "--total-timesteps 400000 --near-goal-share 0.5"),
    "probeF_general_shared_radius": ("E's recipe on the general task (ConstructionPickPlace-v1), one start radius for the "
                                     "three task types, widened after any iteration whose near-goal episodes placed 60%",
                                     "git checkout d37d6c2 && python -m experiments.from_scratch (the recipe's first "
                                     "version; stopped at 514,000 steps)"),
    "probeG_general_task_radii": ("F with one start radius per task type, widened on a window of its last 20 "
                                  "near-goal episodes",
                                  "git checkout dc03ca7 && python -m experiments.from_scratch (stopped at 512,000 steps)"),
    "probeH_general_progress": ("G + the dense reward's progress term (placing still paying 5)",
                                "git checkout 9115d4e && python -m experiments.from_scratch (stopped at 514,000 steps)"),
    "probeI_general_install_offset": ("the campaign's recipe (H, placing paying 10) + the joint move to the "
                                      "installation configuration in the observation (`--obs-install-offset`)",
                                      _recipe(obs_install_offset=True, near_goal_share=0.5, near_goal_max_steps=None, bounded_mean=False,
                                              exp_name="probeI_general_install_offset")
                                      + " (stopped at 190,000 steps)"),
    "probeJ_offset_ng_limit80": ("I + near-goal episodes cut at 80 steps (`--near-goal-max-steps 80`)",
                                 _recipe(obs_install_offset=True, near_goal_share=0.5, near_goal_max_steps=80, bounded_mean=False,
                                         exp_name="probeJ_offset_ng_limit80")
                                 + " (stopped at 48,000 steps, to start K)"),
    "probeK_offset_limit80_tanh": ("J + the policy's mean bounded by tanh (`--bounded-mean`)",
                                   _recipe(obs_install_offset=True, near_goal_share=0.5, near_goal_max_steps=80, bounded_mean=True,
                                           exp_name="probeK_offset_limit80_tanh") + " (stopped at 174,000 steps)"),
    "probeL_share08": ("K + 80% of the episodes from near-goal starts (`--near-goal-share 0.8`): the recipe of the "
                       "campaign's fourth start, which went on from this probe's checkpoint",
                       _recipe(exp_name="probeL_share08") + " (then the campaign: python -m experiments.from_scratch)"),
}
"""name: (what it changed, its arguments beyond COMMON or its whole command), in the order they ran."""


def _mean(rows: list[dict], key: str) -> float:
    values = [float(r[key]) for r in rows if r.get(key) not in ("", None) and not math.isnan(float(r[key]))]
    return sum(values) / len(values) if values else float("nan")


def _pct(x: float) -> str:
    return "-" if math.isnan(x) else f"{100 * x:.0f}%"


def table() -> str:
    lines = ["| probe | what it changed | env steps | pick | placed, ordinary resets | placed, near-goal starts | "
             "start radius | element ends (m from goal) | episodes an update: near-goal / all |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, (what, _) in PROBES.items():
        path = PROBE_DIR / f"{name}.csv"
        if not path.is_file():
            continue
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        last = rows[-max(1, len(rows) // 5):]
        ordinary = _mean(last, "ordinary_place_success")
        if math.isnan(ordinary):  # a probe without near-goal starts: every episode is an ordinary one
            ordinary = _mean(last, "place_success")
        radius = last[-1].get("near_goal_radius") or ""
        per_update = f"{_mean(last, 'near_goal_episodes'):.1f} / {_mean(last, 'episodes'):.1f}" if radius else "-"
        lines.append(f"| {name.split('_')[0]} | {what} | {int(rows[-1]['global_step']):,} | {_pct(_mean(last, 'pick_success'))} | "
                     f"{_pct(ordinary)} | {_pct(_mean(last, 'near_goal_place_success'))} | "
                     f"{float(radius):.1f} | {_mean(last, 'end_place_dist'):.2f} | {per_update} |" if radius else
                     f"| {name.split('_')[0]} | {what} | {int(rows[-1]['global_step']):,} | {_pct(_mean(last, 'pick_success'))} | "
                     f"{_pct(ordinary)} | - | - | {_mean(last, 'end_place_dist'):.2f} | - |")
    commands = "\n".join(f"- {name.split('_')[0]}: `{args if args.startswith(('git ', 'python ')) else f'{COMMON} {args} --exp-name {name}'}`"
                         for name, (_, args) in PROBES.items())
    return ("Command: `python -m experiments.probes` (from docs/data/from_scratch/probes/*.csv).\n\n"
            "Means over the last fifth of each probe's iterations, of its training episodes (stochastic policy).\n\n"
            + "\n".join(lines) + "\n\nThe probes' commands:\n\n" + commands)


if __name__ == "__main__":
    update_section(PAGE, "from-scratch-probes", table(), "Learning from reward alone: the experiment")
    print(f"wrote the probe table to {PAGE}")
