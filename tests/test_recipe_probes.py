"""experiments/recipe_probes.py: each probe is the from-scratch recipe with only its named changes, and the report
tables what the probes' CSVs say (when each radius reached the whole path; ordinary picks and places)."""

import csv

import pytest

from baselines.ppo.checkpoints import CSV_FIELDS
from experiments import from_scratch as fs
from experiments import recipe_probes as rp


def test_each_probe_is_the_recipe_with_its_changes_alone():
    recipe = fs.scratch_args(2).flat()
    for name, (_, changes) in rp.PROBES.items():
        args = rp.probe_args(name).flat()
        differ = {k for k in recipe if args[k] != recipe[k]}
        assert differ == {"exp_name", "log_dir", "total_timesteps", "eval_freq"} | set(changes), (name, differ)
        assert args["total_timesteps"] == rp.PROBE_STEPS and args["seed"] == 1
    assert rp.PROBES["recipe"][1] == {}, "the recipe's own probe"
    with pytest.raises(SystemExit, match="without_reach_starts"):
        rp.probe_args("no_such_probe")


def test_the_table_says_when_each_radius_reached_the_path_and_what_ordinary_resets_did(tmp_path):
    with open(tmp_path / "recipe.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for i in range(1, 201):  # past the probes' length: the control's rows after it do not count
            w.writerow(dict(global_step=2000 * i, iteration=i, near_goal_place_success=0.5,
                            near_goal_radius_ceiling=1.0 if i >= 100 else 0.5, near_goal_radius_window=0.5,
                            near_goal_radius_flooring=1.0, ordinary_pick_ceiling=0.2 if i <= 150 else 1.0, ordinary_pick_window="",
                            ordinary_pick_flooring=0.5, ordinary_place_ceiling=0.0, ordinary_place_window="",
                            ordinary_place_flooring=0.1))
    body = rp.table(tmp_path)
    assert "grasped from their side | 300,000 | 200,000 / - / 2,000 | 20.0 / - / 50.0 | 0.0 / - / 10.0 | 50.0 |" in body
    assert "without_reach_starts" not in body.split("|---|")[-1], "a probe that has not run has no row"
