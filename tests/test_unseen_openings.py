"""experiments/unseen_openings.py: the recipe with goal openings held out of training, and its report."""

import dataclasses
import json
from pathlib import Path

import gymnasium as gym
import pytest
import torch

from baselines.ppo import ppo
from experiments import from_scratch as fs
from experiments import unseen_openings as uo
from ms_construction.envs import PAPER_TASK_ENV_IDS, TASK_ENV_IDS


def test_the_run_is_the_recipe_with_the_held_out_openings_never_drawn_in_training(monkeypatch):
    run = uo.seed_run(3, num_envs=2)
    ppo.validate(run.args)
    recipe = fs.scratch_args(2, seed=3, exp_name="unseen_s3").flat()
    changed = {k for k, v in run.args.flat().items() if recipe[k] != v}
    assert changed == {"goal_slot_weights"} and "demonstrations: none" in run.method
    made = {}
    monkeypatch.setattr(ppo, "CPUVectorEnv", lambda env_id, n, kwargs, **_: made.setdefault(len(made), kwargs))
    ppo.make_envs(run.args, 2, torch.device("cpu"))
    ppo.make_envs(run.args, 2, torch.device("cpu"), eval_mode=True)
    drawn = []
    for kwargs in made.values():
        env = gym.make(run.args.env_id, num_envs=1, **kwargs)
        slots = set()
        for seed in range(40):
            env.reset(seed=seed)
            slots.add(int(env.unwrapped.goal_slot[0]))
        drawn.append(slots)
        env.close()
    training, evaluating = drawn
    assert training == set(uo.TRAINED) and evaluating == set(uo.TRAINED) | set(uo.HELD_OUT)


def test_sac_s_run_is_the_recipe_s_sac_with_the_held_out_openings_never_drawn_in_training():
    """`--seed S` (SAC, the default learner): experiments/sac_recipe.py's SAC but for its name and the goal slots its training envs draw (its
    evaluations during training draw every slot: tests/test_sac.py)."""
    from experiments import sac_recipe

    run = uo.sac_run(2)
    changed = {k for k, v in vars(run.args).items() if v != vars(sac_recipe.sac_args(2))[k]}
    assert changed == {"exp_name", "goal_slots"} and run.args.goal_slots == uo.TRAINED
    assert run.command == "python -m experiments.unseen_openings --seed 2 --learner sac"
    assert run.method == sac_recipe.METHOD  # its campaign record says SAC, not the paper setting
    assert uo.Args().learner == fs.LEARNER == "sac", "the recipe's learner unless --learner ppo"
    assert uo.seed_run(2).command == "python -m experiments.unseen_openings --seed 2 --learner ppo"
    with pytest.raises(SystemExit, match="--learner td3: use one of sac, ppo"):
        uo.main(uo.Args(seed=1, learner="td3", dry_run=True))


def test_the_report_tables_unseen_and_seen_openings_per_seed(tmp_path, monkeypatch):
    monkeypatch.setattr(uo, "EVAL_DIR", tmp_path)
    for seen, placed in ((False, 0.5), (True, 0.9)):
        tasks = {e: dict(place_success=placed, place_success_ci95=(placed - 0.1, placed + 0.05)) for e in TASK_ENV_IDS.values()}
        uo.evaluation_json(1, seen).write_text(json.dumps({"tasks": tasks}))
    body = uo.report(tmp_path / "RESULTS.md")
    assert "| PPO from nothing, seed 1 | - | never trained on (1) | 50.0 [40.0, 55.0] |" in body
    assert "| PPO from nothing, seed 1 | - | trained on (0, 2) | 90.0" in body
    uo.evaluation_json("imitation", False).write_text(json.dumps({"tasks": tasks}))
    assert uo.evaluation_json("imitation", False).name == "unseen_imitation_unseen.json"
    body = uo.report(tmp_path / "RESULTS.md")
    assert "| imitation (clone + residual PPO) | - | never trained on (1) | 90.0" in body
    for policy, step, cell in (("imitation", 400_000, "400,000 of PPO on the clone"),
                               ("imitation_clone", 0, "none: demonstrations only")):
        uo.evaluation_json(policy, True).write_text(json.dumps({"tasks": tasks, "checkpoint_step": step}))
        assert f"| {uo.run_label(policy)} | {cell} | trained on (0, 2) | 90.0" in uo.report(tmp_path / "RESULTS.md")
    assert uo.evaluation_json("imitation_clone", True).name == "unseen_imitation_clone_seen.json"
    uo.evaluation_json("sac_s2", True).write_text(json.dumps({"tasks": tasks, "checkpoint_step": 350_000}))
    assert uo.evaluation_json("sac_s2", True).name == "unseen_sac_s2_seen.json"
    assert "| SAC from nothing, seed 2 | 350,000 | trained on (0, 2) | 90.0" in uo.report(tmp_path / "RESULTS.md")
    assert "unseen-openings" in (tmp_path / "RESULTS.md").read_text()
    # the planning expert's rows lead: it trains on none, and says how many episodes it ran
    uo.expert_json(False).write_text(json.dumps({"tasks": tasks, "episodes_per_task": 60}))
    body = uo.report(tmp_path / "RESULTS.md")
    expert = "| planning expert | none: it plans each episode (60 per task) | never trained on (1) | 90.0"
    assert expert in body and body.index(expert) < body.index("| PPO from nothing, seed 1 |")
    with pytest.raises(SystemExit, match="--seed S"):
        uo.main(uo.Args())


