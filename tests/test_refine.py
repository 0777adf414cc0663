"""The refinement recipe's bookkeeping (experiments/refine.py: snapshots, validation, the best of them,
shipping only what beats the clone) with PPO and the evaluations stood in for, and its report
(experiments/refine_report.py) on a small summary."""

import dataclasses
import json
from pathlib import Path

import pytest
import torch

from baselines.ppo import evaluation
from experiments import refine

ROOT = Path(__file__).resolve().parents[1]
from experiments import refine_report

TASKS = ("CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1")
CLONE_VAL = dict(zip(TASKS, (0.96, 0.96, 0.985)))


@pytest.fixture
def stand_ins(tmp_path, monkeypatch):
    """PPO that only counts steps into its checkpoint; validations read from a table by snapshot."""
    runs, val_table, confirm_table = [], {}, {}

    def fake_ppo(args):
        ckpt = Path(args.log_dir) / args.exp_name / "checkpoint.pt"
        start = torch.load(args.resume)["step"] if args.resume else 0
        runs.append((start, args.total_timesteps, bool(args.resume)))
        ckpt.parent.mkdir(parents=True, exist_ok=True)
        torch.save(dict(step=args.total_timesteps, progress=dict(global_step=args.total_timesteps)), ckpt)

    def fake_validate(checkpoint, out, episodes, seed=refine.VALIDATION_SEED, goal_slots=()):
        name = Path(checkpoint).name
        if name.endswith("clone.pt"):
            return CLONE_VAL
        table = val_table if seed == refine.VALIDATION_SEED else confirm_table
        if Path(checkpoint) == refine.SHIPPED:  # a stand-in for a shipped refinement: its step says which row
            return table[torch.load(checkpoint)["step"]]
        return table[int(name.split("_")[1].split(".")[0])]

    monkeypatch.setattr(refine.ppo, "main", fake_ppo)
    monkeypatch.setattr(refine, "validate", fake_validate)
    shipped = tmp_path / "general_agent.pt"
    monkeypatch.setattr(refine, "SHIPPED", shipped)
    monkeypatch.setattr(refine, "ship", lambda args, ckpt, *a: shipped.write_bytes(Path(ckpt).read_bytes()))
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    torch.save(dict(states=[{}], offsets=[-30, -10]), run_dir / "failure_states.pt")  # the bank exists: not collected again
    args = refine.Args(clone=tmp_path / "clone.pt", run_dir=run_dir, total_timesteps=300, validate_every=100)
    return args, runs, val_table, confirm_table, shipped


def test_snapshots_are_validated_and_the_best_beating_the_clone_on_fresh_seeds_too_is_shipped(stand_ins):
    args, runs, val_table, confirm_table, shipped = stand_ins
    val_table.update({100: dict(zip(TASKS, (0.97, 0.97, 0.99))), 200: dict(zip(TASKS, (0.99, 0.985, 0.99))),
                      300: dict(zip(TASKS, (0.90, 0.99, 1.0)))})
    confirm_table[200] = dict(zip(TASKS, (0.98, 0.97, 0.99)))
    best = refine.main(args)
    assert runs == [(0, 100, False), (100, 200, True), (200, 300, True)], "PPO continues from its checkpoint"
    assert best.name == "checkpoint_200.pt", "the best worst task wins"
    assert torch.load(shipped)["step"] == 200
    refine.main(args)  # everything is in the run folder: no PPO again
    assert len(runs) == 3


def test_a_validation_winner_that_loses_on_fresh_seeds_is_not_shipped(stand_ins):
    args, runs, val_table, confirm_table, shipped = stand_ins
    val_table.update({k: dict(zip(TASKS, (0.995, 0.985, 0.98))) for k in (100, 200, 300)})
    confirm_table[100] = dict(zip(TASKS, (0.99, 0.92, 0.98)))
    refine.main(args)
    assert not shipped.exists()


