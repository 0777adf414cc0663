"""The construction arm: registered agent, controllers, reach of every goal slot, load holding."""

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from ms_construction.agents.construction_arm import REST_QPOS
from ms_construction.assets import load_manifest
from ms_construction.kinematics import ArmIK, pose_error
from ms_construction.parameters import ELEMENT_KINDS

from tests.helpers import make_env, quat_z

CONTROL_MODES = ("pd_joint_delta_pos", "pd_joint_pos", "pd_ee_delta_pos", "pd_ee_delta_pose")


@pytest.fixture(scope="module")
def empty_env():
    env = gym.make("Empty-v1", robot_uids="construction_arm", control_mode="pd_joint_pos", obs_mode="state")
    env.reset(seed=0)
    yield env
    env.close()


def test_agent_has_controllers_tcp_and_rest_keyframe(empty_env):
    agent = empty_env.unwrapped.agent
    assert set(CONTROL_MODES) <= set(agent.supported_control_modes)
    assert agent.tcp.name.endswith("tcp")
    np.testing.assert_allclose(agent.keyframes["rest"].qpos, REST_QPOS)
    # the tcp sits on the plate's face with its z axis out of the plate
    assert agent.tcp_pose.raw_pose.shape == (1, 7)


@pytest.mark.parametrize("kind", ELEMENT_KINDS)
def test_every_goal_slot_is_reachable_in_its_installation_pose(empty_env, kind):
    """IK finds a configuration within joint limits whose tcp holds the element's grasp face at
    every goal slot, for every rotation of the grasp about the plate axis in quarter turns."""
    m = load_manifest()
    ik = ArmIK(empty_env.unwrapped.agent.robot)
    grasp = sapien.Pose(m["elements"][kind]["grasp_pose"][:3], m["elements"][kind]["grasp_pose"][3:])
    for goal in m["goal_poses"][kind]:
        for psi in (0, 90, 180, 270):
            target = sapien.Pose(goal[:3], goal[3:]) * grasp * sapien.Pose(q=quat_z(psi))
            q = ik.solve(target)
            assert q is not None, f"{kind} slot at {goal[:3]}, grasp turned {psi} deg: unreachable"
            assert np.all(q >= ik.lower) and np.all(q <= ik.upper)
            err_p, err_r = pose_error(ik.fk(q), target)
            assert err_p < 1e-3 and err_r < 0.5
    if kind == "ceiling":
        # the flip: at a ceiling slot the plate faces up
        q = ik.solve(sapien.Pose(m["goal_poses"][kind][0][:3], m["goal_poses"][kind][0][3:]) * grasp)
        z_axis = ik.fk(q).to_transformation_matrix()[:3, 2]
        assert z_axis[2] > 0.99


def test_arm_holds_15kg_at_full_reach(empty_env):
    """Arm stretched out horizontally (the worst case for gravity), plate carrying a 15 kg element
    on its face: the tcp sags by less than 1 cm and stays there."""
    u = empty_env.unwrapped
    robot = u.agent.robot
    plate = u.agent.plate._objs[0]
    thickness = max(load_manifest()["elements"][k]["size"][2] for k in ELEMENT_KINDS)
    plate_mass, plate_com = plate.mass, plate.cmass_local_pose.p[0]
    element_com = 0.03 + thickness / 2  # plate face + half the element
    plate.mass = plate_mass + 15.0
    plate.cmass_local_pose = sapien.Pose([(plate_mass * plate_com + 15.0 * element_com) / (plate_mass + 15.0), 0, 0])
    plate.disable_gravity = False  # ManiSkill compensates the arm's own links; the load is real
    try:
        q = np.array([-np.pi / 2, np.pi / 2, -np.pi / 2, 0.0, 0.0, 0.0])
        robot.set_qpos(torch.tensor(q[None], dtype=torch.float32))
        robot.set_qvel(torch.zeros(1, 6))
        u.agent.controller.reset()
        target = ArmIK(robot).fk(q)
        sags = []
        for _ in range(60):  # 3 s
            empty_env.step(torch.tensor(q[None], dtype=torch.float32))
            sags.append(np.linalg.norm(u.agent.tcp_pose.p[0].numpy() - target.p))
        assert max(sags) < 0.01, f"tcp sagged {max(sags) * 1000:.1f} mm"
        assert abs(sags[-1] - sags[-20]) < 1e-3, "the arm is still drifting"
        assert sags[-1] > 1e-4, "the load had no effect: is gravity acting on it?"
    finally:
        plate.mass, plate.cmass_local_pose, plate.disable_gravity = plate_mass, sapien.Pose([plate_com, 0, 0]), True


def test_offscreen_render_of_the_site_is_not_flat():
    env = make_env("ConstructionPickPlace-v1", obs_mode="rgb", render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    img = env.render()[0].float()
    env.close()
    assert img.shape == (512, 512, 3)
    assert img.std() > 20, "flat image"
    # structure, not noise: neighbouring pixels agree far more than distant ones
    assert (img[1:] - img[:-1]).abs().mean() < 0.5 * (img - img.mean((0, 1))).abs().mean()
    sensor = obs["sensor_data"]["base_camera"]["rgb"][0].float()
    assert sensor.shape == (128, 128, 3) and sensor.std() > 10
