"""physx_cuda: many envs, mixed task types, the grasp and hold. Skipped where there is no CUDA GPU."""

import gymnasium as gym
import pytest
import torch

import ms_construction  # noqa: F401

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (physx_cuda)")


def test_general_task_on_gpu_mixes_elements_and_holds_them():
    env = gym.make("ConstructionPickPlace-v1", num_envs=64, sim_backend="physx_cuda", obs_mode="state",
                   control_mode="pd_joint_delta_pos", reward_mode="sparse")
    obs, info = env.reset(seed=0)
    assert obs.shape == (64, 43)
    assert set(info["task_id"].tolist()) == {0, 1, 2}
    u = env.unwrapped
    state = u.get_state_dict()
    state["task"]["held"][:32] = True
    u.set_state_dict(state)
    start = u.obj.pose.p.clone()
    for _ in range(10):
        obs, r, term, trunc, info = env.step(torch.zeros(64, 6, device=u.device))
    assert torch.isfinite(obs).all()
    # held elements follow the plate (pulled onto it), free ones rest on the staging table
    tcp = u.agent.tcp.pose.p
    held_gap = torch.linalg.norm(u.obj.pose.p[:32] - tcp[:32], dim=-1)
    assert (held_gap < 0.1).all(), held_gap
    assert torch.allclose(u.obj.pose.p[32:], start[32:], atol=0.01)
    env.close()
