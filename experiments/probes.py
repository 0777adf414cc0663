"""The from-scratch work's short probes (Flooring-v1 first): what each changed, and what its curve showed.

    python -m experiments.probes            # the tables into docs/experiments/from_scratch.md, from the CSVs and JSONs

Each probe is a ppo.py run of a few hundred thousand env steps; its progress.csv is kept in
docs/data/from_scratch/probes/<name>.csv (copy it there from runs/probes/<name>/ when it ends). The table
reports, over the last fifth of each probe's iterations, the means of its training episodes: pick success,
place success of ordinary resets and of near-goal starts, the start radius reached, and where the element
ended (m from its goal).

Probes that go on from a campaign checkpoint (`CONTINUATIONS`) are compared where the campaign is judged: each
policy evaluated with the paper's protocol on the same test seeds (scripts/evaluate.py --all, deterministic), its
JSON kept beside the CSVs as <name>_eval.json; the campaign itself, run on for as many steps, is the control. They are
also compared by their training episodes of the last 200,000 steps (hundreds of episodes, where an evaluation has
50 of one checkpoint's mean), from <name>.csv: a probe's progress.csv, or a control's rows of the campaign's.
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


def _recipe(at: int, **overrides) -> str:
    """The ppo.py command of the from-scratch recipe (experiments/from_scratch.py, 2 envs) as the campaign ran it just
    before env step `at` (where the probe went on from; 0: before the campaign's fifth start), with `overrides`: the
    probe's own change, so that its command stays what it ran as the recipe moves on."""
    from baselines.ppo.args import command_line
    from experiments.from_scratch import recipe_before, scratch_args

    args = scratch_args(2, **{"log_dir": "runs/probes", "eval_freq": 50, "total_timesteps": 600_000,
                              **recipe_before(at), **overrides})
    return "python baselines/ppo/ppo.py " + shlex.join(command_line(args))


GRASP_STARTS = dict(reach_avoids_vias=True, reach_start_share=1.0, reach_start_radius=0.1,
                    reach_start_tasks=("window",))
"""Probe AF's grasp starts: every window episode that is not a near-goal start one starts on the last tenth of the
reach path toward the turret side of the slot's direct paths, each goal slot's radius widening on its own."""
TURRET_PENALTY = dict(mean_saturation_coef=0.01, mean_saturation_joints=(0,))
"""Probe AF's saturation penalty on the turret's mean alone."""

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
                                      _recipe(0, obs_install_offset=True, near_goal_share=0.5, near_goal_max_steps=None, bounded_mean=False,
                                              exp_name="probeI_general_install_offset", carry_along_paths=False, reach_in_joint_space=False)
                                      + " (stopped at 190,000 steps)"),
    "probeJ_offset_ng_limit80": ("I + near-goal episodes cut at 80 steps (`--near-goal-max-steps 80`)",
                                 _recipe(0, obs_install_offset=True, near_goal_share=0.5, near_goal_max_steps=80, bounded_mean=False,
                                         exp_name="probeJ_offset_ng_limit80", carry_along_paths=False, reach_in_joint_space=False)
                                 + " (stopped at 48,000 steps, to start K)"),
    "probeK_offset_limit80_tanh": ("J + the policy's mean bounded by tanh (`--bounded-mean`)",
                                   _recipe(0, obs_install_offset=True, near_goal_share=0.5, near_goal_max_steps=80, bounded_mean=True,
                                           exp_name="probeK_offset_limit80_tanh", carry_along_paths=False, reach_in_joint_space=False) + " (stopped at 174,000 steps)"),
    "probeL_share08": ("K + 80% of the episodes from near-goal starts (`--near-goal-share 0.8`): the recipe of the "
                       "campaign's fourth start, which went on from this probe's checkpoint",
                       _recipe(0, exp_name="probeL_share08", carry_along_paths=False, reach_in_joint_space=False) + " (then the campaign: python -m experiments.from_scratch)"),
}
"""name: (what it changed, its arguments beyond COMMON or its whole command), in the order they ran."""