def test_the_imitation_twins_dry_run_runs_nothing_and_says_how_far_it_has_come(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(uo, "IMITATION_DIR", tmp_path / "imitation")
    monkeypatch.setattr(uo, "EVAL_DIR", tmp_path / "evaluations")
    monkeypatch.setattr(uo, "imitation", lambda *a, **k: pytest.fail("a dry run trained"))
    monkeypatch.setattr(uo, "KEPT_CLONE", tmp_path / "kept.pt")
    uo.main(uo.Args(imitation=True, dry_run=True))
    plan = capsys.readouterr().out
    assert "goal openings 0, 2 (held out: 1)" in plan and plan.count("not started") == 2 and plan.count("not yet") == 4
    (tmp_path / "imitation" / "clone" / "bc0").mkdir(parents=True)
    (tmp_path / "imitation" / "clone" / "bc0" / "checkpoint.pt").write_bytes(b"")
    (tmp_path / "evaluations").mkdir()
    uo.evaluation_json("imitation", False).write_text("{}")
    plan = uo.imitation_plan(tmp_path / "imitation")
    assert "- clone:" in plan and "1 file in" in plan and plan.count("not started") == 1
    assert "(clone + residual PPO), on the held-out openings: done" in plan and plan.count("not yet") == 3


def test_the_imitation_twin_demonstrates_clones_refines_and_validates_on_the_trained_openings_only(tmp_path, monkeypatch):
    """`--imitation` on a tiny budget, end to end: every stage that draws episodes (demonstrations, the clone's
    validation, the bank, PPO's training envs, the refinement's validations) is given the trained openings only,
    and the result is a policy."""
    from baselines.ppo import evaluation
    from experiments import general_agent, refine
    from ms_construction.planning import demos

    seen = []

    def spy(module, name, take):
        real = getattr(module, name)

        def wrapped(*args, **kwargs):
            seen.append((name, take(*args, **kwargs)))
            return real(*args, **kwargs)

        monkeypatch.setattr(module, name, wrapped)

    monkeypatch.setattr(uo, "KEPT_CLONE", tmp_path / "no_kept_clone.pt")
    weights = evaluation.slot_weights(uo.TRAINED)
    spy(general_agent, "record_demos", lambda *a, **k: k["env_kwargs"] == {"goal_slot_weights": weights})
    spy(refine, "collect_failure_states", lambda *a, **k: k["env_kwargs"] == {"goal_slot_weights": weights})
    spy(evaluation, "main", lambda args: args.goal_slots == uo.TRAINED)
    spy(ppo, "main", lambda args: args.starts.goal_slot_weights == evaluation.training_slot_weights(uo.TRAINED))
    cloned, policy = uo.imitation(tmp_path, clone=dict(demos=2, window_demos=0, flooring_demos=0, validation_episodes=1,
                                               bc_epochs=2, workers=1),
                          refine_args=dict(bank_episodes=2, total_timesteps=40, num_envs=2, num_steps=20,
                                           validate_every=40, validation_episodes=1, confirmation_episodes=1))
    assert cloned.is_file() and policy.is_file() and cloned != policy
    assert demos.tried_episodes(tmp_path / "clone" / "demos" / "general.npz") == 2
    assert {name for name, _ in seen} == {"record_demos", "collect_failure_states", "main"}
    assert all(ok for _, ok in seen), seen


def test_on_a_machine_without_its_demonstrations_the_twin_refines_the_committed_clone(tmp_path, monkeypatch):
    """Where the run directory holds no clone, the committed one (KEPT_CLONE) is refined: no demonstrations are
    recorded again; where it holds one (the machine that made it), its own stages run as before."""
    from experiments import general_agent, refine

    kept = tmp_path / "kept.pt"
    kept.write_bytes(b"clone")
    monkeypatch.setattr(uo, "KEPT_CLONE", kept)
    refined = []
    monkeypatch.setattr(refine, "main", lambda args: refined.append(args) or tmp_path / "refined.pt")
    monkeypatch.setattr(general_agent, "main", lambda args: pytest.fail("recorded demonstrations again"))
    assert "- clone:" in uo.imitation_plan(tmp_path / "fresh") and f"the committed one, {kept}" in uo.imitation_plan(tmp_path / "fresh")
    assert uo.imitation(tmp_path / "fresh") == (kept, tmp_path / "refined.pt")
    assert refined[0].clone == kept and refined[0].goal_slots == uo.TRAINED
    own = tmp_path / "made_here"
    (own / "clone").mkdir(parents=True)
    monkeypatch.setattr(general_agent, "main", lambda args: args.run_dir / "bc0" / "checkpoint.pt")
    assert uo.imitation(own)[0] == own / "clone" / "bc0" / "checkpoint.pt"
    assert Path(uo.__file__).parents[1].joinpath("campaign", "unseen_imitation", "clone.pt").is_file(), \
        "the twin's clone is committed"


def test_the_expert_s_demonstrations_draw_the_goal_slots_their_kwargs_allow():
    from baselines.ppo import evaluation
    from ms_construction.planning.demos import DemoCollector

    collector = DemoCollector("ConstructionPickPlace-v1", env_kwargs={"goal_slot_weights": evaluation.slot_weights(uo.TRAINED)})
    drawn = set()
    for seed in range(30):
        collector.env.reset(seed=seed)
        drawn.add(int(collector.env.unwrapped.goal_slot[0]))
    collector.close()
    assert drawn == set(uo.TRAINED)


def test_a_sac_run_keeps_its_snapshots_and_the_curve_measures_each_once_on_both_sets_of_openings(tmp_path,
                                                                                                  monkeypatch):
    """`--seed S` (SAC) keeps its checkpoint at each part's end (parts of CURVE_EVERY, still stopping only at a
    STOP_EVERY mark by which its training episodes placed 90%); `--curve` measures each kept snapshot on the held-out
    and the trained openings from the validation seeds, once, and plots them; the report shows the plot."""
    from experiments import transfer

    monkeypatch.setattr(uo, "SNAPSHOT_DIR", tmp_path / "snaps")
    monkeypatch.setattr(uo, "EVAL_DIR", tmp_path / "evals")
    monkeypatch.setattr(uo, "CURVE_PLOT", tmp_path / "docs" / "images" / "curve.png")
    monkeypatch.setattr(transfer, "STOP_EVERY", 200)
    monkeypatch.setattr(transfer, "steps_to", lambda progress, *a, **k: 50)  # placed 90% from the start
    run = uo.sac_run(2)
    run = dataclasses.replace(run, args=dataclasses.replace(
        run.args, num_envs=1, hidden_size=32, num_layers=1, batch_size=32, learning_starts=50, buffer_size=1000,
        utd=1.0, log_freq=50, eval_freq=0, total_timesteps=1000, checkpoint_freq=100,
        log_dir=str(tmp_path / "campaign"), env_id="Flooring-v1"))
    monkeypatch.setattr(uo, "sac_run", lambda seed: run)
    with pytest.raises(ValueError, match="a divisor of 200"):
        transfer.train(run, stop_at_target=True, snapshots=(150, None))
    with pytest.raises(SystemExit, match="--until 300: a multiple of 200"):
        transfer.train(run, stop_at_target=True, until=300)
    transfer.train(run, stop_at_target=True, snapshots=(100, lambda step, ckpt: uo.keep_snapshot(run, step, ckpt)))
    kept = sorted(p.name for p in (tmp_path / "snaps" / run.name).glob("*.pt"))
    assert kept == ["checkpoint_100.pt", "checkpoint_200.pt"], "a snapshot per part; no stop at 100, between marks"
    # --until: the same run, its target long reached, goes on past the mark at 200 to the one at 400
    transfer.train(run, stop_at_target=True, until=400,
                   snapshots=(100, lambda step, ckpt: uo.keep_snapshot(run, step, ckpt)))
    kept = sorted(p.name for p in (tmp_path / "snaps" / run.name).glob("*.pt"))
    assert kept == [f"checkpoint_{s}.pt" for s in (100, 200, 300, 400)]
    measured = []

    def fake_evaluation(args):
        measured.append((args.checkpoint.name, args.goal_slots, args.episodes, args.seed))
        placed = 0.2 if args.goal_slots == uo.HELD_OUT else 0.9
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"tasks": {e: dict(place_success=placed) for e in TASK_ENV_IDS.values()}}))

    monkeypatch.setattr(uo.evaluation, "main", fake_evaluation)
    uo.main(uo.Args(seed=2, curve=True))
    assert measured == [(f"checkpoint_{s}.pt", slots, uo.CURVE_EPISODES, uo.CURVE_SEED)
                        for s in (100, 200, 300, 400) for slots in (uo.HELD_OUT, uo.TRAINED)]
    points = uo.curve_points(2)
    assert list(points) == [100, 200, 300, 400]
    assert json.loads(points[200][False].read_text())["checkpoint_step"] == 200
    uo.main(uo.Args(seed=2, curve=True))
    assert len(measured) == 8, "a snapshot measured is not measured again"
    assert uo.CURVE_PLOT.is_file()
    monkeypatch.setattr(uo, "CURVE_PLOT", Path("docs/images/unseen_openings_curve.png"))
    assert "![the openings over training](images/unseen_openings_curve.png)" in uo.report(tmp_path / "RESULTS.md")

    # the paper's protocol at 200, then at 400: the evaluation at 200 is kept beside the latest, both rowed
    def fake_protocol(args):
        placed = 0.2 if args.goal_slots == uo.HELD_OUT else 0.9
        args.json.write_text(json.dumps({"tasks": {e: dict(place_success=placed, place_success_ci95=(placed, placed))
                                                   for e in TASK_ENV_IDS.values()}}))

    monkeypatch.setattr(uo.evaluation, "main", fake_protocol)
    snaps = tmp_path / "snaps" / run.name
    uo.evaluate(snaps / "checkpoint_200.pt", "sac_s2")
    uo.evaluate(snaps / "checkpoint_200.pt", "sac_s2")  # the same env steps again: replaced, not kept twice
    uo.evaluate(snaps / "checkpoint_400.pt", "sac_s2")
    assert sorted(p.name for p in (tmp_path / "evals").glob("unseen_sac_s2_*.json")) == [
        "unseen_sac_s2_seen.json", "unseen_sac_s2_seen_200.json", "unseen_sac_s2_unseen.json",
        "unseen_sac_s2_unseen_200.json"]
    rows = [line for line in uo.report(tmp_path / "RESULTS.md").splitlines() if "seed 2" in line]
    assert [row.split(" | ")[1:3] for row in rows] == [["200", "never trained on (1)"], ["200", "trained on (0, 2)"],
                                                       ["400", "never trained on (1)"], ["400", "trained on (0, 2)"]]


