"""The window site's mirror symmetry in the plane y = 0 (`state_mirror_signs`, JOINT_MIRROR_SIGNS) and the policy that
uses it (`--mirror-windows`: baselines/ppo/networks.py's Mirror)."""

from __future__ import annotations

import pytest
import torch

from baselines.ppo import ppo
from baselines.ppo.checkpoints import make_agent
from mani_skill.utils.structs import Pose
from ms_construction.envs.construction_env import JOINT_MIRROR_SIGNS, STATE_GOAL_Y, STATE_TASK_START, state_mirror_signs
from ms_construction.parameters import ELEMENT_KINDS
from tests.helpers import make_env

GOAL_QUAT = slice(23, 27)
INSTALL_OFFSET = slice(43, 49)


def test_the_mirror_image_of_a_window_episode_at_y_minus_085_is_one_at_plus_085_step_by_step():
    """A window episode for the opening at y = -0.85 and one for +0.85 whose arm and element start as its mirror image
    (joints by JOINT_MIRROR_SIGNS, the element's pose mirrored), driven by mirrored actions, stay each other's mirror
    image: every number of the observation but the goal's orientation and the joint move to the installation equals
    `state_mirror_signs` times the other's, before and after the grasp-free steps. The goal's orientation is the same
    in both (a window's head is up at every opening, so the mirror image is not its installation), and so the joint
    moves to the installation differ: what a mirrored policy has to learn of its own. Other sizes are refused."""
    signs, joint_signs = state_mirror_signs(49), torch.tensor(JOINT_MIRROR_SIGNS)
    kwargs = dict(control_mode="pd_joint_delta_pos", obs_install_offset=True)
    left = make_env("WindowInstallation-v1", goal_slot_weights={"window": (1.0, 0.0, 0.0)}, **kwargs)
    right = make_env("WindowInstallation-v1", goal_slot_weights={"window": (0.0, 0.0, 1.0)}, **kwargs)
    lu, ru = left.unwrapped, right.unwrapped
    obs_l, _ = left.reset(seed=5)
    right.reset(seed=6)
    assert float(lu._goal_table[1, 0, 1]) == pytest.approx(-0.85) and float(ru._goal_table[1, 2, 1]) == pytest.approx(0.85)
    ru.agent.robot.set_qpos(lu.agent.robot.get_qpos() * joint_signs)
    pose = lu.obj.pose.raw_pose * torch.tensor([1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
    ru.obj.set_pose(Pose.create_from_pq(pose[:, :3], pose[:, 3:]))
    obs_r = ru.get_obs()
    same = torch.ones(49, dtype=torch.bool)
    same[GOAL_QUAT] = same[INSTALL_OFFSET] = False
    g = torch.Generator().manual_seed(0)
    for step in range(25):
        assert torch.allclose(obs_r[0, same], (obs_l[0] * signs)[same], atol=2e-3), step
        assert torch.allclose(obs_r[0, GOAL_QUAT], obs_l[0, GOAL_QUAT]), "one orientation for every opening"
        action = torch.rand(1, 6, generator=g) * 0.6 - 0.3
        obs_l, *_ = left.step(action)
        obs_r, *_ = right.step(action * joint_signs)
    assert float(obs_l[0, :6].abs().sum()) > 0.5, "the arm moved"
    assert not torch.allclose(obs_r[0, INSTALL_OFFSET], (obs_l[0] * signs)[INSTALL_OFFSET], atol=0.1)
    for dim in (42, 51, 53):
        with pytest.raises(ValueError, match="state observation"):
            state_mirror_signs(dim)
    left.close()
    right.close()


def _obs(n: int, obs_dim: int = 55) -> torch.Tensor:
    """Random observations with a task one-hot: windows with the goal at y > 0, at y <= 0, and ceiling panels."""
    x = torch.randn(n, obs_dim, generator=torch.Generator().manual_seed(1))
    x[:, STATE_TASK_START:STATE_TASK_START + 3] = 0
    kinds = torch.tensor([ELEMENT_KINDS.index(k) for k in ("window", "window", "ceiling")]).repeat(n // 3 + 1)[:n]
    x[torch.arange(n), STATE_TASK_START + kinds] = 1
    x[:, STATE_GOAL_Y] = torch.tensor([0.85, -0.85, 0.5]).repeat(n // 3 + 1)[:n]
    return x


def test_a_mirrored_policy_acts_on_windows_beyond_y0_as_the_plain_one_on_their_mirror_image():
    """With `mirror_windows`, the policy's mean, its log-probability of an action and its value on a window whose
    goal lies at y > 0 are the plain networks' (same weights) on the mirror image of the state, the mean and the
    action mirrored back; on every other state they are the plain networks'. The mirror needs joint control."""
    args = ppo.Args.of(hidden_size=32, curiosity="none", bounded_mean=True)
    plain = make_agent(args, 55, 6)
    mirrored = make_agent(ppo.Args.of(hidden_size=32, curiosity="none", bounded_mean=True, mirror_windows=True), 55, 6)
    mirrored.load_state_dict(plain.state_dict())
    x = _obs(30)
    mirrored.obs_rms.update(mirrored.features(x))
    plain.obs_rms.load_state_dict(mirrored.obs_rms.state_dict())
    signs, joint_signs = state_mirror_signs(55), torch.tensor(JOINT_MIRROR_SIGNS)
    beyond = torch.tensor([True, False, False]).repeat(10)
    actions = torch.rand(30, 6, generator=torch.Generator().manual_seed(2)) * 2 - 1
    with torch.no_grad():
        mean = mirrored.get_action(x, deterministic=True)
        _, logp, ent, value = mirrored.get_action_and_value(x, actions)
        x_m = torch.where(beyond[:, None], x * signs, x)
        a_m = torch.where(beyond[:, None], actions * joint_signs, actions)
        mean_p = plain.get_action(x_m, deterministic=True)
        _, logp_p, ent_p, value_p = plain.get_action_and_value(x_m, a_m)
    assert torch.allclose(mean, torch.where(beyond[:, None], mean_p * joint_signs, mean_p), atol=1e-6)
    assert torch.allclose(logp, logp_p, atol=1e-5) and torch.allclose(ent, ent_p) and torch.allclose(value, value_p)
    assert not torch.allclose(mean[beyond], plain.get_action(x, deterministic=True)[beyond].detach(), atol=1e-4), \
        "the mirror changes what the policy does there"
    with pytest.raises(SystemExit, match="mirror-windows"):
        ppo.validate(ppo.Args.of(mirror_windows=True, control_mode="pd_ee_delta_pose"))
