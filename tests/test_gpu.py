"""physx_cuda: many envs, mixed task types, the grasp and hold, rgb and video, CPU-GPU parity.
Skipped where there is no CUDA GPU.

`python scripts/benchmark.py --no-cpu` measures the same things on a GPU and writes them to
docs/BENCHMARKS.md (its GPU section), the parity differences included."""


import gymnasium as gym
import numpy as np
import pytest
import torch

import ms_construction  # noqa: F401
from ms_construction.envs import ENV_IDS
from ms_construction.envs.state_layout import STATE_SIZE

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (physx_cuda)")

# CPU-GPU parity tolerances for the scripted grasp and carry of scripts/benchmark.py (`parity`).
# PROVISIONAL: not yet measured on a GPU (no GPU was lent when these tests were written). The two
# backends' solvers differ (ManiSkill says so), but in this script the element is mostly either at
# rest on the table or held, i.e. driven every substep to a pose fixed to the plate, and the plate
# follows joint targets, so the element's pose should follow the arm's kinematics closely on both.
# The tolerances are far below the task's own scales (tau_place 0.10 m, tau_angle 20 degrees at
# cp4); replace them with a few times the differences that docs/BENCHMARKS.md reports once measured.
PARITY_POS_TOL_M = 0.01
PARITY_ANGLE_TOL_DEG = 1.0
PARITY_STEP_TOL = 1
"""grasp and success steps may differ by this many control steps (a ray distance or a placement
error that lands on the threshold on one backend and just past it on the other)."""


@pytest.fixture(scope="module")
def bench():
    """scripts/benchmark.py (the repository root is on pytest's pythonpath)."""
    import scripts.benchmark as bench

    return bench


def test_general_task_on_gpu_mixes_elements_and_holds_them():
    env = gym.make("ConstructionPickPlace-v1", num_envs=64, sim_backend="physx_cuda", obs_mode="state",
                   control_mode="pd_joint_delta_pos", reward_mode="sparse")
    obs, info = env.reset(seed=0)
    assert obs.shape == (64, STATE_SIZE)
    assert set(info["task_id"].tolist()) == {0, 1, 2}
    u = env.unwrapped
    state = u.get_state_dict()
    state["task"]["held"][:32] = True
    u.set_state_dict(state)
    start = u.obj.pose.p.clone()
    start_gap = torch.linalg.norm(start - u.agent.tcp.pose.p, dim=-1)
    for _ in range(10):
        obs, r, term, trunc, info = env.step(torch.zeros(64, 6, device=u.device))
    assert torch.isfinite(obs).all()
    # held elements are pulled towards the plate, free ones rest on the staging table. From the rest
    # pose the plate is about 1.8 m away, behind the arm's pedestal: on physx_cpu the pull (3 m/s at
    # most) closes about 0.8-1.0 m of it in 10 steps and the arm then stops the element (the hold keeps
    # collisions), so "onto the plate" is not expected here.
    tcp = u.agent.tcp.pose.p
    held_gap = torch.linalg.norm(u.obj.pose.p[:32] - tcp[:32], dim=-1)
    assert (held_gap < start_gap[:32] - 0.5).all(), (start_gap[:32], held_gap)
    assert torch.allclose(u.obj.pose.p[32:], start[32:], atol=0.01)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_task_steps_1024_envs_with_and_without_the_element_held(bench, env_id):
    env = bench.make_gpu(env_id, 1024)
    u = env.unwrapped
    sps, finite, obs = bench.gpu_steps_per_second(env, 10, seed=0, warmup=2)
    assert obs.shape == (1024, STATE_SIZE) and finite and sps > 0
    env.reset(seed=0)
    start_gap = torch.linalg.norm(u.obj.pose.p - u.agent.tcp.pose.p, dim=-1)
    sps, finite, obs = bench.gpu_steps_per_second(env, 10, seed=0, warmup=2, held=True)
    assert finite and bool(u.held.all())
    # held elements are pulled towards the plate in every env (see the test above for how far)
    gap = torch.linalg.norm(u.obj.pose.p - u.agent.tcp.pose.p, dim=-1)
    assert bool((gap < start_gap - 0.3).all()), (start_gap, gap)
    env.close()


@pytest.mark.parametrize("env_id", ["CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1",
                                    "ConstructionPickPlace-v1"])
def test_cpu_and_gpu_agree_on_a_scripted_grasp_and_carry(bench, env_id):
    rec = bench.parity(env_id, seed=0, num_envs=2, timeout=600)
    assert "error" not in rec, rec
    assert rec["grasp_step_cpu"] is not None and rec["success_step_cpu"] is not None, rec  # the script works
    assert rec["grasp_step_gpu"] is not None and abs(rec["grasp_step_gpu"] - rec["grasp_step_cpu"]) <= PARITY_STEP_TOL, rec
    assert rec["success_step_gpu"] is not None and abs(rec["success_step_gpu"] - rec["success_step_cpu"]) <= PARITY_STEP_TOL, rec
    assert rec["held_mismatch_steps"] <= PARITY_STEP_TOL, rec
    assert rec["pos_diff_max"] < PARITY_POS_TOL_M, rec
    assert rec["angle_diff_max_deg"] < PARITY_ANGLE_TOL_DEG, rec
    # GPU envs given the same state and actions agree with each other
    assert rec["gpu_spread_held_mismatch"] == 0 and rec["gpu_spread_pos_max"] < PARITY_POS_TOL_M, rec


@pytest.mark.parametrize("env_id", [*ENV_IDS, "PickCube-v1"])
def test_rgb_observations_on_gpu_are_not_flat(bench, env_id):
    env = bench.make_gpu(env_id, 16, obs_mode="rgb")
    _, finite, obs = bench.gpu_steps_per_second(env, 3, seed=0, warmup=1)
    stats = bench.image_stats(obs)
    assert stats["rgb_shape"] == [16, 128, 128, 3]
    assert stats["rgb_std_min"] > 10, stats  # a flat (e.g. black) image has 0
    env.close()


def test_record_episode_video_on_gpu_is_not_flat(tmp_path):
    from mani_skill.utils.wrappers import RecordEpisode

    env = gym.make("Flooring-v1", num_envs=4, sim_backend="physx_cuda", obs_mode="state",
                   control_mode="pd_joint_delta_pos", reward_mode="dense", render_mode="rgb_array")
    env = RecordEpisode(env, str(tmp_path), save_trajectory=False, max_steps_per_video=20, video_fps=20)
    env.reset(seed=0)
    for _ in range(10):
        env.step(torch.rand(4, 6, device=env.unwrapped.device) * 2 - 1)
    frames = [np.asarray(f.cpu() if torch.is_tensor(f) else f) for f in env.render_images]
    assert len(frames) >= 10
    stds = [float(f.reshape(-1, f.shape[-1]).std(axis=0).mean()) for f in frames]
    assert min(stds) > 10, stds
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        env.render_images = []  # no ffmpeg here to encode with: frames checked, no file
        env.close()
        return
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 0
