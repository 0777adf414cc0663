"""The learner: PPO and ICM update, curriculum promotion, checkpoints and exact resume, control groups."""

import csv
import dataclasses
import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from baselines.ppo import ppo
from ms_construction.curriculum import stage_tolerances

TINY = dict(num_envs=2, num_eval_envs=1, num_steps=40, num_minibatches=2, update_epochs=2, eval_freq=100,
            num_eval_steps=250, checkpoint_freq=1, env_id="Flooring-v1", sim_backend="physx_cpu")


def tiny_args(tmp_path, **kw) -> ppo.Args:
    return ppo.Args(**{**TINY, "log_dir": str(tmp_path), **kw})


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


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
        assert not torch.equal(ckpt["icm"]["encoder.0.weight"], initial_icm["encoder.0.weight"])
    else:
        assert ckpt["icm"] is None


def test_icm_forward_error_falls_on_transitions_it_has_seen():
    torch.manual_seed(0)
    icm = ppo.ICM(obs_dim=43, act_dim=6, feature_dim=32, hidden=128)
    opt = torch.optim.Adam(icm.parameters(), lr=1e-3)
    obs, act = torch.randn(256, 43), torch.rand(256, 6) * 2 - 1
    next_obs = obs + 0.1 * torch.cat([act, torch.zeros(256, 37)], -1)
    unseen = torch.randn(256, 43)
    first = icm.forward_error(obs, next_obs, act).mean().item()
    for _ in range(300):
        fwd, inv = icm.losses(obs, next_obs, act)
        loss = 0.8 * inv + 0.2 * fwd
        opt.zero_grad()
        loss.backward()
        opt.step()
    seen_after = icm.forward_error(obs, next_obs, act).mean().item()
    assert seen_after < 0.2 * first
    unseen_after = icm.forward_error(unseen, unseen + 0.1 * torch.cat([act, torch.zeros(256, 37)], -1), act).mean().item()
    assert unseen_after > 2 * seen_after, "curiosity must stay high where the model has not been"
    # the intrinsic reward is that error, normalized and scaled by the strength
    r = icm.intrinsic_reward(obs, next_obs, act, strength=0.02)
    assert r.shape == (256,) and torch.all(r >= 0)


def test_promotion_rules():
    args = ppo.Args(curriculum=("cp1", "cp2"), stage_timesteps=1000, min_stage_timesteps=300, promote_success=0.8)
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


def test_vec_env_stage_change_sets_every_worker_s_tolerances():
    args = ppo.Args(**{**TINY, "num_envs": 2})
    envs = ppo.VecEnv(args, 2, "physx_cpu", torch.device("cpu"))
    envs.reset(seed=0)
    try:
        for stage in ("cp2", "cp3"):
            envs.set_curriculum_stage(stage)
            tol = envs.env.call("tolerances")
            expected = stage_tolerances(stage)
            for t in tol:
                np.testing.assert_allclose(t, [expected["pick"], expected["place"], expected["angle_deg"]], rtol=1e-6)
    finally:
        envs.close()


@pytest.mark.parametrize("by", ["steps", "success"])
def test_promotion_in_a_run_moves_train_and_eval_envs_to_the_next_stage(tmp_path, monkeypatch, by):
    calls = []
    original = ppo.VecEnv.set_curriculum_stage

    def spy(self, stage):
        original(self, stage)
        calls.append((self.num_envs, stage, tuple(map(tuple, self.env.call("tolerances")))))

    monkeypatch.setattr(ppo.VecEnv, "set_curriculum_stage", spy)
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


def test_interrupted_run_resumes_with_the_uninterrupted_run_s_state(tmp_path, monkeypatch):
    """Run U goes 4 iterations; run I is stopped (Ctrl-C) after its iteration-2 checkpoint. Restoring
    I gives U's optimizer, RNG, stage and step at iteration 2, and the resumed run ends where U ends."""
    saved = {}
    original = ppo.save_checkpoint

    def keep_copies(path, args, progress, *rest):
        original(path, args, progress, *rest)
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
    restored = ppo.setup(ppo.Args(resume=str(ckpt_i)))
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
    assert torch.equal(torch.get_rng_state(), ref["rng"]["torch"])
    assert np.random.get_state()[1].tolist() == ref["rng"]["numpy"][1].tolist()
    restored.eval_envs.close()

    resumed = ppo.main(ppo.Args(resume=str(ckpt_i)))
    assert resumed.global_step == u.global_step and resumed.iteration == u.iteration
    assert resumed.stage_changes == u.stage_changes
    rows = read_csv(tmp_path / "interrupted" / "progress.csv")
    assert [int(r["global_step"]) for r in rows] == [80, 160, 240, 320], "the curve continues without gaps or repeats"


def test_checkpoint_for_other_shapes_gives_a_clear_error(tmp_path):
    args = tiny_args(tmp_path, exp_name="shape", total_timesteps=80, curriculum=("cp4",), curiosity="none")
    ppo.main(args)
    path = tmp_path / "shape" / "checkpoint.pt"
    with pytest.raises(SystemExit, match="observations of size 43 and actions of size 6"):
        ppo.load_checkpoint(str(path), obs_dim=43, act_dim=3, env_id="Flooring-v1")
    with pytest.raises(SystemExit, match="control mode"):
        ppo.main(tiny_args(tmp_path, exp_name="shape2", checkpoint=str(path), control_mode="pd_ee_delta_pos", evaluate=True))


def test_control_group_command_plans_three_single_task_runs_at_cp4():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import train_control_groups as cg

    runs = cg.plan(cg.Args(total_timesteps=1234))
    assert [r.env_id for r in runs] == ["CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1"]
    assert [r.exp_name.split("_")[0] for r in runs] == ["controlGroup4.1", "controlGroup4.2", "controlGroup4.3"]
    for r in runs:
        assert r.curriculum == ("cp4",) and r.total_timesteps == 1234 and r.checkpoint is None


def test_short_run_on_the_easiest_stage_shows_a_learning_signal(tmp_path):
    """40k steps of PPO at cp1 (dense reward, two CPU envs): the deterministic policy's evaluation
    pick success rises above the untrained policy's, and so does its evaluation return."""
    args = tiny_args(tmp_path, exp_name="learn", reward_mode="dense", curriculum=("cp1",), curiosity="none",
                     num_steps=250, num_minibatches=4, num_eval_envs=2, total_timesteps=40_000, eval_freq=10,
                     checkpoint_freq=10**6)
    tr = ppo.setup(args)
    tr.eval_envs.set_curriculum_stage("cp1")
    untrained = ppo.evaluate(tr.agent, tr.eval_envs, tr.args, seed=123)
    ppo.train(tr)
    evals = [r for r in read_csv(tmp_path / "learn" / "progress.csv") if r["eval_pick_success"]]
    assert len(evals) == 8
    best_pick = max(float(r["eval_pick_success"]) for r in evals)
    best_return = max(float(r["eval_extrinsic_return"]) for r in evals)
    print(f"pick {untrained['eval_pick_success']} -> {best_pick}, return {untrained['eval_extrinsic_return']:.0f} -> {best_return:.0f}")
    assert best_pick > untrained["eval_pick_success"]
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
