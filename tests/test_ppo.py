"""The learner: PPO and ICM update, curriculum promotion, checkpoints and exact resume."""

import csv
import dataclasses
import math
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import get_args

import gymnasium as gym
import numpy as np
import pytest
import torch

from baselines.ppo import checkpoints, evaluation, ppo, update
from baselines.ppo.args import GROUPS, Args, ControlMode, command_line
from ms_construction.curriculum import stage_tolerances
from ms_construction.envs.state_layout import STATE_SIZE
from ms_construction.vector_env import CPUVectorEnv

ROOT = Path(__file__).resolve().parents[1]
SCRIPT_ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
"""scripts run as subprocesses import this checkout's packages (an editable install may point at another
checkout of the repository, e.g. where git worktrees share one virtual environment)."""

TINY = dict(num_envs=2, num_eval_envs=1, num_steps=40, num_minibatches=2, update_epochs=2, eval_freq=100,
            num_eval_steps=250, checkpoint_freq=1, env_id="Flooring-v1", sim_backend="physx_cpu")


def tiny_args(tmp_path, **kw) -> ppo.Args:
    return ppo.Args.of(**{**TINY, "log_dir": str(tmp_path), **kw})


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def worker_tolerances(envs: CPUVectorEnv) -> list[list[float]]:
    """(tau_pick, tau_place, tau_angle_deg) in force in each worker's env."""
    return [t[0].tolist() for t in envs.call("tolerances")]


def test_args_nest_their_groups_yet_keep_flat_flags_and_flat_checkpoint_args():
    import tyro

    parsed = tyro.cli(Args, args=["--seed", "3", "--gamma", "0.5", "--curiosity", "none", "--curriculum", "cp4",
                                  "--residual-scale", "0.2", "--near-goal-share", "0.3"])
    assert (parsed.seed, parsed.ppo.gamma, parsed.icm.curiosity, parsed.stages.curriculum, parsed.warm.residual_scale,
            parsed.starts.near_goal_share) == (3, 0.5, "none", ("cp4",), 0.2, 0.3), "each flag lands in its group"
    assert set(GROUPS) == {"ppo", "icm", "stages", "warm", "starts"}
    flat = parsed.flat()
    assert "gamma" in flat and "ppo" not in flat and Args.of(**flat) == parsed, "a checkpoint's flat args build the same Args"
    assert tyro.cli(Args, args=command_line(parsed)) == parsed, "command_line writes the flags that build it"
    other = parsed.replace(gamma=0.9, seed=4)
    assert (other.ppo.gamma, other.seed, parsed.ppo.gamma, parsed.seed) == (0.9, 4, 0.5, 3)
    other.ppo.learning_rate = 1.0
    assert parsed.ppo.learning_rate == 3e-4, "a replaced copy shares no group with its original"
    with pytest.raises(TypeError, match="no field"):
        Args.of(gama=0.9)


@pytest.mark.parametrize("curiosity", ["none", "icm"])
def test_a_few_iterations_give_finite_losses_and_change_parameters(tmp_path, curiosity):
    args = tiny_args(tmp_path, curiosity=curiosity, total_timesteps=160, exp_name=f"it_{curiosity}", curriculum=("cp4",))
    torch.manual_seed(args.seed)
    before = ppo.setup(args)
    initial = {k: v.clone() for k, v in before.agent.state_dict().items()}
    initial_icm = None if before.icm is None else {k: v.clone() for k, v in before.icm.state_dict().items()}
    progress = ppo.train(before)
    assert progress.global_step == 160 and progress.iteration == 2
    rows = read_csv(tmp_path / args.exp_name / "progress.csv")
    assert len(rows) == 2
    keys = ["value_loss", "policy_loss", "entropy"] + (["icm_forward_loss", "icm_inverse_loss"] if curiosity == "icm" else [])
    for row in rows:
        for key in keys:
            assert math.isfinite(float(row[key])), (key, row[key])
    ckpt = torch.load(tmp_path / args.exp_name / "checkpoint.pt", weights_only=False)
    changed = [k for k, v in ckpt["agent"].items() if not torch.equal(v, initial[k])]
    assert "actor_mean.0.weight" in changed and "critic.0.weight" in changed
    if curiosity == "icm":
        assert not torch.equal(ckpt["icm"]["forward_model.0.weight"], initial_icm["forward_model.0.weight"])
        assert not torch.equal(ckpt["icm"]["encoder.0.0.weight"], initial_icm["encoder.0.0.weight"])
    else:
        assert ckpt["icm"] is None


def test_promotion_rules():
    args = ppo.Args.of(curriculum=("cp1", "cp2"), stage_timesteps=1000, min_stage_timesteps=300, promote_success=0.8)
    p = ppo.Progress(global_step=999)
    assert ppo.should_promote(args, p) is None
    p.global_step = 1000
    assert ppo.should_promote(args, p) == "steps"
    p = ppo.Progress(global_step=400, smoothed_success=0.85)
    assert ppo.should_promote(args, p) == "success"
    p = ppo.Progress(global_step=400, smoothed_success=0.75)
    assert ppo.should_promote(args, p) is None, "success below promote_success does not promote"
    p = ppo.Progress(global_step=400, smoothed_success=None)
    assert ppo.should_promote(args, p) is None, "no success measured yet"
    p = ppo.Progress(global_step=200, smoothed_success=0.95)
    assert ppo.should_promote(args, p) is None, "not before the minimum stage length"
    p = ppo.Progress(global_step=5000, stage_index=1, stage_start_step=0)
    assert ppo.should_promote(args, p) is None, "the last stage is never left"


