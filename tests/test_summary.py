"""RESULTS' first screen (experiments/summary.py): every number comes from the JSON its row names, the latest
evaluation of each seed of the recipe (the snapshot rule's choice once made), and a dash where a file is not there yet."""

import json

from experiments import from_scratch
from experiments import summary as sm


def _tasks(placed: float) -> dict:
    return {t: {"pick_success": 1.0, "place_success": placed, "place_success_ci95": [0.0, 1.0]} for t in sm.TASKS}


def test_each_row_reads_its_file_and_a_seed_shows_its_latest_evaluation(tmp_path, monkeypatch):
    monkeypatch.setattr(from_scratch, "SEED_EVAL_DIR", tmp_path)
    for step, placed in ((4_000_000, 0.5), (6_000_000, 0.925)):
        from_scratch.seed_evaluation_json(1, step, "ppo").write_text(json.dumps({"tasks": _tasks(placed)}))
    body = sm.summary()
    assert "| the paper's general agent (Table II, cp4) | PPO + ICM (ML-Agents), Table I's stages, 8M env steps | " \
           "68.04 | 84.82 | 85.17 | the paper |" in body
    label, _, path = sm.AGENTS[0]
    shipped = json.loads(path.read_text())["tasks"]
    row = next(line for line in body.splitlines() if line.startswith(f"| {label} |"))
    assert row.split(" | ")[2:5] == [f"{100 * shipped[t]['place_success']:.1f}" for t in sm.TASKS]
    seed1 = next(line for line in body.splitlines() if "the recipe from nothing (PPO), seed 1" in line)
    assert "at 6,000,000 env steps" in seed1 and seed1.count("| 92.5 ") == 3
    assert "(its run has not ended: `python -m experiments.from_scratch --seed 2 --learner ppo` runs it" in body
    assert "| the recipe from nothing (SAC), seed 1 | (its run has not ended: `python -m experiments.from_scratch " \
           "--seed 1` runs it" in body, "SAC is the recipe's learner: its command needs no --learner"
    from_scratch.chosen_json(1, "ppo").parent.mkdir()
    from_scratch.chosen_json(1, "ppo").write_text(json.dumps({"step": 4_000_000}))
    seed1 = next(line for line in sm.summary().splitlines() if "the recipe from nothing (PPO), seed 1" in line)
    assert "at 4,000,000 env steps (the snapshot rule's choice)" in seed1 and seed1.count("| 50.0 ") == 3
    # once shipped, the seed's choice is the reward-only agent's row, not a second row of the same policy
    shipped_eval = tmp_path / "shipped_eval.json"
    shipped_eval.write_text(json.dumps({"tasks": _tasks(0.5), "evaluated_as": {
        "json": str(from_scratch.seed_evaluation_json(1, 4_000_000, "ppo"))}}))
    monkeypatch.setattr(from_scratch, "EVAL_JSON", shipped_eval)
    body = sm.summary()
    assert "the recipe from nothing (PPO), seed 1" not in body and "the recipe from nothing (PPO), seed 2" in body


def test_a_sac_seed_s_evaluation_is_a_row_with_its_env_steps(tmp_path, monkeypatch):
    """SAC's seeds (`python -m experiments.from_scratch --seed S --evaluate`): a row each where an evaluation is
    there, its latest until the snapshot rule has chosen."""
    monkeypatch.setattr(from_scratch, "SEED_EVAL_DIR", tmp_path)
    assert "(SAC), seed 2, at" not in sm.summary()
    from_scratch.seed_evaluation_json(2, 300_368, "sac").write_text(json.dumps({"tasks": _tasks(0.975)}))
    row = next(line for line in sm.summary().splitlines() if "the recipe from nothing (SAC), seed 2" in line)
    assert row.startswith("| the recipe from nothing (SAC), seed 2, at 300,368 env steps (its latest evaluated "
                          "snapshot, not yet chosen) | SAC on") and row.count("| 97.5 ") == 3


def test_a_file_not_there_yet_shows_a_dash_and_the_section_lands_between_its_markers(tmp_path, monkeypatch):
    monkeypatch.setattr(sm, "OBSTACLES", tmp_path / "none.json")
    monkeypatch.setattr(sm, "PANELING", tmp_path / "none.json")
    rows = sm.generalization_table()[2:]
    assert len(rows) == len(sm.GENERALIZATION) and all(row.count("| - ") == 3 for row in rows)
    results = tmp_path / "RESULTS.md"
    results.write_text("# Results\n\nintro\n\n<!-- begin summary (generated) -->\nold\n<!-- end summary -->\n\n## next\n")
    monkeypatch.setattr(sm, "RESULTS_PATH", results)
    sm.main()
    text = results.read_text()
    assert "old" not in text and text.index("## At a glance") < text.index("## next") and text.startswith("# Results")


