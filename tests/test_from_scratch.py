"""The from-scratch pipeline (experiments/from_scratch.py): its recipe is a valid ppo.py run with no demonstrations,
it ships with a record that says so, and its reports write the seeds' curves and sections from their CSVs."""

import csv
import dataclasses
import functools
import json
import shutil
from pathlib import Path

import pytest
import torch
import tyro

from experiments import campaign
from baselines.ppo import ppo
from baselines.ppo.args import command_line
from baselines.ppo.checkpoints import CSV_FIELDS
from experiments import from_scratch as fs


def test_the_recipe_learns_from_reward_alone_on_the_tasks_default_reward_from_nothing():
    run = fs.seed_run(2, num_envs=2, learner="ppo")
    a = run.args
    ppo.validate(a)
    assert a.env_id == "ConstructionPickPlace-v1" and a.stages.curriculum == ("cp4",) and a.total_timesteps <= 10_000_000
    assert (a.seed, a.exp_name, run.shipped) == (2, "scratch_s2", None) and "--seed 2" in run.command
    # the task's own reward and sampling: the default reward mode, nothing weighs a task type or a goal slot
    assert a.reward_mode == ppo.Args().reward_mode and a.task_weights is None and a.starts.goal_slot_weights is None
    assert a.reward_mode == "normalized_dense" and a.starts.near_goal_share > 0 and a.ppo.success_value == "absorbing"
    # nothing from the expert: no demonstrations, no warm start, no residual base, no bank of expert states
    assert a.warm.demos == () and a.warm.bc_coef == 0 and a.checkpoint is None and a.warm.residual_of is None and a.starts.start_states is None
    assert a.num_envs * a.num_steps == 2000
    assert "demonstrations: none" in run.method
    assert fs.SHIPPED.name == "scratch_general_agent.pt"
    # written down as one ppo.py command, it is the same run
    assert tyro.cli(ppo.Args, args=command_line(a)) == a


def test_the_recipe_changes_the_policy_and_a_stopped_run_resumes_in_the_uninterrupted_run_s_state(tmp_path, monkeypatch):
    """The recipe as it runs (the general task, near-goal starts cut at their limit, the install-offset observation,
    the bounded mean), tiny: run U goes 4 iterations, run I stops (Ctrl-C) after its iteration-2 checkpoint.
    Restoring I gives U's weights, optimizer, progress (near-goal radii and windows included) and random states
    at iteration 2; the resumed run ends where U ends."""
    import random
    import shutil

    import numpy as np

    original = ppo.save_checkpoint

    def keep_copies(path, args, progress, *rest, **extra):
        original(path, args, progress, *rest, **extra)
        shutil.copy(path, path.with_name(f"iter{progress.iteration}.pt"))
        if args.exp_name == "interrupted" and progress.iteration == 2 and not (tmp_path / "stopped").exists():
            (tmp_path / "stopped").touch()
            raise KeyboardInterrupt

    monkeypatch.setattr(ppo, "save_checkpoint", keep_copies)
    small = dict(num_envs=2, num_steps=40, num_minibatches=2, update_epochs=1, num_eval_envs=1, eval_freq=100,
                 checkpoint_freq=1, log_dir=str(tmp_path), total_timesteps=320, near_goal_max_steps=10,
                 near_goal_window=2, near_goal_promote=0.5)
    u = ppo.main(fs.scratch_args(exp_name="uninterrupted", **small))
    i = ppo.main(fs.scratch_args(exp_name="interrupted", **small))
    assert i.iteration == 2 and u.iteration == 4
    ref = torch.load(tmp_path / "uninterrupted" / "iter2.pt", weights_only=False)
    first = torch.load(tmp_path / "uninterrupted" / "iter1.pt", weights_only=False)
    assert any(not torch.equal(v, first["agent"][k]) for k, v in ref["agent"].items()), "the policy changed"
    with open(tmp_path / "uninterrupted" / "progress.csv", newline="") as f:
        assert any(int(r["near_goal_episodes"]) for r in csv.DictReader(f)), "near-goal episodes ended (cut at 10 steps)"

    restored = ppo.setup(ppo.Args.of(resume=str(tmp_path / "interrupted" / "checkpoint.pt")))
    assert restored.args.obs_install_offset and restored.args.ppo.bounded_mean and restored.args.starts.near_goal_max_steps == 10
    assert dataclasses.asdict(restored.progress) == ref["progress"]
    for k, v in restored.agent.state_dict().items():
        assert torch.equal(v, ref["agent"][k]), k
    for pid, st in restored.optimizer.state_dict()["state"].items():
        for key in ("exp_avg", "exp_avg_sq", "step"):
            assert torch.equal(st[key], ref["optimizer"]["state"][pid][key]), (pid, key)
    assert torch.equal(torch.get_rng_state(), ref["rng"]["torch"])
    assert np.random.get_state()[1].tolist() == ref["rng"]["numpy"][1].tolist() and random.getstate() == ref["rng"]["python"]
    restored.eval_envs.close()
    resumed = ppo.main(ppo.Args.of(resume=str(tmp_path / "interrupted" / "checkpoint.pt")))
    assert resumed.global_step == u.global_step == 320 and resumed.iteration == u.iteration


