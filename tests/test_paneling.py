"""Paneling, the fourth task type: its site (the partition, built only where paneling is asked for), its goals and
start paths, the expert, and the shipped checkpoints acting unchanged on the observation's new task slot."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import sapien
import torch
from mplib.pymp.collision_detection import fcl

from baselines.ppo.checkpoints import load_checkpoint, load_policy, make_agent
from baselines.ppo.update import adam
from ms_construction.assets import ASSET_DIR, load_manifest
from ms_construction.envs.state_layout import STATE_TASK_START, TASK_SLOTS_BEFORE_PANELING
from ms_construction.goal_configurations import PATH_CHECKS, START_TURNS_DEG, path_point, start_paths
from ms_construction.parameters import ELEMENT_KINDS, PAPER_KINDS
from ms_construction.planning import MotionPlanningExpert
from ms_construction.planning.collision_model import load_convex_parts
from ms_construction.planning.site_check import install_sweep_hits
from tests.helpers import PLAN_TRIES, TEST_EXPERT_CONFIG, make_env

ROOT = Path(__file__).resolve().parent.parent
SHIPPED_OUTPUTS = Path(__file__).parent / "data" / "shipped_policy_outputs.npz"
"""Actions and values of shipped checkpoints on 72 observations of the paper's three task types each (six seeded
episodes of the general task, the policy's own first 12 steps), computed by the code of commit ed49227, before
paneling: the observations there have the three-slot task one-hot."""
BEFORE_PANELING = {"scratch_general_agent": Path(__file__).parent / "data" / "scratch_general_agent_before_paneling.pt"}
"""checkpoints of SHIPPED_OUTPUTS kept here: the first campaign's reward-only agent, the from-scratch agent from before
paneling, which assets/checkpoints/scratch_general_agent.pt held until `experiments.from_scratch --ship-seeds` shipped
the recipe's better seed there."""


def _partition_parts(manifest: dict) -> list[str]:
    return [name for name, part in manifest["parts"].items() if part.get("task") == "paneling"]


def test_the_partition_is_built_only_where_paneling_is_a_task_type():
    manifest = load_manifest()
    partition = _partition_parts(manifest)
    assert partition == ["partition_frame", "partition_boards"]
    for env_id, kwargs, has in (("PanelInstallation-v1", {}, True), ("ConstructionPickPlace-v1", {}, False),
                                ("WindowInstallation-v1", {}, False),
                                ("ConstructionPickPlace-v1", dict(tasks=ELEMENT_KINDS), True)):
        env = make_env(env_id, **kwargs)
        env.reset(seed=0)
        names = set(env.unwrapped.scene.actors)
        assert all((name in names) == has for name in partition), (env_id, kwargs)
        env.close()


def test_the_general_task_samples_paneling_only_when_asked_and_marks_it_in_the_one_hot():
    env = make_env("ConstructionPickPlace-v1")
    seen = set()
    for seed in range(12):
        obs, info = env.reset(seed=seed)
        seen.add(int(info["task_id"][0]))
        one_hot = obs[0, STATE_TASK_START:STATE_TASK_START + len(ELEMENT_KINDS)]
        assert one_hot.tolist() == np.eye(len(ELEMENT_KINDS))[int(info["task_id"][0])].tolist()
    assert seen == {0, 1, 2}
    env.close()
    env = make_env("ConstructionPickPlace-v1", tasks=ELEMENT_KINDS)
    kinds = {int(env.reset(seed=seed)[1]["task_id"][0]) for seed in range(24)}
    assert kinds == {0, 1, 2, 3}
    env.close()


def test_a_panel_set_at_its_goal_in_every_bay_is_placed_and_the_way_in_is_free():
    assert all(not found for (kind, _), found in install_sweep_hits(load_manifest(), ("paneling",)).items())
    env = make_env("PanelInstallation-v1")
    u = env.unwrapped
    for slot in range(3):
        env.reset(seed=slot)
        u.goal_slot[:] = slot
        u._place_goal_markers(torch.arange(1))
        goal = u._goal_table[u.task_id, u.goal_slot]
        assert abs(float(goal[0, 1]) - (load_manifest()["site_params"]["partition_face_y"] - 0.0125)) < 1e-6
        u.obj.set_pose(sapien.Pose(goal[0, :3].numpy(), goal[0, 3:].numpy()))
        info = u.get_info()
        assert float(info["place_dist"][0]) < 1e-5 and float(info["place_angle_deg"][0]) < 0.1  # float32 rounding
    env.close()