def test_stage_change_sets_every_worker_s_tolerances():
    envs = ppo.make_envs(ppo.Args.of(**TINY), 2, torch.device("cpu"))
    ppo.reset(envs, seed=0)
    try:
        for stage in ("cp2", "cp3"):
            ppo.set_curriculum_stage(envs, stage)
            tol = worker_tolerances(envs)
            expected = stage_tolerances(stage)
            for t in tol:
                np.testing.assert_allclose(t, [expected["pick"], expected["place"], expected["angle_deg"]], rtol=1e-6)
    finally:
        envs.close()


@pytest.mark.parametrize("by", ["steps", "success"])
def test_promotion_in_a_run_moves_train_and_eval_envs_to_the_next_stage(tmp_path, monkeypatch, by):
    calls = []
    original = ppo.set_curriculum_stage

    def spy(envs, stage):
        original(envs, stage)
        calls.append((envs.num_envs, stage, tuple(map(tuple, worker_tolerances(envs)))))

    monkeypatch.setattr(ppo, "set_curriculum_stage", spy)
    extra = dict(stage_timesteps=160) if by == "steps" else dict(stage_timesteps=10**9, min_stage_timesteps=80, promote_success=0.0, eval_freq=2)
    args = tiny_args(tmp_path, curriculum=("cp1", "cp2"), total_timesteps=240, exp_name=f"promote_{by}", curiosity="none", **extra)
    progress = ppo.main(args)
    assert [s for _, s in progress.stage_changes] == ["cp1", "cp2"]
    assert progress.stage_changes[1][0] == 160
    cp2 = stage_tolerances("cp2")
    moved = [c for c in calls if c[1] == "cp2"]
    assert {c[0] for c in moved} == {args.num_envs, args.num_eval_envs}, "train and eval envs both change stage"
    for _, _, tols in moved:
        for t in tols:
            np.testing.assert_allclose(t, [cp2["pick"], cp2["place"], cp2["angle_deg"]], rtol=1e-6)
    rows = read_csv(tmp_path / args.exp_name / "progress.csv")
    assert [r["stage"] for r in rows] == ["cp1", "cp1", "cp2"]
    ckpt = torch.load(tmp_path / args.exp_name / "checkpoint.pt", weights_only=False)
    assert ckpt["progress"]["stage_index"] == 1
    # the policy as cp1 ended is kept beside the run's checkpoint, which goes on
    [ended] = (tmp_path / args.exp_name).glob("checkpoint_stage*.pt")
    stage_end = torch.load(ended, weights_only=False)
    assert ended.name == "checkpoint_stage1_cp1.pt" and stage_end["progress"]["global_step"] == 160
    assert ckpt["progress"]["global_step"] == 240


def test_interrupted_run_resumes_with_the_uninterrupted_run_s_state(tmp_path, monkeypatch):
    """Run U goes 4 iterations; run I is stopped (Ctrl-C) after its iteration-2 checkpoint. Restoring
    I gives U's optimizer, RNG, stage and step at iteration 2, and the resumed run ends where U ends."""
    saved = {}
    original = ppo.save_checkpoint

    def keep_copies(path, args, progress, *rest, **extra):
        original(path, args, progress, *rest, **extra)
        shutil.copy(path, path.with_name(f"iter{progress.iteration}.pt"))
        saved.setdefault(args.exp_name, []).append(progress.iteration)
        if args.exp_name == "interrupted" and progress.iteration == 2 and "stopped" not in saved:
            saved["stopped"] = True
            raise KeyboardInterrupt

    monkeypatch.setattr(ppo, "save_checkpoint", keep_copies)
    common = dict(total_timesteps=320, curriculum=("cp1", "cp2"), stage_timesteps=160, curiosity="icm")
    u = ppo.main(tiny_args(tmp_path, exp_name="uninterrupted", **common))
    i = ppo.main(tiny_args(tmp_path, exp_name="interrupted", **common))
    assert i.iteration == 2 and u.iteration == 4

    ckpt_i = tmp_path / "interrupted" / "checkpoint.pt"
    restored = ppo.setup(ppo.Args.of(resume=str(ckpt_i)))
    ref = torch.load(tmp_path / "uninterrupted" / "iter2.pt", weights_only=False)
    assert dataclasses.asdict(restored.progress) == ref["progress"]
    assert restored.progress.global_step == 160 and restored.progress.stage_index == 1
    for k, v in restored.agent.state_dict().items():
        assert torch.equal(v, ref["agent"][k]), k
    opt = restored.optimizer.state_dict()
    for pid, st in opt["state"].items():
        for key in ("exp_avg", "exp_avg_sq", "step"):
            assert torch.equal(st[key], ref["optimizer"]["state"][pid][key]), (pid, key)
    for k, v in restored.icm.state_dict().items():
        assert torch.equal(v, ref["icm"][k]), k
    icm_opt = restored.icm_optimizer.state_dict()
    assert icm_opt["state"], "the curiosity optimizer has taken steps"
    for pid, st in icm_opt["state"].items():
        for key in ("exp_avg", "exp_avg_sq", "step"):
            assert torch.equal(st[key], ref["icm_optimizer"]["state"][pid][key]), ("icm", pid, key)
    assert torch.equal(torch.get_rng_state(), ref["rng"]["torch"])
    assert np.random.get_state()[1].tolist() == ref["rng"]["numpy"][1].tolist()
    assert random.getstate() == ref["rng"]["python"], "Python's random state is restored too"
    restored.eval_envs.close()

    resumed = ppo.main(ppo.Args.of(resume=str(ckpt_i)))
    assert resumed.global_step == u.global_step and resumed.iteration == u.iteration
    assert resumed.stage_changes == u.stage_changes
    rows = read_csv(tmp_path / "interrupted" / "progress.csv")
    assert [int(r["global_step"]) for r in rows] == [80, 160, 240, 320], "the curve continues without gaps or repeats"


