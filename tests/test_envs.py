"""The four construction tasks: API, determinism, grasp, rewards, placement, collisions, state."""

import itertools
import math
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from mani_skill.utils.wrappers import CPUGymWrapper, RecordEpisode

from ms_construction.curriculum import STAGES
from ms_construction.envs import ENV_IDS, TASK_ENV_IDS
from ms_construction.envs.state_layout import STATE_SIZE
from ms_construction.parameters import ELEMENT_KINDS

from tests.helpers import PLAN_TRIES, TEST_EXPERT_CONFIG, JointMover, StepLog, make_env, quat_z, to_sapien

ROOT = Path(__file__).resolve().parents[1]

STATE_OBS_MODES = ("state", "state_dict", "none")
VISUAL_OBS_MODES = ("rgb", "depth", "rgbd", "pointcloud")
"""rendered through the same cameras whatever the task: checked on the general task, which loads every element."""
REWARD_MODES = ("sparse", "dense", "normalized_dense", "none")
CONTROL_MODES = ("pd_joint_delta_pos", "pd_joint_pos", "pd_ee_delta_pos", "pd_ee_delta_pose")
PENALTY = float(np.float32(-1.0 / 250))  # rewards are float32 tensors


@pytest.mark.parametrize("env_id, obs_mode", [(e, m) for e in ENV_IDS for m in STATE_OBS_MODES]
                         + [("ConstructionPickPlace-v1", m) for m in VISUAL_OBS_MODES])
def test_every_obs_reward_and_control_mode_steps(env_id, obs_mode):
    """For each env and obs mode: a step in every control mode, with every reward mode's reward."""
    env = gym.make(env_id, obs_mode=obs_mode, reward_mode="dense",
                   render_mode="rgb_array" if obs_mode in VISUAL_OBS_MODES else None)
    env.reset(seed=0)
    u = env.unwrapped
    for control_mode in CONTROL_MODES:
        u.agent.set_control_mode(control_mode)
        u.agent.controller.reset()
        action = torch.as_tensor(u.agent.controller.single_action_space.sample() * 0.5)[None]
        obs, reward, term, trunc, info = env.step({"control_mode": control_mode, "action": action})
        for reward_mode in REWARD_MODES:
            u._reward_mode = reward_mode
            r = u.get_reward(obs=obs, action=action, info=info)
            assert r.shape == (1,) and torch.isfinite(r).all(), (control_mode, reward_mode)
            if reward_mode == "normalized_dense":
                assert 0 <= float(r) <= 1
        u._reward_mode = "dense"
        if obs_mode == "state":
            assert obs.shape == (1, STATE_SIZE) and torch.isfinite(obs).all()
        for key in ("is_grasped", "picked", "success", "place_dist", "place_angle_deg", "task_id"):
            assert info[key].shape == (1,)
    env.close()


def test_gym_make_with_module_prefix_registers_without_import():
    code = "import gymnasium as gym; e = gym.make('ms_construction:Flooring-v1'); e.reset(seed=0); print(e.unwrapped.task_id.item())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "2"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_seeded_reset_reproduces_and_seeds_differ(env_id):
    env = make_env(env_id)
    a, _ = env.reset(seed=3)
    goal_a = env.unwrapped.goal_pose.raw_pose.clone()
    b, _ = env.reset(seed=3)
    goal_b = env.unwrapped.goal_pose.raw_pose.clone()
    c, _ = env.reset(seed=4)
    env.close()
    assert torch.equal(a, b) and torch.equal(goal_a, goal_b)
    assert not torch.equal(a, c)


@pytest.mark.parametrize("kind", ELEMENT_KINDS)
def test_an_element_at_the_edge_of_its_start_range_lies_still_on_the_staging_table(kind):
    """At every corner of the start range (position +- its noise, yaw +- START_YAW_NOISE_DEG) the element rests on the
    table, clear of its rim: three control steps later it has moved less than 2 mm and 1 degree. (A wall panel lying
    across the table reached the rim at some starts, and the solver threw it off the table or pinned it.)"""
    from ms_construction.parameters import START_YAW_DEG, START_YAW_NOISE_DEG

    env = make_env(TASK_ENV_IDS[kind])
    env.reset(seed=0)
    u = env.unwrapped
    noise = u._start_xy_noise[ELEMENT_KINDS.index(kind)].numpy()
    centre = u._staging_xyz.numpy() + [0, 0, float(u._el_size[ELEMENT_KINDS.index(kind), 2]) / 2 + 1e-3]
    still = u.agent.robot.get_qpos()
    for sx, sy, turn in itertools.product((-1, 1), (-1, 1), (-1, 1)):
        yaw = np.deg2rad(START_YAW_DEG[kind] + turn * START_YAW_NOISE_DEG)
        start = sapien.Pose(centre + [sx * noise[0], sy * noise[1], 0], [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])
        u.obj.set_pose(start)
        u.obj.set_linear_velocity(torch.zeros(1, 3))
        u.obj.set_angular_velocity(torch.zeros(1, 3))
        for _ in range(3):
            env.step(still)
        now = to_sapien(u.obj.pose.raw_pose)
        turned = np.rad2deg(2 * np.arccos(min(1.0, abs(float(np.dot(now.q, start.q))))))
        assert np.linalg.norm(now.p - start.p) < 2e-3 and turned < 1.0, (kind, sx, sy, turn, now)
    env.close()