@pytest.mark.parametrize("shipped_confirmation, replaced", [((0.985, 0.975, 0.995), False), ((0.98, 0.965, 0.99), True)])
def test_a_shipped_refinement_is_replaced_only_by_one_that_beats_it_on_fresh_seeds(stand_ins, shipped_confirmation, replaced):
    args, runs, val_table, confirm_table, shipped = stand_ins
    torch.save(dict(step=50), shipped)  # an earlier refinement, shipped
    confirm_table[50] = dict(zip(TASKS, shipped_confirmation))
    val_table.update({k: dict(zip(TASKS, (0.99, 0.985, 0.99))) for k in (100, 200, 300)})
    confirm_table[100] = dict(zip(TASKS, (0.985, 0.97, 0.995)))  # beats the clone on fresh seeds
    refine.main(args)
    assert torch.load(shipped)["step"] == (100 if replaced else 50)


def test_nothing_is_shipped_when_no_snapshot_beats_the_clone(stand_ins):
    args, runs, val_table, confirm_table, shipped = stand_ins
    val_table.update({k: dict(zip(TASKS, (0.87, 0.925, 0.975))) for k in (100, 200, 300)})
    refine.main(args)
    assert not shipped.exists()


def summary(run: str, steps_and_success: dict) -> dict:
    def validation(success):
        return {t: dict(episodes=200, place_success=s, ci95=[s - 0.03, min(1.0, s + 0.02)], pick_success=1.0,
                        failures=[dict(seed=1, kind="short", dist=0.5, angle_deg=10.0)] * round(200 * (1 - s)))
                for t, s in zip(TASKS, success)}
    return dict(run=run, settings=dict(learning_rate=3e-5, gamma=0.999, start_states_share=0.25, residual_scale=0.1,
                                       num_envs=4, num_steps=250),
                ppo_steps=max(steps_and_success), clone=validation((0.96, 0.96, 0.985)),
                validations={str(k): validation(v) for k, v in steps_and_success.items()})


def test_the_report_tables_each_validation_and_the_failures_of_the_best(tmp_path):
    path = tmp_path / "probe.json"
    path.write_text(json.dumps(summary("probe", {100_000: (0.97, 0.95, 0.99), 200_000: (0.98, 0.97, 0.99)})))
    results = tmp_path / "RESULTS.md"
    out = tmp_path / "docs" / "images" / "refine.png"
    body = refine_report.main(refine_report.Args(runs=(path,), out=out, results=results, write_results=True))
    assert "| probe |" in body and "| 100,000 |" in body and "| 200,000 |" in body
    assert "98.0 [95.0, 100.0]" in body
    assert "| probe | ceiling | 8 short (0.5-0.5 m) | 4 short (0.5-0.5 m) (200,000) |" in body
    assert out.stat().st_size > 0
    assert "<!-- begin refinement (generated) -->" in results.read_text()


def test_the_report_tables_a_confirmation_beside_the_clone_where_a_run_has_one(tmp_path):
    run = summary("probe", {100_000: (0.97, 0.97, 0.99)})
    run["confirmation"] = dict(env_steps=100_000, clone=summary("c", {1: (0.955, 0.95, 0.98)})["validations"]["1"],
                               snapshot=summary("s", {1: (0.96, 0.935, 0.97)})["validations"]["1"])
    path = tmp_path / "probe.json"
    path.write_text(json.dumps(run))
    body = refine_report.main(refine_report.Args(runs=(path,), out=tmp_path / "refine.png"))
    assert "| probe | 100,000 | 95.5 -> 96.0 | 95.0 -> 93.5 | 98.0 -> 97.0 | no | not measured |" in body
    run["confirmation"]["shipped"] = summary("p", {1: (0.98, 0.97, 0.995)})["validations"]["1"]
    path.write_text(json.dumps(run))
    body = refine_report.main(refine_report.Args(runs=(path,), out=tmp_path / "refine.png"))
    assert "| 98.0 -> 97.0 | no | 98.0 / 97.0 / 99.5: no |" in body