def test_a_policy_evaluated_as_it_is_is_not_evaluated_again(tmp_path, monkeypatch):
    """The twin's rerun skips a policy both of whose evaluations name it and record its sha256, whatever the file
    times (a fresh clone's are checkout times); one remade at the same path (another hash) or never evaluated is
    evaluated. An evaluation from before the hash was recorded counts where it was written after the policy."""
    import json
    import os

    from ms_construction.assets import sha256

    monkeypatch.setattr(uo, "EVAL_DIR", tmp_path)
    policy = tmp_path / "checkpoint_300000.pt"
    policy.write_bytes(b"policy")
    assert not uo.evaluated(policy, "imitation")
    for seen in (False, True):
        uo.evaluation_json("imitation", seen).write_text(json.dumps({"checkpoint": str(policy)}))
    os.utime(policy, (0, 0))
    assert uo.evaluated(policy, "imitation")
    other = tmp_path / "other.pt"
    other.write_bytes(b"another policy")
    os.utime(other, (0, 0))
    assert not uo.evaluated(other, "imitation"), "the evaluations name another checkpoint"
    os.utime(policy)  # remade after its evaluations
    assert not uo.evaluated(policy, "imitation")
    for seen in (False, True):  # evaluations that record the policy's hash
        uo.evaluation_json("imitation", seen).write_text(json.dumps({"checkpoint": str(policy),
                                                                     "checkpoint_sha256": sha256(policy)}))
    os.utime(uo.evaluation_json("imitation", True), (0, 0))  # older than the policy: the hash decides
    assert uo.evaluated(policy, "imitation")
    policy.write_bytes(b"a policy trained again")
    assert not uo.evaluated(policy, "imitation")


def test_the_expert_runs_on_the_openings_it_is_given_and_its_json_has_the_report_s_shape(tmp_path, monkeypatch):
    """`--expert`: scripts/run_expert.py with `goal_slots` draws those openings only (here on one real episode per
    task), and the JSON holds per task what the report reads."""
    from scripts import run_expert

    monkeypatch.setattr(uo, "EVAL_DIR", tmp_path)
    monkeypatch.setattr(uo, "HELD_OUT", (2,))
    monkeypatch.setattr(uo, "TRAINED", (0,))
    uo.evaluate_expert(episodes=1, workers=1)
    for seen, slot in ((False, 2), (True, 0)):
        data = json.loads(uo.expert_json(seen).read_text())
        assert data["goal_slots"] == [slot] and data["episodes_per_task"] == 1
        assert {e["goal_slot"] for results in data["episodes"].values() for e in results} == {slot}
        for env_id in PAPER_TASK_ENV_IDS.values():
            task = data["tasks"][env_id]
            assert task["episodes"] == 1 and task["place_success"] in (0.0, 1.0) and len(task["place_success_ci95"]) == 2
    assert run_expert.Args().goal_slots == (), "every opening unless asked"