def test_the_papers_start_paths_keep_clear_of_the_partition():
    """The paper's task types keep their start paths (computed on their own site) in an env with paneling too."""
    from ms_construction.goal_configurations import _path_planners

    import tempfile

    manifest = load_manifest()
    partition = {f"{name}/{i}": fcl.CollisionObject(fcl.Convex(v, f), np.zeros(3), np.array([1.0, 0, 0, 0]))
                 for name in _partition_parts(manifest)
                 for i, (v, f) in enumerate(load_convex_parts(ASSET_DIR / manifest["parts"][name]["collision"]))}
    paths = start_paths()
    with tempfile.TemporaryDirectory() as workdir:
        for k, kind in enumerate(PAPER_KINDS):
            planners = _path_planners(workdir, kind, partition)
            for index in zip(*np.nonzero(paths.usable[k])):
                for a in np.linspace(0.0, 1.0, PATH_CHECKS + 1):
                    q = path_point(paths.waypoints[(k, *index)], a)
                    for planner, turn in zip(planners, START_TURNS_DEG):
                        shifted = q.copy()
                        shifted[5] += np.deg2rad(turn)
                        assert not planner.collides(shifted), (kind, index, a, turn, planner.contacts(shifted))


def test_paneling_has_a_wholly_clear_start_path_at_every_bay():
    k = ELEMENT_KINDS.index("paneling")
    assert (start_paths().free[k].max(axis=(1, 2)) >= 1.0).all()


def test_the_expert_installs_a_panel_in_every_bay():
    env = make_env("PanelInstallation-v1")
    expert = MotionPlanningExpert(env, TEST_EXPERT_CONFIG)
    try:
        for slot in range(3):
            seeds = [s for s in range(40) if int(env.reset(seed=s)[1]["task_id"][0]) == 3
                     and int(env.unwrapped.goal_slot[0]) == slot][:PLAN_TRIES]
            results = [expert.run(seed) for seed in seeds]
            assert any(r.placed for r in results), [r.failure for r in results]
    finally:
        expert.close()
        env.close()


@pytest.mark.parametrize("name", ["general_agent", "general_agent_clone_direct", "paper_general_agent",
                                  "scratch_general_agent", "control_window"])
def test_shipped_checkpoints_act_as_before_on_the_papers_tasks(name):
    """A checkpoint from before paneling reads the task one-hot's new slot with zero weights: on the paper's task
    types (the slot is 0) its actions and values are those the code before paneling computed."""
    saved = np.load(SHIPPED_OUTPUTS)
    path = BEFORE_PANELING.get(name, ROOT / "assets" / "checkpoints" / f"{name}.pt")
    agent, _ = load_policy(path, "ConstructionPickPlace-v1")
    old = torch.as_tensor(saved[f"{name}/obs"])
    at = STATE_TASK_START + TASK_SLOTS_BEFORE_PANELING
    obs = torch.cat([old[:, :at], torch.zeros(len(old), 1), old[:, at:]], 1)
    with torch.no_grad():
        assert torch.allclose(agent.get_action(obs, deterministic=True), torch.as_tensor(saved[f"{name}/action"]),
                              atol=1e-5)
        assert torch.allclose(agent.get_value(obs), torch.as_tensor(saved[f"{name}/value"]), atol=1e-4)
        paneling = obs.clone()
        paneling[:, STATE_TASK_START:STATE_TASK_START + len(ELEMENT_KINDS)] = torch.eye(len(ELEMENT_KINDS))[3]
        assert torch.isfinite(agent.get_action(paneling, deterministic=True)).all()