def test_checkpoint_for_other_shapes_gives_a_clear_error(tmp_path):
    args = tiny_args(tmp_path, exp_name="shape", total_timesteps=80, curriculum=("cp4",), curiosity="none")
    ppo.main(args)
    path = tmp_path / "shape" / "checkpoint.pt"
    with pytest.raises(SystemExit, match=f"observations of size {STATE_SIZE} and actions of size 6"):
        ppo.load_checkpoint(str(path), obs_dim=STATE_SIZE, act_dim=3, env_id="Flooring-v1")
    with pytest.raises(SystemExit, match="control mode"):
        ppo.main(tiny_args(tmp_path, exp_name="shape2", checkpoint=str(path), control_mode="pd_ee_delta_pos", evaluate=True))


def test_short_run_on_the_easiest_stage_shows_a_learning_signal(tmp_path):
    """40k steps of PPO at cp1 (dense reward, two CPU envs): the training episodes' return rises from the run's first
    half to its second, and the deterministic policy's evaluation return rises above the untrained policy's. (The
    task's dense reward pulls the arm to the turret side its goal's paths leave from first; at this budget its
    episodes pick no more often than at the start, docs/experiments/from_scratch.md.)"""
    args = tiny_args(tmp_path, exp_name="learn", reward_mode="dense", curriculum=("cp1",), curiosity="none",
                     num_steps=250, num_minibatches=4, num_eval_envs=2, total_timesteps=40_000, eval_freq=10,
                     checkpoint_freq=10**6)
    tr = ppo.setup(args)
    ppo.set_curriculum_stage(tr.eval_envs, "cp1")
    untrained = evaluation.evaluate_envs(tr.agent, tr.eval_envs, tr.args.num_eval_steps, seed=123)
    ppo.train(tr)
    rows = read_csv(tmp_path / "learn" / "progress.csv")
    evals = [r for r in rows if r["eval_pick_success"]]
    assert len(evals) == 8
    returns = [float(r["extrinsic_return"]) for r in rows if r["extrinsic_return"]]
    first, second = np.mean(returns[:len(returns) // 2]), np.mean(returns[len(returns) // 2:])
    best_return = max(float(r["eval_extrinsic_return"]) for r in evals)
    print(f"training return {first:.0f} -> {second:.0f}, evaluation {untrained['eval_extrinsic_return']:.0f} -> {best_return:.0f}")
    assert second > first
    assert best_return > untrained["eval_extrinsic_return"] + 5.0


def test_capture_video_writes_evaluation_videos_offscreen(tmp_path):
    import imageio.v3 as iio

    args = tiny_args(tmp_path, exp_name="video", capture_video=True, total_timesteps=80, eval_freq=1,
                     curriculum=("cp4",), curiosity="none", save_model=False)
    ppo.main(args)
    videos = sorted((tmp_path / "video" / "videos").glob("*.mp4"))
    assert videos, "no evaluation video"
    frames = iio.imread(videos[0])
    assert frames.shape[0] >= 200 and frames.std() > 20


@pytest.mark.parametrize("field,value,allowed", [("env_id", "Floring-v1", "Flooring-v1"),
                                                 ("control_mode", "pd_joint_vel", "pd_ee_delta_pose"),
                                                 ("reward_mode", "shaped", "normalized_dense")])
def test_an_unknown_env_control_or_reward_mode_is_refused_before_anything_starts(tmp_path, monkeypatch, field, value, allowed):
    monkeypatch.setattr(ppo, "make_envs", lambda *a, **k: pytest.fail("envs were started"))
    with pytest.raises(SystemExit) as e:
        ppo.main(tiny_args(tmp_path, **{field: value}))
    message = str(e.value)
    assert message.startswith(f"--{field.replace('_', '-')} {value}: use one of") and allowed in message


@pytest.mark.parametrize("flag,value,allowed", [("--env-id", "Floring-v1", "Flooring-v1"),
                                                ("--control-mode", "pd_joint_vel", "pd_ee_delta_pose")])
def test_the_command_line_refuses_an_unknown_env_or_control_mode_without_a_traceback(flag, value, allowed):
    out = subprocess.run([sys.executable, "baselines/ppo/ppo.py", flag, value], cwd=ROOT, capture_output=True,
                         text=True, timeout=300, env=SCRIPT_ENV)
    assert out.returncode != 0 and "Traceback" not in out.stderr, out.stderr
    assert value in out.stderr and allowed in out.stderr, out.stderr


def test_the_control_modes_args_allow_are_the_arm_s_controllers():
    env = gym.make("Flooring-v1", num_envs=1, obs_mode="state")
    try:
        assert set(get_args(ControlMode)) == set(env.unwrapped.agent.supported_control_modes)
    finally:
        env.close()


@pytest.mark.parametrize("how", ["SIGTERM", "Ctrl-C"])
def test_a_stopped_run_saves_its_checkpoint_and_exits_with_one_line(tmp_path, how):
    """SIGTERM to the learner, or SIGINT to the whole process group as Ctrl-C in a terminal sends it
    (the env workers get it too): the run ends after its iteration with a checkpoint that resumes,
    and says so in one line, without tracebacks from the workers it closes."""
    cmd = [sys.executable, "baselines/ppo/ppo.py", "--env-id", "Flooring-v1", "--sim-backend", "physx_cpu",
           "--num-envs", "2", "--num-eval-envs", "1", "--num-steps", "40", "--num-minibatches", "2",
           "--update-epochs", "1", "--eval-freq", "1000", "--total-timesteps", "1000000", "--curiosity", "none",
           "--curriculum", "cp4", "--log-dir", str(tmp_path), "--exp-name", "stopped"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=SCRIPT_ENV,
                            start_new_session=True)  # its own process group, as a terminal's job
    csv_path = tmp_path / "stopped" / "progress.csv"
    try:
        deadline = time.monotonic() + 240
        while not (csv_path.exists() and len(read_csv(csv_path)) >= 1):
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[1] if proc.poll() is not None else "no iteration yet"
            time.sleep(0.5)
        sig = signal.SIGTERM if how == "SIGTERM" else signal.SIGINT
        if how == "SIGTERM":
            proc.send_signal(sig)
        else:
            os.killpg(proc.pid, sig)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 128 + sig, (proc.returncode, stderr)
    assert "Traceback" not in stderr, stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith(f"stopped by {sig.name} at step ") and "--resume" in last, stderr
    rows = read_csv(csv_path)
    ckpt = tmp_path / "stopped" / "checkpoint.pt"
    run = ppo.setup(ppo.Args.of(resume=str(ckpt)))
    try:
        assert run.progress.iteration == len(rows) and run.progress.global_step == int(rows[-1]["global_step"])
    finally:
        run.eval_envs.close()


# ---- the update on a fixed batch: the numbers the update gave before it was a function (e2cc667's inline
# update, run on this batch), so that a speed-up cannot change what PPO computes (ICM, which learns
# beside the policy with its own optimizer, has followed ML-Agents since: tests/test_curiosity.py) ----
REFERENCE_UPDATES = {
    "plain": (dict(curiosity="none", bc=False, clip_vloss=False, target_kl=None), dict(
        value_loss=1.0177209327618282, policy_loss=0.23657110623187488, entropy=5.539665751987034,
        approx_kl=0.45542471193605, updates=36, agent_abs_sum=3227.7171355229466, actor_w0_00=-0.4099215865135193,
        critic_last_b=-0.0003031925007235259)),
    "bc_clip": (dict(curiosity="none", bc=True, clip_vloss=True, target_kl=0.1), dict(
        bc_loss=0.3338286429643631, value_loss=1.140690834985839, policy_loss=0.2619187815321816,
        entropy=5.526213937335545, approx_kl=0.4729703813791275, updates=18, agent_abs_sum=3225.788997618196,
        actor_w0_00=-0.41276541352272034, critic_last_b=0.0002896629157476127)),
    "early_stop": (dict(curiosity="none", bc=False, clip_vloss=False, target_kl=1e-4), dict(
        value_loss=1.0333226720492046, policy_loss=0.21124553183714548, entropy=5.519400437672933,
        approx_kl=0.45658889578448403, updates=9, agent_abs_sum=3225.32009339033, actor_w0_00=-0.4143797755241394,
        critic_last_b=0.0005660938913933933)),
}


def fixed_batch(n=500, obs_dim=43, act_dim=6) -> dict:
    g = torch.Generator().manual_seed(0)
    obs = torch.randn(n, obs_dim, generator=g)
    next_obs = obs + 0.1 * torch.randn(n, obs_dim, generator=g)
    actions = torch.rand(n, act_dim, generator=g) * 2 - 1
    adv = torch.randn(n, generator=g)
    values = torch.randn(n, generator=g)
    logprobs = -5 + 0.3 * torch.randn(n, generator=g)
    return dict(obs=obs, next_obs=next_obs, actions=actions, logprobs=logprobs, advantages=adv,
                returns=(adv + values)[:, None], values=values[:, None])  # one value head


@pytest.mark.parametrize("case", list(REFERENCE_UPDATES))
def test_one_update_on_a_fixed_batch_gives_the_losses_and_weights_of_the_original_update(case, monkeypatch):
    setting, expected = REFERENCE_UPDATES[case]
    # the references were computed on the observation layout before paneling's task slot: its quaternions there
    monkeypatch.setattr(checkpoints, "STATE_QUATERNION_STARTS", (16, 23, 33))
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        torch.manual_seed(0)
        np.random.seed(0)
        args = ppo.Args.of(hidden_size=64, num_minibatches=8, update_epochs=4, curiosity=setting["curiosity"],
                        bc_coef=0.1 if setting["bc"] else 0.0, clip_vloss=setting["clip_vloss"],
                        target_kl=setting["target_kl"], icm_feature_dim=16)
        agent = ppo.make_agent(args, 43, 6)
        optimizer = update.adam(agent.parameters(), lr=args.ppo.learning_rate, eps=1e-5)
        batch = fixed_batch()
        agent.obs_rms.update(agent.features(batch["obs"]))
        g = torch.Generator().manual_seed(1)
        demos = (torch.randn(300, 43, generator=g), torch.rand(300, 6, generator=g)) if setting["bc"] else None
        n_steps = []
        step = optimizer.step
        optimizer.step = lambda *a, **k: (n_steps.append(1), step(*a, **k))[1]
        losses = update.ppo_update(agent, optimizer, batch, args, demos=demos)
    finally:
        torch.set_num_threads(threads)
    with torch.no_grad():
        got = dict(losses, updates=len(n_steps), agent_abs_sum=float(sum(p.double().abs().sum() for p in agent.parameters())),
                   actor_w0_00=float(agent.actor_mean[0].weight[0, 0]), critic_last_b=float(agent.critic[6].bias[0]))
    assert set(got) == set(expected)
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-5, abs=1e-6), key


def test_the_saturation_penalty_brings_a_bounded_mean_pinned_past_tanh_s_flat_end_back_where_ppo_can_move_it():
    """A bounded mean whose first action's value before tanh is pinned at +10 (tanh's slope 1e-8: the from-scratch
    policy's turret) stays pinned through a plain update; with `mean_saturation_coef` the update pulls it back toward
    `mean_saturation_bound` (2: tanh's slope 0.07 there; a lower bound pulls further), and reports the penalty;
    `mean_saturation_joints` penalizes only the dimensions named (the turret's, 0, moves; naming another leaves it
    pinned). The weight needs --bounded-mean, the joints the weight, the bound must be > 0."""
    batch = fixed_batch()
    pinned = {}
    for coef, joints, bound in ((0.0, None, 2.0), (0.01, None, 2.0), (0.01, (0,), 2.0), (0.01, (1, 2), 2.0),
                                (0.01, (0,), 0.5)):
        torch.manual_seed(0)
        np.random.seed(0)
        args = ppo.Args.of(hidden_size=64, num_minibatches=8, update_epochs=4, curiosity="none", target_kl=None,
                           bounded_mean=True, mean_saturation_coef=coef, mean_saturation_joints=joints,
                           mean_saturation_bound=bound, learning_rate=0.01)
        agent = ppo.make_agent(args, 43, 6)
        agent.obs_rms.update(agent.features(batch["obs"]))
        with torch.no_grad():
            agent.actor_mean[-2].bias[0] = 10.0  # the last Linear, before the tanh
            before = agent.mean_before_tanh(batch["obs"])[:, 0].mean().item()
        optimizer = update.adam(agent.parameters(), lr=args.ppo.learning_rate, eps=1e-5)
        losses = update.ppo_update(agent, optimizer, batch, args)
        with torch.no_grad():
            pinned[coef, joints, bound] = agent.mean_before_tanh(batch["obs"])[:, 0].mean().item()
        assert ("mean_saturation" in losses) == (coef > 0)
    assert before > 9
    assert pinned[0.0, None, 2.0] == pytest.approx(before, abs=0.05), "without the penalty nothing moves a pinned mean"
    assert pinned[0.01, None, 2.0] < before - 0.5 and pinned[0.01, (0,), 2.0] < before - 0.5, pinned
    assert pinned[0.01, (1, 2), 2.0] == pytest.approx(before, abs=0.05), \
        "a penalty on other joints leaves the turret pinned"
    assert pinned[0.01, (0,), 0.5] < pinned[0.01, (0,), 2.0], "a lower bound pulls the mean further"
    with pytest.raises(SystemExit, match="bounded-mean"):
        ppo.validate(ppo.Args.of(mean_saturation_coef=0.01))
    with pytest.raises(SystemExit, match="mean-saturation-bound"):
        ppo.validate(ppo.Args.of(bounded_mean=True, mean_saturation_coef=0.01, mean_saturation_bound=0.0))
    for joints in ((0,), (0, 0), (-1,)):
        with pytest.raises(SystemExit, match="mean-saturation-joints"):
            ppo.validate(ppo.Args.of(bounded_mean=True, mean_saturation_coef=0.01 if joints != (0,) else 0.0,
                                     mean_saturation_joints=joints))


def test_the_log_std_floor_holds_the_named_joints_spread_through_an_update_and_leaves_the_others():
    """With `log_std_floor` the policy's log standard deviation on `log_std_floor_joints` is raised to the floor and
    stays there through an update whose entropy penalty pushes every spread down; the other joints' spreads fall
    below it. The joints need the floor, and must be distinct dimensions >= 0."""
    batch = fixed_batch()
    torch.manual_seed(0)
    np.random.seed(0)
    args = ppo.Args.of(hidden_size=64, num_minibatches=8, update_epochs=4, curiosity="none", target_kl=None,
                       ent_coef=-1.0, learning_rate=0.05, log_std_floor=-1.2, log_std_floor_joints=(0,))
    agent = ppo.make_agent(args, 43, 6)
    agent.obs_rms.update(agent.features(batch["obs"]))
    with torch.no_grad():
        agent.actor_logstd.fill_(-2.3)
    update.hold_log_std_floor(agent, args)
    assert agent.actor_logstd[0, 0].item() == pytest.approx(-1.2)
    assert agent.actor_logstd[0, 1].item() == pytest.approx(-2.3)
    optimizer = update.adam(agent.parameters(), lr=args.ppo.learning_rate, eps=1e-5)
    update.ppo_update(agent, optimizer, batch, args)
    log_std = agent.actor_logstd[0].detach()
    assert log_std[0].item() == pytest.approx(-1.2), "the floor holds the turret's spread"
    assert (log_std[1:] < -2.3 - 0.1).all(), log_std
    for joints, floor in (((0,), None), ((0, 0), -1.0), ((-1,), -1.0)):
        with pytest.raises(SystemExit, match="log-std-floor-joints"):
            ppo.validate(ppo.Args.of(log_std_floor=floor, log_std_floor_joints=joints))


def test_a_checkpoint_of_an_earlier_version_loads_through_the_checkpoint_api(tmp_path):
    """Checkpoints written before baselines/ppo/checkpoints.py saved their args under earlier names and meanings
    (`finite_horizon_gae`, a boolean `norm_adv`, `icm` for the normalized variant before ML-Agents' curiosity with
    its `icm_gamma` took the name): such args, on the shipped clone's weights, load under today's."""
    ckpt = torch.load(ROOT / "assets/checkpoints/general_agent_clone_direct.pt", map_location="cpu", weights_only=False)
    old = {k: v for k, v in ckpt["args"].items() if k not in ("bootstrap_at_done", "icm_gamma")}
    old.update(finite_horizon_gae=True, norm_adv=True, curiosity="icm")
    last = max(k for k in ckpt["agent"] if k.startswith("critic.")).rsplit(".", 1)[0]  # one value head then
    agent = {k: v[:1] if k.startswith(last + ".") else v for k, v in ckpt["agent"].items()}
    path = tmp_path / "old.pt"
    torch.save({**ckpt, "args": old, "agent": agent}, path)
    ckpt = checkpoints.load_checkpoint(path, env_id="Flooring-v1", obs_dim=STATE_SIZE, act_dim=6,
                                       control_mode="pd_joint_delta_pos")
    assert ckpt["args"]["bootstrap_at_done"] == "truncated" and "finite_horizon_gae" not in ckpt["args"]
    assert ckpt["args"]["norm_adv"] == "minibatch"
    assert ckpt["args"]["curiosity"] == "icm_normalized", "before ML-Agents' curiosity, icm meant the normalized variant"
    args = ppo.Args.of(**{**ckpt["args"], "curriculum": tuple(ckpt["args"]["curriculum"])})  # what --resume builds
    assert args.ppo.bootstrap_at_done == "truncated"
    agent, env_kwargs = checkpoints.load_policy(path, "Flooring-v1")
    assert env_kwargs == {"control_mode": "pd_joint_delta_pos"}
    for k, v in agent.state_dict().items():
        assert torch.equal(v, ckpt["agent"][k]), k
    with pytest.raises(SystemExit, match="control mode pd_joint_delta_pos, not pd_joint_pos"):
        checkpoints.load_checkpoint(path, env_id="Flooring-v1", obs_dim=STATE_SIZE, act_dim=6, control_mode="pd_joint_pos")


@pytest.mark.parametrize("damage", ["random bytes", "truncated", "not a dict"])
def test_a_file_that_is_not_a_checkpoint_is_refused_in_one_line_naming_it(tmp_path, damage):
    from baselines.ppo import checkpoints

    path = tmp_path / "bad.pt"
    if damage == "random bytes":
        path.write_bytes(np.random.default_rng(0).bytes(4096))
    elif damage == "truncated":
        path.write_bytes((ROOT / "assets/checkpoints/general_agent.pt").read_bytes()[:50_000])
    else:
        torch.save([1, 2, 3], path)
    for option in ("--checkpoint", "--resume"):
        with pytest.raises(SystemExit) as e:
            checkpoints.load_checkpoint(path, option)
        message = str(e.value)
        assert message.startswith(f"{option}: {path} is not a checkpoint") and "\n" not in message
        assert "a checkpoint is the .pt file that baselines/ppo/ppo.py" in message
    with pytest.raises(SystemExit, match="is not a checkpoint"):
        ppo.setup(ppo.Args.of(resume=str(path)))


@pytest.mark.parametrize("script", [["scripts/evaluate.py"], ["baselines/ppo/ppo.py", "--evaluate"]])
def test_the_command_line_refuses_a_garbage_checkpoint_without_a_traceback(tmp_path, script):
    path = tmp_path / "garbage.pt"
    path.write_bytes(b"not a checkpoint at all" * 100)
    out = subprocess.run([sys.executable, *script, "--checkpoint", str(path), "--env-id", "Flooring-v1"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, env=SCRIPT_ENV)
    assert out.returncode != 0 and "Traceback" not in out.stderr, out.stderr
    assert f"{path} is not a checkpoint" in out.stderr.strip().splitlines()[-1], out.stderr


def test_near_goal_starts_widen_per_task_with_success_and_a_resumed_run_goes_on_from_its_radii(tmp_path, monkeypatch):
    """The start-state curriculum in a short run of the dense recipe on Flooring-v1: radius 0 starts every
    near-goal episode installed (placed at once), so the floor's radius widens by its step each time its window of
    episodes fills with placements, while the other task types' radii stay; the policy changes; a resumed run
    sets the workers' radii from its checkpoint (with the windows), not from --near-goal-radius."""
    calls = []
    original = ppo.call_task
    monkeypatch.setattr(ppo, "call_task", lambda envs, name, *a: (calls.append((name, a)), original(envs, name, *a))[1])
    common = dict(reward_mode="normalized_dense", curiosity="none", curriculum=("cp4",), near_goal_share=1.0,
                  near_goal_radius=0.0, near_goal_step=0.05, near_goal_promote=0.5, near_goal_window=4, total_timesteps=160)
    args = tiny_args(tmp_path, exp_name="near", **common)
    torch.manual_seed(args.seed)
    initial = {k: v.clone() for k, v in ppo.setup(args).agent.state_dict().items()}
    progress = ppo.main(args)
    rows = read_csv(tmp_path / "near" / "progress.csv")
    assert float(rows[0]["near_goal_radius_flooring"]) == 0.0 and int(rows[0]["near_goal_episodes"]) > 0
    assert float(rows[0]["near_goal_place_success"]) == 1.0
    assert progress.near_goal_radius[:2] == [0.0, 0.0] and progress.near_goal_radius[2] >= 0.05
    shares = (1.0,) * 4  # a share and a radius per task type, paneling's too
    assert ("set_near_goal_starts", (shares, (0.0, 0.0, 0.0, 0.0), None)) in calls
    assert ("set_near_goal_starts", (shares, (0.0, 0.0, 0.05, 0.0), None)) in calls
    ckpt = torch.load(tmp_path / "near" / "checkpoint.pt", weights_only=False)
    assert ckpt["progress"]["near_goal_radius"] == progress.near_goal_radius
    assert ckpt["progress"]["near_goal_recent"] == progress.near_goal_recent and len(progress.near_goal_recent[2]) < 4
    assert any(not torch.equal(v, ckpt["agent"][k]) for k, v in initial.items()), "the policy changed"

    restored = ppo.setup(ppo.Args.of(resume=str(tmp_path / "near" / "checkpoint.pt")))
    assert restored.progress.near_goal_recent == progress.near_goal_recent
    restored.eval_envs.close()
    calls.clear()
    resumed = ppo.main(ppo.Args.of(resume=str(tmp_path / "near" / "checkpoint.pt"), extend=True, total_timesteps=240,
                                curriculum=("cp4",)))
    first = next(c for c in calls if c[0] == "set_near_goal_starts")
    assert first == ("set_near_goal_starts", (shares, tuple(progress.near_goal_radius), None)), calls
    assert resumed.global_step == 240


def test_once_a_radius_is_whole_its_promotions_hand_near_goal_starts_back_to_ordinary_resets():
    """--near-goal-share-end: a task type whose radius is 1 lowers its share of near-goal starts by the step at each
    promotion (a full window placing often enough), down to the end, the other types' shares and radii as they were;
    a type still widening widens; without an end the share stays."""
    from types import SimpleNamespace

    from baselines.ppo.args import validate
    from baselines.ppo.start_states import widen_near_goal

    def run(end, rounds):
        starts = SimpleNamespace(near_goal_window=4, near_goal_promote=0.5, near_goal_step=0.25,
                                 near_goal_share_end=end)
        progress = SimpleNamespace(near_goal_radius=[1.0, 1.0, 0.5, 1.0], near_goal_share=[0.8] * 4,
                                   near_goal_recent=[[] for _ in range(4)])
        changed = [widen_near_goal(SimpleNamespace(starts=starts), progress, [1] * 4 + [2] * 4, [1.0] * 8)
                   for _ in range(rounds)]
        return progress, changed

    progress, changed = run(0.2, 4)  # the window's: 0.8 -> 0.55 -> 0.3 -> 0.2; the floor's radius 0.5 -> 0.75 -> 1.0,
    # then its share 0.8 -> 0.55 -> 0.3
    assert progress.near_goal_share == [0.8, 0.2, 0.3, 0.8] and progress.near_goal_radius == [1.0] * 4
    assert changed == [True] * 4
    progress, changed = run(0.2, 6)
    assert progress.near_goal_share == [0.8, 0.2, 0.2, 0.8] and changed == [True] * 5 + [False]
    progress, changed = run(None, 3)
    assert progress.near_goal_share == [0.8] * 4 and changed == [True, True, False]  # the floor's widening only
    with pytest.raises(SystemExit, match="--near-goal-share-end 0.9"):
        validate(ppo.Args.of(near_goal_share=0.8, near_goal_share_end=0.9))


def test_reach_starts_widen_per_goal_slot_as_they_grasp_from_their_side_and_a_resumed_run_sets_the_radii(tmp_path, monkeypatch):
    """--reach-start-radius: the iteration's reach-start episodes are counted apart from the ordinary resets (not in
    `ordinary_place_*`), and a goal slot's reach-start radius widens by --near-goal-step once its last
    --near-goal-window such episodes grasped from the side they started on often enough (the workers told at once),
    whatever the other slots of its task type did; --reach-start-tasks gives the share to those task types alone.
    A run sets the workers' radii from --reach-start-radius, keeps them and their windows in its checkpoint, and a
    resumed run sets them from there. The flag needs reach starts."""
    for bad in (dict(reach_start_radius=1.5, reach_start_share=1.0), dict(reach_start_radius=0.2)):
        with pytest.raises(SystemExit, match="reach-start-radius"):
            ppo.validate(Args.of(**bad))
    for bad in (dict(reach_start_share=1.0, reach_start_tasks=("window",)),
                dict(reach_start_share=1.0, reach_start_radius=0.1, reach_start_tasks=("windows",))):
        with pytest.raises(SystemExit, match="reach-start-tasks"):
            ppo.validate(Args.of(**bad))
    calls = []
    original = ppo.call_task
    monkeypatch.setattr(ppo, "call_task", lambda envs, name, *a: calls.append((name, a)))  # no envs here
    args = Args.of(env_id="ConstructionPickPlace-v1", reach_start_share=1.0, reach_start_radius=0.1, near_goal_window=4,
                   near_goal_promote=0.5, near_goal_step=0.1)
    progress = ppo.Progress(reach_start_radius=[0.1] * 12, reach_start_recent=[[] for _ in range(12)])  # paneling's 3 last
    episodes = {key: [0.0] * 9 for key in ppo.EPISODE_STATS.values()}
    # windows: slot 0 grasps from its side 3 of 4 times, slot 2 never; a floor panel from an ordinary reset places
    episodes.update(success=[0.0] * 6 + [1.0, 0.0, 0.0], task_id=[1, 1, 1, 1, 1, 1, 2, 0, 1],
                    goal_slot=[0, 0, 0, 0, 2, 2, 1, 0, 2], near_goal=[False] * 9,
                    reach_start=[True] * 6 + [False, True, True], intrinsic_return=[],
                    reach_start_grasped=[1.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    row = ppo.episode_columns(args, progress, episodes, envs=None)
    assert row["reach_start_episodes"] == 8 and row["reach_start_grasp_success"] == pytest.approx(3 / 8)
    assert row["ordinary_place_flooring"] == 1.0 and "ordinary_place_window" not in row, "reach starts are not ordinary"
    widened = [0.1, 0.1, 0.1, 0.2, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]
    assert progress.reach_start_radius == widened, "the slot that never grasps from its side does not widen"
    assert row["reach_start_radius_window0"] == 0.1, "the row holds the radius its episodes started at"
    assert progress.reach_start_recent[3] == [] and progress.reach_start_recent[5] == [0.0, 0.0, 0.0]
    assert calls == [("set_reach_starts", ((1.0, 1.0, 1.0, 1.0), tuple(widened)))]

    monkeypatch.setattr(ppo, "call_task", lambda envs, name, *a: (calls.append((name, a)), original(envs, name, *a))[1])
    calls.clear()
    run = tiny_args(tmp_path, exp_name="reach", reward_mode="normalized_dense", curiosity="none", curriculum=("cp4",),
                    reach_start_share=1.0, reach_start_radius=0.0, reach_start_tasks=("flooring",), total_timesteps=80)
    ppo.main(run)
    assert ("set_reach_starts", ((0.0, 0.0, 1.0, 0.0), (0.0,) * 12)) in calls, "the share for --reach-start-tasks alone"
    assert read_csv(tmp_path / "reach" / "progress.csv")[-1]["reach_start_radius_flooring2"] == "0.0"
    path = tmp_path / "reach" / "checkpoint.pt"
    ckpt = torch.load(path, weights_only=False)
    assert ckpt["progress"]["reach_start_radius"] == [0.0] * 12
    radii, recent = [round(i / 11, 6) for i in range(12)], [[1.0]] + [[] for _ in range(11)]
    ckpt["progress"]["reach_start_radius"], ckpt["progress"]["reach_start_recent"] = radii, recent
    torch.save(ckpt, path)
    calls.clear()
    ppo.main(ppo.Args.of(resume=str(path), extend=True, total_timesteps=120, curriculum=("cp4",)))
    assert next(a for name, a in calls if name == "set_reach_starts") == ((0.0, 0.0, 1.0, 0.0), tuple(radii))
    assert torch.load(path, weights_only=False)["progress"]["reach_start_recent"] == recent


def test_failure_task_weights_sample_more_of_what_fails_and_a_resumed_run_sets_them_from_its_checkpoint(tmp_path, monkeypatch):
    """--failure-task-weights: each task type weighs the floor + its failure rate over its last N ordinary-reset
    episodes (near-goal starts do not count); the weights reach the training envs, the CSV and the checkpoint's
    windows, and a resumed run sets the workers' weights from those windows."""
    from baselines.ppo.start_states import FAILURE_WEIGHT_FLOOR, failure_task_weights

    with pytest.raises(SystemExit, match="without --task-weights"):
        ppo.validate(Args.of(env_id="ConstructionPickPlace-v1", failure_task_weights=10, task_weights=(1.0, 1.0, 1.0)))
    with pytest.raises(SystemExit, match="general task"):
        ppo.validate(Args.of(env_id="Flooring-v1", failure_task_weights=10))
    progress = ppo.Progress()
    assert failure_task_weights(Args.of(failure_task_weights=4), progress, [], []) == pytest.approx([1 / 3] * 3)
    weights = failure_task_weights(Args.of(failure_task_weights=4), progress, [0, 0, 1, 2, 2, 2, 2, 2],
                                   [1, 1, 0, 1, 1, 0, 0, 0])
    assert progress.ordinary_recent == [[1.0, 1.0], [0.0], [1.0, 0.0, 0.0, 0.0], []]  # the last 4 of each type
    raw = [FAILURE_WEIGHT_FLOOR, 1 + FAILURE_WEIGHT_FLOOR, 0.75 + FAILURE_WEIGHT_FLOOR]
    assert weights == pytest.approx([w / sum(raw) for w in raw])

    calls = []
    original = ppo.call_task
    monkeypatch.setattr(ppo, "call_task", lambda envs, name, *a: (calls.append((name, a)), original(envs, name, *a))[1])
    args = tiny_args(tmp_path, exp_name="weights", env_id="ConstructionPickPlace-v1", reward_mode="normalized_dense",
                     curiosity="none", curriculum=("cp4",), failure_task_weights=5, total_timesteps=80)
    ppo.main(args)
    rows = read_csv(tmp_path / "weights" / "progress.csv")
    assert all(sum(float(r[f"task_weight_{k}"]) for k in ("ceiling", "window", "flooring")) == pytest.approx(1)
               for r in rows)
    first = next(a for name, a in calls if name == "set_task_weights")
    assert list(first[0]) == ["ceiling", "window", "flooring"] and list(first[0].values()) == pytest.approx([1 / 3] * 3)
    path = tmp_path / "weights" / "checkpoint.pt"
    ckpt = torch.load(path, weights_only=False)
    assert ckpt["progress"]["ordinary_recent"] == [[], [], [], []]  # no ordinary episode ends in 40 steps
    ckpt["progress"]["ordinary_recent"] = [[1.0, 1.0], [0.0], [1.0, 0.0], []]  # as if some had
    torch.save(ckpt, path)
    calls.clear()
    ppo.main(ppo.Args.of(resume=str(path), extend=True, total_timesteps=120, curriculum=("cp4",)))
    first = next(a for name, a in calls if name == "set_task_weights")
    raw = [FAILURE_WEIGHT_FLOOR, 1 + FAILURE_WEIGHT_FLOOR, 0.5 + FAILURE_WEIGHT_FLOOR]
    assert list(first[0].values()) == pytest.approx([w / sum(raw) for w in raw])


def test_progress_csv_keeps_every_task_type_s_columns_paneling_s_too():
    """A run on paneling logs its own start radii and ordinary-reset success: every per-task-type column
    `episode_columns` writes is one of the CSV's (the CSV drops the rest), for each of ELEMENT_KINDS."""
    from collections import defaultdict

    from experiments.from_scratch import scratch_args
    from ms_construction.parameters import ELEMENT_KINDS

    args = scratch_args(2, env_id="PanelInstallation-v1")
    kinds = len(ELEMENT_KINDS)
    progress = checkpoints.Progress(near_goal_radius=[0.3] * kinds, near_goal_share=[0.8] * kinds,
                                    near_goal_recent=[[] for _ in range(kinds)],
                                    reach_start_radius=[0.2] * (3 * kinds),
                                    reach_start_recent=[[] for _ in range(3 * kinds)])
    paneling = ELEMENT_KINDS.index("paneling")
    # one episode of each kind of start, none enough to widen a radius (so no env is called)
    episodes = defaultdict(list, success=[1.0, 0.0, 1.0], picked=[1.0, 1.0, 1.0], near_goal=[False, True, False],
                    reach_start=[False, False, True], reach_start_grasped=[0.0, 0.0, 1.0], task_id=[paneling] * 3,
                    goal_slot=[0, 1, 2], **{key: [0.0] * 3 for key in ppo.EPISODE_STATS.values()
                                            if key not in ("success", "picked")})
    row = ppo.episode_columns(args, progress, episodes, envs=None)
    per_kind = [k for k in row if any(kind in k for kind in ELEMENT_KINDS)]
    assert {"ordinary_place_paneling", "near_goal_radius_paneling", "reach_start_radius_paneling2"} <= set(per_kind)
    assert not set(per_kind) - set(checkpoints.CSV_FIELDS), set(per_kind) - set(checkpoints.CSV_FIELDS)
    assert row["ordinary_place_paneling"] == 1.0 and row["reach_start_radius_paneling2"] == 0.2
