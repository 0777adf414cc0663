"""The paper's question (experiments/curriculum_question.py): per learner and seed, its cp4 arm is the recipe's own run
and its curriculum arm the same recipe through Table I's stages, moving on by step count alone; the report reads the
committed evaluations back into a Table II-shaped comparison, the curves and the snapshots' table."""

import csv
import dataclasses
import json

import pytest

from baselines.ppo import ppo
from baselines.ppo.checkpoints import CSV_FIELDS, Progress
from baselines.sac import sac
from experiments import curriculum_question as cq
from experiments import from_scratch as fs
from experiments.campaign import checkpoint_of, describe
from ms_construction.envs import PAPER_TASK_ENV_IDS


def test_the_two_arms_are_the_recipe_s_run_and_the_recipe_through_table_i_s_stages():
    ppo_plan, sac_plan = cq.PLANS["ppo"], cq.PLANS["sac"]
    arms = cq.question_runs(2, num_envs=2, learner="ppo")
    cp4, curriculum = arms["cp4"], arms["curriculum"]
    for run in arms.values():
        ppo.validate(run.args)
    assert cp4 == fs.seed_run(2, num_envs=2, learner="ppo"), "the cp4 arm is the seed's run of the recipe itself"
    assert curriculum.args.stages.curriculum == ("cp1", "cp2", "cp3", "cp4")
    a, b = cp4.args.flat(), curriculum.args.flat()
    assert {k for k in a if a[k] != b[k]} == {"exp_name", "curriculum", "promote_success", "total_timesteps",
                                              "stage_timesteps"}
    assert b["total_timesteps"] == ppo_plan.budget and b["stage_timesteps"] == ppo_plan.stage_steps and b["seed"] == 2
    assert ppo_plan.budget in fs.EVALUATE_AT, "the recipe's run evaluates its snapshot where the question compares"
    assert ppo_plan.budget % fs.SNAPSHOT_EVERY == 0 and ppo_plan.stage_steps % fs.SNAPSHOT_EVERY == 0

    arms = cq.question_runs(2, num_envs=2)  # SAC, the recipe's learner, by default
    cp4, curriculum = arms["cp4"], arms["curriculum"]
    for run in arms.values():
        sac.validate(run.args)
    assert cp4 == fs.seed_run(2, num_envs=2, learner="sac")
    a, b = dataclasses.asdict(cp4.args), dataclasses.asdict(curriculum.args)
    assert {k for k in a if a[k] != b[k]} == {"exp_name", "curriculum", "stage_timesteps", "total_timesteps"}
    assert b["curriculum"] == ("cp1", "cp2", "cp3", "cp4") and b["total_timesteps"] == 4 * sac_plan.stage_steps
    assert sac_plan.budget % fs.SNAPSHOT_EVERY == 0, "the recipe's SAC run has a snapshot at the budget"
    assert "stages cp1 cp2 cp3 cp4 (125,000 env steps each), 500,000 env steps" in describe(curriculum)
    assert "stages" not in describe(cp4)
    for seed in fs.SEEDS:  # and its evaluation with the paper's protocol there, committed
        assert cq.evaluation_json("cp4", seed).is_file()


def test_the_curriculum_arm_moves_on_after_its_stage_s_steps_whatever_it_places():
    plan = cq.PLANS["ppo"]
    run = cq.curriculum_run(1, num_envs=2, learner="ppo")
    for success in (None, 0.0, 1.0):  # a perfect record does not promote early: by step count alone, as the paper's
        before = Progress(global_step=plan.stage_steps - 2000, stage_start_step=0, smoothed_success=success)
        assert ppo.should_promote(run.args, before) is None
        at = dataclasses.replace(before, global_step=plan.stage_steps)
        assert ppo.should_promote(run.args, at) == "steps"
    last = Progress(global_step=plan.budget, stage_index=3, stage_start_step=3 * plan.stage_steps,
                    smoothed_success=1.0)
    assert ppo.should_promote(run.args, last) is None  # cp4 runs to the end
    sac_args, step = cq.curriculum_run(1).args, cq.PLANS["sac"].stage_steps
    assert [sac.stage_at(sac_args, s) for s in (0, step - 2, step, 3 * step, cq.PLANS["sac"].budget)] == [
        "cp1", "cp1", "cp2", "cp4", "cp4"]


def _evaluation(place: float) -> dict:
    return {"tasks": {env_id: {"pick_success": 1.0, "place_success": place, "place_success_ci95": [place / 2, place]}
                      for env_id in PAPER_TASK_ENV_IDS.values()}}