STARTS = {
    "start_1682k": ("runs/campaign_1682k.pt", "9688cdd", "the campaign's fourth start at 1,682,000 env steps"),
    "start_4092k": ("runs/campaign_4092k.pt", "51f96b5", "the campaign's fifth start at 4,092,000 env steps"),
    "start_6782k": ("runs/campaign_6782k.pt", "a327587", "the campaign's fifth start at 6,782,000 env steps"),
    "start_10558k": ("runs/campaign_10558k.pt", "ea4fd7f",
                     "the campaign's fifth start at 10,558,000 env steps (the hold reset since 10,010,000)"),
    "start_12948k": ("runs/campaign_12948k.pt", "3b9685c", "the campaign's fifth start at 12,948,000 env steps"),
    "start_17250k": ("runs/campaign_17250k.pt", "066f2d2", "the campaign's fifth start at 17,250,000 env steps"),
    "start_17500k": ("runs/campaign_17500k.pt", "0a742fe",
                     "the campaign's sixth start at 17,500,000 env steps (probe U adopted)"),
    "start_17540k": ("runs/campaign_17540k.pt", "26307e7", "the campaign's sixth start at 17,540,000 env steps"),
    "start_17676k": ("runs/campaign_17676k.pt", "afb2635", "the campaign's seventh start at 17,676,000 env steps "
                     "(probe W adopted)"),
    "start_18062k": ("runs/campaign_18062k.pt", "f8a700d", "the campaign's eighth start at 18,062,000 env steps "
                     "(probe X adopted)"),
    "start_18742k": ("runs/campaign_18742k.pt", "8ffe853", "the campaign's ninth start at 18,742,000 env steps "
                     "(probe Y adopted)"),
}
"""name: (where its checkpoint is put, the commit whose campaign/scratch_general_agent/checkpoint.pt it is, what it
is): the campaign checkpoints the continuation probes of a round start from."""
EVAL = "python scripts/evaluate.py --all --episodes 50"


def _start(name: str) -> tuple[str, str]:
    """A start's (what, how) row: its checkpoint taken out of the commit that holds it."""
    path, commit, what = STARTS[name]
    return f"where round {list(STARTS).index(name) + 1} starts: {what}", \
        f"git show {commit}:campaign/scratch_general_agent/checkpoint.pt > {path}"


VIA_ROUND = dict(checkpoint=STARTS["start_18742k"][0], near_goal_radius=1.0, eval_freq=1000, carry_keeps_to_vias=True,
                 goal_slot_weights=(1.0, 1.0, 1.0, 1.0, 1.0, 3.0, 1.0, 1.0, 1.0), total_timesteps=1_258_000)
"""the settings of the probes from the ninth start that carry the window kept to the via path (AA on): the rest of the
budget, the via opening drawn three times as often."""


