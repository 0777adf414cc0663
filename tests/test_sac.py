"""baselines/sac/sac.py: a short run learns and logs, a resumed run is the uninterrupted one, bad args are refused,
success is absorbing in the critics' target, and scripts/evaluate.py's loader reads a SAC checkpoint."""

import csv
import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from baselines.ppo.checkpoints import load_policy
from baselines.ppo.evaluation import failed_ends
from baselines.sac import sac

TINY = dict(env_id="ConstructionPickPlace-v1", num_envs=1, hidden_size=32, num_layers=1, batch_size=32,
            learning_starts=100, buffer_size=1000, utd=1.0, log_freq=100, eval_freq=0, torch_threads=1)
"""a run that takes seconds: one env in the learner's process, tiny networks, 1 thread (the resume test compares
weights bit for bit)."""


ROOT = Path(__file__).resolve().parents[1]


def tiny_args(tmp_path, **kw) -> sac.Args:
    return sac.Args(**{**TINY, "log_dir": str(tmp_path), **kw})


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def weights(run: sac.Run) -> dict:
    """Every learnt tensor of a run: networks, target networks, log alpha, optimizers' moments."""
    state = run.learner.state_dict()
    out = {f"{net}.{k}": v for net in ("actor", "critics", "critics_target") for k, v in state[net].items()}
    out["log_alpha"] = state["log_alpha"]
    for opt in ("actor_optimizer", "q_optimizer", "alpha_optimizer"):
        for i, s in state[opt]["state"].items():
            out.update({f"{opt}.{i}.{k}": v for k, v in s.items()})
    return out


def test_a_short_run_changes_the_actor_and_writes_the_csv_columns(tmp_path):
    args = tiny_args(tmp_path, total_timesteps=400, exp_name="short", checkpoint_freq=400)
    run = sac.setup(args)
    before = {k: v.clone() for k, v in run.learner.actor.state_dict().items()}
    progress = sac.train(run)
    assert progress.global_step == 400 and run.clock.updates == 300, "utd 1 after 100 random steps"
    changed = [k for k, v in run.learner.actor.net.state_dict().items() if not torch.equal(v, before[f"net.{k}"])]
    assert len(changed) == len(before) - 3, "every weight of the actor's network moved (obs_rms aside)"
    assert not torch.equal(run.learner.actor.obs_rms.mean, before["obs_rms.mean"]), "the observation statistics learnt"
    rows = read_csv(tmp_path / "short" / "progress.csv")
    assert [int(r["global_step"]) for r in rows] == [100, 200, 300, 400]
    plotted = ["global_step", "sps", "place_success", "near_goal_place_success", "stage",
               *[f"ordinary_place_{k}" for k in ("ceiling", "window", "flooring")],
               *[f"near_goal_radius_{k}" for k in ("ceiling", "window", "flooring")]]
    sac_columns = ["wall_s", "update_s", "env_s", "update_share", "alpha", "qf1_loss", "qf2_loss", "actor_loss",
                   "alpha_loss"]
    assert set(plotted + sac_columns) <= set(rows[0])
    last = rows[-1]
    for key in sac_columns + ["sps"]:
        assert float(last[key]) == float(last[key]), f"{key} is a number"
    assert rows[0]["qf1_loss"] == "", "no gradient step before learning starts"
    assert float(last["near_goal_radius_window"]) == 0.1 and float(last["update_s"]) > 0
    assert float(last["wall_s"]) >= float(last["env_s"]) + float(last["update_s"]) - 1e-6
    assert sum(int(r["episodes"]) for r in rows) > 0, "episodes ended (near-goal starts are cut after 80 steps)"
    assert (tmp_path / "short" / "checkpoint.pt").is_file() and (tmp_path / "short" / "replay_buffer_400.pt").is_file()


