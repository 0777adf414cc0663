"""The tasks' `obstacles` option: valid seeded scenes, the worker's walk, collisions counted and failing the episode,
the state round trip, the planning expert among the obstacles, shipped agents meeting them blind, PPO training among
them."""

import dataclasses
import json
from pathlib import Path

import pytest
import torch

from baselines.ppo import evaluation
from baselines.ppo.checkpoints import policy_env_kwargs
from ms_construction.envs.obstacles import (
    OBSTACLE_OBS_SIZE,
    STACK_SIZE,
    WORKER_LANE_X,
    WORKER_PARKED_XY,
    keeps_rules,
    sample_layouts,
)
from ms_construction.envs.state_layout import state_mirror_signs
from ms_construction.parameters import SiteParams
from ms_construction.planning import MotionPlanningExpert
from tests.helpers import TEST_EXPERT_CONFIG, make_env


def first_seed(env, found, seeds: int, what: str) -> int:
    """The first of seeds 0 .. `seeds` - 1 after whose reset `found(env.unwrapped)` holds (the env is left reset on
    it); the test fails naming `what` where none does."""
    for seed in range(seeds):
        env.reset(seed=seed)
        if found(env.unwrapped):
            return seed
    pytest.fail(f"no seed of {seeds} {what}")


def clear_at_every_turn(u, path: torch.Tensor, with_site: bool = False) -> float:
    """goal_configurations' whole check of `path` [P, 6] (`_clear_fraction`: the share of its points clear at every
    START_TURNS_DEG) for env `u`'s task type, with the stack and the post where they stand (`with_site`: and the
    site's collision parts)."""
    import numpy as np

    from ms_construction.goal_configurations import START_TURNS_DEG, _clear_fraction

    planners = u._path_planners(int(u.task_id[0]), with_site)
    return _clear_fraction(planners, path.numpy().astype(float), [float(np.deg2rad(t)) for t in START_TURNS_DEG])


def test_an_unknown_obstacles_option_raises_naming_the_allowed_ones():
    with pytest.raises(ValueError, match="'static'.*'moving'"):
        make_env("Flooring-v1", obstacles="walls")


def test_every_sampled_layout_keeps_the_rules():
    torch.manual_seed(0)
    layouts = sample_layouts(5000, SiteParams(), 20, "cpu")
    assert bool(keeps_rules(layouts, SiteParams()).all())
    # and the layouts vary: the stack's place, its height, the post, the lane's direction
    assert layouts[:, :6].std(0).min() > 0.05
    assert set(torch.sign(layouts[:, 8]).tolist()) == {-1.0, 1.0}


def test_a_mixed_scene_draws_per_episode_whether_the_obstacles_are_there_and_hides_them_when_not():
    """`obstacle_share` < 1: about that share of layouts on the site, each of the others parked out of reach (the
    stack under the floor, the post beyond the barrier, the worker never setting off) with the observation's entry
    zeros; bad shares are refused, naming what is allowed."""
    torch.manual_seed(0)
    layouts = sample_layouts(4000, SiteParams(), 20, "cpu", share=0.5)
    present = layouts[:, 2] > 0
    assert 0.45 < float(present.float().mean()) < 0.55
    assert bool(keeps_rules(layouts[present], SiteParams()).all())
    assert bool((layouts[~present, 2] < -10).all()) and bool((layouts[~present, 5] < -SiteParams().barrier_extent[2]).all())
    env = make_env("Flooring-v1", obstacles="moving", obstacle_share=0.5)
    u, seen = env.unwrapped, set()
    for seed in range(12):
        obs, _ = env.reset(seed=seed)
        here = bool(u.obstacles_present()[0])
        seen.add(here)
        assert bool((obs[0, -OBSTACLE_OBS_SIZE:] != 0).any()) == here
        if not here:
            u.obstacle_clock[:] = 10_000  # long after any worker would have set off
            assert not bool(u.worker_walking()[0]) and bool(u.clear_paths().all())
    assert seen == {True, False}
    env.close()
    for share, kwargs in ((0.0, dict(obstacles="static")), (1.5, dict(obstacles="static")), (0.5, {})):
        with pytest.raises(ValueError, match=r"obstacle_share=.*in \(0, 1\]"):
            make_env("Flooring-v1", obstacle_share=share, **kwargs)
    # SAC's `--obstacle-share`: its training envs only (its evaluations during training meet obstacles every time)
    from baselines.sac import sac

    mixed = sac.Args(obstacles="moving", obstacle_share=0.5)
    assert sac.env_kwargs(mixed)["obstacle_share"] == 0.5 and "obstacle_share" not in sac.env_kwargs(mixed, train=False)
    with pytest.raises(SystemExit, match="below 1 only with --obstacles"):
        sac.validate(sac.Args(obstacle_share=0.5))


def test_a_seed_draws_the_same_episode_with_and_without_obstacles_and_the_obstacles_are_seeded():
    plain, static = make_env("ConstructionPickPlace-v1"), make_env("ConstructionPickPlace-v1", obstacles="static")
    for seed in (3, 4):
        obs_plain, _ = plain.reset(seed=seed)
        obs_static, _ = static.reset(seed=seed)
        # the obstacles come last: the rest of the observation is the episode without them
        assert obs_static.shape[-1] == obs_plain.shape[-1] + OBSTACLE_OBS_SIZE
        torch.testing.assert_close(obs_static[:, :obs_plain.shape[-1]], obs_plain)
    first = static.unwrapped.obstacle_layout.clone()
    static.reset(seed=4)
    torch.testing.assert_close(static.unwrapped.obstacle_layout, first)
    static.reset(seed=5)
    assert not torch.allclose(static.unwrapped.obstacle_layout, first)
    blind = make_env("ConstructionPickPlace-v1", obstacles="static", obs_obstacles=False)
    obs_blind, _ = blind.reset(seed=3)
    assert obs_blind.shape == obs_plain.shape
    for env in (plain, static, blind):
        env.close()


@pytest.mark.parametrize("mode", ["static", "moving"])
def test_the_worker_walks_its_lane_once_when_moving_and_stays_outside_when_static(mode):
    env = make_env("Flooring-v1", obstacles=mode)
    env.reset(seed=1)
    u = env.unwrapped
    u.obstacle_layout[0, 10] = 5  # sets off at step 5
    q = u.agent.robot.get_qpos()
    places, speeds = [], []
    for _ in range(60):
        env.step(q)
        places.append(u.worker_xy()[0].clone())
        speeds.append(float(torch.linalg.norm(u.worker_velocity()[0])))
    places = torch.stack(places)
    parked = torch.tensor(WORKER_PARKED_XY)
    if mode == "static":
        assert torch.allclose(places, parked.expand_as(places)) and max(speeds) == 0
    else:
        in_lane = ~torch.isclose(places, parked).all(-1)
        # places[j] is after step j + 1: in the lane from the step the clock reads 5
        assert in_lane[4:10].all() and not in_lane[:4].any() and not in_lane[-5:].any()
        xs = places[in_lane, 0]
        assert xs.min() >= WORKER_LANE_X[0] - 1e-4 and xs.max() <= WORKER_LANE_X[1] + 1e-4
        steps = (xs[1:] - xs[:-1]).abs()
        speed = abs(float(u.obstacle_layout[0, 8]))
        torch.testing.assert_close(steps, torch.full_like(steps, speed / u.control_freq))  # walking speed
        obs = u.obstacle_observation()[0]
        assert obs.shape == (OBSTACLE_OBS_SIZE,)
    env.close()