CONTINUATIONS = {
    "start_1682k": (*_start("start_1682k"), None),
    "control_campaign": ("the campaign run on (the recipe unchanged, its optimizer and start radii kept)",
                         "python -m experiments.from_scratch (resumed at 1,682,000 steps, stopped at 2,022,000)", None),
    "probeM_paths": ("the dense reward's carry measured along the start paths (`--carry-along-paths`)",
                     _recipe(1_682_000, exp_name="probeM_paths", checkpoint=STARTS["start_1682k"][0], near_goal_radius=0.8,
                             eval_freq=1000, carry_along_paths=True, reach_in_joint_space=False)
                     + " (stopped at 330,000 steps)", "start_1682k"),
    "probeN_paths_joint_reach": ("M + the reach toward the element in joint space (`--reach-in-joint-space`)",
                                 _recipe(1_682_000, exp_name="probeN_paths_joint_reach", checkpoint=STARTS["start_1682k"][0],
                                         near_goal_radius=0.8, eval_freq=1000, carry_along_paths=True,
                                         reach_in_joint_space=True) + " (stopped at 344,000 steps)", "start_1682k"),
    "start_4092k": (*_start("start_4092k"), None),
    "probeO_share05_weights": ("half the episodes from near-goal starts instead of 80% (`--near-goal-share 0.5`) and "
                               "ceiling panels and windows sampled twice as often as floor panels (`--task-weights 2 2 1`)",
                               _recipe(4_092_000, exp_name="probeO_share05_weights", checkpoint=STARTS["start_4092k"][0],
                                       near_goal_radius=1.0, eval_freq=1000, near_goal_share=0.5,
                                       task_weights=(2.0, 2.0, 1.0)) + " (ran its 600,000 steps)", "start_4092k"),
    "start_6782k": (*_start("start_6782k"), None),
    "control_from_6782k": ("the campaign run on (the recipe unchanged)",
                           "python -m experiments.from_scratch (resumed at 6,782,000 steps, stopped at 7,168,000)", None),
    "probeP_lag": ("the carry distance counts how far the held element trails its place on the plate, jammed against a slab "
                   "or wall (`--carry-counts-lag`)",
                   _recipe(6_782_000, exp_name="probeP_lag", checkpoint=STARTS["start_6782k"][0], near_goal_radius=1.0,
                           eval_freq=1000, carry_counts_lag=True, total_timesteps=400_000) + " (ran its 400,000 steps)", "start_6782k"),
    "probeQ_path_offset": ("the observation gains the joint move to a point a little ahead along the start path "
                           "(`--obs-path-offset`; zero weights on it at the start)",
                           _recipe(6_782_000, exp_name="probeQ_path_offset", checkpoint=STARTS["start_6782k"][0], near_goal_radius=1.0,
                                   eval_freq=1000, obs_path_offset=True, total_timesteps=400_000), "start_6782k"),
    "start_10558k": (*_start("start_10558k"), None),
    "control_from_10558k": ("the campaign run on (the recipe unchanged)",
                            "python baselines/ppo/ppo.py --resume campaign/scratch_general_agent/checkpoint.pt --extend "
                            "--total-timesteps 11058000 --curriculum cp4 (the campaign resumed at 10,558,000 steps)", None),
    "probeR_path_offset": ("Q again, from the later start with the hold reset (`--obs-path-offset`; zero weights on it "
                           "at the start)",
                           _recipe(10_558_000, exp_name="probeR_path_offset", checkpoint=STARTS["start_10558k"][0], near_goal_radius=1.0,
                                   eval_freq=1000, obs_path_offset=True, total_timesteps=500_000), "start_10558k"),
    "start_12948k": (*_start("start_12948k"), None),
    "control_from_12948k": ("the campaign run on (the recipe unchanged)",
                            "python baselines/ppo/ppo.py --resume campaign/scratch_general_agent/checkpoint.pt --extend "
                            "--total-timesteps 13448000 --curriculum cp4 (the campaign resumed at 12,948,000 steps)", None),
    "probeS_share02": ("a fifth of the episodes from near-goal starts instead of 80% (`--near-goal-share 0.2`): every "
                       "radius is 1 and those starts all place, so most episodes trained what the policy already does",
                       _recipe(12_948_000, exp_name="probeS_share02", checkpoint=STARTS["start_12948k"][0], near_goal_radius=1.0,
                               eval_freq=1000, near_goal_share=0.2, total_timesteps=500_000), "start_12948k"),
    "probeT_share02_failure_weights": ("S + task types sampled by their recent failures (`--failure-task-weights 100`: "
                                       "0.1 + the failure rate of each one's last 100 ordinary episodes)",
                                       _recipe(12_948_000, exp_name="probeT_share02_failure_weights",
                                               checkpoint=STARTS["start_12948k"][0], near_goal_radius=1.0, eval_freq=1000,
                                               near_goal_share=0.2, failure_task_weights=100, total_timesteps=500_000),
                                       "start_12948k"),
    "start_17250k": (*_start("start_17250k"), None),
    "probeU_path_sides_share02": ("the reach toward the table from the turret side the goal slot's start paths leave from "
                                  "(`--reach-toward-path-sides`: the window opening at y = +0.85 from +pi, where every "
                                  "policy before grasped from -pi and placed 0-2 of its 17 test episodes) + S's fifth "
                                  "of the episodes from near-goal starts; no control run: the recipe run on placed 0-2 "
                                  "there in every evaluation since 1,682,000 steps",
                                  _recipe(17_250_000, exp_name="probeU_path_sides_share02", checkpoint=STARTS["start_17250k"][0],
                                          near_goal_radius=1.0, eval_freq=1000, near_goal_share=0.2,
                                          reach_toward_path_sides=True, total_timesteps=250_000), "start_17250k"),
    "probeV_reach_starts05": ("U's recipe (the campaign's sixth start, which went on from U) + half the episodes start "
                              "with the arm part of the way to the table from the goal slot's side (`--reach-start-share "
                              "0.5`): U's shaping alone did not turn the policy's reach, which went to -pi for every window",
                              _recipe(17_500_000, exp_name="probeV_reach_starts05", checkpoint=STARTS["start_17500k"][0],
                                      near_goal_radius=1.0, eval_freq=1000, reach_start_share=0.5,
                                      total_timesteps=250_000) + " (stopped at 110,000 steps)", "start_17500k"),
    "start_17540k": (*_start("start_17540k"), None),
    "probeW_vias_share08": ("the start paths gain the planned via of the window opening at y = +0.85 from -pi (a code "
                            "and asset change: assets/start_path_vias.json), and 80% of the episodes from near-goal "
                            "starts again; the campaign's seventh start went on from it",
                            _recipe(17_540_000, exp_name="probeW_vias_share08", checkpoint=STARTS["start_17540k"][0],
                                    near_goal_radius=1.0, eval_freq=1000, near_goal_share=0.8, total_timesteps=250_000)
                            + " (stopped at 136,000 steps)", "start_17540k"),
    "start_17676k": (*_start("start_17676k"), None),
    "probeX_window_weights": ("W's recipe (the seventh start) with windows sampled twice as often as either other task "
                              "(`--task-weights 1 2 1`): windows are the task below the paper's rate",
                              _recipe(17_676_000, exp_name="probeX_window_weights", checkpoint=STARTS["start_17676k"][0],
                                      near_goal_radius=1.0, eval_freq=1000, task_weights=(1.0, 2.0, 1.0),
                                      total_timesteps=1_500_000) + " (stopped at 386,000 steps)", "start_17676k"),
    "start_18062k": (*_start("start_18062k"), None),
    "probeY_path_offset": ("X's recipe (the eighth start, which went on from X) + the joint move a little ahead along the "
                           "start path in the observation (`--obs-path-offset`, zero weights on it at the start): X's "
                           "policy still carried that opening's windows to the neighbouring one, where the straight "
                           "move to the installation leads, away from the via",
                           _recipe(18_062_000, exp_name="probeY_path_offset", checkpoint=STARTS["start_18062k"][0],
                                   near_goal_radius=1.0, eval_freq=1000, obs_path_offset=True,
                                   total_timesteps=1_500_000) + " (stopped at 680,000 steps)", "start_18062k"),
    "start_18742k": (*_start("start_18742k"), None),
    "probeZ_slot_weights": ("Y's recipe (the ninth start) with the window opening at y = +0.85 drawn four times as often "
                            "as either other opening (`--goal-slot-weights 1 1 1 1 1 4 1 1 1`): the via path's near-goal "
                            "starts were 4% of the episodes",
                            _recipe(18_742_000, exp_name="probeZ_slot_weights", checkpoint=STARTS["start_18742k"][0],
                                    near_goal_radius=1.0, eval_freq=1000,
                                    goal_slot_weights=(1.0, 1.0, 1.0, 1.0, 1.0, 4.0, 1.0, 1.0, 1.0),
                                    total_timesteps=1_000_000) + " (stopped at 242,000 steps; not adopted)",
                            "start_18742k"),
    "probeAA_keeps_to_vias": ("Y's recipe (the ninth start) with the carry kept to the via path "
                              "(`--carry-keeps-to-vias`: measured only along the paths from the side the window was "
                              "grasped from, each radian off a planned via's path counting 25 times) and that opening "
                              "drawn three times as often (`--goal-slot-weights 1 1 1 1 1 3 1 1 1`): at the old "
                              "weight a window stopped in the neighbouring opening measured nearer its goal than the via",
                              _recipe(18_742_000, exp_name="probeAA_keeps_to_vias", **VIA_ROUND)
                              + " (stopped at 568,000 steps; not adopted)",
                              "start_18742k"),
    "probeAB_keeps_to_vias_from_lift": ("AA with the table's segment of the via paths at the paths' own deviation weight "
                                        "(the via weight from the lift in): AA's policy turned its grasp toward the "
                                        "path's table end and missed half that opening's windows at the pick",
                                        _recipe(18_742_000, exp_name="probeAB_keeps_to_vias_from_lift", **VIA_ROUND)
                                        + " (adopted: the campaign's last 1,258,000 steps, to its 20,000,000 budget, "
                                          "until probe AM's took their place)",
                                        "start_18742k"),
    "probeAC_reach_avoids_vias": ("AB with the reach toward the turret side of the direct paths only (`--reach-avoids-vias`: "
                                  "since the planned via (the seventh start) the reach paid for grasping windows for the "
                                  "opening at y = +0.85 from -pi as much as from +pi, from where the policy places them on "
                                  "near-goal starts) and half the other episodes starting on the way to the table on that "
                                  "side (`--reach-start-share 0.5`: U and V, which had that reach, saw a few dozen such "
                                  "episodes of that opening)",
                                  _recipe(18_742_000, exp_name="probeAC_reach_avoids_vias", **VIA_ROUND,
                                          reach_avoids_vias=True, reach_start_share=0.5)
                                  + " (stopped at 404,000 steps; not adopted)",
                                  "start_18742k"),
    "probeAD_unsaturated_mean": ("AC with the bounded mean kept off tanh's flat ends (`--mean-saturation-coef 0.01`): "
                                 "AC's policy turned those windows to -pi from reach starts at +1.5 to +2.3 rad, its "
                                 "turret mean's value before tanh at -7 to -12, where tanh's slope is 1e-8 and no "
                                 "reward moves it",
                                 _recipe(18_742_000, exp_name="probeAD_unsaturated_mean", **VIA_ROUND,
                                         reach_avoids_vias=True, reach_start_share=0.5, mean_saturation_coef=0.01)
                                 + " (stopped at 788,000 steps; not adopted)",
                                 "start_18742k"),
    "probeAE_reach_starts_to_lift": ("AD went on with the reach starts anywhere up to the lift right above the element "
                                     "(`--reach-starts-to-lift`), every episode that is not a near-goal start one "
                                     "(`--reach-start-share 1`): AD turned back from most of the way to +pi; from "
                                     "right above the element, a grasp at +pi is a few steps away",
                                     _recipe(18_742_000, exp_name="probeAE_reach_starts_to_lift",
                                             **{**VIA_ROUND, "checkpoint": "runs/probes/probeAD_unsaturated_mean/checkpoint.pt",
                                                "total_timesteps": 470_000},
                                             reach_avoids_vias=True, reach_start_share=1.0, reach_starts_to_lift=True,
                                             mean_saturation_coef=0.01)
                                     + " (stopped at 318,000 steps; not adopted)",
                                     "probeAD_unsaturated_mean"),
    "probeAF_grasp_starts": ("AC with the reach starts carried back through the grasp (`--reach-start-radius 0.1`: "
                             "each goal slot's reach starts on the last tenth of the reach path, down to 0.2 m above "
                             "the element, widening as they grasp from the side they started on; every window episode "
                             "that is not a near-goal start one, `--reach-start-tasks window`) and the turret's mean "
                             "alone kept off tanh's flat ends "
                             "(`--mean-saturation-coef 0.01 --mean-saturation-joints 0`): from the plate 0.2 m above "
                             "such a window at +pi the ninth start's policy grasped it there and placed it, and from "
                             "the lift it turned back, its turret mean pinned at -11; AD, which kept all six means off "
                             "the flat ends, lost the ceiling panels",
                             _recipe(18_742_000, exp_name="probeAF_grasp_starts", **VIA_ROUND,
                                     **GRASP_STARTS, **TURRET_PENALTY)
                             + " (stopped at 676,000 steps; not adopted)",
                             "start_18742k"),
    "probeAG_turret_entropy": ("AF with an entropy bonus (`--ent-coef 0.005`): AF's turret spread stayed 0.10 around a "
                               "mean near the penalty's bound, and a turn toward the element at +pi was never drawn",
                               _recipe(18_742_000, exp_name="probeAG_turret_entropy", **VIA_ROUND,
                                       **GRASP_STARTS, **TURRET_PENALTY, ent_coef=0.005)
                               + " (stopped at 366,000 steps; not adopted)",
                               "start_18742k"),
    "probeAH_turret_spread_floor": ("AF with the turret's spread held at 0.3 or more (`--log-std-floor -1.2 "
                                    "--log-std-floor-joints 0`): in AF and AG it stayed at 0.10 around a mean at the "
                                    "penalty's bound, and a turn toward the element at +pi was never drawn",
                                    _recipe(18_742_000, exp_name="probeAH_turret_spread_floor", **VIA_ROUND,
                                            **GRASP_STARTS, **TURRET_PENALTY, log_std_floor=-1.2,
                                            log_std_floor_joints=(0,))
                                    + " (stopped at 268,000 steps; not adopted)",
                                    "start_18742k"),
    "probeAI_turret_mean_bound1": ("AH with the turret's mean pulled within +-1 before tanh "
                                   "(`--mean-saturation-bound 1 --mean-saturation-coef 0.05`, tanh's slope 0.42 "
                                   "there): from the lift above those windows at +pi, AH's turret mean sat at -4 "
                                   "before tanh (slope 0.001), and the opening's radius stopped at 0.4 as AF's had at "
                                   "0.5",
                                   _recipe(18_742_000, exp_name="probeAI_turret_mean_bound1", **VIA_ROUND,
                                           **GRASP_STARTS, **{**TURRET_PENALTY, "mean_saturation_coef": 0.05},
                                           mean_saturation_bound=1.0, log_std_floor=-1.2, log_std_floor_joints=(0,))
                                   + " (stopped at 238,000 steps; not adopted)",
                                   "start_18742k"),
    "probeAJ_mirror_windows": ("AB's recipe (the ninth start's) with the window opening at y = +0.85 met as the mirror "
                               "image of the one at -0.85 (`--mirror-windows`): the arm and the window site are "
                               "symmetric in the plane y = 0, and the policy places the windows of the opening at "
                               "-0.85 from -pi, the side it turns every reach to; in the mirror the window's head "
                               "stays up, so it must be installed half a turn about its normal from the way it is "
                               "there (a goal orientation of its own, learnt from reward)",
                               _recipe(18_742_000, exp_name="probeAJ_mirror_windows", **VIA_ROUND, mirror_windows=True)
                               + " (stopped at 466,000 steps; not adopted)",
                               "start_18742k"),
    "probeAK_mirror_grasp_starts": ("AJ went on with AF's grasp starts for windows (`--reach-start-share 1 "
                                    "--reach-start-radius 0.1 --reach-start-tasks window --reach-avoids-vias`): in the "
                                    "mirror AJ's policy turned those windows' reach the side they place from and "
                                    "placed 3 of 4 from near-goal starts at radius 0.3, but from ordinary resets it "
                                    "hovered 0.7 m above the element and grasped none",
                                    _recipe(18_742_000, exp_name="probeAK_mirror_grasp_starts",
                                            **{**VIA_ROUND, "total_timesteps": 792_000,
                                               "checkpoint": "runs/probes/probeAJ_mirror_windows/checkpoint.pt"},
                                            mirror_windows=True, **GRASP_STARTS)
                                    + " (stopped at 386,000 steps; not adopted)",
                                    "probeAJ_mirror_windows"),
    "probeAL_mirror_twin_reach": ("AJ (the mirror) with the opening at y = +0.85's installation configurations cut to "
                                  "the wrist branch whose mirror image is the -0.85 opening's but for joint 6 "
                                  "(`--install-mirror-branch`), its joint moves until the grasp measured for the "
                                  "element held half a turn on, and its goal orientation shown as it is until the "
                                  "grasp (`--mirror-canonical-reach`): until the grasp the policy sees the -0.85 "
                                  "opening's reach exactly, after it the carry has to turn the window half a turn "
                                  "more; in AJ the mirror's nearest installation was the other wrist branch, and the "
                                  "reach hovered",
                                  _recipe(18_742_000, exp_name="probeAL_mirror_twin_reach", **VIA_ROUND,
                                          mirror_windows=True, install_mirror_branch=True, mirror_canonical_reach=True)
                                  + " (stopped at 466,000 steps; not adopted)",
                                  "start_18742k"),
    "probeAM_mirror_held_half_turn": ("AL with the held window seen half a turn about the plate's axis, joint 6 "
                                      "with it (`--mirror-held-half-turn`): a state of the -0.85 opening, installed "
                                      "where its own installation is; AL's policy grasped those windows at +pi and "
                                      "carried them to 0.2-0.4 m of the opening with the wrist 40 degrees short of "
                                      "the extra half turn, as its habit at -0.85 has it; in this view the half turn "
                                      "shows at the grasp, above the table",
                                      _recipe(18_742_000, exp_name="probeAM_mirror_held_half_turn", **VIA_ROUND,
                                              mirror_windows=True, install_mirror_branch=True,
                                              mirror_canonical_reach=True, mirror_held_half_turn=True)
                                      + " (adopted: the campaign's steps from 18,742,000 to 19,648,000; it ran on "
                                        "with this recipe to its 20,000,000 budget)",
                                      "start_18742k"),
}
"""name: (what it changed, how its policy came to be, the start it went on from, or the probe whose end it went on from:
its steps count after that one's);
each evaluated with `python -m experiments.probes --evaluate <name> --checkpoint <its checkpoint>` (EVAL into
PROBE_DIR/<name>_eval.json; a start's and a control's checkpoints as their commands say, the probes' their
runs/probes/<name>/checkpoint.pt). The campaign run on from each start is that round's control."""