def test_reach_starts_are_a_training_device_counted_apart_from_the_ordinary_resets(tmp_path):
    """--reach-start-share: the training envs get the tasks' `reach_start_share` (evaluation's do not); a run's
    episodes that started on the way to the element are counted in their own columns, not as ordinary resets."""
    from types import SimpleNamespace

    from ms_construction.parameters import ELEMENT_KINDS

    args = sac.Args(reach_start_share=0.5)
    assert sac.env_kwargs(args)["reach_start_share"] == 0.5 and "reach_start_share" not in sac.env_kwargs(args, False)
    assert "reach_start_share" not in sac.env_kwargs(sac.Args())
    episodes = {"success": [1.0, 0.0, 0.0], "picked": [1.0, 1.0, 0.0], "task_id": [1, 1, 1], "collided": [False] * 3,
                "near_goal": [False, False, False], "reach_start": [True, True, False],
                "reach_start_grasped": [1.0, 0.0, 0.0], "length": [1.0] * 3}
    episodes.update({key: [0.0] * 3 for key in sac.EPISODE_STATS.values() if key not in episodes})
    progress = SimpleNamespace(near_goal_radius=[0.1] * len(ELEMENT_KINDS), near_goal_share=[0.8] * len(ELEMENT_KINDS))
    row = sac.episode_columns(args, progress, episodes)
    assert row["reach_start_episodes"] == 2 and row["reach_start_grasp_success"] == 0.5
    assert row["ordinary_place_window"] == 0.0 and row["ordinary_pick_window"] == 0.0  # the one ordinary reset
    assert row["ordinary_place_success"] == 0.0
    run = sac.setup(tiny_args(tmp_path, total_timesteps=400, exp_name="reach", checkpoint_freq=400, near_goal_share=0.0,
                              reach_start_share=1.0))
    sac.train(run)
    rows = read_csv(tmp_path / "reach" / "progress.csv")
    ended = sum(int(r["reach_start_episodes"] or 0) for r in rows)
    assert ended >= 1 and not any(r[f"ordinary_place_{kind}"] for r in rows for kind in ELEMENT_KINDS), \
        "every episode started on the way: none is an ordinary reset's"


def test_a_run_resumed_halfway_ends_with_the_uninterrupted_run_s_weights(tmp_path):
    """Run U: 600 env steps with a checkpoint at 300. Run I: 300 steps, then --resume --extend to 600. Every weight,
    optimizer moment, log alpha, the replay buffer and the curriculum's progress end the same, bit for bit (every
    near-goal episode promotes its type: the first widens the radius to 1, the next hands its starts back, so the
    shares move)."""
    common = dict(checkpoint_freq=300, learning_starts=100, near_goal_window=1, near_goal_promote=0.0,
                  near_goal_step=1.0, near_goal_share_end=0.2)
    u = sac.setup(tiny_args(tmp_path, total_timesteps=600, exp_name="u", **common))
    sac.train(u)
    i = sac.setup(tiny_args(tmp_path, total_timesteps=300, exp_name="i", **common))
    sac.train(i)
    ckpt = tmp_path / "i" / "checkpoint.pt"
    assert (tmp_path / "i" / "replay_buffer_300.pt").is_file()
    resumed = sac.setup(sac.Args(resume=str(ckpt), extend=True, total_timesteps=600))
    assert resumed.progress.global_step == 300 and resumed.clock.updates == 200 and resumed.buffer.count == 300
    sac.train(resumed)
    assert resumed.progress.global_step == u.progress.global_step == 600
    assert resumed.clock.updates == u.clock.updates == 500
    wu, wi = weights(u), weights(resumed)
    assert wu.keys() == wi.keys() and len(wu) > 20
    different = [k for k in wu if not torch.equal(wu[k], wi[k])]
    assert not different, f"differ after the resume: {different}"
    for key in sac.ReplayBuffer.KEYS:
        assert torch.equal(getattr(u.buffer, key), getattr(resumed.buffer, key)), key
    assert resumed.progress.near_goal_radius == u.progress.near_goal_radius
    assert resumed.progress.near_goal_recent == u.progress.near_goal_recent
    assert resumed.progress.near_goal_share == u.progress.near_goal_share and min(u.progress.near_goal_share) == 0.2
    assert not (tmp_path / "i" / "replay_buffer_300.pt").exists(), "the old buffer goes once the new checkpoint is in"
    assert (tmp_path / "i" / "replay_buffer_600.pt").is_file()
    rows = read_csv(tmp_path / "i" / "progress.csv")
    assert [int(r["global_step"]) for r in rows] == list(range(100, 601, 100)), "the resumed run appends its rows"