def test_touching_an_obstacle_is_counted_and_fails_the_episode():
    env = make_env("CeilingInstallation-v1", obstacles="static")
    env.reset(seed=0)
    u = env.unwrapped
    q = u.agent.robot.get_qpos()
    _, _, terminated, _, info = env.step(q)
    assert not bool(info["obstacle_collision"]) and not bool(info["fail"]) and not bool(terminated)
    # the stack moved under the plate at rest, its top above the plate
    tcp = u.agent.tcp.pose.raw_pose[0]
    u.obstacle_layout[0, 0:2] = tcp[:2]
    u.obstacle_layout[0, 2] = float(tcp[2]) + 0.1
    u._pose_obstacles()
    _, _, terminated, _, info = env.step(q)
    assert bool(info["obstacle_collision"]) and bool(info["fail"]) and bool(terminated)
    assert float(u.obstacle_layout[0, 2]) - STACK_SIZE[2] < float(tcp[2])
    env.close()


def test_state_round_trip_restores_the_obstacles_and_the_worker_s_clock():
    env = make_env("Flooring-v1", obstacles="moving")
    env.reset(seed=2)
    u = env.unwrapped
    q = u.agent.robot.get_qpos()
    for _ in range(10):
        env.step(q)
    u.obstacle_collided[:] = True  # as after a touch
    state = u.get_state_dict()
    layout, clock = u.obstacle_layout.clone(), u.obstacle_clock.clone()
    after = [env.step(q)[0] for _ in range(30)]
    env.reset(seed=9)
    u.set_state_dict(state)
    torch.testing.assert_close(u.obstacle_layout, layout)
    assert torch.equal(u.obstacle_clock, clock) and bool(u.obstacle_collided.all())
    again = [env.step(q)[0] for _ in range(30)]
    for a, b in zip(after, again):
        torch.testing.assert_close(a[:, -OBSTACLE_OBS_SIZE:], b[:, -OBSTACLE_OBS_SIZE:])
    env.close()


@pytest.mark.parametrize("mode", ["static", "moving"])
def test_the_expert_places_among_the_obstacles_without_touching_them(mode):
    env = make_env("Flooring-v1", obstacles=mode)
    expert = MotionPlanningExpert(env, TEST_EXPERT_CONFIG)
    # on these seeds the walking worker crosses the recesses' side while the arm works there: the expert replans or
    # waits on some of them (on which, depends on the paths RRTConnect finds)
    results = [expert.run(seed) for seed in (2, 4, 5, 6)]
    assert sum(r.placed for r in results) >= 3, [r.failure for r in results]
    # the expert gives way to the worker, but sees it coming only a second ahead: it may be caught, rarely
    assert sum(r.collisions > 0 for r in results) <= (0 if mode == "static" else 1)
    assert all("touched an obstacle" in r.failure for r in results if r.collisions)
    if mode == "moving":
        # whether the worker crosses where the arm is, on these seeds, depends on the paths RRTConnect finds (OMPL
        # draws from its own unseeded generator): where it gave way on none of them, more seeds until it does
        more = iter(range(7, 23))
        while not any(r.replans + r.waited_steps + r.escapes > 0 for r in results):
            seed = next(more, None)
            assert seed is not None, "the expert gave way to the walking worker on none of 20 flooring seeds"
            results.append(expert.run(seed))
    else:
        assert all(r.replans + r.waited_steps + r.escapes == 0 for r in results)
    expert.close()
    env.close()


def test_a_policy_trained_without_obstacles_meets_them_blind(tmp_path):
    assert "obs_obstacles" not in policy_env_kwargs({"control_mode": "pd_joint_delta_pos"})
    assert policy_env_kwargs({"control_mode": "pd_joint_delta_pos", "obstacles": "static"})["obs_obstacles"] is True
    # scripts/evaluate.py runs the shipped agent (trained without obstacles) among them on its own observation
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=2, seed=1_000_000, workers=1, obstacles="static",
                                    json=out))
    episodes = json.loads(out.read_text())["episode_results"]
    assert len(episodes) == 2 and all(isinstance(e["collided"], bool) for e in episodes)
    with pytest.raises(SystemExit, match="other episodes than the published table"):
        evaluation.main(evaluation.Args(env_id="Flooring-v1", obstacles="static", write_results=True))


def test_obstacles_are_refused_on_the_gpu_until_written_there():
    if not torch.cuda.is_available():
        pytest.skip("needs a CUDA device (physx_cuda)")
    with pytest.raises(NotImplementedError, match="physx_cpu"):
        make_env("Flooring-v1", obstacles="static", sim_backend="physx_cuda", num_envs=2)


def test_the_dense_reward_measures_the_carry_along_the_paths_clear_of_the_obstacles():
    env = make_env("CeilingInstallation-v1", obstacles="static", reward_mode="dense")
    u = env.unwrapped

    def one_blocked_one_clear(u):  # the stack or the post blocks one of the goal slot's usable paths, not all
        usable, clear = u.geometry.paths["usable"][u.task_id, u.goal_slot], u.clear_paths()
        return bool((usable & ~clear).any() and (usable & clear).any())

    first_seed(env, one_blocked_one_clear, 20, "with a usable start path blocked and another clear")
    usable, clear = u.geometry.paths["usable"][u.task_id, u.goal_slot], u.clear_paths()
    blocked = int((usable & ~clear)[0].nonzero()[0, 0])
    path = u.geometry.paths["waypoints"][u.task_id, u.goal_slot][0, blocked]  # [P, 6]
    on_path = ((path[2] + path[3]) / 2)[None]  # past the back-off, which a way searched around the obstacles shares
    turn, side = torch.zeros(1), torch.full((1,), -1)
    along_all = u.geometry.project(on_path, turn, u.task_id, u.goal_slot, side)
    along_clear = u.geometry.project(on_path, turn, u.task_id, u.goal_slot, side, u.obstacle_ways())
    # on the blocked path the arm is on a usable path, but off every path the reward now measures along
    assert float(along_clear.distance) > float(along_all.distance) + 0.1
    # and the obstacles parked far away block nothing
    state = u.get_state_dict()
    state["task"]["obstacle_layout"][0, 0:2] = torch.tensor([-5.0, 5.0])
    state["task"]["obstacle_layout"][0, 4:6] = torch.tensor([5.0, 5.0])
    u.set_state_dict(state)
    assert bool(u.clear_paths().all())
    env.close()