def test_an_old_run_resumes_with_the_new_slot_held_at_zero():
    """A checkpoint saved before paneling resumes: the shipped imitation agent (a residual with its Adam state) gains
    the new input with zero weights and zero Adam moments, and an update on the paper's task types leaves those
    weights at 0; the from-scratch agent's per-task-type curricula gain paneling's entries, the others unchanged."""
    raw = torch.load(ROOT / "assets/checkpoints/general_agent.pt", map_location="cpu", weights_only=False)
    assert raw.get("task_slots") is None and raw["optimizer"] is not None, "a checkpoint from before paneling"
    ckpt = load_checkpoint(ROOT / "assets/checkpoints/general_agent.pt")
    assert ckpt["obs_dim"] == raw["obs_dim"] + 1 and ckpt["task_slots"] == len(ELEMENT_KINDS)
    agent = make_agent(ckpt["args"], ckpt["obs_dim"], ckpt["act_dim"], ckpt.get("base_args"))
    agent.load_state_dict(ckpt["agent"])
    optimizer = adam([p for p in agent.parameters() if p.requires_grad], lr=3e-4, eps=1e-5)
    optimizer.load_state_dict(ckpt["optimizer"])
    zero = lambda w: [i for i in range(w.shape[1]) if w[:, i].abs().sum() == 0]  # noqa: E731
    columns = zero(agent.residual_mean[0].weight)
    assert len(columns) == 1 and zero(agent.critic[0].weight) == columns
    obs = torch.randn(64, ckpt["obs_dim"])
    obs[:, STATE_TASK_START:STATE_TASK_START + len(ELEMENT_KINDS)] = torch.eye(len(ELEMENT_KINDS))[torch.arange(64) % 3]
    _, logp, _, value = agent.get_action_and_value(obs)
    (value.square().mean() - logp.mean()).backward()
    optimizer.step()
    assert zero(agent.residual_mean[0].weight) == columns and zero(agent.critic[0].weight) == columns
    assert zero(agent.base.actor_mean[0].weight) == columns, "the frozen base reads the new slot with zero weights too"

    old = torch.load(BEFORE_PANELING["scratch_general_agent"], map_location="cpu", weights_only=False)
    progress = load_checkpoint(BEFORE_PANELING["scratch_general_agent"])["progress"]
    assert progress["near_goal_radius"] == old["progress"]["near_goal_radius"] + [old["args"]["near_goal_radius"]]
    assert progress["near_goal_recent"][:3] == old["progress"]["near_goal_recent"] and progress["near_goal_recent"][3] == []


def test_the_zero_shot_experiment_writes_its_rows_and_skips_what_it_has(tmp_path):
    from experiments import paneling

    args = paneling.Args(episodes=1, workers=1, out=tmp_path, write_results=False,
                         agents={"clone": str(ROOT / "assets/checkpoints/general_agent_clone_direct.pt")})
    rows = paneling.main(args)
    assert list(rows) == ["planning expert", "clone, zero-shot"]
    assert all(r["episodes"] == 1 for r in rows.values())
    assert sorted(p.name for p in tmp_path.glob("*.json")) == ["expert.json", "general_agent_clone_direct.json", "summary.json"]
    saved = json.loads((tmp_path / "expert.json").read_text())
    saved["episodes"][0]["placed"] = flipped = not saved["episodes"][0]["placed"]
    (tmp_path / "expert.json").write_text(json.dumps(saved))
    assert paneling.main(args)["planning expert"]["place_success"] == float(flipped), "a row on file is read, not rerun"


def test_the_recipe_trains_on_paneling_from_the_shipped_weights_and_from_nothing_unchanged_but_for_env_and_budget(
        tmp_path):
    """`--train`: the from-scratch recipe's arguments, but for the env, the budget, the run's name and (from the shipped
    reward-only agent) its initial weights, which load into the four-slot observation and train; an unknown start is
    refused with the starts allowed."""
    from baselines.ppo import ppo
    from experiments import from_scratch, paneling

    with pytest.raises(SystemExit, match="nothing, shipped"):
        paneling.training_run("imitation")
    assert paneling.training_run("shipped", seed=2).command == "python -m experiments.paneling --train shipped --train-seed 2"
    recipe = from_scratch.scratch_args(2, seed=1)
    for start, init in (("shipped", "assets/checkpoints/scratch_general_agent_ppo.pt"), ("nothing", None)):
        run = paneling.training_run(start, num_envs=2, learner="ppo")
        changed = {k for k, v in vars(run.args).items() if v != vars(recipe)[k]}
        assert changed <= {"env_id", "total_timesteps", "exp_name", "checkpoint"} and run.args.checkpoint == init
        tiny = run.args.replace(total_timesteps=40, num_steps=20, num_minibatches=2, update_epochs=1, num_eval_envs=1,
                                log_dir=str(tmp_path), checkpoint_freq=1)
        ppo.main(tiny)
        trained = load_checkpoint(tmp_path / run.args.exp_name / "checkpoint.pt")
        assert trained["progress"]["global_step"] == 40 and trained["args"]["env_id"] == "PanelInstallation-v1"
        if init is not None:
            before = load_checkpoint(ROOT / init)["agent"]
            same = {k: v for k, v in trained["agent"].items() if k in before and v.shape == before[k].shape
                    and v.is_floating_point()}
            assert same and all(torch.allclose(v, before[k], atol=0.05) for k, v in same.items()), "started from them"
            assert any(not torch.equal(v, before[k]) for k, v in same.items()), "and trained"