def test_sigterm_ends_a_run_with_a_checkpoint_and_its_buffer_at_that_step_and_one_line_on_how_to_resume(tmp_path):
    """SIGTERM (a session's end) to a run between checkpoints: it stops after the iteration under way, saves the
    checkpoint and the replay buffer at that step, exits with 128 + SIGTERM and says how to resume (then its time
    split); the checkpoint resumes there."""
    cmd = [sys.executable, "baselines/sac/sac.py", *[f"--{k.replace('_', '-')}={v}" for k, v in TINY.items()],
           "--total-timesteps=1000000", "--checkpoint-freq=1000000", f"--log-dir={tmp_path}", "--exp-name=stopped"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    csv_path = tmp_path / "stopped" / "progress.csv"
    try:
        deadline = time.monotonic() + 240
        while not (csv_path.exists() and len(read_csv(csv_path)) >= 2):
            ended = proc.poll() is not None
            assert not ended and time.monotonic() < deadline, proc.communicate()[1] if ended else "no row yet"
            time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, stderr)
    assert "Traceback" not in stderr, stderr
    stopped, split = stderr.strip().splitlines()[-2:]
    assert stopped.startswith("stopped by SIGTERM at step ") and "checkpoint saved; resume with: " in stopped, stderr
    assert "--resume" in stopped and "env steps/s" in split, stderr
    step = int(stopped.removeprefix("stopped by SIGTERM at step ").split()[0])
    assert step >= int(read_csv(csv_path)[-1]["global_step"]) >= 200
    resumed = sac.setup(sac.Args(resume=str(tmp_path / "stopped" / "checkpoint.pt")))
    try:
        assert resumed.progress.global_step == step and resumed.buffer.count == min(step, TINY["buffer_size"])
        assert (tmp_path / "stopped" / f"replay_buffer_{step}.pt").is_file()
    finally:
        sac.close(resumed.envs, resumed.eval_envs)


def test_table_i_s_stages_follow_env_steps_in_the_envs_and_the_csv_and_a_resume_mid_curriculum_is_exact(tmp_path,
                                                                                                       monkeypatch):
    """--curriculum cp1 cp2 cp4 with 200-step stages: the envs (training and evaluation) are set to each stage where
    the run's env steps enter it, progress.csv names the stage of each row, and a run resumed at 300 (inside cp2)
    is set to cp2 at once and ends with the uninterrupted run's weights."""
    calls = []
    call = sac.CPUVectorEnv.call

    def spy(self, name, *args, **kwargs):
        if name == "set_curriculum_stage":
            calls.append((id(self), args[0]))
        return call(self, name, *args, **kwargs)

    monkeypatch.setattr(sac.CPUVectorEnv, "call", spy)
    common = dict(checkpoint_freq=300, curriculum=("cp1", "cp2", "cp4"), stage_timesteps=200, eval_freq=300,
                  num_eval_envs=1, num_eval_steps=5)
    u = sac.setup(tiny_args(tmp_path, total_timesteps=600, exp_name="u", **common))
    sac.train(u)
    stages = [stage for _, stage in calls]
    assert stages == ["cp1", "cp1", "cp2", "cp2", "cp4", "cp4"], "training and evaluation envs, at 0, 200 and 400"
    assert len({env for env, _ in calls}) == 2
    rows = read_csv(tmp_path / "u" / "progress.csv")
    assert [r["stage"] for r in rows] == ["cp1", "cp1", "cp2", "cp2", "cp4", "cp4"]
    assert [sac.stage_at(u.args, s) for s in (0, 199, 200, 399, 400, 10_000)] == ["cp1", "cp1", "cp2", "cp2", "cp4",
                                                                                   "cp4"]
    i = sac.setup(tiny_args(tmp_path, total_timesteps=300, exp_name="i", **common))
    sac.train(i)
    calls.clear()
    resumed = sac.setup(sac.Args(resume=str(tmp_path / "i" / "checkpoint.pt"), extend=True, total_timesteps=600))
    sac.train(resumed)
    assert [stage for _, stage in calls] == ["cp2", "cp2", "cp4", "cp4"]
    wu, wi = weights(u), weights(resumed)
    assert not [k for k in wu if not torch.equal(wu[k], wi[k])], "the resumed run is the uninterrupted one"