def continuation_table() -> str:
    import json

    from experiments.expert_modes import placed_per_slot

    from baselines.ppo.evaluation import pct

    lines = ["| policy | what it changed | env steps in all | pick: ceiling / window / flooring | "
             "placed: ceiling / window / flooring | windows placed per opening (y = -0.85, 0, +0.85) | training "
             "episodes of its last 200,000 steps placed, ordinary resets: ceiling / window / flooring (episodes) |",
             "|---|---|---|---|---|---|---|"]
    for name, (what, _, _) in CONTINUATIONS.items():
        path = PROBE_DIR / f"{name}_eval.json"
        if not path.is_file():
            continue
        result = json.loads(path.read_text())
        tasks = result["tasks"].values()
        steps = result.get("global_step")
        lines.append(f"| {name} | {what} | {'-' if steps is None else f'{steps:,}'} | "
                     + " / ".join(f"{100 * t['pick_success']:.0f}%" for t in tasks) + " | "
                     + " / ".join(pct(t["place_success"], t["place_success_ci95"]) for t in tasks) + " | "
                     + placed_per_slot("WindowInstallation-v1", result["tasks"]["WindowInstallation-v1"]["episode_results"]) + " | "
                     + _late_training(PROBE_DIR / f"{name}.csv") + " |")
    commands = "\n".join(f"- {name}: `{how}`, then `python -m experiments.probes --evaluate {name} --checkpoint <its checkpoint>` "
                         f"(`{EVAL}`)" for name, (_, how, _) in CONTINUATIONS.items())
    return (f"Command: `python -m experiments.probes` (from {PROBE_DIR}/*_eval.json).\n\n"
            "Each policy evaluated with the paper's protocol on the first 50 test seeds of each task (deterministic); "
            "placed with its Wilson 95% interval. Evaluated with each reset setting the nominal hold (a8d32d8): the "
            "evaluations before it read the last episode's hold in the offset observation.\n\n" + "\n".join(lines)
            + "\n\nHow each came to be:\n\n" + commands)