def test_the_report_compares_the_arms_at_cp4_per_learner_and_seed_beside_the_paper_s_rows(tmp_path, monkeypatch):
    """From the committed evaluations and CSVs alone (a fresh machine: no snapshots); a seed whose arm is not at
    the budget yet says where it stands and how it goes on. The recipe's learner (SAC) first."""
    monkeypatch.setattr(cq, "DATA", tmp_path / "data")
    monkeypatch.setattr(cq, "PLANS", {learner: dataclasses.replace(plan, curve=tmp_path / "images" / f"{learner}.png")
                                      for learner, plan in cq.PLANS.items()})
    monkeypatch.setattr(cq, "PAGE", tmp_path / "page.md")
    monkeypatch.setattr(fs, "SEED_EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(fs, "CAMPAIGN_DIR", tmp_path / "campaign")
    monkeypatch.setattr(cq.sac_recipe, "CAMPAIGN_DIR", tmp_path / "campaign")
    for learner, plan in cq.PLANS.items():
        for arm, place, every in (("cp4", 0.25, fs.SNAPSHOT_EVERY), ("curriculum", 0.5, plan.every)):
            for path in [cq.validation_json(arm, 1, step, learner) for step in range(every, plan.budget + 1, every)] \
                    + [cq.evaluation_json(arm, 1, learner)]:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(_evaluation(place)))
            csv_path = checkpoint_of(cq.question_runs(1, learner=learner)[arm]).with_name("progress.csv")
            csv_path.parent.mkdir(parents=True)
            with open(csv_path, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
                w.writeheader()
                for i in range(1, 31):
                    w.writerow(dict(global_step=2000 * i, iteration=i, stage="cp1", ordinary_place_ceiling=place,
                                    ordinary_place_window="", ordinary_place_flooring=0.0))
    results = tmp_path / "RESULTS.md"
    body = cq.report(seeds=(1, 2), results=results)
    rows = [line for line in body.splitlines() if line.startswith(("| SAC |", "| PPO |"))]
    assert len(rows) == 8 and all(r.startswith("| SAC |") for r in rows[:4])
    assert rows[0].startswith("| SAC | 1 | cp4: SAC from nothing, seed 1 | 500,000 | 100.0 / 25.0 [12.5, 25.0] |")
    assert rows[1].startswith("| SAC | 1 | curriculum: SAC through Table I's stages, 125,000 env steps each, seed 1 | "
                              "500,000 | 100.0 / 50.0 [25.0, 50.0] |")
    assert rows[2].startswith("| SAC | 2 | cp4: SAC from nothing, seed 2 | 500,000 | not yet (0; "
                              "`python -m experiments.from_scratch --seed 2` goes on) |")
    assert f"`{cq.COMMAND} --seed 2` goes on" in rows[3]
    assert rows[4].startswith("| PPO | 1 | cp4: the PPO recipe from nothing, seed 1 | 3,000,000 | 100.0 / 25.0")
    assert "`python -m experiments.from_scratch --seed 2 --learner ppo` goes on" in rows[6]
    assert f"`{cq.COMMAND} --seed 2 --learner ppo` goes on" in rows[7]
    assert "| the paper | | general agent: cp1 -> cp4, 2M steps each (Table II) | 8,000,000 | 84.55 / 68.04 |" in body
    page = (tmp_path / "page.md").read_text()
    sac_part, ppo_part = page.split("\nSAC:\n")[1].split("\nPPO:\n")
    assert "| 1 | 125,000 | cp1 | - | 50 / 50 / 50 |" in sac_part, "the recipe's run keeps no snapshot there"
    assert "| 1 | 250,000 | cp2 | 25 / 25 / 25 | 50 / 50 / 50 |" in sac_part
    assert "| 1 | 500,000 | cp4 | 25 / 25 / 25 | 50 / 50 / 50 |" in sac_part
    assert "| 1 | 250,000 | cp1 | 25 / 25 / 25 | 50 / 50 / 50 |" in ppo_part
    assert "| 1 | 3,000,000 | cp4 | 25 / 25 / 25 | 50 / 50 / 50 |" in ppo_part
    assert "<!-- begin curriculum-question (generated) -->" in results.read_text()
    for learner in ("sac", "ppo"):
        assert (tmp_path / "images" / f"{learner}.png").stat().st_size > 0 and f"images/{learner}.png" in body


def test_the_curriculum_arm_screens_each_snapshot_and_evaluates_the_one_at_its_budget(tmp_path, monkeypatch):
    monkeypatch.setattr(cq, "DATA", tmp_path / "data")
    validated, evaluated = [], []
    monkeypatch.setattr(cq, "validate", lambda path, out, episodes: validated.append((path.name, out.name, episodes)))
    monkeypatch.setattr(cq.evaluation, "main", lambda args: evaluated.append((args.checkpoint.name, args.steps)))
    budget = cq.PLANS["sac"].budget
    cq.screen(1, 125_000, tmp_path / "checkpoint_a.pt")
    cq.screen(1, budget, tmp_path / "checkpoint_b.pt")
    cq.screen(1, cq.PLANS["ppo"].budget, tmp_path / "checkpoint_c.pt", learner="ppo")
    assert validated == [("checkpoint_a.pt", "question_curriculum_sac_s1_val30_125000.json", 30),
                         ("checkpoint_b.pt", f"question_curriculum_sac_s1_val30_{budget}.json", 30),
                         ("checkpoint_c.pt", "question_curriculum_s1_val30_3000000.json", 30)]
    assert evaluated == [("checkpoint_b.pt", cq.PAPER_STEPS), ("checkpoint_c.pt", cq.PAPER_STEPS)]


def test_a_seed_is_asked_for():
    with pytest.raises(SystemExit, match="--seed S"):
        cq.main(cq.Args())


def test_an_unknown_learner_is_refused():
    with pytest.raises(SystemExit, match="--learner td3: use one of sac, ppo"):
        cq.main(cq.Args(seed=1, learner="td3"))