def test_a_run_from_a_checkpoint_s_networks_acts_and_values_as_it_did_and_among_obstacles_reads_them_with_zeros(
        tmp_path):
    """--init-from: a run among obstacles from a checkpoint trained without them starts with its actor, critics,
    target critics, entropy coefficient and statistics, the obstacles' inputs weighted zero: the same actions and Q
    values on the same state, whatever the obstacles say; it acts with the actor from its first step, and resumes
    from its own checkpoint. Networks of another shape and a policy that kept its actor alone are refused."""
    from baselines.ppo.evaluation import reset

    source = tiny_args(tmp_path, total_timesteps=200, exp_name="source", checkpoint_freq=200)
    trained = sac.setup(source)
    sac.train(trained)
    ckpt = str(tmp_path / "source" / "checkpoint.pt")
    warm = sac.setup(tiny_args(tmp_path, total_timesteps=200, exp_name="warm", init_from=ckpt, obstacles="static"))
    try:
        obs = reset(warm.envs, 7)
    finally:
        sac.close(warm.envs, warm.eval_envs)
    assert obs.shape[-1] == trained.obs_dim + 11, "the obstacles' entry ends the observation"
    assert torch.equal(warm.learner.log_alpha, trained.learner.log_alpha)
    for shift in (0.0, 3.0):  # whatever the obstacles' entry says
        seen = obs.clone()
        seen[:, trained.obs_dim:] += shift
        z_old, z_new = trained.learner.actor.normalize(obs[:, :trained.obs_dim]), warm.learner.actor.normalize(seen)
        assert torch.allclose(trained.learner.actor.get_action(obs[:, :trained.obs_dim], deterministic=True),
                              warm.learner.actor.get_action(seen, deterministic=True), atol=1e-6)
        a = torch.zeros(len(obs), warm.act_dim)
        for old_nets, new_nets in ((trained.learner.critics, warm.learner.critics),
                                   (trained.learner.critics_target, warm.learner.critics_target)):
            for q_old, q_new in zip(old_nets(z_old, a), new_nets(z_new, a)):
                assert torch.allclose(q_old, q_new, atol=1e-5)
    assert not sac.acts_at_random(warm.args, 0) and sac.acts_at_random(source, 0)
    with pytest.raises(SystemExit, match="not this run's shape"):
        sac.setup(tiny_args(tmp_path, exp_name="wide", init_from=ckpt, hidden_size=16))
    with pytest.raises(SystemExit, match="its networks read"):  # new inputs other than the obstacles' are refused
        sac.setup(tiny_args(tmp_path, exp_name="path", init_from=ckpt, obs_path_offset=False))
    actor_only = tmp_path / "actor_only.pt"
    saved = torch.load(ckpt, weights_only=False)
    torch.save({**saved, "sac": {"actor": saved["sac"]["actor"]}}, actor_only)
    with pytest.raises(SystemExit, match="it keeps the actor alone"):
        sac.setup(tiny_args(tmp_path, exp_name="alone", init_from=str(actor_only)))
    from experiments.campaign import policy_only

    shipped = tmp_path / "shipped.pt"  # a policy as it ships keeps what a new run starts from, not the optimizers
    torch.save(policy_only(saved), shipped)
    assert set(torch.load(shipped, weights_only=False)["sac"]) == {"actor", "critics", "critics_target", "log_alpha"}
    again = sac.setup(tiny_args(tmp_path, exp_name="again", init_from=str(shipped)))
    sac.close(again.envs, again.eval_envs)
    assert torch.equal(again.learner.critics.q1[0].weight, trained.learner.critics.q1[0].weight)
    # a run started so resumes from its own checkpoint (its args keep --init-from: where it started)
    sac.train(sac.setup(tiny_args(tmp_path, exp_name="part", init_from=ckpt, total_timesteps=100, checkpoint_freq=100)))
    resumed = sac.setup(sac.Args(resume=str(tmp_path / "part" / "checkpoint.pt"), extend=True, total_timesteps=200))
    assert resumed.args.init_from == ckpt and resumed.progress.global_step == 100
    sac.train(resumed)
    assert resumed.progress.global_step == 200