def test_the_zero_shot_episodes_default_to_the_test_seeds_and_a_training_run_takes_its_own_seed():
    """The evaluation's first seed (--seed) and a training run's seed (--train-seed) are two options: neither
    default shadows the other."""
    from experiments import paneling

    args = paneling.Args()
    assert args.seed == 1_000_000 and args.train_seed == 1


def test_steps_to_reads_the_first_crossing_of_the_training_episodes_moving_mean(tmp_path):
    from experiments import transfer

    progress = tmp_path / "progress.csv"
    placed = [0.0] * 10 + [1.0] * 20
    progress.write_text("global_step,ordinary_place_success\n"
                        + "".join(f"{2000 * (i + 1)},{p}\n" for i, p in enumerate(placed)))
    # a 10-iteration mean first reaches 0.9 nine iterations into the ones
    assert transfer.steps_to(progress, 0.9, window=10) == 2000 * 19
    assert transfer.steps_to(progress, 1.01, window=10) is None


def test_a_paneling_run_ends_at_the_first_mark_by_which_its_training_episodes_placed_the_target(tmp_path, monkeypatch,
                                                                                                capsys):
    """`--train`: what the run measures is the env steps to 90% placed; it trains in parts and ends after the first
    part by whose end its training episodes got there, and a resumed run that has got there trains no more. (ppo.py
    is a stand-in that writes the checkpoint and the progress of each part: its training episodes place every time
    from 302,000 env steps on.)"""

    from experiments import campaign, paneling, transfer
    from experiments import from_scratch as fs

    run = paneling.training_run("shipped")
    run = dataclasses.replace(run, args=run.args.replace(log_dir=str(tmp_path / "campaign"), total_timesteps=1_000_000))
    monkeypatch.setattr(transfer, "SNAPSHOT_DIR", tmp_path / "snapshots")
    for module in (fs, campaign):
        monkeypatch.setattr(module, "load_checkpoint", lambda path: torch.load(path, weights_only=False))
    parts = []

    def part_of_training(args):
        ckpt = Path(args.log_dir) / args.exp_name / "checkpoint.pt"
        assert (args.resume is not None) == ckpt.is_file(), "each part resumes the last"
        done = torch.load(ckpt, weights_only=False)["progress"]["global_step"] if ckpt.is_file() else 0
        ckpt.parent.mkdir(parents=True, exist_ok=True)
        with open(ckpt.parent / "progress.csv", "a") as f:
            f.write("" if done else "global_step,ordinary_place_success\n")
            f.writelines(f"{s},{float(s >= 302_000)}\n" for s in range(done + 2000, args.total_timesteps + 1, 2000))
        torch.save({"progress": {"global_step": args.total_timesteps}}, ckpt)
        parts.append(args.total_timesteps)

    monkeypatch.setattr(fs.ppo, "main", part_of_training)
    transfer.train(run, stop_at_target=True)
    # the 50-iteration mean first reaches 90% 45 iterations into the ones, at 390,000: the part that ends at 500,000
    assert parts == [250_000, 500_000]
    assert "placed >= 90% from 390,000 env steps" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "snapshots" / run.name).iterdir()) == ["checkpoint_250000.pt",
                                                                                     "checkpoint_500000.pt"]
    transfer.train(run, stop_at_target=True)
    assert parts == [250_000, 500_000], "a run that has reached the target trains no more"