def test_a_run_folder_s_confirmation_names_the_snapshot_and_the_agent_shipped_then(tmp_path):
    run = tmp_path / "refine9"
    (run / "ppo").mkdir(parents=True)
    torch.save(dict(args=dict(learning_rate=3e-5), progress=dict(global_step=200_000), agent={}, obs_dim=43, act_dim=6,
                    task_slots=4),
               run / "ppo" / "checkpoint.pt")
    for name, success in [("val200_clone", 0.96), ("val200_200000", 0.97), ("confirm200_clone", 0.95),
                          ("confirm200_200000", 0.99), ("confirm200_shipped_fe56ed4d", 0.97)]:
        (run / f"{name}.json").write_text(json.dumps(dict(tasks={t: dict(
            episodes=200, place_success=success, place_success_ci95=[0.9, 1.0], pick_success=1.0, episode_results=[])
            for t in TASKS})))
    summary_ = refine_report.load(run, tmp_path / "data")
    c = summary_["confirmation"]
    assert c["env_steps"] == 200_000
    assert [c[k]["Flooring-v1"]["place_success"] for k in ("clone", "snapshot", "shipped")] == [0.95, 0.99, 0.97]


def test_the_reward_reaches_ppo_and_a_dense_run_is_labelled_so(tmp_path):
    args = refine.Args(run_dir=tmp_path, reward_mode="normalized_dense", reward_scale=0.02, gamma=0.99)
    run = refine.ppo_args(args, tmp_path / "failure_states.pt")
    assert (run.reward_mode, run.ppo.reward_scale, run.ppo.gamma, run.ppo.bootstrap_at_done) == ("normalized_dense", 0.02, 0.99, "always")
    dense, sparse = (summary(name, {100_000: (0.97, 0.95, 0.99)}) for name in ("dense", "sparse"))
    dense["settings"].update(reward_mode="normalized_dense", reward_scale=0.02)
    paths = [tmp_path / "dense.json", tmp_path / "sparse.json"]
    for path, run in zip(paths, (dense, sparse)):
        path.write_text(json.dumps(run))
    body = refine_report.main(refine_report.Args(runs=tuple(paths), out=tmp_path / "refine.png"))
    assert "| dense | normalized_dense reward x 0.02, lr 3e-05" in body
    assert "| sparse | lr 3e-05" in body  # runs before the flag, and sparse ones, read as they did


def test_task_weights_reach_the_training_envs_only_and_label_the_run(tmp_path):
    from baselines.ppo import ppo

    run = refine.ppo_args(refine.Args(run_dir=tmp_path, task_weights=(0.0, 1.0, 0.0)), tmp_path / "bank.pt")
    run.starts.start_states = None
    with pytest.raises(SystemExit, match="task-weights"):
        ppo.validate(run.replace(task_weights=(0.0, 0.0, 0.0)))
    seen = {}
    for mode in (False, True):  # training, then evaluation
        envs = ppo.make_envs(run, 1, torch.device("cpu"), eval_mode=mode)
        seen[mode] = {int(envs.reset(seed=s)[1]["task_id"][0]) for s in range(12)}
        envs.close()
    assert seen[False] == {1} and len(seen[True]) > 1
    weighted = summary("weighted", {100_000: (0.97, 0.95, 0.99)})
    weighted["settings"]["task_weights"] = [1.0, 2.0, 1.0]
    (tmp_path / "weighted.json").write_text(json.dumps(weighted))
    body = refine_report.main(refine_report.Args(runs=(tmp_path / "weighted.json",), out=tmp_path / "refine.png"))
    assert ", task weights 1/2/1 |" in body


def test_the_elapsed_time_reaches_ppo_and_labels_the_run(tmp_path):
    run = refine.ppo_args(refine.Args(run_dir=tmp_path, obs_elapsed_time=True, bootstrap_at_done="terminated"),
                          tmp_path / "bank.pt")
    assert run.obs_elapsed_time and run.ppo.bootstrap_at_done == "terminated"
    timed = summary("timed", {100_000: (0.97, 0.95, 0.99)})
    timed["settings"].update(obs_elapsed_time=True, bootstrap_at_done="terminated")
    (tmp_path / "timed.json").write_text(json.dumps(timed))
    body = refine_report.main(refine_report.Args(runs=(tmp_path / "timed.json",), out=tmp_path / "refine.png"))
    assert ", bootstrap-at-done terminated, elapsed time observed |" in body