def test_the_paths_clear_of_the_obstacles_are_those_the_start_paths_own_check_finds_clear():
    """The env checks the arm's self-collision once per goal slot and the obstacles per episode: the same paths as
    goal_configurations' whole check (`_clear_fraction`) with the stack and the post in its world, on every task
    type, blocked and clear paths both among them."""
    env = make_env("ConstructionPickPlace-v1", obstacles="static")
    u = env.unwrapped
    seen, kinds = torch.zeros(2, dtype=torch.bool), set()
    for seed in range(12):
        env.reset(seed=seed)
        kind, slot = int(u.task_id[0]), int(u.goal_slot[0])
        whole = [clear_at_every_turn(u, path) == 1.0 for path in u.geometry.paths["waypoints"][kind, slot]]
        ways = u.obstacle_ways()
        assert (ways.clear & ~ways.searched)[0].tolist() == whole
        seen |= torch.tensor([not all(whole), any(whole)])
        kinds.add(kind)
    assert bool(seen.all()) and kinds == {0, 1, 2}
    env.close()


def test_near_goal_starts_pose_the_arm_on_the_paths_clear_of_the_obstacles():
    env = make_env("CeilingInstallation-v1", obstacles="static", reward_mode="dense")
    u = env.unwrapped
    u.set_near_goal_starts(1.0, 1.0)
    touched, starts, blocked = 0, 0, 0
    for seed in range(12):
        env.reset(seed=seed)
        ways = u.geometry.clear_ways(u.task_id, u.goal_slot, u.clear_paths())  # usable, else detours, clear
        if not ways.any():  # every way out of this goal blocked: an ordinary reset instead
            assert not bool(u.near_goal_start[0])
            blocked += 1
            continue
        assert bool(u.near_goal_start[0])
        sides = ways.view(-1, 2).any(0)  # the start's grasp side is a side of a clear path
        assert bool(sides[u.carry_side[0]])
        _, _, _, _, info = env.step(u.agent.robot.get_qpos())
        touched += int(info["obstacle_collision"])
        starts += 1
    assert touched == 0 and starts >= 8, (touched, starts, blocked)
    env.close()


def test_where_the_obstacles_block_every_usable_path_and_no_via_is_found_the_reward_takes_a_clear_detour(monkeypatch):
    """A window layout whose stack or post blocks every usable start path of its goal slot (all from one turret side)
    where the search for a via around them finds none (here: it draws none) and a detour from the other side is clear
    (`CarryGeometry.clear_ways`): the dense reward reaches for the table from the detour's side and measures the carry
    along it, and a near-goal start is posed on it and touches nothing. (Without the detours the reward fell back to
    the blocked paths, into the obstacle.)"""
    from ms_construction import goal_configurations

    monkeypatch.setattr(goal_configurations, "WAY_SEARCH_DRAWS", 0)
    env = make_env("WindowInstallation-v1", obstacles="static", reward_mode="dense")
    u = env.unwrapped
    g = u.geometry

    def only_a_detour_clear(u):
        clear = u.clear_paths()
        return bool(not (g.paths["usable"][u.task_id, u.goal_slot] & clear).any()
                    and g.clear_ways(u.task_id, u.goal_slot, clear).any())

    seed = first_seed(env, only_a_detour_clear, 40, "whose obstacles block every usable path and leave a detour")
    clear = u.clear_paths()
    usable = g.paths["usable"][u.task_id, u.goal_slot]
    ways = g.clear_ways(u.task_id, u.goal_slot, clear)
    assert (ways <= g.paths["detour"][u.task_id, u.goal_slot]).all()
    assert torch.equal(g.usable(u.task_id, u.goal_slot, clear), ways)
    sides = ways.view(-1, 2).any(0)
    assert int(sides.sum()) == 1 and not (usable.view(-1, 2).any(0) & sides).any(), "the side without usable paths"
    side = int(sides.float().argmax())
    q = u.agent.robot.get_qpos()
    torch.testing.assert_close(u.reach_distance(), (g.table_q[u.task_id, side, :5] - q[:, :5]).abs().sum(-1))
    path = g.paths["waypoints"][u.task_id, u.goal_slot][0, int(ways[0].nonzero()[0, 0])]  # [install .. table]
    at_via = g.project(path[2][None], torch.zeros(1), u.task_id, u.goal_slot, torch.full((1,), side), u.obstacle_ways())
    assert float(at_via.distance) <= float((path[1:3] - path[:2]).abs().sum()) + 1e-4, "on the detour: its length left"
    # grasped from the other side (the turret cannot cross holding it): along that side's usable paths, blocked or not
    other = 1 - side
    config = int(usable[0].view(-1, 2)[:, other].nonzero()[0, 0])
    blocked = g.paths["waypoints"][u.task_id, u.goal_slot][0, config * 2 + other]
    assert torch.equal(g.carry_paths(u.task_id, u.goal_slot, torch.full((1,), other), u.obstacle_ways()),
                       usable)
    at_lift = g.project(blocked[3][None], torch.zeros(1), u.task_id, u.goal_slot, torch.full((1,), other),
                        u.obstacle_ways())
    assert float(at_lift.distance) <= float((blocked[1:4] - blocked[:3]).abs().sum()) + 1e-4
    before = g.project(blocked[3][None], torch.zeros(1), u.task_id, u.goal_slot, torch.full((1,), -1),
                       u.obstacle_ways())
    assert float(before.distance) > float(at_lift.distance) + 0.1, "not grasped: along the clear detour only"
    u.set_near_goal_starts(1.0, 1.0)
    env.reset(seed=seed)
    assert bool(u.near_goal_start[0]) and int(u.carry_side[0]) == side
    _, _, _, _, info = env.step(u.agent.robot.get_qpos())
    assert not bool(info["obstacle_collision"])
    env.close()