def test_the_training_section_reads_each_run_s_progress_and_evaluation(tmp_path, monkeypatch):
    """`--training-report`: a row per run, from its progress.csv (env steps, the env steps its training episodes took
    to place 90%, wall time) and its paper-protocol evaluation where there is one; a run not started says how to
    start it; the curve is drawn and linked."""
    from experiments import paneling
    from experiments.campaign import checkpoint_of

    monkeypatch.chdir(tmp_path)
    progress = checkpoint_of(paneling.training_run("shipped")).parent / "progress.csv"
    progress.parent.mkdir(parents=True)
    placed = [0.0] * 100 + [1.0] * 100  # 2,000 env steps an iteration, each taking 2 s
    progress.write_text("global_step,ordinary_place_success,sps\n"
                        + "".join(f"{2000 * (i + 1)},{p},1000\n" for i, p in enumerate(placed)))
    evaluated = paneling.train_eval_json(paneling.training_run("shipped"))
    assert evaluated == Path("docs/data/paneling/train_shipped_s1_eval50k.json"), "the evaluation JSON's committed name"
    evaluated.parent.mkdir(parents=True)
    # as scripts/evaluate.py --json writes one task's results: at the top level, no "tasks" entry
    evaluated.write_text(json.dumps({"env_id": paneling.ENV_ID, "place_success": 0.95, "place_success_ci95": [0.9, 0.97],
                                     "place_success_by_goal_slot": {"0": 1.0, "1": 0.9, "2": 0.95}}))
    body = paneling.training_report(tmp_path / "RESULTS.md", tmp_path / "images" / "curve.png")
    # the 50-iteration mean first reaches 50% 25 iterations into the ones (250,000 env steps), 90% 45 (290,000)
    assert "scratch_general_agent_ppo.pt, seed 1 | 400,000 | 250,000 / 290,000 | 0.1 | 95.0 [90.0, 97.0] | 100 / 90 / 95 |" in body
    assert "| not run: `python -m experiments.paneling --train nothing --train-seed 1 --learner ppo` |" in body
    assert "| SAC on paneling from nothing, seed 1 | not run: `python -m experiments.paneling --train nothing " \
           "--learner sac --train-seed 1` |" in body
    assert "| SAC on paneling from nothing, seed 2 | not run: `python -m experiments.paneling --train nothing " \
           "--learner sac --train-seed 2` |" in body  # SAC's two seeds, PPO's one from each start
    assert "| SAC on paneling from the weights of campaign/sac_s1/checkpoint.pt, seed 1 | not run: " \
           "`python -m experiments.paneling --train shipped --learner sac --train-seed 1` |" in body
    assert "| SAC on paneling from the weights of campaign/sac_s1/checkpoint.pt, seed 2 | not run: " \
           "`python -m experiments.paneling --train shipped --learner sac --train-seed 2` |" in body  # and two from SAC's
    assert body.count("| not run: ") == 5
    assert (tmp_path / "images" / "curve.png").stat().st_size > 0 and "](images/curve.png)" in body
    assert "<!-- begin paneling-training (generated) -->" in (tmp_path / "RESULTS.md").read_text()


def test_a_run_that_used_its_whole_budget_short_of_the_target_says_so(tmp_path, monkeypatch):
    """A run whose training episodes never placed 90% reads "not within <budget>" there once it has trained its
    budget (after the env steps to 50% where they got that far), "not yet" before that; a run not evaluated yet says
    how to evaluate it."""
    from experiments import paneling
    from experiments.campaign import checkpoint_of

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(paneling, "TRAIN_BUDGET", 20_000)
    for start, iterations, placed in (("shipped", 10, 0.5), ("nothing", 5, 0.4)):
        progress = checkpoint_of(paneling.training_run(start, learner="ppo")).parent / "progress.csv"
        progress.parent.mkdir(parents=True)
        progress.write_text("global_step,ordinary_place_success,sps\n"
                            + "".join(f"{2000 * (i + 1)},{placed},1000\n" for i in range(iterations)))
    body = paneling.training_report(tmp_path / "RESULTS.md", tmp_path / "images" / "curve.png")
    assert "scratch_general_agent_ppo.pt, seed 1 | 20,000 | 2,000 / not within 20,000 | 0.0 | not yet: `" in body
    assert "from nothing, seed 1 | 10,000 | not yet | 0.0 | not yet: `python -m experiments.paneling --train nothing" in body