def test_resume_refuses_a_checkpoint_without_its_buffer_and_a_ppo_checkpoint(tmp_path):
    run = sac.setup(tiny_args(tmp_path, total_timesteps=100, exp_name="b", learning_starts=50))
    sac.train(run)
    (tmp_path / "b" / "replay_buffer_100.pt").unlink()
    with pytest.raises(SystemExit, match="replay buffer .* is missing"):
        sac.setup(sac.Args(resume=str(tmp_path / "b" / "checkpoint.pt")))
    with pytest.raises(SystemExit, match="--refill-lost-buffer"):
        sac.setup(sac.Args(resume=str(tmp_path / "b" / "checkpoint.pt")))
    ckpt = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=False)
    ckpt["args"]["algorithm"] = None  # as a PPO checkpoint's args
    torch.save(ckpt, tmp_path / "ppo.pt")
    with pytest.raises(SystemExit, match="not a SAC checkpoint"):
        sac.setup(sac.Args(resume=str(tmp_path / "ppo.pt")))


@pytest.mark.parametrize("change, message", [
    (dict(batch_size=512, buffer_size=256, learning_starts=256), "larger than the replay buffer"),
    (dict(utd=0.0), "--utd 0.0"),
    (dict(utd=-1.0), "must be > 0"),
    (dict(learning_starts=10), "--learning-starts 10"),
    (dict(gamma=1.0), "--gamma"),
    (dict(tau=0.0), "--tau"),
    (dict(near_goal_share=1.5), "--near-goal-share"),
    (dict(reach_start_share=-0.1), "--reach-start-share"),
    (dict(near_goal_share_end=0.9), "--near-goal-share-end 0.9: a share in \\[0, --near-goal-share \\(0.8\\)\\]"),
    (dict(env_id="PickCube-v1"), "--env-id"),
    (dict(num_layers=0), "--num-layers"),
    (dict(checkpoint="x.pt"), "--evaluate"),
    (dict(evaluate=True), "--evaluate evaluates --checkpoint"),
    (dict(extend=True), "--extend"),
    (dict(log_std_min=2.0), "--log-std-min"),
    (dict(goal_slots=(0, 3)), "--goal-slots 0 3: give distinct indices in 0..2"),
    (dict(goal_slots=(1, 1)), "--goal-slots 1 1"),
    (dict(curriculum=("cp1", "cp5")), "--curriculum cp1 cp5: give stages among cp1, cp2, cp3, cp4"),
    (dict(curriculum=()), "--curriculum"),
    (dict(stage_timesteps=0), "--stage-timesteps 0"),
])
def test_bad_args_are_refused_with_a_message(change, message):
    with pytest.raises(SystemExit, match=message):
        sac.validate(dataclasses.replace(sac.Args(), **change))
    sac.validate(sac.Args())  # the defaults pass