def test_where_the_obstacles_block_every_usable_path_of_a_side_the_episode_searches_a_clear_via_for_it():
    """A flooring layout whose stack or post blocks every usable start path of its goal slot: the episode gets one of
    them back through a via searched at reset (`SiteObstacles._search_vias`), wholly clear of the site and the
    obstacles by goal_configurations' own check; the same via after a reset with the same seed and after
    `set_state_dict`; the reward reaches for the table from that side and measures the carry along the searched way,
    and a near-goal start is posed on it and touches nothing."""
    env = make_env("Flooring-v1", obstacles="static", reward_mode="dense")
    u = env.unwrapped
    g = u.geometry

    def only_a_searched_way_clear(u):
        ways = u.obstacle_ways()
        return bool(not (g.paths["usable"][u.task_id, u.goal_slot] & ways.clear & ~ways.searched).any()
                    and ways.searched.any())

    seed = first_seed(env, only_a_searched_way_clear, 40, "whose obstacles block every usable path and whose search "
                      "finds a via")
    ways = u.obstacle_ways()
    usable = g.paths["usable"][u.task_id, u.goal_slot]
    assert (ways.searched <= usable).all() and int(ways.searched.sum()) == 1
    path = int(ways.searched[0].nonzero()[0, 0])
    side = path % 2
    searched = ways.waypoints[0, path]
    # the slot's own path but for its corner, and clear of the site and the obstacles at every checked turn
    site_path = g.paths["waypoints"][u.task_id, u.goal_slot][0, path]
    assert torch.equal(searched[[0, 1, 3, 4]], site_path[[0, 1, 3, 4]]) and not torch.equal(searched[2], site_path[2])
    assert clear_at_every_turn(u, searched, with_site=True) == 1.0
    assert clear_at_every_turn(u, site_path, with_site=True) < 1.0
    # seeded by the layout: the same way again, and after the state is set back
    state = u.get_state_dict()
    env.reset(seed=seed)
    assert torch.equal(u.obstacle_ways().waypoints, ways.waypoints)
    env.reset(seed=seed + 1)
    u.set_state_dict(state)
    assert torch.equal(u.obstacle_ways().waypoints, ways.waypoints)
    # the reach pays the searched way's side; the carry falls along it after a grasp from there
    assert g.path_sides(u.task_id, u.goal_slot, u.obstacle_ways())[0].tolist() == [side == 0, side == 1]
    grasped = torch.full((1,), side)
    at = [float(g.project(q[None], torch.zeros(1), u.task_id, u.goal_slot, grasped, u.obstacle_ways()).distance)
          for q in (searched[3], searched[2], searched[1])]
    assert at[0] > at[1] > at[2]
    length_left = float((searched[1:3] - searched[:2]).abs().sum())
    assert at[1] <= length_left + 1e-4, "at the via: the searched way's length left"
    u.set_near_goal_starts(1.0, 1.0)
    env.reset(seed=seed)
    assert bool(u.near_goal_start[0]) and int(u.carry_side[0]) == side
    _, _, _, _, info = env.step(u.agent.robot.get_qpos())
    assert not bool(info["obstacle_collision"])
    env.close()


def test_the_obstacles_entry_is_zeros_without_obstacles_and_mirrors_with_the_scene():
    plain = make_env("Flooring-v1")
    forced = make_env("Flooring-v1", obs_obstacles=True)
    obs_plain, _ = plain.reset(seed=1)
    obs_forced, _ = forced.reset(seed=1)
    assert torch.equal(obs_forced[:, -OBSTACLE_OBS_SIZE:], torch.zeros(1, OBSTACLE_OBS_SIZE))
    torch.testing.assert_close(obs_forced[:, :-OBSTACLE_OBS_SIZE], obs_plain)
    plain.close()
    forced.close()
    # the mirror's signs turn the entry into the one of the scene mirrored in the plane y = 0
    env = make_env("Flooring-v1", obstacles="moving")
    env.reset(seed=3)
    u = env.unwrapped
    u.obstacle_layout[0, 10] = 0  # walking from the first step
    q = u.agent.robot.get_qpos()
    obs = env.step(q)[0][0]
    mirrored = u.obstacle_layout.clone()
    mirrored[:, [1, 5, 7, 9]] *= -1  # the stack's, the post's and the lane's y, the worker's vy
    mirrored[:, 3] = -mirrored[:, 3]  # the stack's yaw
    state = u.get_state_dict()
    state["task"]["obstacle_layout"] = mirrored
    u.set_state_dict(state)
    signs = state_mirror_signs(obs.shape[-1], obstacles=True)[-OBSTACLE_OBS_SIZE:]
    torch.testing.assert_close(u.obstacle_observation()[0], obs[-OBSTACLE_OBS_SIZE:] * signs)
    env.close()


def test_ppo_trains_among_obstacles_and_its_policy_sees_them_wherever_it_is_evaluated(tmp_path):
    from baselines.ppo import ppo
    from baselines.ppo.checkpoints import load_policy

    args = ppo.Args.of(num_envs=2, num_eval_envs=1, num_steps=20, num_minibatches=2, update_epochs=1, eval_freq=100,
                       checkpoint_freq=1, env_id="Flooring-v1", sim_backend="physx_cpu", log_dir=str(tmp_path),
                       exp_name="among", total_timesteps=80, obstacles="moving", mirror_twins=True)
    ppo.main(args)
    checkpoint = tmp_path / "among" / "checkpoint.pt"
    agent, kwargs = load_policy(checkpoint, "Flooring-v1")
    assert kwargs["obs_obstacles"] is True and agent.mirror is not None
    for obstacles in (None, "static"):
        out = tmp_path / f"{obstacles}.json"
        evaluation.main(evaluation.Args(checkpoint=checkpoint, env_id="Flooring-v1", episodes=1, workers=1,
                                        obstacles=obstacles, json=out))
        assert json.loads(out.read_text())["episodes"] == 1



def test_the_recipe_trains_among_obstacles_from_the_shipped_weights_unchanged_but_for_the_scene_and_budget(tmp_path):
    """`--train shipped`: the from-scratch recipe's arguments, but for the tasks' `obstacles`, the budget, the run's
    name, the hand-back of near-goal starts (version 5; its reach starts, version 6, are the recipe's own) and the
    initial weights: the shipped reward-only agent's, which gain the obstacle inputs (at zero weight) and train among
    them; its row files are named for its run."""
    from baselines.ppo import ppo
    from baselines.ppo.checkpoints import load_checkpoint
    from experiments import from_scratch, obstacles

    run = obstacles.training_run("shipped", num_envs=2)
    recipe = from_scratch.scratch_args(2, seed=1)
    changed = {k for k, v in vars(run.args).items() if v != vars(recipe)[k]}
    assert changed <= {"obstacles", "total_timesteps", "exp_name", "checkpoint", "starts"}
    assert run.args.obstacles == "moving" and run.args.starts.near_goal_share_end == obstacles.HAND_BACK_END
    assert dataclasses.replace(run.args.starts, near_goal_share_end=None) == recipe.starts
    assert obstacles.row_name(str(from_scratch.CAMPAIGN_DIR / run.name / "checkpoint.pt")) == run.name
    assert obstacles.row_name("campaign/scratch_s2/candidates/candidate_5000000.pt") == "scratch_s2_candidate_5000000"
    assert obstacles.row_name("assets/checkpoints/general_agent.pt") == "general_agent"
    tiny = run.args.replace(total_timesteps=40, num_steps=20, num_minibatches=2, update_epochs=1, num_eval_envs=1,
                            log_dir=str(tmp_path), checkpoint_freq=1, env_id="Flooring-v1", task_weights=None)
    ppo.main(tiny)
    trained = load_checkpoint(tmp_path / run.name / "checkpoint.pt")
    before = load_checkpoint(run.args.checkpoint)
    assert trained["progress"]["global_step"] == 40 and trained["args"]["obstacles"] == "moving"
    assert trained["obs_dim"] == before["obs_dim"] + OBSTACLE_OBS_SIZE
    at = before["agent"]["obs_rms.mean"].shape[0]  # the obstacles' entry ends the observation
    w, w0 = trained["agent"]["actor_mean.0.weight"], before["agent"]["actor_mean.0.weight"]
    rest = torch.cat([w[:, :at], w[:, at + OBSTACLE_OBS_SIZE:]], 1)
    assert torch.allclose(rest, w0, atol=0.05) and not torch.equal(rest, w0), "started from the shipped weights, and trained"
    # `--evaluate` evaluates the run's policy at its env steps, kept beside it: a later checkpoint gets rows of its own
    local = dataclasses.replace(run, args=tiny)
    step, policy = obstacles.trained_policy(local)
    assert (step, policy) == (40, tmp_path / run.name / "candidates" / "candidate_40.pt")
    kept = torch.load(policy, weights_only=False)
    assert "optimizer" not in kept and torch.equal(kept["agent"]["actor_mean.0.weight"], w)
    assert obstacles.row_name(str(policy)) == f"{run.name}_candidate_40"
    with pytest.raises(SystemExit, match="has no checkpoint at .*train it first: python -m experiments.obstacles"):
        obstacles.trained_policy(dataclasses.replace(run, args=tiny.replace(log_dir=str(tmp_path / "none"))))


