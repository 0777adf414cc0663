"""The paper's question (experiments/curriculum_question.py): its two arms are the from-scratch recipe and differ
only in Table I's curriculum, the curriculum arm moves on by step count alone, and the report reads the committed
evaluations back into a Table II-shaped comparison, the curves and the snapshots' table."""

import csv
import dataclasses
import json

import pytest

from baselines.ppo import ppo
from baselines.ppo.checkpoints import CSV_FIELDS, Progress
from experiments import curriculum_question as cq
from experiments.from_scratch import scratch_args
from ms_construction.envs import PAPER_TASK_ENV_IDS


def test_the_two_arms_are_the_from_scratch_recipe_and_differ_only_in_the_curriculum():
    cp4, curriculum = cq.question_runs(num_envs=2)
    for run in (cp4, curriculum):
        ppo.validate(run.args)
    assert cp4.args.stages.curriculum == ("cp4",)
    assert curriculum.args.stages.curriculum == ("cp1", "cp2", "cp3", "cp4")
    a, b, recipe = cp4.args.flat(), curriculum.args.flat(), scratch_args(2).flat()
    assert {k for k in a if a[k] != b[k]} == {"exp_name", "curriculum", "promote_success"}
    # apart from its name, length and stage length, the cp4 arm is the recipe the from-scratch campaign runs now
    assert {k for k in a if a[k] != recipe[k]} == {"exp_name", "total_timesteps", "stage_timesteps"}
    assert a["total_timesteps"] == b["total_timesteps"] == cq.BUDGET and a["stage_timesteps"] == cq.STAGE_STEPS
    assert a["seed"] == b["seed"] and a["demos"] == () and a["checkpoint"] is None


@pytest.mark.parametrize("steps", [3 * cq.STAGE_STEPS, cq.BUDGET + 1])
def test_a_budget_that_does_not_fit_the_stages_is_refused_with_what_is_allowed(steps):
    with pytest.raises(SystemExit, match=f"multiple of {cq.STAGE_STEPS:,} of at least {4 * cq.STAGE_STEPS:,}"):
        cq.question_runs(steps)


def test_the_curriculum_arm_moves_on_after_its_stage_s_steps_whatever_it_places():
    _, run = cq.question_runs(num_envs=2)
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


def test_the_report_compares_the_arms_at_cp4_beside_the_paper_s_rows(tmp_path, monkeypatch):
    """From the committed evaluations and CSVs alone (a fresh machine: no snapshots)."""
    data = tmp_path / "data"
    data.mkdir()
    monkeypatch.setattr(cq, "DATA", data)
    monkeypatch.setattr(cq, "SNAPSHOT_DIR", tmp_path / "snapshots")
    monkeypatch.setattr(cq, "CURVE", tmp_path / "images" / "curve.png")
    monkeypatch.setattr(cq, "PAGE", tmp_path / "page.md")
    runs = [dataclasses.replace(r, args=r.args.replace(log_dir=str(tmp_path / "campaign")))
            for r in cq.question_runs(num_envs=2)]
    for run, place in zip(runs, (0.25, 0.5)):
        for step in range(cq.STAGE_STEPS, cq.BUDGET + 1, cq.STAGE_STEPS):
            (data / f"{run.name}_val{cq.VALIDATION_EPISODES}_{step}.json").write_text(json.dumps(_evaluation(place)))
        (data / f"{run.name}_eval50k_{cq.BUDGET}.json").write_text(json.dumps(_evaluation(place)))
        csv_path = tmp_path / "campaign" / run.name / "progress.csv"
        csv_path.parent.mkdir(parents=True)
        with open(csv_path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
            w.writeheader()
            for i in range(1, 31):
                w.writerow(dict(global_step=2000 * i, iteration=i, stage="cp1", ordinary_place_ceiling=place,
                                ordinary_place_window="", ordinary_place_flooring=0.0, near_goal_place_success=place,
                                near_goal_radius_ceiling=0.1, near_goal_radius_window=0.2,
                                near_goal_radius_flooring=min(1.0, 0.1 * (1 + i // 3))))
    results = tmp_path / "RESULTS.md"
    body = cq.report(runs, results)
    page = (tmp_path / "page.md").read_text()
    rows = [line for line in body.splitlines() if line.startswith(("| question_cp4: ", "| question_curriculum: "))]
    assert len(rows) == 2
    assert rows[0].startswith("| question_cp4: ") and f"| {cq.BUDGET:,} | 100.0 / 25.0 [12.5, 25.0] |" in rows[0]
    assert rows[1].startswith("| question_curriculum: ") and "| 100.0 / 50.0 [25.0, 50.0] |" in rows[1]
    assert "| the paper's general agent: cp1 -> cp4, 2M steps each (Table II) | 8,000,000 | 84.55 / 68.04 |" in body
    # where training stood: the radii of the last row, the last 25 iterations' placing (no window episode ended)
    for arm, placed in (("question_cp4", "25.0"), ("question_curriculum", "50.0")):
        row = f"| {arm} | 60,000 | cp1 | 0.1 / 0.2 / 1.0 | not yet / not yet / 54,000 | {placed} | {placed} / - / 0.0 |"
        assert row in page and row not in body  # on the experiment page; RESULTS keeps the comparison
    assert "<!-- begin curriculum-question (generated) -->" in results.read_text()
    assert f"| {cq.STAGE_STEPS:,} | cp1 (its end) | 25 / 25 / 25 | 50 / 50 / 50 |" in page
    assert f"| {cq.BUDGET:,} | cp4 | 25 / 25 / 25 | 50 / 50 / 50 |" in page
    assert (tmp_path / "images" / "curve.png").stat().st_size > 0


def test_an_arm_not_yet_at_its_budget_says_where_it_stands_and_how_it_goes_on(tmp_path, monkeypatch):
    monkeypatch.setattr(cq, "DATA", tmp_path / "data")
    monkeypatch.setattr(cq, "SNAPSHOT_DIR", tmp_path / "snapshots")
    monkeypatch.setattr(cq, "CURVE", tmp_path / "curve.png")
    monkeypatch.setattr(cq, "PAGE", tmp_path / "page.md")
    runs = [dataclasses.replace(r, args=r.args.replace(log_dir=str(tmp_path / "campaign")))
            for r in cq.question_runs(num_envs=2)]
    body = cq.report(runs, tmp_path / "RESULTS.md")
    assert f"| 0 of {cq.BUDGET:,} (not evaluated: `{cq.COMMAND} --runs question_cp4` goes on) |" in body


def test_an_unknown_arm_is_refused_with_the_arms_there_are():
    with pytest.raises(SystemExit, match="--runs question_cp3: use among question_cp4, question_curriculum"):
        cq.main(cq.Args(runs=("question_cp3",), dry_run=True))