def test_held_out_goal_slots_are_never_drawn_in_training_and_obstacles_are_met_in_training_and_evaluation():
    args = sac.Args(goal_slots=(0, 2), obstacles="moving")
    train, evaluate = sac.env_kwargs(args), sac.env_kwargs(args, train=False)
    assert all(w == [1.0, 0.0, 1.0] for w in train["goal_slot_weights"].values())
    assert "goal_slot_weights" not in evaluate, "evaluation during training draws every slot"
    assert train["obstacles"] == evaluate["obstacles"] == "moving"
    assert train["obs_obstacles"] and evaluate["obs_obstacles"], "the policy observes the obstacles it trains among"
    plain = sac.env_kwargs(sac.Args())
    assert not {"goal_slot_weights", "obstacles", "obs_obstacles"} & set(plain)


def test_success_is_absorbing_in_the_critics_target_a_failure_ends_it_and_truncations_bootstrap():
    gamma, alpha = 0.95, torch.tensor(0.2)
    rewards = torch.tensor([1.0, 0.5, 0.5, 0.0, 3.0])
    terminated = torch.tensor([True, False, True, False, True])
    failed = torch.tensor([False, False, False, False, True])  # the last one touched an obstacle
    next_q = torch.tensor([100.0, 2.0, -7.0, 3.0, 50.0])  # the critic's guess at s' (ignored where the episode ended)
    next_log_pi = torch.tensor([5.0, -1.0, 5.0, 0.5, 5.0])
    y = sac.soft_q_target(rewards, terminated, failed, next_q, next_log_pi, alpha, gamma)
    expected = torch.tensor([1.0 / 0.05, 0.5 + 0.95 * (2.0 + 0.2), 0.5 / 0.05, 0.95 * (3.0 - 0.1), 3.0])
    torch.testing.assert_close(y, expected)



def test_the_buffer_tells_a_touch_of_an_obstacle_from_success_and_reads_a_buffer_saved_before_it_did():
    """What the learners store of an episode end (evaluation.failed_ends): among the envs that terminated, those
    whose final info says `fail`; a step without ended episodes or without obstacles (no `fail`) marks none."""
    terminated = torch.tensor([True, True, False])
    infos = {"final_info": {"fail": torch.tensor([True, False, True])}, "_final_info": terminated}
    assert failed_ends(terminated, infos).tolist() == [True, False, False]
    assert failed_ends(terminated, {"final_info": {"success": terminated}}).tolist() == [False] * 3
    assert failed_ends(torch.zeros(3, dtype=torch.bool), {}).tolist() == [False] * 3
    buffer = sac.ReplayBuffer(8, obs_dim=2, act_dim=1)
    buffer.add(torch.zeros(3, 2), torch.ones(3, 2), torch.zeros(3, 1), torch.ones(3), terminated,
               failed_ends(terminated, infos))
    state = buffer.state_dict()
    assert state["failed"].tolist() == [True, False, False]
    older = {k: v for k, v in state.items() if k != "failed"}
    again = sac.ReplayBuffer(8, obs_dim=2, act_dim=1)
    again.failed[:] = True
    again.load_state_dict(older)
    assert again.count == 3 and not again.failed.any() and torch.equal(again.terminated[:3], terminated)

def test_the_squashed_gaussian_s_log_probability_is_the_change_of_variables():
    torch.manual_seed(0)
    actor = sac.Actor(obs_dim=5, act_dim=3, hidden=16, layers=1)
    z = torch.randn(4, 5)
    torch.manual_seed(1)
    a, log_pi = actor.sample(z)
    mean, log_std = actor.mean_log_std(z)
    u = torch.atanh(a.clamp(-1 + 1e-6, 1 - 1e-6))
    gauss = torch.distributions.Normal(mean, log_std.exp()).log_prob(u).sum(-1)
    torch.testing.assert_close(log_pi, gauss - torch.log(1 - a.pow(2)).sum(-1), rtol=1e-3, atol=1e-3)
    assert a.abs().max() < 1
    torch.testing.assert_close(actor.get_action(z, deterministic=True), torch.tanh(mean))