def test_a_row_on_file_is_read_only_for_the_same_seeds_and_the_same_weights(tmp_path):
    """An agent's row is kept for the checkpoint's weights, not its name: a policy shipped again under the same file
    name (scratch_general_agent.pt, PPO's and then SAC's) is run again, the same one is read back."""
    from experiments import obstacles

    class Pool:  # the episodes in this process, counted
        def __init__(self):
            self.ran = 0

        def imap(self, fn, jobs):
            self.ran += len(jobs)
            return map(fn, jobs)

    checkpoint, row = tmp_path / "agent.pt", tmp_path / "agent_none_ceiling.json"
    checkpoint.write_bytes(b"PPO's weights")
    pool = Pool()

    def episode(job):
        return dict(seed=job[1], placed=checkpoint.read_bytes() == b"SAC's weights")

    def run(seeds):
        return obstacles.run_row(pool, row, episode, [(str(checkpoint), s) for s in seeds], seeds, "row", str(checkpoint))

    assert [e["placed"] for e in run([1, 2])] == [False, False] and pool.ran == 2
    assert run([1, 2]) and pool.ran == 2, "the same seeds and weights: read from the file"
    assert run([1, 2, 3]) and pool.ran == 5, "other seeds: run again"
    checkpoint.write_bytes(b"SAC's weights")
    assert [e["placed"] for e in run([1, 2, 3])] == [True] * 3 and pool.ran == 8, "other weights: run again"
    assert json.loads(row.read_text())["checkpoint_sha256"] == obstacles.sha256(checkpoint)


def test_more_agents_join_the_shipped_ones_and_a_bad_one_is_refused():
    from experiments import obstacles

    agents = obstacles.with_more_agents({"a": "x.pt"}, ("seed 1=assets/checkpoints/general_agent.pt",))
    assert agents == {"a": "x.pt", "seed 1": "assets/checkpoints/general_agent.pt"}
    for spec in ("no checkpoint", "label=missing.pt"):
        with pytest.raises(SystemExit, match="LABEL=CHECKPOINT"):
            obstacles.with_more_agents({}, (spec,))


def test_each_trained_snapshot_results_shows_is_committed_and_labelled_by_its_run():
    """SHOWN, the trained rows of RESULTS' obstacle table and summary: each an evaluated candidate kept in git (a fresh
    clone runs `python -m experiments.obstacles` with them), each label naming its learner, start, scene, reward,
    seed and env steps, every label its own."""
    import subprocess

    from experiments import obstacles

    agents = obstacles.shown_agents()
    assert len(agents) == len(obstacles.SHOWN) and set(agents.items()) <= set(obstacles.Args().agents.items())
    for (start, learner, share, reward, seed, step), (label, policy) in zip(obstacles.SHOWN, agents.items()):
        run = obstacles.training_run(start, seed, None, learner, share, reward)
        assert Path(policy) == obstacles.candidate_path(run, step) and Path(policy).is_file()
        assert subprocess.run(["git", "ls-files", "--error-unmatch", policy], capture_output=True).returncode == 0
        assert label.endswith(obstacles.TRAINED)
        assert f"{obstacles.version_name(reward)}, seed {seed}, {step:,} env steps" in label
    assert obstacles.trained_label("shipped", "sac", 0.5, 3, 2, 400_000) == (
        "SAC from SAC's agent, moving obstacles in 50% of episodes, reward 3, seed 2, 400,000 env steps"
        " (trained among obstacles)")
    assert obstacles.trained_label("shipped", None, 1.0, 1, 1, 460_000).startswith(
        "PPO from PPO's agent, moving obstacles,")
    assert ", moving obstacles, reward 4, near-goal starts handed back, seed 1," in obstacles.trained_label(
        "shipped", "sac", 1.0, 5, 1, 200_000), "version 5 is no reward of its own"
    assert ", reward 4, near-goal starts handed back, reach starts, seed 1," in obstacles.trained_label(
        "shipped", "sac", 1.0, 6, 1, 200_000)


def test_sac_on_a_mixed_scene_is_its_own_run_unchanged_but_for_the_share_and_refuses_ppo():
    """`--share 0.5 --train nothing --learner sac`: SAC's obstacle run but for `obstacle_share`, in a run (and a
    command) of its own; PPO's recipe has no such option, and a share outside (0, 1] is refused."""
    from experiments import obstacles

    full, mixed = obstacles.training_run("nothing"), obstacles.training_run("nothing", share=0.5)  # SAC by default
    assert full == obstacles.training_run("nothing", learner="sac") and full.name == "obstacles_moving_r7_sac_s1"
    changed = {k for k, v in vars(mixed.args).items() if v != vars(full.args)[k]}
    assert changed == {"obstacle_share", "exp_name"} and mixed.args.obstacle_share == 0.5
    assert mixed.name == "obstacles_moving_share50_r7_sac_s1" != full.name
    assert mixed.command == "python -m experiments.obstacles --share 0.5 --train nothing --learner sac --train-seed 1"
    assert "in 50% of its training episodes" in mixed.what
    with pytest.raises(SystemExit, match="SAC's option"):
        obstacles.training_run("shipped", share=0.5)
    with pytest.raises(SystemExit, match="SAC's option"):
        obstacles.training_run("nothing", learner="ppo", share=0.5)
    with pytest.raises(SystemExit, match=r"in \(0, 1\]"):
        obstacles.training_run("nothing", learner="sac", share=0.0)


