"""Expert demonstrations in the learner's control mode, behaviour cloning, and the PPO pieces of the
recipe (observation normalization, critic warm-up)."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch

from baselines.ppo import bc, checkpoints, networks, ppo
from ms_construction.envs.state_layout import STATE_SIZE
from ms_construction.planning.demos import DEMO_EXPERT_CONFIG, DemoCollector, load_demos, save_demos

from tests.helpers import PLAN_TRIES, SLOW_MACHINE_RRT_TIME

EXPERT = dataclasses.replace(DEMO_EXPERT_CONFIG, rrt_time=SLOW_MACHINE_RRT_TIME)


@pytest.fixture(scope="module")
def flooring_demos():
    collector = DemoCollector("Flooring-v1", config=EXPERT)
    try:
        demos = []
        for seed, noise in ((3, 0.0), (4, 0.1)):
            for _ in range(PLAN_TRIES):  # OMPL seeds itself from the clock: a rare unlucky plan is tried again
                d = collector.collect(seed, noise)
                if d.placed:
                    break
            demos.append(d)
    finally:
        collector.close()
    return demos


def test_demonstrations_place_and_their_clean_actions_replay_to_a_placement(flooring_demos):
    clean, noisy = flooring_demos
    for d in flooring_demos:
        assert d.placed and d.obs.shape == (len(d.actions), STATE_SIZE) and d.actions.shape[1] == 6
        assert np.abs(d.actions).max() <= 1.0 and d.rewards.shape == (len(d.actions),)
        assert d.rewards[-1] == pytest.approx(2.0) and (d.rewards == 1.0).sum() == 1, "Algorithm 1: grasp once, place"
    # without noise the recorded actions are the executed ones: replayed open loop, they place again
    env = gym.make("Flooring-v1", obs_mode="state", control_mode="pd_joint_delta_pos", num_envs=1)
    obs, _ = env.reset(seed=clean.seed)
    np.testing.assert_allclose(obs[0].numpy(), clean.obs[0], atol=1e-6)
    for a in clean.actions:
        obs, _, terminated, truncated, info = env.step(torch.as_tensor(a[None]))
    assert bool(info["success"][0]) and bool(terminated[0])
    env.close()
    # with DART noise the executed actions differ, so the clean labels do not replay the episode
    assert noisy.noise > 0


def test_demos_file_round_trip(tmp_path, flooring_demos):
    dicts = [dict(obs=d.obs, actions=d.actions, rewards=d.rewards, placed=True, task=d.task, seed=d.seed, noise=d.noise)
             for d in flooring_demos]
    save_demos(tmp_path / "d.npz", dicts, tried=5, wall_s=12.5)
    back, tried, wall_s = load_demos(tmp_path / "d.npz")
    assert tried == 5 and wall_s == 12.5 and [b["seed"] for b in back] == [3, 4]
    np.testing.assert_array_equal(back[1]["actions"], flooring_demos[1].actions)


def test_behaviour_cloning_fits_the_demonstrations_and_writes_a_ppo_checkpoint(tmp_path, flooring_demos):
    dicts = [dict(obs=d.obs, actions=d.actions, rewards=d.rewards, placed=True, task=d.task, seed=d.seed, noise=d.noise)
             for d in flooring_demos * 10]
    save_demos(tmp_path / "d.npz", dicts, tried=20)
    out = bc.main(bc.Args(demos=(tmp_path / "d.npz",), out=tmp_path / "bc" / "checkpoint.pt", epochs=30, hidden_size=64,
                          val_fraction=0.1, env_id="Flooring-v1"))
    ckpt = torch.load(out, weights_only=False)
    assert ckpt["bc"]["val_action_mse"] < 0.5 * float(np.var(np.concatenate([d.actions for d in flooring_demos])))
    agent, env_kwargs = checkpoints.load_policy(out, "Flooring-v1")
    assert env_kwargs == {"control_mode": "pd_joint_delta_pos"}
    obs = torch.as_tensor(flooring_demos[0].obs)
    features = agent.features(torch.as_tensor(np.concatenate([d.obs for d in flooring_demos])))
    np.testing.assert_allclose(agent.obs_rms.mean.numpy(), features.mean(0).numpy(), atol=0.2)  # train split only
    with torch.no_grad():
        err = ((agent.get_action(obs, deterministic=True) - torch.as_tensor(flooring_demos[0].actions)) ** 2).mean()
    assert float(err) < 0.05
    assert float(agent.actor_logstd.detach().mean()) == pytest.approx(bc.Args.init_logstd)


class _ReplayThenStop:
    """A stand-in policy: the expert's recorded actions for its first `stop` steps, then still."""

    def __init__(self, actions: np.ndarray, stop: int):
        self.actions, self.stop, self.t = torch.as_tensor(actions), stop, 0

    def get_action(self, obs, deterministic=True):
        a = self.actions[self.t] if self.t < self.stop else torch.zeros(6)
        self.t += 1
        return a[None]


