"""The policy network's options that change what it can express: the bounded mean, and the inputs a policy gains
when a run adds the path offset to its observation."""

import pytest
import torch

from baselines.ppo.checkpoints import make_agent, with_obstacle_inputs, with_path_offset_inputs
from baselines.ppo.networks import Agent


def test_a_bounded_mean_stays_within_the_action_bounds_with_the_same_weights():
    plain, bounded = Agent(43, 6, 32), Agent(43, 6, 32, bounded_mean=True)
    assert plain.state_dict().keys() == bounded.state_dict().keys(), "the same checkpoint layout either way"
    with torch.no_grad():  # an output layer that drives the unbounded mean far past the bounds
        plain.actor_mean[-1].weight.mul_(300.0)
    bounded.load_state_dict(plain.state_dict())
    x = torch.randn(256, 43)
    raw, squashed = plain.get_action(x, deterministic=True), bounded.get_action(x, deterministic=True)
    assert raw.abs().max() > 2 and squashed.abs().max() <= 1
    assert torch.allclose(squashed, torch.tanh(raw), atol=1e-6)
    # the mean the update's log-probabilities use is the same bounded one
    _, logprob, _, _ = bounded.get_action_and_value(x, squashed)
    _, logprob_raw, _, _ = plain.get_action_and_value(x, squashed)
    assert not torch.allclose(logprob, logprob_raw)


def test_the_bounded_mean_comes_back_from_a_checkpoint_s_args():
    args = dict(hidden_size=32, curiosity="none", rotation_features=True, num_layers=2)
    assert not isinstance(make_agent(args, 43, 6).actor_mean[-1], torch.nn.Tanh)
    assert isinstance(make_agent({**args, "bounded_mean": True}, 43, 6).actor_mean[-1], torch.nn.Tanh)


@pytest.mark.parametrize("rotation_features,elapsed", [(True, False), (False, True)])
def test_a_policy_gains_the_path_offset_inputs_and_acts_as_before(rotation_features, elapsed):
    """The path offset lands after the install offset and before the elapsed time; the widened policy and value give the
    checkpoint's outputs whatever the new inputs say, and its observation statistics are the checkpoint's for the rest."""
    args = dict(hidden_size=32, curiosity="none", rotation_features=rotation_features, num_layers=2, bounded_mean=True,
                obs_elapsed_time=elapsed, obs_install_offset=True)
    old = make_agent(args, 49, 6)
    with torch.no_grad():  # statistics that are not the defaults, as a trained policy's
        old.obs_rms.mean.uniform_(-1, 1)
        old.obs_rms.var.uniform_(0.5, 2)
        old.obs_rms.count.fill_(1e6)
    ckpt = dict(args=args, agent=old.state_dict(), obs_dim=49, act_dim=6, icm=None)
    wide = with_path_offset_inputs(ckpt, "test.pt")
    assert wide["obs_dim"] == 55 and wide["args"]["obs_path_offset"] and not ckpt["args"].get("obs_path_offset")
    new = make_agent(wide["args"], 55, 6)
    new.load_state_dict(wide["agent"])
    x = torch.randn(64, 49)
    at = 49 - int(elapsed)
    widened = torch.cat([x[:, :at], 3 * torch.randn(64, 6), x[:, at:]], 1)
    with torch.no_grad():
        assert torch.allclose(new.get_action(widened, True), old.get_action(x, True), atol=1e-6)
        assert torch.allclose(new.get_value(widened), old.get_value(x), atol=1e-6)
    with pytest.raises(SystemExit, match="without curiosity"):
        with_path_offset_inputs({**ckpt, "icm": {"w": torch.zeros(1)}}, "test.pt")


@pytest.mark.parametrize("elapsed", [False, True])
def test_a_policy_gains_the_obstacle_inputs_at_the_end_and_acts_as_before(elapsed):
    """The obstacles' entry ends the observation (after the elapsed time too): the widened policy and value give the
    checkpoint's outputs whatever the obstacles are, and it says it reads them (its args name a scene)."""
    from ms_construction.envs.obstacles import OBSTACLE_OBS_SIZE

    args = dict(hidden_size=32, curiosity="none", rotation_features=True, num_layers=2, bounded_mean=True,
                obs_elapsed_time=elapsed, obs_install_offset=True, obs_path_offset=True)
    old = make_agent(args, 55, 6)
    with torch.no_grad():
        old.obs_rms.mean.uniform_(-1, 1)
        old.obs_rms.var.uniform_(0.5, 2)
    ckpt = dict(args=args, agent=old.state_dict(), obs_dim=55, act_dim=6, icm=None)
    wide = with_obstacle_inputs(ckpt, "test.pt")
    assert wide["obs_dim"] == 55 + OBSTACLE_OBS_SIZE and wide["args"]["obstacles"] and "obstacles" not in ckpt["args"]
    new = make_agent(wide["args"], wide["obs_dim"], 6)
    new.load_state_dict(wide["agent"])
    x = torch.randn(64, 55)
    widened = torch.cat([x, 3 * torch.randn(64, OBSTACLE_OBS_SIZE)], 1)
    with torch.no_grad():
        assert torch.allclose(new.get_action(widened, True), old.get_action(x, True), atol=1e-6)
        assert torch.allclose(new.get_value(widened), old.get_value(x), atol=1e-6)
