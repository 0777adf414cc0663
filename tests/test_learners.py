"""experiments/learners.py: SAC and the recipe with curiosity against the recipe's own PPO run, at equal env steps
and equal wall time, read from each arm's progress.csv."""

import csv
import json

import numpy as np
import pytest
import torch

from baselines.ppo import ppo
from baselines.ppo.checkpoints import load_checkpoint
from experiments import from_scratch
from experiments import learners as ln


def _write(path, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _rows(n, placed, wall=None):
    """n rows of 2,000 env steps: PPO's (500 env steps/s) or, with `wall` seconds of training per row, SAC's (a
    quarter simulating, the rest updating; its evaluations' seconds, in wall_s only, are not training)."""
    rows = []
    for i in range(n):
        row = dict(global_step=2000 * (i + 1), sps=500.0, ordinary_place_ceiling=placed(i),
                   ordinary_place_window=placed(i) + 0.1, ordinary_place_flooring=1.0)
        if wall is not None:
            row.update(env_s=0.25 * wall * (i + 1), update_s=0.75 * wall * (i + 1), wall_s=1.5 * wall * (i + 1))
        rows.append(row)
    return rows


def test_the_curve_takes_each_arm_s_wall_time_and_the_worst_task_type(tmp_path):
    ppo_csv, sac_csv = tmp_path / "ppo.csv", tmp_path / "sac.csv"
    _write(ppo_csv, _rows(100, lambda i: 0.5))
    _write(sac_csv, _rows(100, lambda i: 0.5, wall=20.0))
    p, s = ln.curve(ppo_csv), ln.curve(sac_csv)
    assert np.allclose(p["hours"][-1], 100 * 4.0 / 3600) and np.allclose(s["hours"][-1], 100 * 20.0 / 3600)
    assert np.allclose(p["worst"], 0.5) and np.allclose(s["worst"], 0.5)  # ceiling's, the worst of the three
    assert ln.value_at(p, "steps", 100_000) == 0.5 and ln.value_at(p, "steps", 300_000) is None


def test_the_report_rows_each_arm_and_says_how_to_run_those_not_run(tmp_path, monkeypatch):
    monkeypatch.setattr(ln, "CURVES", tmp_path / "images" / "learners.png")
    monkeypatch.setattr(from_scratch, "SEED_EVAL_DIR", tmp_path / "from_scratch")
    log_dir = tmp_path / "campaign"
    # the PPO arm: nothing placed for 60 rows of 2,000 env steps (4 s each), then 90% of its worst task
    _write(ln.progress_csv("ppo", log_dir), _rows(100, lambda i: 0.0 if i < 60 else 0.9))
    body = ln.report(tmp_path / "RESULTS.md", log_dir=log_dir, eval_dir=tmp_path / "learners", page=tmp_path / "page.md")
    row = next(line for line in body.splitlines() if line.startswith("| PPO (the recipe"))
    # its worst task's mean over the last 50 rows (100,000 env steps) first reaches 50% 28 rows after the jump: at
    # 176,000 env steps, 88 rows of 4 s; 90% it would reach only 50 rows after the jump, beyond the run
    assert row.startswith("| PPO (the recipe's run) | 1 | 200,000 / 2,000,000 | 0.1 | - / - | - / - / - |")  # 0.1 h: short of 0.5
    # each task's mean over its last 50 rows (100,000 env steps), 40 of them after the jump: ceiling 0.9 x 40 / 50,
    # window (0.1 x 10 + 1.0 x 40) / 50, flooring 1.0
    assert row.endswith("| 176,000 / - | 0.1 / - | 72% / 82% / 100% | not evaluated |")
    assert "None yet." in (tmp_path / "page.md").read_text(), "no evaluation: the page's table says so"
    # each planned run not yet run says how: the SAC and PPO arms are the recipe's runs (SAC its learner)
    for seed, command in ((2, f"{from_scratch.COMMAND} --seed 2 --learner ppo"), (1, f"{from_scratch.COMMAND} --seed 1"),
                          (2, f"{from_scratch.COMMAND} --seed 2"), (1, f"{ln.COMMAND} --arm icm --seed 1"),
                          (1, f"{ln.COMMAND} --arm sac_utd --seed 1"), (2, f"{ln.COMMAND} --arm sac_utd --seed 2")):
        assert f"| {seed} | not run: `{command}` |" in body
    assert "--arm icm --seed 2" not in body, "curiosity is one probe, on seed 1"
    assert (tmp_path / "images" / "learners.png").stat().st_size > 0
    assert "refilled" not in body
    sac_checkpoint = ln.arm_checkpoint("sac", log_dir, seed=2)
    sac_checkpoint.parent.mkdir(parents=True)
    torch.save({"clock": {"refilled_at": [1_250_000]}}, sac_checkpoint)  # the part of a SAC checkpoint read here
    body = ln.report(tmp_path / "RESULTS.md", log_dir=log_dir, eval_dir=tmp_path / "learners", page=tmp_path / "page.md")
    assert "SAC seed 2's replay buffer was lost between sessions and refilled by its actor at 1,250,000 env steps" \
        in body, "an inexact resume is said"


def test_an_unknown_arm_is_refused_and_the_icm_arm_is_the_recipe_with_curiosity(tmp_path):
    for arm in ("ppo", "sac"):  # the recipe's runs: experiments/from_scratch.py runs them
        with pytest.raises(SystemExit, match="use icm or sac_utd .the SAC and PPO arms are the recipe's runs: `python -m "
                                             "experiments.from_scratch --seed 1` with SAC"):
            ln.main(ln.Args(arm=arm))
    with pytest.raises(SystemExit, match="--seed 3: use one of 1, 2"):
        ln.main(ln.Args(arm="icm", seed=3))
    run = ln.icm_run(num_envs=2)
    recipe = from_scratch.scratch_args(2, seed=1)
    changed = {k for k, v in vars(run.args).items() if v != vars(recipe)[k]}
    assert changed == {"icm", "total_timesteps", "exp_name"} and run.args.icm.curiosity == "icm"
    tiny = run.args.replace(total_timesteps=40, num_steps=20, num_minibatches=2, update_epochs=1, num_eval_envs=1,
                            log_dir=str(tmp_path), checkpoint_freq=1)
    ppo.main(tiny)
    trained = load_checkpoint(tmp_path / run.args.exp_name / "checkpoint.pt")
    assert trained["icm"] is not None and trained["progress"]["global_step"] == 40


def test_the_update_ratio_arm_is_the_recipe_s_sac_with_half_its_gradient_steps(tmp_path, monkeypatch):
    a, recipe = ln.sac_utd_args(1), ln.sac_args(1)
    changed = {k for k, v in vars(a).items() if v != vars(recipe)[k]}
    assert changed == {"utd", "total_timesteps", "exp_name"}
    assert a.utd == recipe.utd / 2 and a.total_timesteps == ln.PROBE_BUDGET
    assert ln.progress_csv("sac_utd", tmp_path) == tmp_path / "sac_utd025_s1" / "progress.csv"
    ran = []
    monkeypatch.setattr(ln, "run_sac", ran.append)
    ln.main(ln.Args(arm="sac_utd", dry_run=True))
    assert ran == [], "a dry run runs nothing"
    ln.main(ln.Args(arm="sac_utd"))
    assert ran == [a], "the probe runs (or resumes) as the recipe's SAC runs do"


def test_the_update_ratio_probe_is_judged_by_its_own_clock_against_the_recipe_s_env_steps(tmp_path):
    """Its env steps 2 ms each and its gradient steps 12 ms each: 2 + 0.25 x 12 = 5 ms an env step against the
    recipe's 2 + 0.5 x 12 = 8 ms, 1.6x; it reached 90% 100 rows (200,000 env steps) in, the recipe's run at 100,000."""
    rows = _rows(150, lambda i: 0.0 if i < 50 else 0.95)
    for i, row in enumerate(rows):
        row.update(env_s=0.002 * row["global_step"], updates=0.25 * row["global_step"],
                   update_s=0.012 * 0.25 * row["global_step"])
    _write(tmp_path / "probe.csv", rows)
    recipe = _rows(150, lambda i: 0.0 if i < 25 else 0.95, wall=8.0)
    _write(tmp_path / "recipe.csv", recipe)
    sentence = ln.update_ratio_sentence(tmp_path / "probe.csv", ln.curve(tmp_path / "recipe.csv", until=None), seed=2)
    assert sentence.startswith("The update-ratio probe's own clock on seed 2 (300,000 env steps)")
    assert "its env steps took 2.00 ms per env step and a gradient step 12.0 ms" in sentence
    assert "costs 5.00 ms at 0.25 gradient steps per env step against 8.00 ms at the recipe's 0.5 (1.60x)" in sentence
    # the worst task's mean over 50 rows crosses 90% 48 rows after the jump (0.95 x 48 / 50 = 0.912)
    assert sentence.endswith("it reached 90% at 196,000 env steps, the recipe's run on its seed at 146,000 (1.34x).")
    assert ln.update_ratio_sentence(tmp_path / "probe.csv", None).endswith("it reached 90% at 196,000 env steps.")


def test_each_paper_protocol_evaluation_is_rowed_with_its_wall_time_and_whether_it_meets_the_target(tmp_path,
                                                                                                   monkeypatch):
    """The evaluations table: `--evaluate icm --seed S` writes EVAL_DIR/icm_s<seed>_eval50k.json as
    scripts/evaluate.py --all does, with the env steps its checkpoint had trained; the SAC and PPO arms' are the
    recipe's snapshot evaluations (experiments/from_scratch.py). Each row has the training wall time its run had taken by
    then and whether every task met the target (placed >= 90%, picked >= 95%); nothing where none is."""
    monkeypatch.setattr(from_scratch, "SEED_EVAL_DIR", tmp_path / "from_scratch")
    log_dir = tmp_path / "campaign"
    assert ln.evaluations_table(tmp_path, log_dir) == []

    def tasks(placed, picked=1.0):
        return {env_id: {"place_success": p, "place_success_ci95": [p - 0.05, p], "pick_success": picked}
                for env_id, p in zip(("CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1"), placed)}

    (tmp_path / "from_scratch").mkdir()
    from_scratch.seed_evaluation_json(2, 350_000, "sac").write_text(json.dumps({"tasks": tasks((0.9, 0.95, 1.0))}))
    _write(ln.progress_csv("sac", log_dir, seed=2), _rows(200, lambda i: 0.5, wall=36.0))  # 2,000 env steps a row
    from_scratch.seed_evaluation_json(1, 3_000_000, "ppo").write_text(
        json.dumps({"tasks": tasks((0.99, 0.95, 0.99), picked=0.9)}))
    ln.eval_json("icm", 1, tmp_path).write_text(json.dumps({"tasks": tasks((0.5, 0.5, 0.5)), "checkpoint_step": 40}))
    table = "\n".join(ln.evaluations_table(tmp_path, log_dir))
    assert "| learner | seed | its env steps | its training wall time (h) | CeilingInstallation-v1: placed % [95% CI] |" \
        in table
    # its row at 350,000 env steps: the 175th of 36 s each
    assert "| SAC (replay, twin Q, tanh Gaussian, auto entropy) | 2 | 350,000 | 1.8 | 90.0 [85.0, 90.0] | " \
           "95.0 [90.0, 95.0] | 100.0 [95.0, 100.0] | yes |" in table
    assert "| PPO (the recipe's run) | 1 | 3,000,000 | - | 99.0 [94.0, 99.0] | 95.0 [90.0, 95.0] | 99.0 [94.0, 99.0] | " \
           "no |" in table, "picked 90%: short of the target; no progress.csv: no wall time"
    assert "| PPO + ICM (the recipe with curiosity) | 1 | 40 | - | 50.0 [45.0, 50.0] |" in table
    sac_curve = ln.curve(ln.progress_csv("sac", log_dir, seed=2), until=None)
    assert ln.first_met("sac", 2, sac_curve, tmp_path) == "350,000 (1.8 h)"
    assert ln.first_met("ppo", 1, None, tmp_path) == "none of 1" and ln.first_met("ppo", 2, None, tmp_path) == \
        "not evaluated"
    monkeypatch.setattr(ln, "CURVES", tmp_path / "images" / "learners.png")
    body = ln.report(tmp_path / "RESULTS.md", log_dir=log_dir, eval_dir=tmp_path, page=tmp_path / "page.md")
    assert "| 350,000 (1.8 h) |" in body and "yes |" not in body, "RESULTS: the first met, not every evaluation"
    assert table in (tmp_path / "page.md").read_text(), "every evaluation on the experiment's page"
    with pytest.raises(SystemExit, match="no checkpoint at .*--arm icm --seed 1"):
        ln.evaluate_arm("icm", log_dir=tmp_path)
    with pytest.raises(SystemExit, match="use one of ppo, icm, sac"):
        ln.evaluate_arm("td3", log_dir=tmp_path)
