"""The paper's experiment: the run plans (stages, budgets, env ids, promotion by steps) and resuming
a campaign run from its checkpoint."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from baselines.ppo import evaluation
from experiments import campaign
from experiments import paper as ps
from baselines.ppo import ppo

ROOT = Path(__file__).resolve().parents[1]


def test_the_general_agent_runs_the_four_table_i_stages_of_exactly_2m_steps_promoted_by_steps_only():
    general, no_curiosity = ps.general_runs(num_envs=2)
    a = general.args
    assert a.env_id == "ConstructionPickPlace-v1" and a.reward_mode == "sparse" and a.icm.curiosity == "icm"
    assert a.stages.curriculum == ("cp1", "cp2", "cp3", "cp4") and a.stages.stage_timesteps == 2_000_000 and a.total_timesteps == 8_000_000
    assert a.icm.icm_strength == 0.02 and a.stages.stage_schedules
    assert a.num_envs * a.num_steps == ps.UPDATE_SAMPLES and a.stages.stage_timesteps % ps.UPDATE_SAMPLES == 0
    # promotion at exactly 2M steps whatever the success, never before
    assert ppo.should_promote(a, ppo.Progress(global_step=1_990_000, smoothed_success=1.0)) is None
    assert ppo.should_promote(a, ppo.Progress(global_step=2_000_000, smoothed_success=0.0)) == "steps"
    b = no_curiosity.args
    assert b.icm.curiosity == "none" and b.stages.curriculum == ("cp1",) and b.total_timesteps == 2_000_000 and b.seed == a.seed
    assert general.shipped == campaign.SHIPPED_DIR / "paper_general_agent.pt" and no_curiosity.shipped is None
    assert b.replace(curiosity="icm", curriculum=a.stages.curriculum, total_timesteps=a.total_timesteps,
                     exp_name=a.exp_name) == a, "the ablation differs from run 1 in curiosity and length only"


@pytest.mark.parametrize("total, stages", [(2_000_000, 1), (8_000_000, 4)])
def test_control_groups_are_single_task_cp4_runs_in_2m_step_stages(total, stages):
    runs = ps.control_group_runs(total, num_envs=2)
    assert [r.args.env_id for r in runs] == ["CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1"]
    assert [r.what.split(":")[0] for r in runs] == ["controlGroup4.1", "controlGroup4.2", "controlGroup4.3"]
    general = ps.general_runs(num_envs=2)[0].args
    for r in runs:
        assert r.args.stages.curriculum == ("cp4",) * stages and r.args.total_timesteps == total
        same = set(ppo.Args().flat()) - {"env_id", "curriculum", "total_timesteps", "exp_name"}
        assert all(r.args.flat()[k] == general.flat()[k] for k in same), "otherwise the paper setting"
    # the 2M point and the 8M point are published both, each in its own file
    suffix = "" if total == 2_000_000 else "_8m"
    assert [r.shipped.name for r in runs] == [f"control_{k}{suffix}.pt" for k in ("ceiling", "window", "flooring")]
    with pytest.raises(SystemExit, match="multiple of 2000000"):
        ps.control_group_runs(3_000_000)


def test_an_env_count_that_does_not_divide_the_update_is_refused():
    with pytest.raises(SystemExit, match="--num-envs 3"):
        ps.paper_args(num_envs=3)


def test_dry_runs_print_the_plans():
    for flags, names in [((), ["paper_general_agent", "paper_cp1_no_curiosity"]),
                         (("--control-groups",), ["control_ceiling", "control_window", "control_flooring"])]:
        res = subprocess.run([sys.executable, "-m", "experiments.paper", *flags, "--dry-run", "--num-envs", "2"],
                             capture_output=True, text=True, timeout=300, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert res.returncode == 0, res.stderr
        for name in names:
            assert name in res.stdout
        assert "2,000,000 steps each" in res.stdout


def test_a_campaign_run_resumes_from_its_checkpoint_with_its_step_count_and_stage_and_ships_at_its_end(tmp_path):
    """A tiny paper-setting run (two stages of 80 steps) stopped after its first stage, as a session's
    end leaves it, continues from the checkpoint to the end of its plan: same stage, same step count.
    Only then is its policy shipped, with its campaign record, and scripts/evaluate.py runs it."""
    small = dict(num_envs=2, num_steps=20, num_minibatches=2, num_eval_envs=1, eval_freq=100, checkpoint_freq=1,
                 env_id="Flooring-v1", log_dir=str(tmp_path), exp_name="tiny", stage_timesteps=80,
                 curriculum=("cp1", "cp2"), total_timesteps=80)
    run = campaign.Run("tiny", ps.paper_args(**small), "test", "python tiny.py")
    campaign.run_or_resume(run)
    ckpt = campaign.checkpoint_of(run)
    first = torch.load(ckpt, weights_only=False)
    assert first["progress"]["global_step"] == 80
    shipped = tmp_path / "assets" / "tiny.pt"
    planned = campaign.Run("tiny", run.args.replace(total_timesteps=160), "test", "python tiny.py", shipped)
    assert "resumes at step 80" in campaign.describe(planned) and str(shipped) in campaign.describe(planned)
    with pytest.raises(SystemExit, match="at step 80 of 160"):
        campaign.ship(planned)
    campaign.run_or_resume(planned)
    last = torch.load(ckpt, weights_only=False)
    assert last["progress"]["global_step"] == 160
    assert last["progress"]["stage_changes"] == [[0, "cp1"], [80, "cp2"]] or last["progress"]["stage_changes"] == [(0, "cp1"), (80, "cp2")]
    assert last["args"]["icm_strength"] == 0.02 and last["args"]["stage_schedules"]

    policy = torch.load(shipped, weights_only=False)
    assert "optimizer" not in policy and "rng" not in policy and torch.equal(policy["agent"]["actor_logstd"], last["agent"]["actor_logstd"])
    record = policy["campaign"]["record"]
    assert policy["campaign"]["command"] == "python tiny.py" and record["env steps"] == "160"
    assert record["stages"] == "cp1 from step 0, cp2 from step 80" and " h of training iterations" in record["wall time"]
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(checkpoint=shipped, env_id="Flooring-v1", episodes=1, workers=1, json=out))
    assert json.loads(out.read_text())["episodes"] == 1


def test_the_campaign_report_summarizes_each_run_and_stage_and_draws_figure_3_and_table_ii(tmp_path):
    """experiments/paper_report.py on a small progress.csv: the run's row, its stages, Figure 3, and Table II
    with the paper's rows, ours where evaluated (95% intervals) and, where not yet, why and the command."""
    from baselines.ppo.checkpoints import CSV_FIELDS

    run_dir = tmp_path / "campaign" / "paper_general_agent"
    run_dir.mkdir(parents=True)
    with open(run_dir / "progress.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for i in range(1, 401):  # 2M steps of cp1, then 2M of cp2 with placements
            stage = "cp1" if i <= 200 else "cp2"
            w.writerow(dict(global_step=10_000 * i, iteration=i, stage=stage, episodes=40, pick_success=0.5,
                            place_success=0.0 if stage == "cp1" else 0.25, extrinsic_return=0.5, intrinsic_return=0.1,
                            end_place_dist=1.0, end_place_angle_deg=30.0, held_at_end=0.5))
    run3 = tmp_path / "campaign" / "paper_cp1_no_curiosity"
    run3.mkdir()
    with open(run3 / "progress.csv", "w", newline="") as f:  # run 3, half of its cp1 stage
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for i in range(1, 101):
            w.writerow(dict(global_step=10_000 * i, iteration=i, stage="cp1", episodes=40, pick_success=0.25,
                            place_success=0.0, extrinsic_return=-0.5, end_place_dist=1.5, end_place_angle_deg=40.0,
                            held_at_end=0.25))
    flooring = tmp_path / "campaign" / "control_flooring"
    flooring.mkdir()
    with open(flooring / "progress.csv", "w", newline="") as f:  # a control group past its 2M point, on to 8M
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for i in range(1, 211):
            w.writerow(dict(global_step=10_000 * i, iteration=i, stage="cp4", episodes=40, pick_success=1.0,
                            place_success=0.0, extrinsic_return=0.0, end_place_dist=2.0, end_place_angle_deg=60.0,
                            held_at_end=1.0))
    results = tmp_path / "RESULTS.md"
    res = subprocess.run([sys.executable, "-m", "experiments.paper_report", "--campaign-dir", str(tmp_path / "campaign"),
                          "--write-results", "--results", str(results), "--images", str(tmp_path / "images"),
                          "--eval-dir", str(tmp_path / "evaluations"), "--readme", str(tmp_path / "README.md"),
                          "--experiment-page", str(tmp_path / "experiments" / "paper.md")],
                         capture_output=True, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert res.returncode == 0, res.stderr
    text = results.read_text()
    page = (tmp_path / "experiments" / "paper.md").read_text()  # the runs, the stages, the settings: the page's
    assert "(experiments/paper.md#the-training-runs)" in text and "## Each stage, and the settings" in page
    assert "## The training runs" in page and "### The training runs" not in text
    assert "| curiosity |" in page and "| curiosity |" not in text
    assert "| paper_general_agent | the paper setting" in page and "4,000,000 / 8,000,000 | cp2 | 200,000 | 800 |" in page
    assert "| paper_general_agent | the paper setting" not in text
    assert "| paper_general_agent | cp1 | 0-2,000,000 | 8,000 | 50.0 | 0.0 |" in page
    assert "| paper_general_agent | cp2 | 2,000,000-4,000,000 | 8,000 | 50.0 | 25.0 |" in page
    assert "| control_ceiling | controlGroup4.1" in page and "not started" in page
    assert "| control_flooring | controlGroup4.3: Flooring-v1, cp4 from the first step | 2,100,000 / 8,000,000 | cp4 |" in page
    assert "| control_flooring | cp4 | 2,000,000-2,100,000 | 400 | 100.0 | 0.0 |" in page
    assert (tmp_path / "images" / "paper_fig4.png").stat().st_size > 0
    assert (tmp_path / "images" / "paper_fig3.png").stat().st_size > 0
    assert "| paper_cp1_no_curiosity | run 1's cp1 stage without curiosity" in page and "1,000,000 / 2,000,000 | cp1 |" in page
    assert "| paper_cp1_no_curiosity | cp1 | 0-1,000,000 | 4,000 | 25.0 | 0.0 |" in page
    # curiosity's effect: run 3 beside run 1's own cp1 stage only; the figures shown on the page, linked from it
    assert (tmp_path / "images" / "paper_curiosity.png").stat().st_size > 0
    assert "--max-steps 2000000 --out" in page and "](../images/paper_curiosity.png)" in page
    table = text.split("### Table II")[1]
    assert "| paper: general agent |" in table and "| 84.55 / 68.04 | 95.32 / 84.82 | 88.43 / 85.17 |" in table
    assert "| 63.00 / 0.21 | 62.89 / 0.30 | 64.72 / 4.45 |" in table
    assert "| ours: paper setting, general agent |" in table and "| not yet | not yet | not yet |" in table
    sources = page.split("### Where each row of Table II comes from")[1]
    assert ("ours: paper setting, general agent: not yet (its run is at step 4,000,000 of 8,000,000 "
            "(python -m experiments.paper)); then `python scripts/evaluate.py --checkpoint "
            "assets/checkpoints/paper_general_agent.pt --all --steps 50000") in sources
    assert "ours: paper setting, end of cp3: not yet (the end of cp3 comes at step 6,000,000)" in sources
    # a stage passed whose final policy was not kept: its row says so, with no command that could not run
    assert "| ours: paper setting, end of cp1 | the general agent after 2,000,000 env steps, judged at cp4 | " \
           "not kept | not kept | not kept |" in table
    assert "ours: paper setting, end of cp1: not kept (that stage's final policy was not kept" in sources
    assert "--checkpoint campaign/paper_general_agent/checkpoint_stage1_cp1.pt" not in sources
    assert "--checkpoint assets/checkpoints/control_window_8m.pt --env-id WindowInstallation-v1 --steps 50000" in sources
    # a control group is judged on its own task alone
    assert "| ours: controlGroup4.2, 2M | controlGroup4.2: WindowInstallation-v1, cp4 from the first step; 2M env steps " \
           "| - | not yet | - |" in table
    expert = next(line for line in table.splitlines() if line.startswith("| ours: planning expert"))
    assert expert.count("100.0 [96.3, 100.0] / 100.0 [96.3, 100.0]") == 3, "100 of 100 with its Wilson interval"
    # the from-scratch agent: shipped, so its row waits on its evaluation, with the command that writes it
    assert "| ours: from reward alone |" in table
    assert ("ours: from reward alone: not yet (not evaluated yet); then `python scripts/evaluate.py --checkpoint "
            "assets/checkpoints/scratch_general_agent.pt --all") in sources
    # the README's headline: Table II's rows a reader compares first, the same cells
    headline = (tmp_path / "README.md").read_text()
    assert "| paper: general agent | 84.55 / 68.04 | 95.32 / 84.82 | 88.43 / 85.17 |" in headline
    assert "| planning expert | " + " | ".join(["100.0 [96.3, 100.0] / 100.0 [96.3, 100.0]"] * 3) + " |" in headline
    assert "| paper setting, general agent | not yet | not yet | not yet |" in headline


SHIPPED_RUNS = [r for r in ps.general_runs(num_envs=2) + ps.control_group_runs(num_envs=2)
                + ps.control_group_runs(8_000_000, num_envs=2) if r.shipped is not None]


@pytest.mark.parametrize("run", SHIPPED_RUNS, ids=[r.shipped.name for r in SHIPPED_RUNS])
def test_each_shipped_campaign_checkpoint_loads_and_evaluates_with_its_record(run, tmp_path):
    """A shipped paper-setting checkpoint (assets/checkpoints/) carries its campaign record and plays
    an episode of its task through scripts/evaluate.py; a missing one fails, naming the command that ships it."""
    path = ROOT / run.shipped
    assert path.is_file(), f"{run.shipped} is missing ({run.command} ships it at the end of its plan)"
    record = torch.load(path, map_location="cpu", weights_only=False)["campaign"]["record"]
    assert record["env steps"] == f"{run.args.total_timesteps:,}" and "wall time" in record and "hardware" in record
    env_id = "WindowInstallation-v1" if run.args.env_id == "ConstructionPickPlace-v1" else run.args.env_id
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(checkpoint=path, env_id=env_id, episodes=1, workers=1, json=out))
    assert json.loads(out.read_text())["episodes"] == 1


def test_an_evaluation_records_the_env_steps_its_checkpoint_had_trained_where_the_checkpoint_says(tmp_path):
    out, ckpt, bare = tmp_path / "eval.json", tmp_path / "checkpoint.pt", tmp_path / "policy.pt"
    out.write_text(json.dumps({"place_success": 0.9}))
    torch.save({"progress": {"global_step": 250_000}}, ckpt)
    torch.save({"agent": {}}, bare)  # a shipped policy keeps no progress
    campaign.record_checkpoint_step(out, bare)
    assert json.loads(out.read_text()) == {"place_success": 0.9}
    campaign.record_checkpoint_step(out, ckpt)
    assert json.loads(out.read_text()) == {"place_success": 0.9, "checkpoint_step": 250_000}
