"""The policy network's options that change what it can express: the bounded mean."""

import torch

from baselines.ppo.checkpoints import make_agent
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
