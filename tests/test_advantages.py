"""The advantages and returns the learner trains on (update.signal_advantages, which ppo.py's loop calls once per
iteration), against numbers computed by hand on a tiny rollout: one env, three steps, an episode that ends by
success at step 1 and a new one that runs past the rollout's end.

    step                    0      1 (success: terminated)   2
    extrinsic reward        1      2                          0.5
    curiosity reward        0.1    0.2                        0.3
    V(s_t) extr., curios.   1, .5  2, 1                       .5, .2
    V(final obs of step 1)         10, 2
    V(obs after step 2)                                       4, .4

gamma 0.5 (extrinsic), 0.8 (curiosity), lambda 1 (advantage = discounted return - V), so that every number below
is a short sum.
"""


import pytest
import torch

from baselines.ppo.args import Args
from baselines.ppo.update import signal_advantages


def rollout():
    t = lambda *x: torch.tensor(x, dtype=torch.float32)[:, None]  # noqa: E731  [steps, envs=1]
    return dict(rewards=t(1.0, 2.0, 0.5), intrinsic=t(0.1, 0.2, 0.3),
                values=torch.tensor([[[1.0, 0.5]], [[2.0, 1.0]], [[0.5, 0.2]]]),
                next_value=torch.tensor([[4.0, 0.4]]),
                final_values=torch.tensor([[[0.0, 0.0]], [[10.0, 2.0]], [[0.0, 0.0]]]),
                dones=t(0, 1, 0), terminated=t(0, 1, 0), failed=t(0, 0, 0))


def args(**kw):
    base = dict(curiosity="icm", gamma=0.5, icm_gamma=0.8, gae_lambda=1.0, bootstrap_at_done="truncated", success_value="critic")
    return Args.of(**{**base, **kw})


def test_curiosity_has_its_own_head_discount_and_bootstraps_at_every_episode_end():
    adv, ret = signal_advantages(args(), **rollout())
    # extrinsic head: success is an end with nothing after it (bootstrap_at_done="truncated")
    #   G2 = 0.5 + 0.5 * 4 = 2.5;  G1 = 2 (no bootstrap);  G0 = 1 + 0.5 * G1 = 2
    # curiosity head: every end bootstraps with V(final obs), its own discount 0.8
    #   G2 = 0.3 + 0.8 * 0.4 = 0.62;  G1 = 0.2 + 0.8 * 2 = 1.8;  G0 = 0.1 + 0.8 * 1.8 = 1.54
    assert torch.allclose(ret[:, 0, 0], torch.tensor([2.0, 2.0, 2.5]))
    assert torch.allclose(ret[:, 0, 1], torch.tensor([1.54, 1.8, 0.62]))
    # the advantage is the mean of the heads' (ML-Agents): ((G - V)_extr + (G - V)_curios) / 2
    assert torch.allclose(adv[:, 0], torch.tensor([(1.0 + 1.04) / 2, (0.0 + 0.8) / 2, (2.0 + 0.42) / 2]))


def test_a_bootstrapped_success_adds_its_discounted_final_value():
    _, ret = signal_advantages(args(bootstrap_at_done="always"), **rollout())
    # G1 = 2 + 0.5 * 10 = 7;  G0 = 1 + 0.5 * 7 = 4.5; the curiosity head is unchanged
    assert torch.allclose(ret[:, 0, 0], torch.tensor([4.5, 7.0, 2.5]))
    assert torch.allclose(ret[:, 0, 1], torch.tensor([1.54, 1.8, 0.62]))


def test_lambda_below_one_mixes_the_one_step_estimates():
    adv, _ = signal_advantages(args(curiosity="none", gae_lambda=0.5), **{
        **rollout(), "values": rollout()["values"][..., :1], "next_value": rollout()["next_value"][:, :1],
        "final_values": rollout()["final_values"][..., :1]})
    # deltas: d2 = 0.5 + 0.5 * 4 - 0.5 = 2;  d1 = 2 - 2 = 0 (episode end);  d0 = 1 + 0.5 * 2 - 1 = 1
    # A2 = 2;  A1 = 0;  A0 = d0 + 0.5 * 0.5 * A1 = 1
    assert torch.allclose(adv[:, 0], torch.tensor([1.0, 0.0, 2.0]))


@pytest.mark.parametrize("curiosity", ["none", "icm_normalized"])
def test_one_head_without_ml_agents_curiosity_and_the_normalized_bonus_joins_the_extrinsic_reward(curiosity):
    r = rollout()
    one = {**r, "values": r["values"][..., :1], "next_value": r["next_value"][:, :1],
           "final_values": r["final_values"][..., :1]}
    adv, ret = signal_advantages(args(curiosity=curiosity), **one)
    assert ret.shape == (3, 1, 1)
    bonus = {"none": torch.zeros(3), "icm_normalized": torch.tensor([0.1, 0.2, 0.3])}[curiosity]
    # G2 = (0.5 + b2) + 0.5 * 4;  G1 = 2 + b1;  G0 = (1 + b0) + 0.5 * G1
    g2, g1 = 0.5 + bonus[2] + 2.0, 2.0 + bonus[1]
    expected = torch.stack([1.0 + bonus[0] + 0.5 * g1, g1, g2])
    assert torch.allclose(ret[:, 0, 0], expected)
    assert torch.allclose(adv[:, 0], expected - torch.tensor([1.0, 2.0, 0.5]))


def test_an_absorbing_success_is_worth_its_reward_for_ever_not_the_critic_s_guess():
    _, ret = signal_advantages(args(bootstrap_at_done="always", success_value="absorbing"), **rollout())
    # G1 = 2 + 0.5 * (2 / (1 - 0.5)) = 4, whatever V(final obs) = 10 says;  G0 = 1 + 0.5 * 4 = 3
    assert torch.allclose(ret[:, 0, 0], torch.tensor([3.0, 4.0, 2.5]))
    # without a bootstrap at success (the sparse reward's default) it changes nothing
    _, ret = signal_advantages(args(bootstrap_at_done="truncated", success_value="absorbing"), **rollout())
    assert torch.allclose(ret[:, 0, 0], torch.tensor([2.0, 2.0, 2.5]))


@pytest.mark.parametrize("bootstrap_at_done", ["always", "terminated", "truncated"])
def test_an_episode_that_ended_by_failure_has_nothing_after_it(bootstrap_at_done):
    failed = {**rollout(), "failed": rollout()["terminated"]}  # the end at step 1 was a touch of an obstacle
    _, ret = signal_advantages(args(bootstrap_at_done=bootstrap_at_done, success_value="absorbing"), **failed)
    # G1 = 2, neither 2 / (1 - 0.5) for ever nor V(final obs) = 10;  G0 = 1 + 0.5 * 2 = 2
    assert torch.allclose(ret[:, 0, 0], torch.tensor([2.0, 2.0, 2.5]))
    # curiosity ignores how an episode ended (it bootstraps at every end)
    assert torch.allclose(ret[:, 0, 1], torch.tensor([1.54, 1.8, 0.62]))