def test_nan_action_raises_value_error():
    env = make_env("Flooring-v1", control_mode="pd_joint_delta_pos")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(torch.full((1, 6), float("nan")))
    env.close()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(curriculum_stage="cp9"), "cp9"),
        (dict(tolerances=dict(place=-0.1)), "place"),
        (dict(tolerances=dict(angle_deg=float("nan"))), "angle_deg"),
        (dict(tolerances=dict(reach=0.1)), "reach"),
        (dict(tolerances=dict(angle_deg=270)), "angle_deg"),
    ],
)
def test_invalid_tolerances_raise_value_error_naming_the_value(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_env("Flooring-v1", **kwargs)


def test_tasks_kwarg_is_validated_and_restricts_the_general_task():
    with pytest.raises(ValueError, match="bricks"):
        make_env("ConstructionPickPlace-v1", tasks=("ceiling", "bricks"))
    with pytest.raises(ValueError, match="general task only"):
        make_env("Flooring-v1", tasks=("flooring",))
    env = make_env("ConstructionPickPlace-v1", tasks=("window",))
    seen = {int(env.reset(seed=s)[1]["task_id"][0]) for s in range(6)}
    env.close()
    assert seen == {1}


def test_task_weights_kwarg_is_validated_and_weighs_the_general_task_s_choice():
    with pytest.raises(ValueError, match="bricks"):
        make_env("ConstructionPickPlace-v1", task_weights={"bricks": 1.0})
    with pytest.raises(ValueError, match="not all 0"):
        make_env("ConstructionPickPlace-v1", task_weights={"ceiling": 0, "window": 0, "flooring": 0})
    with pytest.raises(ValueError, match="general task only"):
        make_env("Flooring-v1", task_weights={"flooring": 1.0})
    # unnamed types weigh 1; a weight of 0 leaves a type out
    env = make_env("ConstructionPickPlace-v1", task_weights={"ceiling": 0, "window": 3})
    seen = [int(env.reset(seed=s)[1]["task_id"][0]) for s in range(40)]
    again = [int(env.reset(seed=s)[1]["task_id"][0]) for s in range(40)]
    # a trainer moves them between resets (failure-weighted sampling), validated alike; None is uniform again
    env.unwrapped.set_task_weights({"ceiling": 0, "window": 0})
    only_floors = {int(env.reset(seed=s)[1]["task_id"][0]) for s in range(10)}
    with pytest.raises(ValueError, match="not all 0"):
        env.unwrapped.set_task_weights({"ceiling": 0, "window": 0, "flooring": 0})
    env.unwrapped.set_task_weights(None)
    uniform = {int(env.reset(seed=s)[1]["task_id"][0]) for s in range(40)}
    env.close()
    assert seen == again  # a seed still fixes the episode
    assert 0 not in seen and 20 < seen.count(1) < 40 and seen.count(2) > 0
    assert only_floors == {2} and uniform == {0, 1, 2}


def test_obs_elapsed_time_appends_the_step_fraction_last_and_changes_nothing_else():
    plain, timed = make_env("WindowInstallation-v1"), make_env("WindowInstallation-v1", obs_elapsed_time=True)
    obs, obs_t = plain.reset(seed=5)[0], timed.reset(seed=5)[0]
    assert obs_t.shape[-1] == obs.shape[-1] + 1 and float(obs_t[0, -1]) == 0.0
    assert torch.equal(obs_t[..., :-1], obs)
    action = torch.zeros(plain.action_space.shape)
    for step in (1, 2, 3):
        obs, obs_t = plain.step(action)[0], timed.step(action)[0]
        assert torch.equal(obs_t[..., :-1], obs) and float(obs_t[0, -1]) == pytest.approx(step / 250)
    assert float(timed.reset(seed=6)[0][0, -1]) == 0.0, "a reset starts the clock again"
    plain.close()
    timed.close()


def test_general_task_yields_all_three_task_types():
    env = make_env("ConstructionPickPlace-v1")
    seen = set()
    for seed in range(40):
        _, info = env.reset(seed=seed)
        tid = int(info["task_id"][0])
        seen.add(tid)
        # the episode's element is on the staging table; the handles point at it
        assert env.unwrapped.obj._objs[0].name.endswith(f"{ELEMENT_KINDS[tid]}_element")
        assert float(env.unwrapped.obj.pose.p[0, 2]) > 0.4
        if len(seen) == 3:
            break
    assert seen == {0, 1, 2}
    # a state of another task type: the handles follow its task_id
    u = env.unwrapped
    env.reset(seed=0)
    other = u.get_state_dict()
    for seed in range(1, 40):
        env.reset(seed=seed)
        if int(u.task_id[0]) != int(other["task"]["task_id"][0, 0]):
            break
    u.set_state_dict(other)
    tid = int(u.task_id[0])
    assert u.obj._objs[0].name.endswith(f"{ELEMENT_KINDS[tid]}_element") and float(u.obj.pose.p[0, 2]) > 0.4
    env.close()


TABLE_I = {  # the paper's Table I, typed from the paper: tau_pick (m), tau_place (m), tau_angle (deg)
    "cp1": (0.40, 0.50, 80.0),
    "cp2": (0.30, 0.25, 60.0),
    "cp3": (0.30, 0.13, 40.0),
    "cp4": (0.30, 0.10, 20.0),
}


def test_curriculum_stages_are_the_papers_table_one():
    assert {s: (t["pick"], t["place"], t["angle_deg"]) for s, t in STAGES.items()} == TABLE_I


def test_curriculum_stage_sets_table_one_and_changes_nothing_else():
    env = make_env("ConstructionPickPlace-v1", curriculum_stage="cp1")
    u = env.unwrapped
    env.reset(seed=0)
    for stage, tol in STAGES.items():
        before = u.get_state_dict()
        u.set_curriculum_stage(stage)
        after = u.get_state_dict()
        np.testing.assert_allclose(u.tolerances[0].numpy(), [tol["pick"], tol["place"], tol["angle_deg"]], rtol=1e-6)
        for key in after["actors"]:
            assert torch.equal(before["actors"][key], after["actors"][key])
        assert torch.equal(before["articulations"]["construction_arm"], after["articulations"]["construction_arm"])
    u.set_tolerances(place=0.2)
    assert math.isclose(float(u.tau_place[0]), 0.2, rel_tol=1e-6) and math.isclose(float(u.tau_angle_deg[0]), 20.0)
    with pytest.raises(ValueError, match="cp0"):
        u.set_curriculum_stage("cp0")
    with pytest.raises(ValueError, match="pick"):
        u.set_tolerances(pick=-1)
    env.close()


@pytest.mark.parametrize("stage", ["cp1", "cp4"])
def test_grasp_triggers_just_inside_tau_pick_and_not_just_outside(stage):
    tau = STAGES[stage]["pick"]
    for distance, expect in ((tau - 0.015, True), (tau + 0.015, False)):
        env = make_env("Flooring-v1", curriculum_stage=stage)
        env.reset(seed=0)
        m = JointMover(env)
        q = m.solve(m.grasp_pose_above(distance))
        m.u.agent.robot.set_qpos(torch.tensor(q[None], dtype=torch.float32))
        m.u.agent.controller.reset()
        m.q = q
        assert not bool(m.u.held[0])
        m.move_to(q, 1)  # the grasp test runs after the step; a pull would start only then
        dist = float(m.u.grasp_ray()[0][0])
        assert abs(dist - distance) < 0.005, "the arm did not hold the test pose"
        assert bool(m.u.held[0]) is expect, f"{stage}: plate {dist:.3f} m from the face, tau_pick {tau}"
        env.close()


def test_sparse_reward_is_algorithm_one_step_by_step():
    from ms_construction.planning import MotionPlanningExpert

    env = StepLog(make_env("Flooring-v1", reward_mode="sparse"))
    expert = MotionPlanningExpert(env, TEST_EXPERT_CONFIG)  # as robust as the other expert tests
    for _ in range(PLAN_TRIES):
        result = expert.run(1)
        if result.placed:
            break
    expert.close()
    assert result.placed, result.failure
    r = np.array(env.rewards)
    grasp_steps = np.flatnonzero(r == 1.0)
    assert len(grasp_steps) == 1, "+1 exactly once, on the first grasp"
    assert env.infos[grasp_steps[0]]["first_grasp"] and not env.infos[grasp_steps[0] - 1]["is_grasped"]
    assert r[-1] == 2.0 and env.terminated[-1] and env.infos[-1]["success"]
    assert not any(env.terminated[:-1])
    others = np.delete(r, [grasp_steps[0], len(r) - 1])
    np.testing.assert_array_equal(others, np.full_like(others, PENALTY))
    # dropping the element and taking it again pays nothing more
    u = env.unwrapped
    state = u.get_state_dict()
    state["task"]["held"][:] = False
    u.set_state_dict(state)
    _, reward, _, _, info = env.step(u.agent.robot.get_qpos())
    assert bool(info["is_grasped"][0]) and float(reward[0]) in (PENALTY, 2.0)
    env.close()


@pytest.mark.parametrize("env_id", ["CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1"])
def test_placement_succeeds_just_inside_and_fails_just_outside_the_tolerances(env_id):
    env = make_env(env_id)
    env.reset(seed=0)
    u = env.unwrapped
    u.set_held()
    goal = to_sapien(u.goal_pose.raw_pose)
    tau_place, tau_angle = float(u.tau_place[0]), float(u.tau_angle_deg[0])

    def placed(offset: float, angle: float) -> bool:
        pose = goal * sapien.Pose([offset, 0, 0]) * sapien.Pose(q=quat_z(angle))
        u.obj.set_pose(pose)
        info = u.evaluate()
        assert math.isclose(float(info["place_dist"][0]), offset, abs_tol=2e-4)
        assert math.isclose(float(info["place_angle_deg"][0]), abs(angle), abs_tol=0.05)
        return bool(info["success"][0])

    assert placed(0.0, 0.0)
    assert placed(tau_place - 0.002, 0.0) and not placed(tau_place + 0.002, 0.0)
    assert placed(0.0, tau_angle - 0.2) and not placed(0.0, tau_angle + 0.2)
    assert placed(0.0, -(tau_angle - 0.2)) and not placed(0.0, -(tau_angle + 0.2))
    # not held: never placed
    state = u.get_state_dict()
    state["task"]["held"][:] = False
    u.set_state_dict(state)
    u.obj.set_pose(goal)
    assert not bool(u.evaluate()["success"][0])
    env.close()


def test_symmetric_placements_count_as_placed():
    env = make_env("Flooring-v1")
    env.reset(seed=0)
    u = env.unwrapped
    goal = to_sapien(u.goal_pose.raw_pose)
    for angle, expect in ((90, 0.0), (180, 0.0), (45, 45.0)):
        u.obj.set_pose(goal * sapien.Pose(q=quat_z(angle)))
        assert math.isclose(float(u.evaluate()["place_angle_deg"][0]), expect, abs_tol=0.05)
    env.close()


@pytest.mark.parametrize("env_id, turn", [
    ("WindowInstallation-v1", sapien.Pose(q=[0, 0, 0, 1])),                 # 180 deg about z: inside face out
    ("CeilingInstallation-v1", sapien.Pose(q=quat_z(90))),                  # a rectangle across its opening
    ("Flooring-v1", sapien.Pose(q=[0, 1, 0, 0])),                           # upside down: finish face down
    ("CeilingInstallation-v1", sapien.Pose(q=[np.cos(np.pi / 12), np.sin(np.pi / 12), 0, 0])),  # tilted 30 deg
])
def test_turned_upside_down_or_tilted_elements_at_the_goal_are_not_placed(env_id, turn):
    env = make_env(env_id)
    env.reset(seed=0)
    u = env.unwrapped
    u.set_held()
    goal = to_sapien(u.goal_pose.raw_pose)
    u.obj.set_pose(goal)
    assert bool(u.evaluate()["success"][0]), "the goal pose itself is placed"
    u.obj.set_pose(goal * turn)
    info = u.evaluate()
    assert float(info["place_angle_deg"][0]) > float(u.tau_angle_deg[0]) and float(info["place_dist"][0]) < 1e-4
    assert not bool(info["success"][0])
    env.close()


def test_sparse_reward_of_an_episode_that_runs_out_of_time():
    env = make_env("WindowInstallation-v1", control_mode="pd_joint_delta_pos")
    env.reset(seed=0)
    rewards, terminated, truncated = [], [], []
    for _ in range(env.unwrapped.MAX_EPISODE_STEPS):
        _, r, term, trunc, info = env.step(torch.zeros(1, 6))
        rewards.append(float(r[0])), terminated.append(bool(term[0])), truncated.append(bool(trunc[0]))
    assert not any(terminated) and truncated[-1] and not any(truncated[:-1])
    np.testing.assert_allclose(rewards, PENALTY)
    assert math.isclose(sum(rewards), -1.0, abs_tol=1e-4) and not bool(info["picked"][0])
    env.close()


@pytest.mark.parametrize("env_id", ["CeilingInstallation-v1", "ConstructionPickPlace-v1"])
def test_cpu_hold_computes_the_same_velocities_as_the_batched_hold(env_id):
    """physx_cpu's hold (numpy on SAPIEN poses) and the batched one (torch, as on the GPU) agree."""
    env = make_env(env_id, control_mode="pd_joint_delta_pos")
    env.reset(seed=3)
    u = env.unwrapped
    u.set_held()
    gen = torch.Generator().manual_seed(0)
    checked = 0
    for i in range(12):
        env.step(torch.rand(1, 6, generator=gen) * 2 - 1)
        v, w = u.gripper.velocities(u.obj)
        v_cpu, w_cpu = u.gripper.velocities_cpu(u.obj)
        np.testing.assert_allclose(v_cpu, v[0].numpy(), atol=2e-3, rtol=1e-3)
        np.testing.assert_allclose(w_cpu, w[0].numpy(), atol=2e-3, rtol=1e-3)
        checked += float(torch.linalg.norm(v)) > 0.01  # the arm moving, the element being pulled
    assert checked >= 6
    env.close()


PUSH_PAST = 0.2
"""m; how far beyond the surface the plate's target would put the element's leading face."""
SOLID_SURFACES = {
    # env: (tcp position facing a solid part of the site, tcp rotation [w, x, y, z] (its z axis: where the
    #       element is pushed), axis of the world the surface faces along, where the surface is along it)
    "CeilingInstallation-v1": ([0.0, -0.6, 2.2], [1, 0, 0, 0], 2, "story_height"),  # up into the slab, no opening
    "WindowInstallation-v1": ([0.85, 0.0, 0.45], [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0], 0, "wall_x"),  # below the sills
    "Flooring-v1": ([0.0, 0.7, 0.25], [0, 1, 0, 0], 2, None),  # down onto the ground slab, away from the recesses
}


@pytest.mark.parametrize("env_id", list(SOLID_SURFACES))
def test_held_element_driven_into_the_site_does_not_pass_through(env_id):
    """Hold each kind of element facing a solid part of the site (the slab's underside, the wall under the
    window sills, the ground) and drive the plate 0.3 m past the surface: the element stops at the surface."""
    env = make_env(env_id)
    env.reset(seed=0)
    m = JointMover(env)
    u = m.u
    position, rotation, axis, key = SOLID_SURFACES[env_id]
    surface = 0.0 if key is None else u.site.manifest["site_params"][key]
    sign = 1.0 if axis == 0 or key is not None else -1.0  # which way along the axis the plate pushes
    kind = ELEMENT_KINDS[int(u.task_id[0])]
    thickness = u.site.manifest["elements"][kind]["size"][2]
    start = sapien.Pose(position, rotation)
    q = m.solve(start)
    u.agent.robot.set_qpos(torch.tensor(q[None], dtype=torch.float32))
    u.agent.controller.reset()
    m.q = q
    hold = sapien.Pose([0, 0, thickness / 2], [0, 1, 0, 0])  # the grasp face (+z) against the plate
    state = u.get_state_dict()
    state["task"]["held"][:] = True
    state["task"]["hold_pose_in_tcp"][:] = torch.tensor([[*hold.p, *hold.q]])
    u.set_state_dict(state)
    u.obj.set_pose(start * hold)
    m.move_to(q, 5)
    assert bool(u.held[0])
    lead = lambda: sign * (float(u.obj.pose.p[0, axis]) + sign * thickness / 2)  # noqa: E731  the leading face
    assert lead() < sign * surface - 0.03, "the element starts short of the surface"
    push = sign * (sign * surface - lead() + PUSH_PAST)  # the plate's way along the axis: the element this far past
    q_past = m.ik.solve(sapien.Pose(np.array(position) + np.eye(3)[axis] * push, rotation), seeds=[q], n_random=0)
    assert q_past is not None, "the pushed-through pose is reachable"
    leads = []
    for _ in range(3):
        m.move_to(q_past, 10, stop_on_done=False)
        leads.append(lead())
    assert max(leads) < sign * surface + 0.01, f"{kind}: leading face reached {max(leads):.3f}, surface at {sign * surface}"
    assert max(leads) > sign * surface - 0.05, f"{kind}: the element never reached the surface"
    env.close()


@pytest.mark.parametrize("env_id", ["ConstructionPickPlace-v1", "Flooring-v1"])
def test_state_round_trip_continues_identically(env_id):
    env = make_env(env_id, control_mode="pd_joint_delta_pos")
    env.reset(seed=5)
    u = env.unwrapped
    gen = torch.Generator().manual_seed(0)
    actions = [torch.rand(1, 6, generator=gen) * 2 - 1 for _ in range(12)]
    for a in actions[:4]:
        env.step(a)
    # a held element is part of the task state
    u.set_held()
    saved = u.get_state_dict()

    def rollout():
        out = []
        for a in actions[4:]:
            obs, r, *_ , info = env.step(a)
            out.append((obs.clone(), r.clone(), info["is_grasped"].clone()))
        return out

    first = rollout()
    env.reset(seed=9)  # somewhere else entirely
    u.set_state_dict(saved)
    second = rollout()
    for (o1, r1, g1), (o2, r2, g2) in zip(first, second):
        torch.testing.assert_close(o1, o2, atol=1e-5, rtol=0)
        assert torch.equal(r1, r2) and torch.equal(g1, g2)
    env.close()


def test_cpu_gym_wrapper_returns_numpy_floats_and_bools():
    env = CPUGymWrapper(make_env("ConstructionPickPlace-v1", control_mode="pd_joint_delta_pos", reward_mode="dense"))
    obs, info = env.reset(seed=0)
    assert isinstance(obs, np.ndarray) and obs.shape == (STATE_SIZE,)
    obs, reward, term, trunc, info = env.step(env.action_space.sample())
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32
    assert isinstance(reward, float) and isinstance(term, bool) and isinstance(trunc, bool)
    assert isinstance(info["success"], bool) and isinstance(info["place_dist"], float)
    env.close()


@pytest.mark.parametrize("env_id", ["ConstructionPickPlace-v1", "Flooring-v1"])
def test_record_episode_video_is_not_flat(env_id, tmp_path):
    import imageio.v3 as iio

    env = RecordEpisode(make_env(env_id, render_mode="rgb_array", control_mode="pd_joint_delta_pos"),
                        str(tmp_path), save_trajectory=False, save_on_reset=False)
    env.reset(seed=0)
    for _ in range(8):
        env.step(torch.as_tensor(env.action_space.sample()))
    env.flush_video(name="v")
    env.close()
    frames = iio.imread(tmp_path / "v.mp4").astype(np.float32)
    assert frames.shape[0] >= 8 and frames.shape[1:] == (512, 512, 3)
    assert frames.std() > 20
    assert np.abs(frames[-1] - frames[0]).mean() > 0.1, "nothing moved"


def test_without_cuda_the_cpu_render_backend_is_chosen_up_front_and_said_once():
    """No CUDA device: every env gets render_backend="cpu" before ManiSkill looks for one (which warns
    in every env, every worker process); the choice is printed once per process tree."""
    code = ("import gymnasium as gym, ms_construction\n"
            "from ms_construction.vector_env import CPUVectorEnv\n"
            "envs = CPUVectorEnv('Flooring-v1', 2, dict(obs_mode='state'))\n"
            "envs.reset(seed=0); envs.close()\n"
            "for _ in range(2):\n"
            "    env = gym.make('Flooring-v1', obs_mode='state'); print('backend', env.unwrapped.backend.render_backend); env.close()\n")
    env = {k: v for k, v in os.environ.items() if k != "MS_CONSTRUCTION_RENDER_BACKEND"}
    env["PYTHONPATH"] = str(ROOT)  # this checkout's ms_construction, whatever the editable install points at
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr
    try:
        sapien.Device("cuda")
        pytest.skip("a CUDA device is here")
    except RuntimeError:
        pass
    text = out.stdout + out.stderr
    assert "CUDA device was not found" not in text, text
    assert text.count("no CUDA device found, rendering on the CPU") == 1, text
    assert out.stdout.count("backend sapien_cpu") == 2, out.stdout
