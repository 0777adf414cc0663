"""The paper's question (experiments/curriculum_question.py): per seed, its cp4 arm is the recipe's own run and its
curriculum arm the same recipe through Table I's stages, moving on by step count alone; the report reads the committed
evaluations back into a Table II-shaped comparison, the curves and the snapshots' table."""

import csv
import dataclasses
import json

import pytest

from baselines.ppo import ppo
from baselines.ppo.checkpoints import CSV_FIELDS, Progress
from experiments import curriculum_question as cq
from experiments import from_scratch as fs
from ms_construction.envs import PAPER_TASK_ENV_IDS


def test_the_two_arms_are_the_recipe_s_run_and_the_recipe_through_table_i_s_stages():
    arms = cq.question_runs(2, num_envs=2)
    cp4, curriculum = arms["cp4"], arms["curriculum"]
    for run in arms.values():
        ppo.validate(run.args)
    assert cp4 == fs.seed_run(2, num_envs=2, learner="ppo"), "the cp4 arm is the seed's run of the recipe itself"
    assert curriculum.args.stages.curriculum == ("cp1", "cp2", "cp3", "cp4")
    a, b = cp4.args.flat(), curriculum.args.flat()
    assert {k for k in a if a[k] != b[k]} == {"exp_name", "curriculum", "promote_success", "total_timesteps",
                                              "stage_timesteps"}
    assert b["total_timesteps"] == cq.BUDGET and b["stage_timesteps"] == cq.STAGE_STEPS and b["seed"] == 2
    assert cq.BUDGET in fs.EVALUATE_AT, "the recipe's run evaluates its snapshot where the question compares"
    assert cq.BUDGET % fs.SNAPSHOT_EVERY == 0 and cq.STAGE_STEPS % fs.SNAPSHOT_EVERY == 0


def test_the_curriculum_arm_moves_on_after_its_stage_s_steps_whatever_it_places():
    run = cq.curriculum_run(1, num_envs=2)
    for success in (None, 0.0, 1.0):  # a perfect record does not promote early: by step count alone, as the paper's
        before = Progress(global_step=cq.STAGE_STEPS - 2000, stage_start_step=0, smoothed_success=success)
        assert ppo.should_promote(run.args, before) is None
        at = dataclasses.replace(before, global_step=cq.STAGE_STEPS)
        assert ppo.should_promote(run.args, at) == "steps"
    last = Progress(global_step=cq.BUDGET, stage_index=3, stage_start_step=3 * cq.STAGE_STEPS, smoothed_success=1.0)
    assert ppo.should_promote(run.args, last) is None  # cp4 runs to the end


def _evaluation(place: float) -> dict:
    return {"tasks": {env_id: {"pick_success": 1.0, "place_success": place, "place_success_ci95": [place / 2, place]}
                      for env_id in PAPER_TASK_ENV_IDS.values()}}


def test_the_report_compares_the_arms_at_cp4_per_seed_beside_the_paper_s_rows(tmp_path, monkeypatch):
    """From the committed evaluations and CSVs alone (a fresh machine: no snapshots); a seed whose arm is not at
    the budget yet says where it stands and how it goes on."""
    monkeypatch.setattr(cq, "DATA", tmp_path / "data")
    monkeypatch.setattr(cq, "CURVE", tmp_path / "images" / "curve.png")
    monkeypatch.setattr(cq, "PAGE", tmp_path / "page.md")
    monkeypatch.setattr(fs, "SEED_EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(fs, "CAMPAIGN_DIR", tmp_path / "campaign")
    for arm, place in (("cp4", 0.25), ("curriculum", 0.5)):
        for step in range(fs.SNAPSHOT_EVERY, cq.BUDGET + 1, fs.SNAPSHOT_EVERY):
            cq.validation_json(arm, 1, step).parent.mkdir(parents=True, exist_ok=True)
            cq.validation_json(arm, 1, step).write_text(json.dumps(_evaluation(place)))
        cq.evaluation_json(arm, 1).parent.mkdir(parents=True, exist_ok=True)
        cq.evaluation_json(arm, 1).write_text(json.dumps(_evaluation(place)))
        csv_path = tmp_path / "campaign" / cq.question_runs(1)[arm].name / "progress.csv"
        csv_path.parent.mkdir(parents=True)
        with open(csv_path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
            w.writeheader()
            for i in range(1, 31):
                w.writerow(dict(global_step=2000 * i, iteration=i, stage="cp1", ordinary_place_ceiling=place,
                                ordinary_place_window="", ordinary_place_flooring=0.0))
    results = tmp_path / "RESULTS.md"
    body = cq.report(seeds=(1, 2), results=results)
    rows = [line for line in body.splitlines() if line.startswith(("| 1 |", "| 2 |"))]
    assert rows[0].startswith("| 1 | cp4: the PPO recipe from nothing, seed 1 | 100.0 / 25.0 [12.5, 25.0] |")
    assert rows[1].startswith("| 1 | curriculum: the recipe through Table I's stages") and "| 100.0 / 50.0 [25.0, 50.0] |" in rows[1]
    assert f"| 2 | cp4: the PPO recipe from nothing, seed 2 | not yet at {cq.BUDGET:,} env steps (0; " \
           "`python -m experiments.from_scratch --seed 2 --learner ppo` goes on) |" in body
    assert f"`{cq.COMMAND} --seed 2` goes on" in rows[3]
    assert "| the paper | general agent: cp1 -> cp4, 2M steps each (Table II), 8M env steps | 84.55 / 68.04 |" in body
    page = (tmp_path / "page.md").read_text()
    assert f"| 1 | {fs.SNAPSHOT_EVERY:,} | cp1 | 25 / 25 / 25 | 50 / 50 / 50 |" in page
    assert f"| 1 | {cq.BUDGET:,} | cp4 | 25 / 25 / 25 | 50 / 50 / 50 |" in page
    assert "<!-- begin curriculum-question (generated) -->" in results.read_text()
    assert (tmp_path / "images" / "curve.png").stat().st_size > 0


def test_the_curriculum_arm_screens_each_snapshot_and_evaluates_the_one_at_its_budget(tmp_path, monkeypatch):
    monkeypatch.setattr(cq, "DATA", tmp_path / "data")
    validated, evaluated = [], []
    monkeypatch.setattr(cq, "validate", lambda path, out, episodes: validated.append((path.name, out.name, episodes)))
    monkeypatch.setattr(cq.evaluation, "main", lambda args: evaluated.append((args.checkpoint.name, args.steps)))
    cq.screen(1, fs.SNAPSHOT_EVERY, tmp_path / "checkpoint_a.pt")
    cq.screen(1, cq.BUDGET, tmp_path / "checkpoint_b.pt")
    assert validated == [("checkpoint_a.pt", f"question_curriculum_s1_val30_{fs.SNAPSHOT_EVERY}.json", 30),
                         ("checkpoint_b.pt", f"question_curriculum_s1_val30_{cq.BUDGET}.json", 30)]
    assert evaluated == [("checkpoint_b.pt", cq.PAPER_STEPS)]


def test_a_seed_is_asked_for():
    with pytest.raises(SystemExit, match="--seed S"):
        cq.main(cq.Args())