def test_sac_on_paneling_is_the_recipe_s_sac_but_for_the_env_and_budget_from_nothing_only_and_trains_there(tmp_path):
    """`--learner sac`: experiments/sac_recipe.py's SAC arguments, but for the env, the budget and the run's name;
    from the shipped weights, those of SAC's shipped agent (--init-from); a tiny run on PanelInstallation-v1 trains
    its actor."""
    from baselines.sac import sac
    from experiments import paneling, sac_recipe

    warm = paneling.training_run("shipped", learner="sac")
    assert warm.args.init_from == "campaign/sac_s1/checkpoint.pt" and warm.name == "paneling_shipped_sac_s1"
    assert warm.command == "python -m experiments.paneling --train shipped --learner sac --train-seed 1"
    assert {k for k, v in vars(warm.args).items() if v != vars(sac_recipe.sac_args(1))[k]} == {
        "env_id", "total_timesteps", "exp_name", "init_from"}
    with pytest.raises(SystemExit, match="--learner td3: use one of ppo, sac"):
        paneling.training_run("nothing", learner="td3")
    run = paneling.training_run("nothing", seed=2, learner="sac")
    assert run.command == "python -m experiments.paneling --train nothing --learner sac --train-seed 2"
    # SAC is the recipe's learner: the default from nothing; from the shipped weights (PPO's), PPO
    assert paneling.training_run("nothing", seed=2) == run and paneling.Args().learner is None
    assert paneling.training_run("shipped").command == "python -m experiments.paneling --train shipped --train-seed 1"
    assert paneling.training_run("nothing", learner="ppo").command == \
        "python -m experiments.paneling --train nothing --train-seed 1 --learner ppo"
    assert paneling.train_eval_json(run) == Path("docs/data/paneling/train_sac_s2_eval50k.json")
    changed = {k for k, v in vars(run.args).items() if v != vars(sac_recipe.sac_args(2))[k]}
    assert changed == {"env_id", "total_timesteps", "exp_name"} and run.args.env_id == paneling.ENV_ID
    tiny = dataclasses.replace(run.args, num_envs=1, hidden_size=32, num_layers=1, batch_size=32, learning_starts=100,
                               buffer_size=1000, utd=1.0, log_freq=50, eval_freq=0, total_timesteps=300,
                               checkpoint_freq=150, log_dir=str(tmp_path))
    ckpt_path, actors = tmp_path / run.args.exp_name / "checkpoint.pt", []

    def after_part():  # `stop`, asked at the end of each part but the last: go on
        actors.append(torch.load(ckpt_path, weights_only=False)["sac"]["actor"])
        return False

    sac_recipe.run_sac(tiny, every=150, stop=after_part)
    ckpt = torch.load(ckpt_path, weights_only=False)
    assert ckpt["progress"]["global_step"] == 300 and ckpt["args"]["env_id"] == paneling.ENV_ID
    assert len(actors) == 1, "two parts, the second resumed from the first's checkpoint"
    assert any(not torch.equal(v, actors[0][k]) for k, v in ckpt["sac"]["actor"].items() if v.is_floating_point()), \
        "the actor trained on in the second part"


@pytest.mark.parametrize("learner", ["ppo", "sac"])
def test_a_run_resumed_inside_a_part_after_its_target_finishes_the_part_to_the_mark(tmp_path, monkeypatch, learner):
    """A stop-at-target run cut short inside a part (SIGTERM at a session's end) after its training episodes got to
    the target resumes to the part's end, as the uninterrupted run would have ended, and no further; resumed at
    that mark it trains no more. (The learner's main is a stand-in that writes the checkpoint of each part.)"""
    from experiments import campaign, paneling, sac_recipe, transfer
    from experiments import from_scratch as fs

    run = paneling.training_run("nothing", learner=learner)
    run = dataclasses.replace(run, args=dataclasses.replace(run.args, log_dir=str(tmp_path / "campaign"),
                                                            total_timesteps=1_000_000))
    monkeypatch.setattr(transfer, "SNAPSHOT_DIR", tmp_path / "snapshots")
    for module in (fs, campaign):
        monkeypatch.setattr(module, "load_checkpoint", lambda path: torch.load(path, weights_only=False))
    ckpt = campaign.args_checkpoint(run.args)
    ckpt.parent.mkdir(parents=True)
    # cut short at 141,824 env steps, its training episodes placing every time from 2,000 on
    (ckpt.parent / "progress.csv").write_text("global_step,ordinary_place_success\n"
                                              + "".join(f"{s},1.0\n" for s in range(2000, 141_825, 2000)))
    torch.save({"progress": {"global_step": 141_824}}, ckpt)
    parts = []

    def part_of_training(args):
        assert args.resume == str(ckpt), "the part resumes the checkpoint"
        torch.save({"progress": {"global_step": args.total_timesteps}}, ckpt)
        parts.append(args.total_timesteps)

    monkeypatch.setattr(sac_recipe.sac if learner == "sac" else fs.ppo, "main", part_of_training)
    transfer.train(run, stop_at_target=True)
    assert parts == [transfer.STOP_EVERY], "the part finished to its mark, then the run stopped"
    transfer.train(run, stop_at_target=True)
    assert parts == [transfer.STOP_EVERY], "resumed at the mark, past its target: it trains no more"
