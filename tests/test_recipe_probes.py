"""experiments/recipe_probes.py: each probe is the from-scratch recipe with only its named changes, on a seed, and the
report tables what the probes' CSVs say (when each near-goal radius reached the whole path; how far the least-widened
reach-start radius came; ordinary picks and places), the recipe's own probes read from the recipe's runs."""

import csv

import pytest

from baselines.ppo.checkpoints import CSV_FIELDS
from experiments import from_scratch as fs
from experiments import recipe_probes as rp


def test_each_probe_is_the_recipe_with_its_changes_alone_on_its_seed():
    recipe = fs.scratch_args(2).flat()
    for name, (_, changes, steps) in rp.PROBES.items():
        args = rp.probe_args(name, seed=3).flat()
        differ = {k for k in recipe if args[k] != recipe[k]}
        assert differ == {"exp_name", "log_dir", "total_timesteps", "eval_freq", "seed"} | set(changes), (name, differ)
        assert args["total_timesteps"] == steps and args["seed"] == 3 and args["exp_name"] == f"{name}_s3"
    assert rp.PROBES["recipe"][1] == {}, "the recipe's own probe"
    with pytest.raises(SystemExit, match="the probes are without_reach_starts"):
        rp.run("no_such_probe", 1)


def test_the_recipes_own_probe_on_a_seed_with_a_recipe_run_is_not_run_again(tmp_path, monkeypatch):
    monkeypatch.setattr(rp, "CAMPAIGN_DIR", tmp_path)
    (tmp_path / "scratch_s2").mkdir()
    (tmp_path / "scratch_s2" / "progress.csv").write_text("global_step\n")
    with pytest.raises(SystemExit, match="holds this probe's steps"):
        rp.run("recipe_1m", 2)


def write_csv(path, rows):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)


def test_the_table_rows_each_probe_and_seed_with_what_its_csv_says(tmp_path):
    data, campaign = tmp_path / "data", tmp_path / "campaign"
    data.mkdir()
    (campaign / "scratch_s2").mkdir(parents=True)
    rows = []
    for i in range(1, 201):  # past the 300,000-step probes' length: the rows after it do not count
        rows.append(dict(global_step=2000 * i, iteration=i, near_goal_place_success=0.5,
                         near_goal_radius_ceiling=1.0 if i >= 100 else 0.5, near_goal_radius_window=0.5,
                         near_goal_radius_flooring=1.0, ordinary_pick_ceiling=0.2 if i <= 150 else 1.0,
                         ordinary_pick_window="", ordinary_pick_flooring=0.5, ordinary_place_ceiling=0.0,
                         ordinary_place_window="", ordinary_place_flooring=0.1,
                         **{f"reach_start_radius_{k}{s}": 0.1 * (s + 1) for k in ("ceiling", "window", "flooring")
                            for s in range(3)}))
    write_csv(data / "without_reach_starts_s1.csv", rows)
    write_csv(campaign / "scratch_s2" / "progress.csv", rows)  # the recipe's run on seed 2: its own probes
    write_csv(data / "recipe_s2.csv", rows[:10])  # a copy of a probe the recipe's run holds: the run wins
    write_csv(data / "recipe_1m_s3.csv", rows[:50])  # a probe whose name another's begins: only its own rows
    body = rp.table(data, campaign)
    radii = "0.1, 0.2, 0.3 / 0.1, 0.2, 0.3 / 0.1, 0.2, 0.3"
    assert (f"| 1 | 300,000 | 200,000 / - / 2,000 | {radii} | 20.0 / - / 50.0 | 0.0 / - / 10.0 | 50.0 |"
            in body.split("without_reach_starts:")[1].splitlines()[0])
    rows_of = {}
    for line in body.splitlines()[4:]:
        rows_of.setdefault(line.split(":")[0].lstrip("| "), []).append(line.split(" | ")[1:3])
    assert rows_of == {"without_reach_starts": [["1", "300,000"]], "recipe": [["2", "300,000"]],
                       "recipe_1m": [["2", "400,000"], ["3", "100,000"]]}
    assert f"| 2 | 400,000 | 200,000 / - / 2,000 | {radii} | 100.0 / - / 50.0 |" in body