def _late_training(path: Path, window: int = 200_000) -> str:
    """The ordinary-reset training episodes of a run's last `window` env steps that placed, per task (its progress.csv
    at `path`: a probe's, or the campaign's rows over a control's steps); "-" for a start (no training of its own).
    Hundreds of episodes of the stochastic policy, where the evaluation has 50 of one checkpoint's mean."""
    if not path.is_file():
        return "-"
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    late = [r for r in rows if int(r["global_step"]) > int(rows[-1]["global_step"]) - window]
    episodes = sum(float(r["episodes"]) - float(r["near_goal_episodes"] or 0) for r in late)
    return " / ".join(_pct(_mean(late, f"ordinary_place_{k}")) for k in ("ceiling", "window", "flooring")) + f" ({episodes:,.0f})"


def evaluate_continuation(name: str, checkpoint: Path) -> None:
    """`EVAL` of `checkpoint` into PROBE_DIR/<name>_eval.json, with the env steps it trained since the start."""
    import json
    import subprocess
    import sys

    from baselines.ppo.checkpoints import load_checkpoint

    if name not in CONTINUATIONS:
        raise SystemExit(f"--evaluate {name}: one of {', '.join(CONTINUATIONS)}")
    out = PROBE_DIR / f"{name}_eval.json"
    subprocess.run([sys.executable, *shlex.split(EVAL)[1:], "--checkpoint", str(checkpoint), "--json", str(out)], check=True)
    result = json.loads(out.read_text())
    result["global_step"] = int(load_checkpoint(checkpoint)["progress"]["global_step"])
    start = CONTINUATIONS[name][2]
    if start in STARTS:  # a probe counts from 0 again: after its start's steps
        result["global_step"] += int(load_checkpoint(Path(STARTS[start][0]))["progress"]["global_step"])
    elif start is not None:  # a probe that went on from another's end: after that one's, as its evaluation counted them
        result["global_step"] += json.loads((PROBE_DIR / f"{start}_eval.json").read_text())["global_step"]
    out.write_text(json.dumps(result, indent=1))


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
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--evaluate", metavar="NAME", help=f"evaluate a continuation ({', '.join(CONTINUATIONS)}) and exit")
    parser.add_argument("--checkpoint", type=Path, help="with --evaluate: its checkpoint")
    cli = parser.parse_args()
    if cli.evaluate:
        if cli.checkpoint is None:
            raise SystemExit("--evaluate: give its --checkpoint")
        evaluate_continuation(cli.evaluate, cli.checkpoint)
        raise SystemExit(0)
    update_section(PAGE, "from-scratch-probes", table(), "Learning from reward alone: the experiment")
    update_section(PAGE, "from-scratch-continuations", continuation_table(), "Learning from reward alone: the experiment")
    print(f"wrote the probe table to {PAGE}")