def test_the_expert_takes_over_where_a_policy_stalls_with_the_element_held(flooring_demos):
    clean = flooring_demos[0]
    grasped_at = int(np.flatnonzero(clean.rewards == 1.0)[0])
    # stalled late in the carry, where the element is nearer its goal than anywhere before
    # (closer to the start a floor panel is farther from its recess than on the table)
    stop = grasped_at + 9 * (len(clean.actions) - grasped_at) // 10
    collector = DemoCollector("Flooring-v1", config=EXPERT)
    try:
        takeovers, steps = collector.takeovers(clean.seed, 0.0, _ReplayThenStop(clean.actions, stop))
        assert steps == collector.env.unwrapped.MAX_EPISODE_STEPS, "the stalled policy ran out of time"
        assert takeovers, "the expert placed from none of the stalled policy's states"
        for d in takeovers:
            assert d.placed and d.seed == clean.seed and len(d.actions) < steps
            assert (d.rewards == 1.0).sum() <= 1 and d.rewards[-1] == pytest.approx(2.0)
        # those after the stall start with the element held: no first-grasp reward again
        assert any((d.rewards == 1.0).sum() == 0 for d in takeovers)
        # a policy that places needs no takeover
        placed, steps = collector.takeovers(clean.seed, 0.0, _ReplayThenStop(clean.actions, len(clean.actions)))
        assert placed == [] and steps == len(clean.actions)
    finally:
        collector.close()


def test_behaviour_cloning_repeats_refuses_more_weights_than_files(tmp_path):
    with pytest.raises(SystemExit, match="--repeats"):
        bc.main(bc.Args(demos=(tmp_path / "a.npz",), repeats=(1, 5), out=tmp_path / "x.pt"))


def test_discounted_returns_restart_at_every_demonstration():
    r = np.array([-0.1, 1.0, 2.0, -0.1, 2.0], np.float32)
    ret = bc.discounted_returns(r, np.array([0, 0, 0, 1, 1]), gamma=0.5)
    np.testing.assert_allclose(ret, [-0.1 + 0.5 * (1 + 0.5 * 2), 1 + 0.5 * 2, 2, -0.1 + 0.5 * 2, 2], rtol=1e-6)


def test_running_mean_std_matches_the_data_it_has_seen():
    rms = networks.RunningMeanStd((3,))
    x = torch.randn(1000, 3) * torch.tensor([1.0, 5.0, 0.1]) + torch.tensor([2.0, -1.0, 0.0])
    for chunk in x.split(250):
        rms.update(chunk)
    np.testing.assert_allclose(rms.mean.numpy(), x.mean(0).numpy(), atol=1e-4)
    np.testing.assert_allclose(rms.var.numpy(), x.var(0, unbiased=False).numpy(), rtol=1e-3)
    agent = networks.Agent(3, 2, 16)
    raw = agent.normalize(x[:5])
    assert torch.equal(raw, x[:5]), "an agent that has seen no data passes observations through"
    agent.obs_rms.load_state_dict(rms.state_dict())
    z = agent.normalize(x)
    np.testing.assert_allclose(z.mean(0).numpy(), 0, atol=1e-3)


def test_critic_warmup_moves_the_value_only_and_obs_norm_is_kept_in_the_checkpoint(tmp_path):
    args = ppo.Args.of(num_envs=2, num_eval_envs=1, num_steps=40, num_minibatches=2, update_epochs=2, eval_freq=100,
                    checkpoint_freq=1, env_id="Flooring-v1", sim_backend="physx_cpu", log_dir=str(tmp_path),
                    exp_name="warm", total_timesteps=80, curriculum=("cp4",), curiosity="none",
                    critic_warmup_iterations=1)
    tr = ppo.setup(args)
    before = {k: v.clone() for k, v in tr.agent.state_dict().items()}
    ppo.train(tr)
    after = torch.load(tmp_path / "warm" / "checkpoint.pt", weights_only=False)["agent"]
    assert all(torch.equal(after[k], before[k]) for k in before if k.startswith("actor")), "the policy stays"
    assert not torch.equal(after["critic.0.weight"], before["critic.0.weight"])
    assert float(after["obs_rms.count"]) >= 80 and not torch.equal(after["obs_rms.mean"], before["obs_rms.mean"])


