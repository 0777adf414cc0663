"""The window site's mirror symmetry in the plane y = 0 (`state_mirror_signs`, JOINT_MIRROR_SIGNS) and the policy that
uses it (`--mirror-twins`: baselines/ppo/networks.py's Mirror)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from baselines.ppo import ppo
from baselines.ppo.checkpoints import make_agent
from mani_skill.utils.structs import Pose
from ms_construction.envs.carry_geometry import JOINT_MIRROR_SIGNS
from ms_construction.envs.state_layout import (
    STATE_GOAL_Y,
    STATE_IS_GRASPED,
    STATE_QUATERNION_STARTS,
    STATE_SIZE,
    STATE_TASK_START,
    state_mirror_signs,
)
from ms_construction.assets import load_manifest
from ms_construction.parameters import ELEMENT_KINDS
from tests.helpers import make_env

GOAL_QUAT = slice(23, 27)
INSTALL_OFFSET = slice(STATE_SIZE, STATE_SIZE + 6)
WITH_INSTALL = STATE_SIZE + 6
WITH_BOTH = STATE_SIZE + 12
"""observation sizes with the install offset, and with the path offset too."""


def test_the_mirror_image_of_a_window_episode_at_y_minus_085_is_one_at_plus_085_step_by_step():
    """A window episode for the opening at y = -0.85 and one for +0.85 whose arm and element start as its mirror image
    (joints by JOINT_MIRROR_SIGNS, the element's pose mirrored), driven by mirrored actions, stay each other's mirror
    image: every number of the observation but the goal's orientation equals `state_mirror_signs` times the other's,
    over grasp-free steps, the joint move to the installation included (until the grasp it is measured for the mirror
    branch, the element turned half a turn: the rule of `carry_geometry` for a slot that mirrors another). The goal's
    orientation is the same in both (a window's head is up at every opening). Other sizes are refused."""
    signs, joint_signs = state_mirror_signs(WITH_INSTALL), torch.tensor(JOINT_MIRROR_SIGNS)
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
    same = torch.ones(WITH_INSTALL, dtype=torch.bool)
    same[GOAL_QUAT] = False
    g = torch.Generator().manual_seed(0)
    for step in range(25):
        assert torch.allclose(obs_r[0, same], (obs_l[0] * signs)[same], atol=2e-3), step
        assert torch.allclose(obs_r[0, GOAL_QUAT], obs_l[0, GOAL_QUAT]), "one orientation for every opening"
        action = torch.rand(1, 6, generator=g) * 0.6 - 0.3
        obs_l, *_ = left.step(action)
        obs_r, *_ = right.step(action * joint_signs)
    assert float(obs_l[0, :6].abs().sum()) > 0.5, "the arm moved"
    for dim in (STATE_SIZE - 1, STATE_SIZE + 8, STATE_SIZE + 10):
        with pytest.raises(ValueError, match="state observation"):
            state_mirror_signs(dim)
    left.close()
    right.close()


def _obs(n: int, obs_dim: int = WITH_BOTH) -> torch.Tensor:
    """Random observations with a task one-hot: windows with the goal at y > 0, at y <= 0, and ceiling panels."""
    x = torch.randn(n, obs_dim, generator=torch.Generator().manual_seed(1))
    x[:, STATE_TASK_START:STATE_TASK_START + 3] = 0
    kinds = torch.tensor([ELEMENT_KINDS.index(k) for k in ("window", "window", "ceiling")]).repeat(n // 3 + 1)[:n]
    x[torch.arange(n), STATE_TASK_START + kinds] = 1
    goals = load_manifest()["goal_poses"]  # the window openings at y = +0.85 and -0.85, a ceiling opening
    at = torch.tensor([goals["window"][2][:3], goals["window"][0][:3], goals["ceiling"][0][:3]])
    x[:, STATE_GOAL_Y - 1:STATE_GOAL_Y + 2] = at.repeat(n // 3 + 1, 1)[:n]
    return x


def test_a_mirrored_policy_acts_on_windows_beyond_y0_as_the_plain_one_on_their_mirror_image():
    """With `mirror_twins`, the policy's mean, its log-probability of an action and its value on a window whose
    goal lies at y > 0 are the plain networks' (same weights) on the mirror image of the state, the mean and the
    action mirrored back; on every other state they are the plain networks'. The mirror needs joint control."""
    args = ppo.Args.of(hidden_size=32, curiosity="none", bounded_mean=True)
    plain = make_agent(args, WITH_BOTH, 6)
    mirrored = make_agent(ppo.Args.of(hidden_size=32, curiosity="none", bounded_mean=True, mirror_twins=True), WITH_BOTH, 6)
    mirrored.load_state_dict(plain.state_dict())
    x = _obs(30)
    mirrored.obs_rms.update(mirrored.features(x))
    plain.obs_rms.load_state_dict(mirrored.obs_rms.state_dict())
    signs, joint_signs = state_mirror_signs(WITH_BOTH), torch.tensor(JOINT_MIRROR_SIGNS)
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
    with pytest.raises(SystemExit, match="mirror-twins"):
        ppo.validate(ppo.Args.of(mirror_twins=True, control_mode="pd_ee_delta_pose"))


def test_the_mirror_branch_keeps_the_installations_whose_mirror_image_differs_from_the_twins_in_joint_6_alone():
    """`mirror_branch_mask`: the window opening at y = +0.85 keeps the installation configurations whose mirror image
    has the -0.85 opening's least folded configuration's joints 1-5, and their joint 6 is half a turn from it (the
    window's head is up at both); the other wrist branch, its joints 4 and 5 far off, is cut; every other slot keeps
    all. The env's installation table repeats a kept configuration in a cut one's place."""
    from ms_construction.goal_configurations import install_configurations, mirror_branch_mask, mirror_twins

    w = ELEMENT_KINDS.index("window")
    twins, keep, install = mirror_twins(), mirror_branch_mask(JOINT_MIRROR_SIGNS), install_configurations()
    assert twins[w].tolist() == [-1, -1, 0] and (twins[[0, 2]] == -1).all()
    assert keep[w, 2].any() and not keep[w, 2].all() and keep[w, :2].all() and keep[[0, 2]].all()
    mirrored = install[w, 2] * np.asarray(JOINT_MIRROR_SIGNS, dtype=np.float32)
    twin = install[w, 0, 0]
    assert np.abs(mirrored[keep[w, 2], :5] - twin[:5]).max() < 1e-3
    roll = np.remainder(mirrored[keep[w, 2], 5] - twin[5], 2 * np.pi)
    assert np.allclose(roll, np.pi, atol=1e-3), "half a turn of joint 6"
    assert (np.abs(mirrored[~keep[w, 2], 3:5] - twin[3:5]).sum(-1) > 2).all(), "the other wrist branch is cut"


def _twin_envs(**kwargs):
    """A window env for the opening at y = -0.85 and one for +0.85 posed as its mirror image."""
    left = make_env("WindowInstallation-v1", goal_slot_weights={"window": (1.0, 0.0, 0.0)}, **kwargs)
    right = make_env("WindowInstallation-v1", goal_slot_weights={"window": (0.0, 0.0, 1.0)}, **kwargs)
    left.reset(seed=5)
    right.reset(seed=6)
    lu, ru = left.unwrapped, right.unwrapped
    ru.agent.robot.set_qpos(lu.agent.robot.get_qpos() * torch.tensor(JOINT_MIRROR_SIGNS))
    pose = lu.obj.pose.raw_pose * torch.tensor([1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
    ru.obj.set_pose(Pose.create_from_pq(pose[:, :3], pose[:, 3:]))
    return left, right


def test_with_the_mirror_branch_the_joint_moves_are_the_twins_mirror_image_until_the_grasp_and_half_a_turn_after():
    """A window episode for +0.85 (the mirror branch its installation is cut to, by the rule) posed as the mirror image of one for -0.85 observes
    the mirror image of the other's every number but the goal's orientation before the grasp, both joint moves (to the
    installation and along the start path) included, over random mirrored steps; once the element is held (the
    nominal hold in both), the joint moves to the installation differ in joint 6 alone, by half a turn: the turn the
    carry has to add."""
    signs, joint_signs = state_mirror_signs(WITH_BOTH), torch.tensor(JOINT_MIRROR_SIGNS)
    left, right = _twin_envs(control_mode="pd_joint_delta_pos", obs_install_offset=True, obs_path_offset=True)
    lu, ru = left.unwrapped, right.unwrapped
    same = torch.ones(WITH_BOTH, dtype=torch.bool)
    same[GOAL_QUAT] = False
    g = torch.Generator().manual_seed(0)
    for step in range(15):
        obs_l, obs_r = lu.get_obs(), ru.get_obs()
        assert not bool(lu.picked[0]) and not bool(ru.picked[0])
        assert torch.allclose(obs_r[0, same], (obs_l[0] * signs)[same], atol=2e-3), step
        action = torch.rand(1, 6, generator=g) * 0.6 - 0.3
        left.step(action)
        right.step(action * joint_signs)
    lu.picked[:] = True
    ru.picked[:] = True
    move_l, move_r = lu.get_obs()[0, INSTALL_OFFSET] * signs[INSTALL_OFFSET], ru.get_obs()[0, INSTALL_OFFSET]
    assert torch.allclose(move_r[:5], move_l[:5], atol=2e-3)
    assert float(torch.remainder(move_r[5] - move_l[5], 2 * np.pi)) == pytest.approx(np.pi, abs=2e-3)
    left.close()
    right.close()


def test_the_canonical_reach_shows_a_mirrored_window_its_goal_orientation_as_it_is_until_the_grasp():
    """With `mirror_canonical_reach`, the mirrored networks see a window at y > 0 before the grasp as the mirror image
    with the goal's orientation as it is (what the twin opening shows), after the grasp as the plain mirror image;
    other states as they are. It needs the mirror."""
    args = ppo.Args.of(hidden_size=32, curiosity="none", bounded_mean=True, mirror_twins=True)
    honest = make_agent(args, WITH_BOTH, 6)
    canonical = make_agent(args.replace(mirror_canonical_reach=True), WITH_BOTH, 6)
    x = _obs(30)
    x[:, STATE_IS_GRASPED] = torch.tensor([0.0, 1.0]).repeat(15)
    signs = state_mirror_signs(WITH_BOTH)
    beyond = torch.tensor([True, False, False]).repeat(10)
    before = beyond & (x[:, STATE_IS_GRASPED] < 0.5)
    expected = torch.where(beyond[:, None], x * signs, x)
    expected[before, 23:27] = x[before, 23:27]
    assert before.any() and (beyond & ~before).any()
    assert torch.equal(canonical.mirror.observation(x), expected)
    assert torch.equal(honest.mirror.observation(x)[~before], expected[~before])
    assert not torch.equal(honest.mirror.observation(x)[before], expected[before])
    with pytest.raises(SystemExit, match="mirror-twins"):
        ppo.validate(ppo.Args.of(mirror_canonical_reach=True))


def test_held_the_half_turn_view_of_a_window_installed_at_plus_085_is_a_window_installed_at_minus_085(monkeypatch):
    """With `mirror_held_half_turn`, a window held at its installation at y = +0.85 (a near-goal start at radius 0, no
    turn on the plate) is seen as one installed at -0.85 in the installation configuration that is the mirror image of
    its own but for joint 6: the same joints, plate, goal and window orientation (a window is a box, so turning it
    half a turn about the plate's axis is a state of that opening), and joint moves of 0; before the grasp the view is
    the canonical reach's. It needs the canonical reach."""
    from ms_construction.envs import construction_env, start_states
    from ms_construction.goal_configurations import install_configurations

    monkeypatch.setattr(construction_env, "START_YAW_NOISE_DEG", 0.0)
    monkeypatch.setattr(start_states, "START_YAW_NOISE_DEG", 0.0)
    kwargs = dict(control_mode="pd_joint_delta_pos", obs_install_offset=True, obs_path_offset=True)
    right = make_env("WindowInstallation-v1", goal_slot_weights={"window": (0.0, 0.0, 1.0)}, **kwargs)
    left = make_env("WindowInstallation-v1", goal_slot_weights={"window": (1.0, 0.0, 0.0)}, **kwargs)
    for env in (left, right):
        env.unwrapped.set_near_goal_starts(1.0, 0.0)
    obs_r, _ = right.reset(seed=1)
    obs_l, _ = left.reset(seed=1)
    args = ppo.Args.of(hidden_size=32, curiosity="none", mirror_twins=True, mirror_canonical_reach=True)
    view = make_agent(args.replace(mirror_held_half_turn=True), WITH_BOTH, 6).mirror
    seen = view.observation(obs_r)[0]
    w = ELEMENT_KINDS.index("window")
    assert float(obs_r[0, STATE_IS_GRASPED]) == 1.0
    assert torch.allclose(seen[:6], torch.tensor(install_configurations()[w, 0, 0]), atol=1e-3)
    for quat in (slice(s, s + 4) for s in STATE_QUATERNION_STARTS):  # the plate, the goal, the window: the same rotations
        assert float((seen[quat] * obs_l[0, quat]).sum().abs()) == pytest.approx(1.0, abs=1e-3)
    assert torch.allclose(seen[STATE_SIZE:], torch.zeros(12), atol=1e-3)
    before = _obs(3)
    before[:, STATE_IS_GRASPED] = 0
    canonical_reach = make_agent(args, WITH_BOTH, 6).mirror
    assert torch.equal(view.observation(before), canonical_reach.observation(before))
    with pytest.raises(SystemExit, match="mirror-canonical-reach"):
        ppo.validate(ppo.Args.of(mirror_twins=True, mirror_held_half_turn=True))
    left.close()
    right.close()