def test_a_run_ships_at_its_end_or_a_chosen_snapshot_with_a_record_that_says_where_it_stands(tmp_path):
    small = dict(num_envs=2, num_steps=20, num_minibatches=2, update_epochs=1, num_eval_envs=1, eval_freq=100,
                 checkpoint_freq=1, env_id="Flooring-v1", task_weights=None, log_dir=str(tmp_path), exp_name="tiny", total_timesteps=80)
    run = dataclasses.replace(fs.seed_run(1, learner="ppo"), args=fs.scratch_args(**small), shipped=tmp_path / "scratch.pt")
    campaign.run_or_resume(dataclasses.replace(run, shipped=None))
    longer = dataclasses.replace(run, args=run.args.replace(total_timesteps=160))
    with pytest.raises(SystemExit, match="at step 80 of 160"):
        campaign.ship(longer)
    campaign.ship(longer, snapshot=tmp_path / "tiny" / "checkpoint.pt", chosen="the test's choice")
    record = torch.load(run.shipped, weights_only=False)["campaign"]["record"]
    assert record["env steps"] == "80 (of the 160 planned)" and "demonstrations: none" in record["method"]
    assert record["chosen"] == "the test's choice"


def test_the_shipped_agent_s_section_is_its_evaluation_beside_the_paper_s_or_says_how_it_ships(tmp_path, monkeypatch):
    results = tmp_path / "RESULTS.md"
    monkeypatch.setattr(fs, "EVAL_JSON", tmp_path / "none.json")
    body = fs.shipped_report(results, shipped=tmp_path / "none.pt")
    assert body.startswith("Not shipped yet: `python -m experiments.from_scratch --ship-seeds`")
    assert "<!-- begin from-scratch (generated) -->" in results.read_text()
    shipped = tmp_path / "scratch.pt"
    assert fs.shipped_report(results, shipped=Path(__file__).resolve().parents[1] / fs.SHIPPED).endswith(
        f"is not evaluated yet: `python scripts/evaluate.py --checkpoint {Path(__file__).resolve().parents[1] / fs.SHIPPED} "
        f"--all --steps 50000 --json {fs.EVAL_JSON}`.")
    campaign.ship_checkpoint(Path(__file__).resolve().parents[1] / fs.SHIPPED, shipped, "cmd", dict(method="PPO; demonstrations: none", **{"env steps": "40"},
                                                               chosen="seed 1 of 2 (the better on validation)"))
    episodes = [dict(placed=True, picked=True, goal_slot=0)] * 3 + [dict(placed=False, picked=False, goal_slot=1)]
    fs.EVAL_JSON.write_text(json.dumps(dict(command="python scripts/evaluate.py ...", tasks={
        env: dict(pick_success=0.75, pick_success_ci95=[0.3, 0.95], place_success=0.75, place_success_ci95=[0.3, 0.95],
                  episode_results=episodes) for env in fs.PAPER_TABLE_II})))
    body = fs.shipped_report(results, shipped=shipped)
    assert f"The shipped policy ({shipped}; PPO; demonstrations: none; env steps: 40; seed 1 of 2 (the better on validation))" in body
    row = next(line for line in body.splitlines() if line.startswith("| CeilingInstallation-v1 |"))
    assert "| 84.55 / 68.04 |" in row and row.endswith("| 1 never picked |")
    learner = "SAC" if torch.load(shipped, weights_only=False).get("sac") is not None else "PPO"  # the copied file's
    assert fs.shipped_how(shipped) == (f"{learner} on the dense reward, no demonstrations; the recipe unchanged from "
                                       "step 0, seed 1 of 2, 40 env steps")
    assert fs.shipped_how(tmp_path / "none.pt") == "not shipped yet"