def test_a_bank_that_keeps_its_clock_reaches_ppo_and_one_of_other_offsets_is_refused(stand_ins):
    args, runs, *_ = stand_ins
    run = refine.ppo_args(dataclasses.replace(args, bank_keeps_clock=True), args.run_dir / "failure_states.pt")
    assert run.starts.start_states_keep_clock
    with pytest.raises(SystemExit, match="other offsets"):
        refine.main(dataclasses.replace(args, bank_offsets=(-90, -50, -20)))
    with pytest.raises(SystemExit, match="without elapsed steps"):  # the stand-in bank predates them
        refine.main(dataclasses.replace(args, bank_keeps_clock=True))
    assert runs == [], "nothing trained on a bank the run did not ask for"
    clocked = summary("clocked", {100_000: (0.97, 0.95, 0.99)})
    clocked["settings"].update(start_states_keep_clock=True, bank_offsets=[-90, -50, -20])
    (args.run_dir / "clocked.json").write_text(json.dumps(clocked))
    body = refine_report.main(refine_report.Args(runs=(args.run_dir / "clocked.json",), out=args.run_dir / "refine.png"))
    assert ", bank at -90/-50/-20 steps, bank keeps its clock |" in body


def test_a_second_round_is_reported_against_its_base_not_the_clone(tmp_path):
    run = summary("round2", {100_000: (0.985, 0.98, 0.98)})
    run["settings"]["residual_of"] = "assets/checkpoints/general_agent_refine8.pt"
    run["confirmation"] = dict(env_steps=100_000, clone=summary("c", {1: (0.995, 0.995, 0.98)})["validations"]["1"],
                               snapshot=summary("s", {1: (0.99, 0.955, 1.0)})["validations"]["1"])
    path = tmp_path / "round2.json"
    path.write_text(json.dumps(run))
    body = refine_report.main(refine_report.Args(runs=(path,), out=tmp_path / "refine.png"))
    assert "| round2 | on general_agent_refine8.pt, lr 3e-05," in body and "| the base | 96.0" in body
    assert "| round2 (its base, general_agent_refine8.pt, in the clone's place) | 100,000 | 99.5 -> 99.0 |" in body
    assert "the clone" not in body.split("| round2 |")[1].split("\n")[0]


def test_failure_kinds_follow_the_stage_tolerances():
    def episode(seed, placed, held, dist, angle):
        return dict(seed=seed, placed=placed, held_at_end=held, final_place_dist=dist, final_place_angle_deg=angle)

    episodes = [episode(0, False, False, 0.05, 3.0), episode(1, False, True, 0.3, 3.0), episode(2, False, True, 0.05, 45.0),
                episode(3, True, True, 0.05, 3.0), episode(4, False, True, 0.2, 30.0)]
    failed = evaluation.failures(episodes)  # cp4: 0.10 m, 20 degrees
    assert [(f["seed"], f["kind"]) for f in failed] == [(0, "dropped"), (1, "short"), (2, "turned"), (4, "short and turned")]
    assert [f["kind"] for f in evaluation.failures(episodes, "cp2")] == ["dropped", "short", "turned", "turned"]  # 0.25 m, 60 deg
    assert evaluation.kinds(failed) == ("1 short (0.3-0.3 m), 1 short and turned (0.2-0.2 m, 30-30 deg), "
                                        "1 turned (45-45 deg), 1 dropped (0.05-0.05 m)")
    assert evaluation.kinds([]) == "none"


def test_a_folder_that_is_not_a_refine_run_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="neither a refine.py run folder"):
        refine_report.load(tmp_path, tmp_path / "data")


def test_wall_times_add_up_across_resumed_commands_and_are_kept_when_a_step_fails(tmp_path):
    from ms_construction.reporting import WallTimes

    path = tmp_path / "campaign.json"
    assert WallTimes(path).timed("PPO", lambda: 7) == 7
    with pytest.raises(RuntimeError):
        WallTimes(path).timed("PPO", lambda: (_ for _ in ()).throw(RuntimeError("interrupted")))
    WallTimes(path).timed("validation", lambda: None)
    record = json.loads(path.read_text())
    assert set(record["wall_s"]) == {"PPO", "validation"} and record["wall_s"]["PPO"] >= 0
