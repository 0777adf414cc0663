"""Curiosity as ML-Agents computes it (baselines/ppo/curiosity.py), on hand-made batches: no env."""

import pytest
import torch

from baselines.ppo.curiosity import ICM, LOSS_SCALE


def batch(n=256, obs_dim=43, act_dim=6, seed=0):
    g = torch.Generator().manual_seed(seed)
    obs, act = torch.randn(n, obs_dim, generator=g), torch.rand(n, act_dim, generator=g) * 2 - 1
    next_obs = obs + 0.1 * torch.cat([act, torch.zeros(n, obs_dim - act_dim)], -1)
    return obs, next_obs, act


def test_reward_is_half_the_summed_squared_forward_error_times_strength_capped_at_one():
    torch.manual_seed(0)
    icm = ICM(43, 6, strength=0.02)
    obs, next_obs, act = batch()
    assert torch.all(icm.intrinsic_reward(obs, next_obs, act) == 0), "no reward before the module's first update"
    icm.updated.fill_(True)
    with torch.no_grad():
        phi, phi_next = icm.encoder(obs), icm.encoder(next_obs)
        err = 0.5 * ((icm.forward_model(torch.cat([phi, act], -1)) - phi_next) ** 2).sum(-1)
    r = icm.intrinsic_reward(obs, next_obs, act)
    assert torch.allclose(r, 0.02 * torch.clamp(err, max=50.0))
    # the cap: an error above 1 / strength gives exactly 1, never more
    with torch.no_grad():
        icm.forward_model[-1].bias.add_(1e3)
    r = icm.intrinsic_reward(obs, next_obs, act)
    assert torch.allclose(r, torch.ones_like(r))


def test_loss_is_ten_times_the_weighted_forward_and_inverse_losses_and_trains_the_encoder():
    torch.manual_seed(0)
    icm = ICM(43, 6, strength=0.02)
    obs, next_obs, act = batch()
    parts = icm.losses(obs, next_obs, act)
    assert torch.allclose(parts["loss"], LOSS_SCALE * (0.2 * parts["forward"] + 0.8 * parts["inverse"]))
    assert torch.allclose(parts["forward"], icm.forward_error(obs, next_obs, act).mean())
    opt = torch.optim.Adam(icm.parameters(), lr=3e-4)
    icm.losses(obs, next_obs, act)["forward"].backward()
    assert icm.encoder[0][0].weight.grad.abs().sum() > 0, "the forward loss reaches the encoder (ML-Agents does not detach it)"
    opt.zero_grad()
    before = icm.encoder[0][0].weight.clone()
    icm.update(opt, obs, next_obs, act)
    assert not torch.equal(before, icm.encoder[0][0].weight) and bool(icm.updated)


def test_reward_fades_as_the_forward_model_learns_a_fixed_batch_and_stays_where_it_has_not_been():
    torch.manual_seed(0)
    icm = ICM(43, 6, strength=0.02)
    opt = torch.optim.Adam(icm.parameters(), lr=3e-4)
    obs, next_obs, act = batch()
    icm.update(opt, obs, next_obs, act)
    first = icm.intrinsic_reward(obs, next_obs, act).mean().item()
    for _ in range(400):
        icm.update(opt, obs, next_obs, act)
    after = icm.intrinsic_reward(obs, next_obs, act).mean().item()
    assert after < 0.2 * first, (first, after)
    unseen = batch(seed=1)
    assert icm.intrinsic_reward(*unseen).mean().item() > 2 * after, "curiosity stays where the model has not been"


def test_normalized_variant_divides_by_the_running_std_and_is_not_capped():
    torch.manual_seed(0)
    icm = ICM(43, 6, strength=0.02, normalize=True)
    obs, next_obs, act = batch()
    err = icm.forward_error(obs, next_obs, act).detach()
    r = icm.intrinsic_reward(obs, next_obs, act)
    assert torch.allclose(r, 0.02 * err / torch.sqrt(icm.error_var + 1e-8), rtol=1e-5)
    assert float(icm.error_count) > 256


def test_a_strength_that_is_not_positive_is_refused():
    with pytest.raises(ValueError, match="strength"):
        ICM(43, 6, strength=0.0)


def test_reward_and_losses_match_numbers_computed_by_hand():
    """An ICM with weights set by hand: the encoder the identity up to its two Swish layers, the forward model
    predicting the constant c, the inverse model the constant action 0.5. With s' = 0, phi(s') = 0, so the
    forward error is 0.5 |c|^2 and the inverse loss the squared distance of the actions from 0.5."""
    icm = ICM(2, 1, strength=0.02, encoding_size=2, hidden=2)
    with torch.no_grad():
        for layer in [m for m in icm.modules() if isinstance(m, torch.nn.Linear)]:
            layer.weight.zero_()
            layer.bias.zero_()
        enc = [m for m in icm.encoder.modules() if isinstance(m, torch.nn.Linear)]
        for layer in enc:
            layer.weight.copy_(torch.eye(2))
        icm.forward_model[-1].bias.copy_(torch.tensor([3.0, 4.0]))
        icm.inverse[-1].bias.fill_(0.5)
    icm.updated.fill_(True)
    obs = torch.tensor([[1.0, -2.0], [0.5, 0.0]])
    next_obs = torch.zeros(2, 2)
    act = torch.tensor([[1.0], [-1.0]])
    # 0.5 * (3^2 + 4^2) = 12.5, times the strength 0.02: 0.25 (below the cap of 1)
    assert torch.allclose(icm.intrinsic_reward(obs, next_obs, act), torch.tensor([0.25, 0.25]))
    parts = icm.losses(obs, next_obs, act)
    assert torch.isclose(parts["forward"], torch.tensor(12.5))
    assert torch.isclose(parts["inverse"], torch.tensor(((1 - 0.5) ** 2 + (-1 - 0.5) ** 2) / 2))  # 1.25
    assert torch.isclose(parts["loss"], torch.tensor(10 * (0.2 * 12.5 + 0.8 * 1.25)))
    # error 0.5 * 10^2 = 50 = 1 / strength: reward exactly 1; beyond it, still 1
    with torch.no_grad():
        icm.forward_model[-1].bias.copy_(torch.tensor([10.0, 0.0]))
    assert torch.allclose(icm.intrinsic_reward(obs, next_obs, act), torch.ones(2))
    with torch.no_grad():
        icm.forward_model[-1].bias.copy_(torch.tensor([20.0, 0.0]))
    assert torch.allclose(icm.intrinsic_reward(obs, next_obs, act), torch.ones(2))
