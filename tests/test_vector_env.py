"""ms_construction.vector_env: physx_cpu envs in worker processes behind ManiSkillVectorEnv's interface."""

import signal

import torch

from ms_construction.vector_env import CPUVectorEnv


def test_an_ended_episode_is_reset_in_the_same_step_and_reported_in_final_info():
    handlers = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]
    envs = CPUVectorEnv("Flooring-v1", 2, dict(obs_mode="state", control_mode="pd_joint_delta_pos",
                                               reward_mode="dense", max_episode_steps=3))
    try:
        # the workers ignore Ctrl-C (their creator stops them); the creating process keeps its handlers
        assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == handlers
        obs, _ = envs.reset(seed=[0, 1])
        assert obs.shape == (2, 44) and obs.dtype == torch.float32
        zeros = torch.zeros(2, *envs.single_action_space.shape)
        for _ in range(2):
            obs, reward, terminated, truncated, info = envs.step(zeros)
            assert info == {} and not (terminated | truncated).any()
            assert reward.shape == (2,) and reward.dtype == torch.float32
        before = obs
        obs, reward, terminated, truncated, info = envs.step(zeros)
        assert truncated.all() and not terminated.any()
        assert info["_final_info"].tolist() == [True, True]
        assert info["final_info"]["episode"]["episode_len"].tolist() == [3, 3]
        assert "success_once" in info["final_info"]["episode"] and "picked" in info["final_info"]
        # the final observation is the ended episode's (it moved on from the step before); the
        # returned one is the next episode's first, in an env already reset
        assert info["final_observation"].shape == (2, 44) and not torch.equal(info["final_observation"], obs)
        assert torch.allclose(info["final_observation"][:, :6], before[:, :6], atol=0.2)
        assert [int(t) for t in envs.call("elapsed_steps")] == [0, 0]
    finally:
        envs.close()


def _rollout(first_env_in_process: bool, steps: int = 12):
    """Observations, rewards and ends of a fixed action sequence over two short episodes per env, and
    the learner's next torch random number."""
    torch.manual_seed(0)
    envs = CPUVectorEnv("Flooring-v1", 2, dict(obs_mode="state", control_mode="pd_joint_delta_pos", reward_mode="dense",
                                               max_episode_steps=5), first_env_in_process=first_env_in_process)
    try:
        actions = torch.rand(steps, 2, *envs.single_action_space.shape, generator=torch.Generator().manual_seed(1)) * 2 - 1
        obs, _ = envs.reset(seed=3)
        record = [obs]
        for a in actions:
            obs, reward, terminated, truncated, info = envs.step(a)
            record += [obs, reward, terminated | truncated]
            if info:
                record.append(info["final_observation"])
        return record, torch.rand(1), envs.call("elapsed_steps")
    finally:
        envs.close()


def test_the_first_env_in_the_learners_process_gives_the_same_samples_and_leaves_its_random_numbers_alone():
    """Env 0 in this process (the default) or in a worker: the same observations, rewards, ends and
    same-step resets (episode starts drawn from each env's own seeded generators), and the caller's
    torch random stream is not moved by the env it hosts."""
    here, rand_here, elapsed_here = _rollout(True)
    apart, rand_apart, elapsed_apart = _rollout(False)
    assert len(here) == len(apart) > 12 * 3 + 2  # the episodes of 5 steps ended twice in 12 steps
    for x, y in zip(here, apart):
        assert torch.equal(x, y)
    assert torch.equal(rand_here, rand_apart) and torch.equal(rand_here, torch.manual_seed(0) and torch.rand(1))
    assert [int(t) for t in elapsed_here] == [int(t) for t in elapsed_apart] == [2, 2]