def test_the_shipped_agent_from_reward_alone_has_no_demonstrations_in_it_and_plays(tmp_path):
    """assets/checkpoints/scratch_general_agent.pt: its record says how far its campaign got and that it saw no
    demonstrations, its args hold no warm start, residual base or expert states, and scripts/evaluate.py runs it."""
    from baselines.ppo import evaluation

    path = Path(__file__).resolve().parents[1] / "assets/checkpoints/scratch_general_agent.pt"
    assert path.is_file(), f"{path} is missing (`python -m experiments.from_scratch --ship-seeds` ships it)"
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    record = ckpt["campaign"]["record"]
    assert "demonstrations: none" in record["method"] and "wall time" in record and "hardware" in record
    a = ckpt["args"]
    assert not a.get("demos") and a["checkpoint"] is None and a.get("residual_of") is None \
        and a.get("start_states") is None, "PPO's warm starts; SAC's args have none of them"
    assert a["near_goal_share"] > 0 and a["reward_mode"] == "normalized_dense"
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(checkpoint=path, env_id="Flooring-v1", episodes=1, workers=1, json=out))
    assert json.loads(out.read_text())["episodes"] == 1


def test_the_seeds_report_has_a_row_per_seed_and_says_how_a_seed_not_started_starts(tmp_path, monkeypatch):
    run_dir = tmp_path / "campaign" / "scratch_s1"
    run_dir.mkdir(parents=True)
    with open(run_dir / "progress.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for i in range(1, 151):
            w.writerow(dict(global_step=2000 * i, iteration=i, stage="cp4", episodes=10, sps=500, near_goal_place_success=0.5,
                            near_goal_radius_ceiling=0.3, near_goal_radius_window=0.6, near_goal_radius_flooring=1.0,
                            ordinary_place_ceiling=0.0, ordinary_place_window=0.1, ordinary_place_flooring="",
                            **{f"reach_start_radius_{k}{s}": 0.1 * (s + 1) for k in ("ceiling", "window", "flooring")
                               for s in range(3)}))
    monkeypatch.setattr(fs, "SEEDS_CURVE", tmp_path / "images" / "seeds.png")
    results = tmp_path / "RESULTS.md"
    body = fs.seeds_report(results, log_dir=tmp_path / "campaign")
    assert ("| PPO | 1 | 300,000 / 10,000,000 | 0.2 h | 0.3 / 0.6 / 1.0 | 0.1, 0.2, 0.3 / 0.1, 0.2, 0.3 / 0.1, 0.2, 0.3 | "
            "0.0 / 10.0 / - | 50.0 |") in body
    with open(run_dir / "progress.csv", newline="") as f:
        assert fs.reach_radius(list(csv.DictReader(f)), "window")[-1] == pytest.approx(0.2)
    assert "| PPO | 2 | not started: `python -m experiments.from_scratch --seed 2 --learner ppo` |" in body
    assert (tmp_path / "images" / "seeds.png").stat().st_size > 0
    assert "<!-- begin from-scratch-seeds (generated) -->" in results.read_text()


def test_a_seed_is_evaluated_on_its_latest_snapshot_once_and_its_row_joins_the_seeds_report(tmp_path, monkeypatch):
    """`--seed S --evaluate`: the latest of the seed's snapshots and its run's own checkpoint (all a fresh machine
    has), or the one asked for; a missing one is refused with those there are; an evaluation on file is kept."""
    monkeypatch.setattr(fs, "CAMPAIGN_DIR", tmp_path / "campaign")
    monkeypatch.setattr(fs, "SNAPSHOT_DIR", tmp_path / "runs" / "snaps")
    monkeypatch.setattr(fs, "SEED_EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(fs, "EVAL_STEPS", 300)
    monkeypatch.setattr(fs, "SEEDS_CURVE", tmp_path / "images" / "seeds.png")
    with pytest.raises(SystemExit, match="no snapshots of seed 1"):
        fs.evaluate_seed(1, learner="ppo")
    tiny = fs.seed_run(1, learner="ppo").args.replace(num_envs=2, num_steps=20, num_minibatches=2, update_epochs=1, num_eval_envs=1,
                                       eval_freq=100, checkpoint_freq=1, env_id="Flooring-v1", task_weights=None,
                                       total_timesteps=40)
    ppo.main(tiny)
    snaps = fs.seed_snapshots(1, "ppo")
    snaps.mkdir(parents=True)
    shutil.copyfile(tmp_path / "campaign" / "scratch_s1" / "checkpoint.pt", snaps / "checkpoint_20.pt")
    with pytest.raises(SystemExit, match="there are: 20, 40"):
        fs.evaluate_seed(1, 30, learner="ppo")
    out = fs.evaluate_seed(1, workers=1, learner="ppo")
    assert out == tmp_path / "evals" / "scratch_s1_eval50k_40.json"
    tasks = json.loads(out.read_text())["tasks"]
    assert set(tasks) == {"CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1"}
    assert all(t["steps"] >= 300 and t["episodes"] >= 1 for t in tasks.values())
    assert json.loads(out.read_text())["command"] == (f"python scripts/evaluate.py --checkpoint {tmp_path}/campaign/scratch_s1/"
                                                      f"checkpoint.pt --all --steps 300 --seed 1000000 --json {out} --workers 1")
    written = out.stat().st_mtime_ns
    assert fs.evaluate_seed(1, learner="ppo") == out and out.stat().st_mtime_ns == written  # kept, not run again
    body = fs.seeds_report(tmp_path / "RESULTS.md", log_dir=tmp_path / "campaign")
    assert "| paper's general agent (Table II, cp4) | | 8,000,000 | 84.55 / 68.04 |" in body
    row = next(line for line in body.splitlines() if line.startswith("| PPO | 1 | 40 |"))
    assert row.count("/") == 3


def test_a_seed_s_snapshots_are_screened_as_made_and_the_rule_chooses_among_the_committed_candidates(tmp_path, monkeypatch):
    """The snapshot rule: a seed's run screens each snapshot as it makes it, keeps the CONFIRM_TOP best-screened
    policies committed (one that falls out is deleted), and at its end confirms those on fresh episodes, with the
    snapshots on the machine gone, and chooses the one that places most there on its worst task; the paper's
    protocol then runs on that candidate, and the report marks it."""
    monkeypatch.setattr(fs, "CAMPAIGN_DIR", tmp_path / "campaign")
    monkeypatch.setattr(fs, "SNAPSHOT_DIR", tmp_path / "runs" / "snaps")
    monkeypatch.setattr(fs, "SEED_EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(fs, "SEEDS_CURVE", tmp_path / "images" / "seeds.png")
    monkeypatch.setattr(fs, "CONFIRM_TOP", 2)
    envs = list(fs.PAPER_TABLE_II)
    screening = {20: (0.5, 0.5, 0.5), 40: (0.9, 0.1, 0.9), 60: (0.6, 0.6, 0.6), 80: (0.7, 0.2, 0.8)}
    confirmation = {20: (0.8, 0.7, 0.9), 60: (0.4, 0.9, 0.9)}
    kept_after = []

    def fake_validate(checkpoint, out, episodes, seed=fs.VALIDATION_SEED):
        step = int(checkpoint.stem.split("_")[1])
        confirming = (episodes, seed) == (fs.CONFIRM_EPISODES, fs.CONFIRMATION_SEED)
        assert confirming == (checkpoint.parent == fs.seed_candidates(1, "ppo")), "confirmed from the committed candidates"
        placed = dict(zip(envs, (confirmation if confirming else screening)[step]))
        episodes = {e: [dict(goal_slot=i % 3, placed=i < round(10 * v)) for i in range(10)] for e, v in placed.items()}
        out.write_text(json.dumps(dict(tasks={e: dict(place_success=v, episode_results=episodes[e])
                                              for e, v in placed.items()})))
        return placed

    def screen_and_look(seed, step, snapshot, learner):
        placed = real_screen(seed, step, snapshot, learner)
        kept_after.append(sorted(int(p.stem.split("_")[1]) for p in fs.seed_candidates(1, "ppo").glob("candidate_*.pt")))
        return placed

    real_screen = fs.screen_snapshot
    monkeypatch.setattr(fs, "validate", fake_validate)
    monkeypatch.setattr(fs, "screen_snapshot", screen_and_look)
    run = fs.seed_run(1, learner="ppo")
    run = dataclasses.replace(run, args=run.args.replace(
        num_envs=2, num_steps=10, num_minibatches=2, update_epochs=1, num_eval_envs=1, eval_freq=100, checkpoint_freq=1,
        env_id="Flooring-v1", task_weights=None, total_timesteps=80))
    evaluated_at, real_evaluate_seed = [], fs.evaluate_seed
    monkeypatch.setattr(fs, "EVALUATE_AT", (40,))
    monkeypatch.setattr(fs, "evaluate_seed", lambda seed, step, learner: evaluated_at.append((seed, step, learner)))
    fs.train(run, every=20, snapshots=fs.seed_snapshots(1, "ppo"), after_snapshot=functools.partial(fs.snapshot_made, 1, learner="ppo"))
    assert kept_after == [[20], [20, 40], [20, 60], [20, 60]], "the two best-screened so far, the others deleted"
    assert evaluated_at == [(1, 40, "ppo")], "the snapshot at EVALUATE_AT meets the paper's protocol as it is made"
    monkeypatch.setattr(fs, "evaluate_seed", real_evaluate_seed)
    assert fs.seed_screening(1, "ppo") == {s: dict(zip(envs, v)) for s, v in screening.items()}
    candidate = torch.load(fs.seed_candidates(1, "ppo") / "candidate_60.pt", weights_only=False)
    assert candidate["progress"]["global_step"] == 60 and "optimizer" not in candidate and "rng" not in candidate
    shutil.rmtree(fs.seed_snapshots(1, "ppo"))  # a fresh machine: the committed candidates and validations only
    assert fs.chosen_step(1, "ppo") is None
    assert fs.choose_snapshot(1, "ppo") == 20, "the confirmation chooses (worst task 70% against 40%), not the screening"
    assert fs.chosen_step(1, "ppo") == 20
    evaluated = []

    def fake_paper_protocol(args):
        evaluated.append(args.checkpoint)
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(dict(tasks={e: dict(pick_success=1.0, place_success=0.9,
                                                            place_success_ci95=[0.8, 0.95]) for e in envs})))

    monkeypatch.setattr(fs.evaluation, "main", fake_paper_protocol)
    assert fs.evaluate_seed(1, fs.chosen_step(1, "ppo"), learner="ppo") == fs.seed_evaluation_json(1, 20, "ppo")
    assert evaluated == [fs.seed_candidates(1, "ppo") / "candidate_20.pt"]
    body = fs.seeds_report(tmp_path / "RESULTS.md", log_dir=tmp_path / "campaign")
    assert next(line for line in body.splitlines() if line.startswith("| PPO | 1 | 20 |")).endswith("| **the rule chose it** |")
    assert "| PPO | 1 | 4 | 20 (80 / 70 / 90); 60 (40 / 90 / 90) | 20 |" in body
    # the latest screening (80 env steps: 70 / 20 / 80 % of 10 episodes, slots 0, 1, 2 in turn) per goal slot
    assert "| 3/4, 2/3, 2/3 / 1/4, 1/3, 0/3 / 3/4, 3/3, 2/3 (at 80) |" in body
    assert "| PPO | 2 | 0 | (chosen at the end of its run) | - |" in body


def test_candidates_tied_on_the_confirmation_are_validated_again_and_ranked_on_all_their_episodes(tmp_path, monkeypatch):
    """`break_tie`: where several candidates place alike on the confirmation, those only (not one below them) meet
    TIEBREAK_EPISODES more per task from TIEBREAK_SEED and the most placed over all their episodes is chosen; a tie
    that stays goes to the first; with no tie nothing more is validated."""
    envs = ("ceiling", "window", "flooring")
    more = {"a": (1.0, 0.99, 1.0), "b": (1.0, 1.0, 1.0), "c": (0.995, 1.0, 1.0)}
    validated = []

    def fake_validate(checkpoint, out, episodes, seed):
        assert (episodes, seed) == (fs.TIEBREAK_EPISODES, fs.TIEBREAK_SEED) and out == tmp_path / f"{checkpoint.stem}.json"
        validated.append(checkpoint.stem)
        return dict(zip(envs, more[checkpoint.stem]))

    monkeypatch.setattr(fs, "validate", fake_validate)
    confirmed = {"a": dict.fromkeys(envs, 1.0), "b": dict.fromkeys(envs, 1.0), "c": dict.fromkeys(envs, 1.0),
                 "d": dict(zip(envs, (0.99, 1.0, 1.0)))}
    best, pooled = fs.break_tie(confirmed, lambda k: Path(k + ".pt"), lambda k: tmp_path / f"{k}.json")
    assert best == "b" and validated == ["a", "b", "c"], "the three tied, not d below them; b placed every one"
    n = fs.CONFIRM_EPISODES + fs.TIEBREAK_EPISODES
    assert pooled["a"]["window"] == pytest.approx((fs.CONFIRM_EPISODES + 0.99 * fs.TIEBREAK_EPISODES) / n)
    more["b"] = more["c"] = (1.0, 1.0, 1.0)
    validated.clear()
    assert fs.break_tie(confirmed, lambda k: Path(k + ".pt"), lambda k: tmp_path / f"{k}.json")[0] == "b", \
        "b and c still tied: the first of them"
    validated.clear()
    assert fs.break_tie({"d": confirmed["d"], "a": confirmed["a"]}, lambda k: Path(k + ".pt"),
                        lambda k: tmp_path / f"{k}.json") == ("a", {}) and not validated


def test_the_better_seed_on_validation_ships_only_if_it_places_what_the_shipped_policy_does_on_the_test_seeds(
        tmp_path, monkeypatch):
    """`--ship-seeds`: refused until every seed has run to its end; then the seed whose choice confirmed best on the
    validation seeds, which ships only if it places at least what the policy shipped now does on every task on the
    test seeds, with a record naming the seed, the recipe's commit and no demonstrations."""
    monkeypatch.setattr(fs, "CAMPAIGN_DIR", tmp_path / "campaign")
    monkeypatch.setattr(fs, "SEED_EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(fs, "EVAL_JSON", tmp_path / "shipped_eval.json")
    shipped = tmp_path / "scratch_general_agent.pt"
    with pytest.raises(SystemExit, match="--seed 1 --learner ppo`, `python -m experiments.from_scratch --seed 2 --learner ppo"):
        fs.ship_seeds(shipped, "ppo")
    ppo.main(fs.seed_run(1, learner="ppo").args.replace(num_envs=2, num_steps=20, num_minibatches=2, update_epochs=1, num_eval_envs=1,
                                         eval_freq=100, checkpoint_freq=1, env_id="Flooring-v1", task_weights=None,
                                         total_timesteps=40))
    shutil.copytree(tmp_path / "campaign" / "scratch_s1", tmp_path / "campaign" / "scratch_s2")
    envs = list(fs.PAPER_TABLE_II)

    def tasks(placed):
        return {"command": "python scripts/evaluate.py ...", "checkpoint": "runs/snapshot.pt",
                "tasks": {e: dict(pick_success=1.0, place_success=placed, place_success_ci95=[0, 1]) for e in envs}}

    for seed, (validated, tested) in {1: (0.8, 0.97), 2: (0.9, 0.9)}.items():
        fs.seed_candidates(seed, "ppo").mkdir(parents=True)
        shutil.copyfile(tmp_path / "campaign" / f"scratch_s{seed}" / "checkpoint.pt",
                        fs.seed_candidates(seed, "ppo") / "candidate_40.pt")
        fs.chosen_json(seed, "ppo").parent.mkdir(parents=True, exist_ok=True)
        fs.chosen_json(seed, "ppo").write_text(json.dumps(dict(step=40, confirmed={"40": dict.fromkeys(envs, validated)})))
        fs.seed_evaluation_json(seed, 40, "ppo").write_text(json.dumps(tasks(tested)))
    fs.EVAL_JSON.write_text(json.dumps(tasks(0.95)))
    assert fs.ship_seeds(shipped, "ppo") is None and not shipped.exists(), "seed 2 is better on validation, worse on test"
    fs.EVAL_JSON.write_text(json.dumps(tasks(0.85)))
    assert fs.ship_seeds(shipped, "ppo") == shipped
    record = torch.load(shipped, weights_only=False)["campaign"]["record"]
    assert record["chosen"].startswith("seed 2 of 2") and "demonstrations: none" in record["chosen"]
    assert f"at commit {fs.recipe_commit('ppo')}" in record["chosen"] and fs.recipe_commit("ppo") != "unknown"
    now = json.loads(fs.EVAL_JSON.read_text())
    assert now["tasks"] == tasks(0.9)["tasks"], "its evaluation is the shipped policy's now"
    assert now["command"] == (f"python scripts/evaluate.py --checkpoint {shipped} --all --steps 50000 --seed 1000000 "
                              f"--json {fs.EVAL_JSON}")
    assert now["evaluated_as"] == dict(checkpoint="runs/snapshot.pt", json=str(fs.seed_evaluation_json(2, 40, "ppo")))


def test_sac_is_the_recipe_s_learner_and_its_run_keeps_screens_chooses_and_ships_snapshots_as_ppo_s_does(tmp_path,
                                                                                                         monkeypatch):
    """`--seed S` runs SAC (experiments/sac_recipe.py) unless `--learner ppo`: in parts of SNAPSHOT_EVERY env steps,
    each part's checkpoint kept as a snapshot and screened, the best committed as a candidate without the critics or
    the replay buffer (a policy only); at its end the rule chooses, the paper's protocol evaluates the choice, and
    `--ship-seeds` ships it with a record naming SAC and its recipe's commit."""
    from baselines.sac import sac
    from experiments import sac_recipe

    monkeypatch.setattr(fs, "CAMPAIGN_DIR", tmp_path / "campaign")
    monkeypatch.setattr(fs, "SNAPSHOT_DIR", tmp_path / "runs" / "snaps")
    monkeypatch.setattr(fs, "SEED_EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(fs, "EVAL_JSON", tmp_path / "shipped_eval.json")
    monkeypatch.setattr(fs, "SNAPSHOT_EVERY", 150)
    monkeypatch.setattr(fs, "CONFIRM_TOP", 1)
    assert fs.LEARNER == "sac" and fs.Args().learner == "sac"
    run = fs.seed_run(1)
    assert isinstance(run.args, sac.Args) and run.args == sac_recipe.sac_args(1) and run.name == "sac_s1"
    assert run.command == "python -m experiments.from_scratch --seed 1" and "demonstrations: none" in run.method
    assert fs.seed_run(1, learner="ppo").command == "python -m experiments.from_scratch --seed 1 --learner ppo"
    with pytest.raises(SystemExit, match="--learner td3: use one of sac, ppo"):
        fs.seed_run(1, learner="td3")
    envs = list(fs.PAPER_TABLE_II)
    screened, evaluated = {150: 0.4, 300: 0.7}, []

    def fake_validate(checkpoint, out, episodes, seed=fs.VALIDATION_SEED):
        step = torch.load(checkpoint, weights_only=False)["progress"]["global_step"]
        placed = dict.fromkeys(envs, screened[step] + (0.1 if episodes == fs.CONFIRM_EPISODES else 0.0))
        out.write_text(json.dumps(dict(tasks={e: dict(place_success=v, episode_results=[]) for e, v in placed.items()})))
        return placed

    def fake_paper_protocol(args):
        evaluated.append(args.checkpoint)
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(dict(command="python scripts/evaluate.py ...", checkpoint=str(args.checkpoint),
                                             tasks={e: dict(pick_success=1.0, place_success=0.95,
                                                            place_success_ci95=[0.9, 1.0]) for e in envs})))

    monkeypatch.setattr(fs, "validate", fake_validate)
    monkeypatch.setattr(fs.evaluation, "main", fake_paper_protocol)
    tiny = dataclasses.replace(run.args, num_envs=1, hidden_size=32, num_layers=1, batch_size=32, learning_starts=100,
                               buffer_size=1000, utd=1.0, log_freq=50, eval_freq=0, total_timesteps=300,
                               checkpoint_freq=150, log_dir=str(tmp_path / "campaign"), env_id="Flooring-v1")
    monkeypatch.setattr(fs, "seed_run", lambda seed, num_envs=None, learner=fs.LEARNER: dataclasses.replace(run, args=tiny))
    fs.main(fs.Args(seed=1))
    assert sorted(p.name for p in fs.seed_snapshots(1).glob("*.pt")) == ["checkpoint_150.pt", "checkpoint_300.pt"]
    assert fs.seed_screening(1) == {150: dict.fromkeys(envs, 0.4), 300: dict.fromkeys(envs, 0.7)}
    candidate = torch.load(fs.seed_candidates(1) / "candidate_300.pt", weights_only=False)
    # a candidate keeps what a new run starts from (sac.py --init-from), not what only resumes its run
    assert set(candidate["sac"]) == {"actor", "critics", "critics_target", "log_alpha"}
    assert "replay_buffer" not in candidate and "rng" not in candidate
    assert fs.chosen_step(1) == 300 and evaluated == [fs.seed_snapshots(1) / "checkpoint_300.pt"]
    assert fs.seed_evaluations(1) == {300: fs.seed_evaluation_json(1, 300)}
    # seed 2 as seed 1 (a copy), then the better on validation ships: it places what the shipped policy does
    shutil.copytree(tmp_path / "campaign" / "sac_s1", tmp_path / "campaign" / "sac_s2")
    for path in (fs.chosen_json(1), fs.seed_evaluation_json(1, 300)):
        shutil.copyfile(path, str(path).replace("sac_s1", "sac_s2"))
    fs.EVAL_JSON.write_text(json.dumps(dict(tasks={e: dict(place_success=0.95) for e in envs})))
    shipped = fs.ship_seeds(tmp_path / "scratch_general_agent.pt")
    policy = torch.load(shipped, weights_only=False)
    record = policy["campaign"]["record"]
    assert record["chosen"].startswith("seed 1 of 2") and "the recipe: SAC, sac_args of experiments/sac_recipe.py" \
        in record["chosen"] and "demonstrations: none" in record["chosen"]
    assert record["method"] == sac_recipe.METHOD and "h of training iterations" in record["wall time"]
    assert set(policy["sac"]) == {"actor", "critics", "critics_target", "log_alpha"}, "a new run can start from it"
    assert fs.shipped_how(shipped).startswith("SAC on the dense reward, no demonstrations; the recipe unchanged")