def test_evaluate_py_s_loader_reads_a_sac_checkpoint_as_its_deterministic_policy(tmp_path):
    run = sac.setup(tiny_args(tmp_path, total_timesteps=200, exp_name="e", rotation_features=True))
    sac.train(run)
    agent, env_kwargs = load_policy(tmp_path / "e" / "checkpoint.pt", "ConstructionPickPlace-v1")
    assert env_kwargs == dict(control_mode="pd_joint_delta_pos", obs_install_offset=True, obs_path_offset=True)
    obs = run.buffer.obs[:50]
    with torch.no_grad():
        torch.testing.assert_close(agent.get_action(obs, deterministic=True),
                                   run.learner.actor.get_action(obs, deterministic=True))


def test_a_run_whose_buffer_is_lost_goes_on_with_an_empty_one_refilled_before_any_gradient_step(tmp_path):
    """--refill-lost-buffer (a fresh machine: the buffer is not committed): the actor refills the buffer for
    --learning-starts env steps without gradient steps, then they go on at the run's rate with no backlog; the
    clock records where."""
    run = sac.setup(tiny_args(tmp_path, total_timesteps=200, exp_name="r", learning_starts=50, checkpoint_freq=200))
    sac.train(run)
    assert run.clock.updates == 150
    (tmp_path / "r" / "replay_buffer_200.pt").unlink()
    resumed = sac.setup(sac.Args(resume=str(tmp_path / "r" / "checkpoint.pt"), refill_lost_buffer=True, extend=True,
                                 total_timesteps=249))
    assert resumed.buffer.count == 0 and resumed.clock.refilled_at == [200] and resumed.clock.refill_until == 250
    sac.train(resumed)
    assert resumed.clock.updates == 150 and resumed.buffer.count == 49, "refilling: no gradient step yet"
    again = sac.setup(sac.Args(resume=str(tmp_path / "r" / "checkpoint.pt"), extend=True, total_timesteps=300))
    assert again.buffer.count == 49, "the refilled buffer is saved and resumes exactly"
    sac.train(again)
    assert again.clock.updates == 150 + 51 and again.clock.skipped_updates == 49, "from step 250 on, one a step"
    assert again.clock.refilled_at == [200]


def test_among_obstacles_the_csv_counts_per_task_type_the_ordinary_episodes_that_touched_one():
    """`episode_columns` with --obstacles: per task type, the share of the episodes from ordinary resets that ended
    on a touch of an obstacle (near-goal starts not counted, as for placed); without obstacles no such column."""
    from types import SimpleNamespace

    from baselines.ppo.ppo import EPISODE_STATS
    from ms_construction.parameters import ELEMENT_KINDS

    assert all(f"ordinary_collided_{kind}" in sac.CSV_FIELDS for kind in ELEMENT_KINDS)
    episodes = {key: [0.0] * 5 for key in EPISODE_STATS.values()}
    episodes.update(task_id=[0, 0, 0, 1, 0], near_goal=[False, False, False, False, True],
                    collided=[True, False, False, False, True], success=[0.0, 1.0, 1.0, 1.0, 0.0])
    progress = SimpleNamespace(near_goal_radius=[0.1] * len(ELEMENT_KINDS), near_goal_share=[0.8] * len(ELEMENT_KINDS))
    row = sac.episode_columns(sac.Args(obstacles="moving"), progress, episodes)
    ceiling, window = ELEMENT_KINDS[0], ELEMENT_KINDS[1]
    assert row[f"ordinary_collided_{ceiling}"] == pytest.approx(1 / 3) and row[f"ordinary_collided_{window}"] == 0.0
    assert row[f"ordinary_place_{ceiling}"] == pytest.approx(2 / 3)
    assert not any(k.startswith("ordinary_collided") for k in sac.episode_columns(sac.Args(), progress, episodes))