def test_the_trained_generalization_rows_are_the_runs_evaluated_their_setting_learner_seed_and_steps_in_columns(tmp_path, monkeypatch):
    from experiments import paneling
    from experiments import unseen_openings as uo

    monkeypatch.chdir(tmp_path)  # every evaluation's path is relative to the repository: none is here
    monkeypatch.setattr(sm, "OBSTACLES", tmp_path / "obstacles.json")
    assert sm.trained_table()[2:] == []
    sac = paneling.training_run("nothing", 2, learner="sac")
    paneling.train_eval_json(sac).parent.mkdir(parents=True)
    paneling.train_eval_json(sac).write_text(json.dumps({"env_id": paneling.ENV_ID, "place_success": 0.95,
                                                         "checkpoint_step": 250_000}))
    uo.EVAL_DIR.mkdir(parents=True)
    uo.evaluation_json("sac_s1", seen=False).write_text(json.dumps({"tasks": _tasks(0.25), "checkpoint_step": 300_000}))
    uo.evaluation_json("sac_s1", seen=True).write_text(json.dumps({"tasks": _tasks(1.0), "checkpoint_step": 300_000}))
    # the imitation clone had no RL: its row says so, not "0 env steps"
    uo.evaluation_json("imitation_clone", seen=False).write_text(json.dumps({"tasks": _tasks(0.0),
                                                                             "checkpoint_step": 0}))
    from experiments import obstacles

    today = obstacles.OBSTACLE_REWARD
    shown, earlier = ("shipped", "sac", 0.5, today, 2, 100), ("shipped", "sac", 0.5, 3, 1, 100)
    monkeypatch.setattr(obstacles, "SHOWN", (earlier, shown, ("nothing", "sac", 1.0, today, 1, 200)))
    label = obstacles.trained_label(*shown)
    uo.expert_json(seen=False).write_text(json.dumps({"tasks": _tasks(1.0)}))  # the expert beside the learners
    (tmp_path / "obstacles.json").write_text(json.dumps({"rows": {  # the third snapshot not evaluated
        f"{label} | moving (solvable seeds)": _tasks(0.5), f"{label} | none (solvable seeds)": _tasks(0.0),
        f"{obstacles.trained_label(*earlier)} | moving (solvable seeds)": _tasks(0.75),  # an earlier version's
        "planning expert | moving (solvable seeds)": _tasks(1.0)}}))
    rows = sm.trained_table()[2:]
    assert rows == [
        f"| paneling | SAC from nothing | 2 | 250,000 | 95.0 | {paneling.train_eval_json(sac)} |",
        f"| openings 0 and 2 (placed at 1, never trained on) | planning expert (plans each episode, trains on none) | "
        f"- | - | 100.0 / 100.0 / 100.0 | {uo.expert_json(seen=False)} |",
        f"| openings 0 and 2 (placed at 1, never trained on) | SAC from nothing | 1 | 300,000 | 25.0 / 25.0 / 25.0 | "
        f"{uo.evaluation_json('sac_s1', seen=False)} |",
        f"| openings 0 and 2 (placed at 1, never trained on) | imitation: its clone alone | - | "
        f"none: demonstrations only | 0.0 / 0.0 / 0.0 | {uo.evaluation_json('imitation_clone', seen=False)} |",
        f"| moving obstacles in 50% of episodes, {obstacles.version_name(today)} | SAC from SAC's agent | 2 | 100 | "
        f"50.0 / 50.0 / 50.0 (the site as built: 0.0 / 0.0 / 0.0) | {tmp_path / 'obstacles.json'} |"]


def test_the_seeds_evaluation_table_shows_each_seed_s_chosen_snapshot_or_its_latest(tmp_path, monkeypatch):
    """experiments/from_scratch.py's table beside Table II: one row per learner and seed, the rule's choice once made
    (not its latest), the latest evaluated before; every evaluated snapshot is the learners' section's."""
    monkeypatch.setattr(from_scratch, "SEED_EVAL_DIR", tmp_path)
    for step, placed in ((4_000_000, 0.5), (6_000_000, 0.925)):
        from_scratch.seed_evaluation_json(1, step, "ppo").write_text(json.dumps({"tasks": _tasks(placed)}))
    rows = [line for line in from_scratch.seed_evaluations_table() if line.startswith("| PPO |")]
    assert rows == ["| PPO | 1 | 6,000,000 | " + " | ".join(["100.0 / 92.5 [0.0, 100.0]"] * 3)
                    + " | the latest, not yet chosen |"]
    from_scratch.chosen_json(1, "ppo").parent.mkdir()
    from_scratch.chosen_json(1, "ppo").write_text(json.dumps({"step": 4_000_000}))
    rows = [line for line in from_scratch.seed_evaluations_table() if line.startswith("| PPO |")]
    assert rows == ["| PPO | 1 | 4,000,000 | " + " | ".join(["100.0 / 50.0 [0.0, 100.0]"] * 3)
                    + " | **the rule chose it** |"]