def test_rotation_features_are_the_same_for_q_and_minus_q_and_sit_where_the_state_has_quaternions():
    from ms_construction.envs.state_layout import STATE_QUATERNION_STARTS

    env = gym.make("ConstructionPickPlace-v1", obs_mode="state_dict", num_envs=1)
    obs_dict, _ = env.reset(seed=0)
    flat, _ = gym.make("ConstructionPickPlace-v1", obs_mode="state", num_envs=1).reset(seed=0)
    extra = obs_dict["extra"]
    for start, key in zip(STATE_QUATERNION_STARTS, ("tcp_pose", "goal_pose", "obj_pose")):
        np.testing.assert_allclose(flat[0, start:start + 4].numpy(), extra[key][0, 3:].numpy(), atol=1e-6)
    x = flat.repeat(2, 1)
    for s in STATE_QUATERNION_STARTS:
        x[1, s:s + 4] *= -1
    f = networks.rotation_features(x, STATE_QUATERNION_STARTS)
    assert f.shape == (2, flat.shape[1] + 6) and torch.allclose(f[0], f[1], atol=1e-6)
    assert not torch.allclose(x[0], x[1])
    env.close()


def test_sparse_reward_pays_the_expert_s_placement_more_than_grasping_and_holding_still(flooring_demos):
    """Algorithm 1 along the expert's trajectory: its placed episode returns about 3 - T/250; taking the
    same trajectory up to the grasp and then holding still until the time limit returns about 0."""
    clean = flooring_demos[0]
    expert_return = float(clean.rewards.sum())
    grasp_step = int(np.flatnonzero(clean.rewards == 1.0)[0])
    env = gym.make("Flooring-v1", obs_mode="state", control_mode="pd_joint_delta_pos", reward_mode="sparse", num_envs=1)
    env.reset(seed=clean.seed)
    hold_return, steps = 0.0, 0
    while True:
        a = clean.actions[steps] if steps <= grasp_step else np.zeros(6, np.float32)
        _, r, terminated, truncated, info = env.step(torch.as_tensor(a[None]))
        hold_return, steps = hold_return + float(r[0]), steps + 1
        if bool(terminated[0]) or bool(truncated[0]):
            break
    env.close()
    assert bool(info["is_grasped"][0]) and not bool(info["success"][0]) and steps == 250
    assert hold_return == pytest.approx(1.0 - 249 / 250, abs=1e-3)
    assert expert_return == pytest.approx(3.0 - (len(clean.rewards) - 2) / 250, abs=1e-3)
    assert expert_return > hold_return + 1.5


def test_a_demonstration_worker_drives_the_expert_asked_for(monkeypatch):
    """record_demos(expert=...) reaches the expert of every worker (experiments/general_agent.py
    --branch-preference fixed --demo-pace fast: one way per goal slot, and joints capped at 0.08 rad per step)."""
    from ms_construction.planning import demos

    fast_fixed = dataclasses.replace(demos.demo_expert_config("fixed", "fast"), rrt_time=SLOW_MACHINE_RRT_TIME)
    monkeypatch.setattr(demos, "_collector", None)
    try:
        for _ in range(PLAN_TRIES):
            kept, policy_steps = demos._collect(("WindowInstallation-v1", "cp4", 500_000, 0.0, None, None, fast_fixed, None))
            if kept:
                break
        expert = demos._collector.expert
        assert expert.cfg.branch_preference == "fixed" and expert.cfg.max_joint_step == 0.08
        # the shoulder joints gain speed (0.8 of their limits), the wrist joints are held to the cap
        assert np.all(expert.vel * expert.dt <= 0.08 + 1e-9)
        assert np.all(expert.vel[:3] > demos.DEMO_EXPERT_CONFIG.speed * expert.vmax[:3])
        assert kept and kept[0]["placed"] and policy_steps == 0
    finally:
        demos._collector.close()


def test_an_unknown_demonstration_pace_is_refused():
    from ms_construction.planning import demos

    with pytest.raises(ValueError, match="slow, fast"):
        demos.demo_expert_config("fixed", "quick")