def test_the_runs_on_the_earlier_obstacle_reward_keep_their_folders_and_are_not_trained_on():
    """OBSTACLE_REWARD names what a run among obstacles trains on: today's runs' folders carry it (`_r7`), the runs
    on the earlier versions keep theirs, for --evaluate and the tables, and training one is refused (their reward
    code is gone); 5 is 4 with the hand-back of near-goal starts, 6 is 5 with reach starts, and 7 trains as 6 does
    (its change is the tasks' reward among obstacles, not an option of the run)."""
    from experiments import obstacles

    old = obstacles.training_run("shipped", 1, None, "sac", 0.5, reward=1)
    assert old.name == "obstacles_moving_share50_shipped_sac_s1" and "obstacle reward" not in old.what
    assert old.command.startswith("python -m experiments.obstacles --share 0.5 --obstacle-reward 1 --train shipped")
    today = obstacles.training_run("shipped", 1, None, "sac", 0.5)
    assert today.name == "obstacles_moving_share50_r7_shipped_sac_s1" and "--obstacle-reward" not in today.command
    assert "(obstacle reward 5 (ways searched at reset), near-goal starts handed back, reach starts)" in today.what
    new = obstacles.training_run("shipped", 1, None, "sac", 0.5, reward=6)
    assert new.name == "obstacles_moving_share50_r6_shipped_sac_s1" and "--obstacle-reward 6" in new.command
    assert "(obstacle reward 4, near-goal starts handed back, reach starts)" in new.what
    assert {k for k, v in vars(today.args).items() if v != vars(new.args)[k]} == {"exp_name"}
    r4, r5 = (obstacles.training_run("shipped", 1, None, "sac", 0.5, reward=v) for v in (4, 5))
    assert r4.name == "obstacles_moving_share50_r4_shipped_sac_s1" and "--obstacle-reward 4" in r4.command
    assert r5.name == "obstacles_moving_share50_r5_shipped_sac_s1" and "--obstacle-reward 5" in r5.command
    changed = {k for k, v in vars(r5.args).items() if v != vars(r4.args)[k]}
    assert changed == {"exp_name", "near_goal_share_end"} and r4.args.near_goal_share_end is None
    assert r5.args.near_goal_share_end == obstacles.HAND_BACK_END < r5.args.near_goal_share
    changed = {k for k, v in vars(new.args).items() if v != vars(r5.args)[k]}
    assert changed == {"exp_name", "reach_start_share"} and r5.args.reach_start_share == 0
    assert new.args.reach_start_share == obstacles.REACH_START_SHARE
    probe = obstacles.training_run("shipped", 1, None, "sac", 0.5, reward=2)
    assert probe.name == "obstacles_moving_share50_r2_shipped_sac_s1" and "--obstacle-reward 2" in probe.command
    r3 = obstacles.training_run("shipped", 1, None, "sac", 0.5, reward=3)
    assert r3.name == "obstacles_moving_share50_r3_shipped_sac_s1" and "--obstacle-reward 3" in r3.command
    with pytest.raises(SystemExit, match="--obstacle-reward 8"):
        obstacles.training_run("shipped", reward=8)
    for earlier in (1, 2, 3, 4, 5, 6):
        with pytest.raises(SystemExit, match="that reward is gone"):
            obstacles.main(obstacles.Args(train="shipped", learner="sac", share=0.5, obstacle_reward=earlier))


def test_the_training_curve_draws_every_run_with_a_progress_file_per_task_type(tmp_path, monkeypatch):
    """`--training-curve`: one panel per task type, a curve per run of TRAIN_RUNS whose progress.csv is there (its
    per-task moving mean of the training episodes placed), labelled with its env steps, and the touches of an
    obstacle where the run logged them; with no run there it says how to start one."""
    from experiments import obstacles
    from experiments.campaign import checkpoint_of

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match="train one with --train"):
        obstacles.training_curve(tmp_path / "curve.png")
    drawn, touched = {}, {}
    monkeypatch.setattr(obstacles.transfer, "plot_training",
                        lambda panels, out, title, collided: (drawn.update(panels), touched.update(collided)))
    progress = checkpoint_of(obstacles.training_run("nothing", share=0.5, reward=1)).parent / "progress.csv"
    progress.parent.mkdir(parents=True)
    progress.write_text("global_step,ordinary_place_ceiling,ordinary_place_window,ordinary_place_flooring,"
                        "ordinary_collided_ceiling\n"  # the touches logged from the second row on, ceiling only
                        + "".join(f"{2000 * (i + 1)},1.0,,0.0,{'' if i == 0 else 0.5}\n" for i in range(3)))
    obstacles.training_curve(tmp_path / "curve.png")
    assert list(drawn) == ["ceiling", "window", "flooring"]
    label = "SAC from nothing, mixed scene (--share 0.5), reward 1, seed 1, 6,000 env steps"
    assert all(list(curves) == [label] for curves in drawn.values()), "only the run with a progress.csv"
    steps, placed = drawn["ceiling"][label]
    assert list(steps) == [2000, 4000, 6000] and list(placed) == [1.0, 1.0, 1.0]
    assert list(drawn["flooring"][label][1]) == [0.0] * 3
    assert all(v != v for v in drawn["window"][label][1]), "no window episode ended: nothing to average"
    assert list(touched["ceiling"]) == [label] and not touched["window"] and not touched["flooring"]
    assert list(touched["ceiling"][label][1])[1:] == [0.5, 0.5], "the touches from where the run logged them"
    seed2 = checkpoint_of(obstacles.training_run("nothing", 2, share=0.5, reward=1)).parent / "progress.csv"
    seed2.parent.mkdir(parents=True)
    seed2.write_text("global_step,ordinary_place_ceiling,ordinary_place_window,ordinary_place_flooring\n"
                     "2000,0.0,0.0,0.0\n")
    drawn.clear()
    obstacles.training_curve(tmp_path / "curve.png")
    assert list(drawn["window"]) == [label, "SAC from nothing, mixed scene (--share 0.5), reward 1, seed 2, 2,000 env steps"], \
        "a second seed of the run is drawn beside the first"


def test_the_snapshot_table_reads_each_seed_s_evaluated_candidates_from_their_episodes(tmp_path):
    """`--train S --snapshot-table`: a row per seed, evaluated snapshot and scene (none, moving), each task's placed %
    [95% CI] / touched %, read from the JSONs --evaluate wrote; a task not evaluated is a dash."""
    from experiments import obstacles
    from experiments.campaign import checkpoint_of

    def write(seed: int, step: int, scene: str, kind: str, placed: int, touched: int, n: int = 4) -> None:
        name = checkpoint_of(obstacles.training_run("shipped", seed, None, "sac", 0.5)).parent.name
        episodes = [{"seed": i, "placed": i < placed, "picked": i <= placed,
                     "collided": placed <= i < placed + touched, "length": 10, "policy_time_s": 0.01} for i in range(n)]
        (tmp_path / f"{name}_candidate_{step}_{scene}_{kind}.json").write_text(json.dumps({"episodes": episodes}))

    for kind in ("ceiling", "window", "flooring"):
        for step in (300_000, 100_000):
            write(1, step, "none", kind, 4, 0)
            write(1, step, "moving", kind, 3, 1)
        if kind != "window":
            write(2, 100_000, "moving", kind, 2, 2)
    rows = obstacles.snapshot_table("shipped", "sac", 0.5, tmp_path)[2:]
    assert [r.split(" | ")[:3] for r in rows] == [["| 1", "100,000", "none"], ["| 1", "100,000", "moving"],
                                                  ["| 1", "300,000", "none"], ["| 1", "300,000", "moving"],
                                                  ["| 2", "100,000", "none"], ["| 2", "100,000", "moving"]]
    assert rows[1].count("75.0 [") == 3 and rows[1].count("] / 25") == 3
    assert rows[4].endswith("| - | - | - |"), "seed 2 was not evaluated without obstacles"
    assert rows[5].split(" | ")[4] == "-" and rows[5].count("50.0 [") == 2, "seed 2's window rows are not there"
    # the touches of a seed's latest snapshot in the static scene against the blind reward-only agent's
    blind = obstacles.row_name(obstacles.AGENTS[obstacles.BLIND])
    for kind in ("ceiling", "window", "flooring"):
        write(1, 300_000, "static", kind, 2, 2)  # touched in the episodes of seeds 2 and 3
        (tmp_path / f"{blind}_static_{kind}.json").write_text(json.dumps({"episodes": [
            {"seed": i, "collided": i in (1, 3), "picked": i == 1} for i in range(4)]}))
    notes = obstacles.snapshot_table("shipped", "sac", 0.5, tmp_path)[9:]
    assert notes == ["Seed 1 at 300,000 env steps, static scene: touched an obstacle in 2 / 2 / 2 episodes (ceiling / "
                     "window / flooring; 1 / 1 / 1 before picking its element up), of which the blind reward-only "
                     "agent touched 1 / 1 / 1 too (it touched 2 / 2 / 2; 1 / 1 / 1 before picking it up)."], \
        "seed 2's static scene was not evaluated: no note; each one's touch in seed 3's episode came before the pick"


def test_the_touches_by_post_side_count_each_agent_s_static_episodes_on_each_side(tmp_path, monkeypatch):
    """`--train S --touches-by post-side`: per task, the blind reward-only agent and each seed's evaluated snapshots,
    the static episodes placed and touched of those with the post on each side of the arm."""
    from experiments import obstacles
    from experiments.campaign import checkpoint_of

    monkeypatch.setattr(obstacles, "layouts", lambda env_id, seeds: {
        s: {"post-side": "-y" if s < 2 else "+y", "clear-way": "none"} for s in seeds})
    blind = obstacles.row_name(obstacles.AGENTS[obstacles.BLIND])
    name = checkpoint_of(obstacles.training_run("shipped", 1, None, "sac", 0.5)).parent.name
    for kind in ("ceiling", "window", "flooring"):
        for row, touched in ((blind, {0, 1, 2}), (f"{name}_candidate_100", {0}), (f"{name}_candidate_300", {2})):
            (tmp_path / f"{row}_static_{kind}.json").write_text(json.dumps({"episodes": [
                {"seed": s, "collided": s in touched, "placed": s == 3} for s in range(4)]}))
    table = obstacles.touches_by("post-side", "shipped", "sac", 0.5, tmp_path)
    assert table[0] == ("| task | agent | post side -y: placed / touched / episodes | post side +y: placed / touched / "
                        "episodes |")
    rows = table[2:]
    assert rows[:3] == ["| ceiling | scratch general agent (reward alone, shipped) | 0 / 2 / 2 | 1 / 1 / 2 |",
                        "| ceiling | seed 1 at 100 env steps | 0 / 1 / 2 | 1 / 0 / 2 |",
                        "| ceiling | seed 1 at 300 env steps | 0 / 0 / 2 | 1 / 1 / 2 |"], "seed 1's snapshots; seed 2 not there"
    assert len(rows) == 9
    by_way = obstacles.touches_by("clear-way", "shipped", "sac", 0.5, tmp_path)
    assert by_way[2] == "| ceiling | scratch general agent (reward alone, shipped) | 0 / 0 / 0 | 0 / 0 / 0 | 1 / 3 / 4 |"


def test_the_reach_touches_count_which_way_the_turret_turned_where_each_agent_touched_before_the_pick(
        tmp_path, monkeypatch):
    """`--train S --reach-touches`: per task, the blind reward-only agent and each seed's latest evaluated snapshot,
    only the static episodes touched before the pick are replayed (`first_touches`), and those whose replay touched
    before the pick too counted by the turret's way against the reach's side, with their control steps."""
    from experiments import obstacles
    from experiments.campaign import checkpoint_of

    replayed = []

    def first_touches(checkpoint, env_id, seeds):
        replayed.append((Path(checkpoint).name, env_id, seeds))
        return [{"seed": s, "step": 10 * (s + 1), "touched": True, "picked": s == 1, "turret": -1.0, "toward": s == 0}
                for s in seeds]

    monkeypatch.setattr(obstacles, "first_touches", first_touches)
    blind = obstacles.row_name(obstacles.AGENTS[obstacles.BLIND])
    name = checkpoint_of(obstacles.training_run("shipped", 1, None, "sac", 0.5)).parent.name
    for kind in ("ceiling", "window", "flooring"):
        for row, touched in ((blind, {0, 1, 2}), (f"{name}_candidate_300", set())):
            (tmp_path / f"{row}_static_{kind}.json").write_text(json.dumps({"episodes": [
                {"seed": s, "collided": s in touched, "picked": s == 2} for s in range(4)]}))
    rows = obstacles.reach_touches("shipped", "sac", 0.5, tmp_path)[2:]
    assert rows[:2] == ["| ceiling | scratch general agent (reward alone, shipped) | 2 | 1 | 1 | 0 | 10 (10-10) |",
                        "| ceiling | seed 1 at 300 env steps | 0 | 0 | 0 | 0 | - |"], \
        "seed 1's replay picked its element up before its touch: not counted"
    assert len(rows) == 6 and replayed[0] == ("scratch_general_agent.pt", "CeilingInstallation-v1", [0, 1])
    assert len(replayed) == 3, "an agent without touches before the pick replays nothing"


def test_a_replayed_episode_is_the_evaluated_one_to_its_first_touch():
    """`first_touches` on the blind reward-only agent's first window episode that touched before the pick (its
    evaluation JSON): the replay touches before the pick too, within a control step of the evaluated episode's end
    (the physics carries state from one episode to the next), the turret turned there."""
    from experiments import obstacles

    episodes = json.loads((Path("docs/data/obstacles") / "scratch_general_agent_static_window.json").read_text())
    first = next(e for e in episodes["episodes"] if e["collided"] and not e["picked"])
    [found] = obstacles.first_touches(obstacles.AGENTS[obstacles.BLIND], "WindowInstallation-v1", [first["seed"]])
    assert found["seed"] == first["seed"] and found["touched"] and not found["picked"]
    assert abs(found["step"] - first["length"]) <= 1
    assert abs(found["turret"]) > 0.1 and isinstance(found["toward"], bool)

def test_the_layouts_of_a_scene_name_the_post_s_side_and_the_ways_the_reward_finds_clear():
    """`layouts` (what `--touches-by` groups by) on real window scenes: each seed's post side is the sign of its
    post's y, its clear way the one `CarryGeometry.clear_ways` gives for its goal slot's start paths, and whether the
    episode searched a via around the obstacles."""
    from experiments.obstacles import LAYOUT_GROUPS, layouts

    found = layouts("WindowInstallation-v1", list(range(6)))
    env = make_env("WindowInstallation-v1", obstacles="static")
    u = env.unwrapped
    for seed, layout in found.items():
        env.reset(seed=seed)
        assert layout["post-side"] == ("-y" if float(u.obstacle_layout[0, 5]) < 0 else "+y")
        assert layout["clear-way"] in LAYOUT_GROUPS["clear-way"]
        ways = u.obstacle_ways()
        clear = ways.clear & ~ways.searched  # the site's start paths: a layout's class is theirs
        usable_clear = bool((u.geometry.paths["usable"][u.task_id, u.goal_slot] & clear).any())
        assert (layout["clear-way"] == "a usable path") == usable_clear
        assert (layout["clear-way"] == "none") == (not bool(u.geometry.clear_ways(u.task_id, u.goal_slot, clear).any()))
        assert (layout["searched-way"] == "a via searched") == bool(ways.searched.any())
    env.close()


def test_an_evaluation_without_write_results_leaves_results_and_the_summary_json_as_they_are(tmp_path, monkeypatch):
    """`--no-write-results` (a snapshot evaluated on its own) prints its table and writes neither RESULTS' section
    nor summary.json, which the project summary reads: an evaluation of fewer agents does not replace the full one."""
    from experiments import obstacles

    expert = dict(placed=True, collisions=0, steps=10, planning_time=0.1, replans=0, escapes=0, waited_steps=0)
    agent = dict(placed=True, collided=False, length=10, policy_time_s=0.01)
    monkeypatch.setattr(obstacles, "run_row", lambda pool, path, fn, jobs, seeds, desc, checkpoint=None: [
        dict(expert if fn is obstacles._expert_episode else agent, seed=s) for s in seeds])
    results, versions = tmp_path / "RESULTS.md", tmp_path / "versions.md"
    results.write_text("kept\n")
    monkeypatch.setattr(obstacles, "RESULTS_PATH", results)
    monkeypatch.setattr(obstacles, "VERSIONS_PATH", versions)
    earlier, today = ("shipped", "sac", 1.0, 3, 1, 100), ("shipped", "sac", 1.0, obstacles.OBSTACLE_REWARD, 1, 200)
    monkeypatch.setattr(obstacles, "SHOWN", (earlier, today))
    trained = {obstacles.trained_label(*shown): f"{shown[3]}.pt" for shown in (earlier, today)}
    args = dict(episodes=2, workers=1, out=tmp_path, agents={"an agent": "a/b.pt", **trained})
    rows = obstacles.main(obstacles.Args(**args, write_results=False))
    assert "an agent | moving (solvable seeds)" in rows
    assert results.read_text() == "kept\n" and not (tmp_path / "summary.json").exists() and not versions.exists()
    obstacles.main(obstacles.Args(**args))
    written = json.loads((tmp_path / "summary.json").read_text())["rows"]
    assert set(written) == set(rows) and "an agent | none (solvable seeds)" in written
    assert "obstacles, zero-shot" in results.read_text()
    # RESULTS shows today's version beside the agents; the experiment page every version's snapshot, not the others
    old_label, today_label = trained
    assert today_label in results.read_text() and old_label not in results.read_text()
    assert {old_label, today_label, "planning expert"} <= {line.split(" | ")[0][2:]
                                                            for line in versions.read_text().splitlines()}
    assert "an agent" not in versions.read_text()


def test_the_results_table_of_one_scene_has_a_row_per_agent_and_the_full_one_every_scene():
    from experiments import obstacles

    tasks = list(obstacles.PAPER_TASK_ENV_IDS.values())
    result = obstacles.summarize([dict(placed=True, collided=False, length=10, policy_time_s=0.01)], False)
    rows = {(agent, f"{scene} (solvable seeds)"): {t: result for t in tasks}
            for agent in ("agent A", "agent B") for scene in obstacles.SCENES}
    moving = obstacles.table(rows, "moving").splitlines()
    full = obstacles.table(rows).splitlines()
    assert [line.split(" | ")[0] for line in moving[2:]] == ["| agent A", "| agent B"]
    assert moving[0].count("|") == full[0].count("|") - 1 and len(full) == 2 + 2 * len(obstacles.SCENES)
    assert all(line.count("|") == moving[0].count("|") for line in moving)
    assert "moving" not in "".join(moving) and "100.0 [" in moving[2]


def test_the_carry_course_of_an_episode_says_whether_the_carry_fell_and_how_long_it_paid_nothing():
    """`carry_course` (what `--carry-along-expert` reports per episode): the rank correlation of the carry distance
    with the step is -1 where it falls all the way and +1 where it rises; `beyond` counts the steps past the carry
    range, where the carry term pays 0."""
    from experiments.obstacles import carry_course, rank_correlation

    assert rank_correlation([5.0, 4.0, 2.0, 1.0]) == pytest.approx(-1.0)
    assert rank_correlation([1.0, 2.0, 4.0]) == pytest.approx(1.0)
    assert rank_correlation([1.0, 2.0]) == 0.0
    course = carry_course([6.0, 13.0, 15.0, 3.0, 1.0], carry_range=12.0)
    assert course == dict(rho=pytest.approx(-0.6), beyond=pytest.approx(0.4), first=6.0, most=15.0)


def test_the_carry_along_the_expert_is_measured_per_clear_way_and_scene_on_the_seeds_it_solved(tmp_path, monkeypatch):
    """`--carry-along-expert`: one row per clear-way class and scene (the site as built, the static obstacles), each
    over the expert's placed episodes of the seeds it solved (a seed it did not solve is not tried)."""
    from experiments import obstacles

    monkeypatch.setattr(obstacles, "PAPER_TASK_ENV_IDS", {"flooring": "Flooring-v1"})
    episodes = [dict(seed=1_000_000, placed=True), dict(seed=1_000_001, placed=False), dict(seed=1_000_005, placed=True)]
    (tmp_path / "expert_static_flooring.json").write_text(json.dumps({"episodes": episodes}))
    rows = [line.split(" | ") for line in obstacles.carry_along_expert(tmp_path, per_class=1)[2:]]
    assert [(r[1], r[2]) for r in rows] == [("a usable path", "none"), ("a usable path", "static"),
                                            ("a detour only", "none"), ("a detour only", "static")]
    for r in rows:
        assert r[3] == "1 of 1"
        median, worst = (float(x.strip("()")) for x in r[4].split())
        assert -1 <= median <= worst <= 1
        first, most = (float(x) for x in r[6].rstrip(" |").split(" / "))
        assert 0 <= first <= most
