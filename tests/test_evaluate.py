"""scripts/evaluate.py on the shipped general agent: the JSON it writes, the places it makes, its errors."""

import json

import gymnasium as gym
import pytest
import torch

from baselines.ppo import evaluation
from baselines.ppo.checkpoints import Progress, load_policy, save_checkpoint
from baselines.ppo.networks import Agent
from baselines.ppo.ppo import Args as PPOArgs
from ms_construction.envs.state_layout import STATE_SIZE
from ms_construction.vector_env import CPUVectorEnv


SHIPPED_EPISODES = 80
SHIPPED_MAX_FAILURES = 1


def test_shipped_general_agent_places_at_its_published_rate(tmp_path):
    """The main job's agent on SHIPPED_EPISODES fixed test seeds per task fails at most SHIPPED_MAX_FAILURES.

    Why these numbers: docs/RESULTS.md publishes 99.5-100% placed per task (50,000 steps each). With 80 episodes
    and at most 1 failure, an agent that places 99.5% passes on unseen seeds 94% of the time, and one 5 points
    worse (94.5%) passes only 6% of the time (binomial: P(X <= 1), X ~ Bin(80, 0.055) = 0.061); at 90% it passes
    0.2% of the time. The seeds are fixed (physx_cpu replays them exactly), so the shipped agent's outcome here
    is the same on every run; the slack of one failure keeps a machine whose floating point differs from
    failing on one borderline episode."""
    out = tmp_path / "eval.json"
    results = evaluation.main(evaluation.Args(all=True, episodes=SHIPPED_EPISODES, seed=1_000_000, json=out))
    data = json.loads(out.read_text())
    assert set(data["tasks"]) == {"CeilingInstallation-v1", "WindowInstallation-v1", "Flooring-v1"}
    for env_id, r in data["tasks"].items():
        assert r["episodes"] == SHIPPED_EPISODES and len(r["episode_results"]) == SHIPPED_EPISODES
        for key in ("pick_success", "place_success"):
            lo, hi = r[f"{key}_ci95"]
            assert (lo, hi) == pytest.approx(evaluation.wilson(round(r[key] * SHIPPED_EPISODES), SHIPPED_EPISODES))
        assert r["mean_length"] <= 250 and isinstance(r["mean_return"], float)
        failures = [e["seed"] for e in r["episode_results"] if not e["placed"]]
        assert len(failures) <= SHIPPED_MAX_FAILURES, (env_id, failures)
        assert r["pick_success"] >= r["place_success"]
    assert results["Flooring-v1"]["place_success"] == data["tasks"]["Flooring-v1"]["place_success"]


def test_single_task_json_has_the_fields_at_top_level(tmp_path):
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=2, seed=1_000_000, json=out, workers=1))
    data = json.loads(out.read_text())
    for key in ("pick_success", "place_success", "episodes", "mean_return", "mean_length",
                "pick_success_ci95", "place_success_ci95"):
        assert key in data
    assert data["episodes"] == 2 and [e["seed"] for e in data["episode_results"]] == [1_000_000, 1_000_001]
    assert data["command"] == (f"python scripts/evaluate.py --checkpoint {evaluation.DEFAULT_CHECKPOINT} --env-id "
                               f"Flooring-v1 --episodes 2 --seed 1000000 --json {out} --workers 1")


def test_the_command_written_down_builds_the_same_args():
    """An evaluation run from code (experiments/) records the scripts/evaluate.py command that repeats it: parsed
    back, that command gives the same Args."""
    import shlex

    import tyro

    args = evaluation.Args(all=True, steps=50_000, json=None, goal_slots=(0, 2), sample_actions=True,
                           beside=("the clone=docs/data/x y.json",), curriculum_stage="cp2")
    argv = shlex.split(evaluation.command_of(args))
    assert argv[:2] == ["python", "scripts/evaluate.py"]
    assert tyro.cli(evaluation.Args, args=argv[2:]) == args
    assert evaluation.command_of(evaluation.Args()) == ("python scripts/evaluate.py --checkpoint "
                                                         f"{evaluation.DEFAULT_CHECKPOINT} --seed 1000000")


def test_training_and_scripts_evaluate_py_run_the_same_episode_loop(tmp_path):
    """ppo.py's evaluation envs (worker processes behind ManiSkillVectorEnv's interface) and
    scripts/evaluate.py's worker (ManiSkillVectorEnv on one env, no auto reset) play the same seeded
    episodes through `run_episodes` and report the same thing."""
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=2, seed=1_000_000, json=out, workers=1))
    by_script = json.loads(out.read_text())["episode_results"]
    agent, env_kwargs = load_policy(evaluation.DEFAULT_CHECKPOINT, "Flooring-v1")
    # one env, as scripts/evaluate.py's workers: the policy's batch size changes its last float bits
    envs = CPUVectorEnv("Flooring-v1", 1, dict(obs_mode="state", **env_kwargs, reward_mode="sparse",
                                               curriculum_stage="cp4"))
    try:
        in_training = [e for seed in (1_000_000, 1_000_001) for e in evaluation.run_episodes(agent, envs, 250, seed=seed)]
        summary = evaluation.evaluate_envs(agent, envs, 250, seed=1_000_001)
    finally:
        envs.close()
    assert [e["seed"] for e in in_training] == [1_000_000, 1_000_001]
    for a, b in zip(by_script, in_training):
        for key in ("task_id", "goal_slot", "picked", "placed", "length", "held_at_end"):
            assert a[key] == b[key], key
        for key in ("ret", "final_place_dist", "final_place_angle_deg"):
            assert a[key] == pytest.approx(b[key], abs=1e-5), key
    assert summary["eval_episodes"] == 1 and summary["eval_place_success"] == float(by_script[1]["placed"])
    # each record names its goal slot: the one a reset with its seed draws
    env = gym.make("Flooring-v1", obs_mode="state")
    for e in by_script:
        env.reset(seed=e["seed"])
        assert e["goal_slot"] == int(env.unwrapped.goal_slot[0])
    env.close()


def test_the_recorded_episode_is_one_video_named_by_task_and_seed(tmp_path):
    """`--video-dir`: the first episode of the task as one video, every frame of it and no more."""
    import imageio.v2 as iio

    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, seed=1_000_000, json=out, workers=1,
                                    video_dir=tmp_path / "videos"))
    [video] = (tmp_path / "videos").glob("*.mp4")
    assert video.name == "Flooring-v1_seed1000000.mp4"
    length = json.loads(out.read_text())["episode_results"][0]["length"]
    assert iio.get_reader(video).count_frames() == length + 1  # the reset's frame and one per step


def test_a_checkpoint_of_the_wrong_shape_is_a_clear_error(tmp_path):
    path = tmp_path / "wrong.pt"
    agent = Agent(40, 6, 32)
    save_checkpoint(path, PPOArgs.of(hidden_size=32, control_mode="pd_joint_delta_pos"), Progress(), agent,
                    torch.optim.Adam(agent.parameters()), None, None, 40, 6)
    with pytest.raises(SystemExit, match=rf"does not fit Flooring-v1.*observations of size 40.*has {STATE_SIZE}"):
        evaluation.main(evaluation.Args(checkpoint=path, env_id="Flooring-v1", episodes=1))


def test_goal_slots_evaluate_only_those_openings_and_the_json_breaks_placing_down_by_slot(tmp_path):
    out = tmp_path / "eval.json"
    evaluation.main(evaluation.Args(env_id="ConstructionPickPlace-v1", episodes=6, seed=1_000_000, json=out, workers=1,
                                    goal_slots=(1,)))
    data = json.loads(out.read_text())
    assert {e["goal_slot"] for e in data["episode_results"]} == {1}
    assert list(data["place_success_by_goal_slot"]) == ["1"]
    assert data["place_success_by_goal_slot"]["1"] == data["place_success"]
    with pytest.raises(SystemExit, match="distinct indices in 0..2"):
        evaluation.main(evaluation.Args(env_id="Flooring-v1", goal_slots=(3,)))


def test_bad_arguments_are_refused_with_the_allowed_values(tmp_path):
    with pytest.raises(SystemExit, match="allowed: ConstructionPickPlace-v1"):
        evaluation.main(evaluation.Args(env_id="Roofing-v1"))
    with pytest.raises(SystemExit, match="checkpoint not found"):
        evaluation.main(evaluation.Args(checkpoint=tmp_path / "none.pt", env_id="Flooring-v1"))


@pytest.mark.parametrize("k,n", [(0, 10), (10, 10), (7, 10), (95, 100)])
def test_wilson_interval_holds_the_estimate(k, n):
    lo, hi = evaluation.wilson(k, n)
    assert 0 <= lo <= k / n <= hi <= 1 and hi - lo < 0.5


@pytest.mark.parametrize("k,n,lo,hi", [(81, 263, 0.2553, 0.3662), (15, 148, 0.0624, 0.1605), (1, 29, 0.0061, 0.1718),
                                       (0, 20, 0.0, 0.1611)])
def test_wilson_interval_matches_newcombe_s_published_values(k, n, lo, hi):
    """Newcombe (1998), Statistics in Medicine 17:857-872, Table I, method 3 (score interval without continuity
    correction). A Wald interval gives 0.2522-0.3638 and 0.0527-0.1500 for the first two: it would fail here."""
    got = evaluation.wilson(k, n)
    assert got == pytest.approx((lo, hi), abs=6e-5)


def test_sampled_actions_are_seeded_by_the_episode_and_stay_out_of_the_published_table(tmp_path):
    """--sample-actions (a diagnostic): the same seeds give the same episodes, other than the mean's."""
    runs = []
    for name, sample in (("a", True), ("b", True), ("mean", False)):
        out = tmp_path / f"{name}.json"
        evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=2, seed=1_000_000, json=out, workers=1,
                                        sample_actions=sample))
        runs.append(json.loads(out.read_text()))
    lengths = [[(e["length"], e["final_place_dist"]) for e in r["episode_results"]] for r in runs]
    assert runs[0]["sample_actions"] and not runs[2]["sample_actions"]
    assert lengths[0] == lengths[1], "sampled episodes are reproducible"
    assert lengths[0] != lengths[2], "sampled actions are not the policy's mean"
    with pytest.raises(SystemExit, match="diagnostic"):
        evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, sample_actions=True, write_results=True))


def test_a_longer_step_limit_tells_late_arrivals_and_stays_out_of_the_published_table(tmp_path):
    """--max-episode-steps (a diagnostic): episodes run to the limit given; what placed within the task's own
    250 steps is counted beside."""
    short = evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, seed=1_000_000, workers=1,
                                            max_episode_steps=20))["Flooring-v1"]
    assert short["episode_results"][0]["length"] == 20 and short["place_success"] == 0
    assert short["place_success_within_limit"] == 0 and short["task_step_limit"] == 250
    longer = evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, seed=1_000_000, workers=1,
                                             max_episode_steps=300))["Flooring-v1"]
    ordinary = evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, seed=1_000_000, workers=1))["Flooring-v1"]
    assert longer["episode_results"][0]["length"] == ordinary["episode_results"][0]["length"] <= 250
    assert longer["place_success_within_limit"] == ordinary["place_success"] == 1.0
    assert "place_success_within_limit" not in ordinary
    for bad in (dict(write_results=True), dict(steps=1000), dict(max_episode_steps=0)):
        with pytest.raises(SystemExit, match="max-episode-steps"):
            evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, **{"max_episode_steps": 300, **bad}))


def test_an_action_gain_speeds_the_policy_up_and_stays_out_of_the_published_table(tmp_path):
    """--action-gain (a diagnostic): the policy's actions times the gain; a faster arm places the same panel sooner."""
    run = lambda **kw: evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, seed=1_000_000, workers=1,  # noqa: E731
                                                       json=tmp_path / "gain.json", **kw))["Flooring-v1"]["episode_results"][0]
    ordinary, faster = run(), run(action_gain=1.5)
    assert json.loads((tmp_path / "gain.json").read_text())["action_gain"] == 1.5
    assert faster["placed"] and faster["length"] < ordinary["length"]
    for bad in (dict(action_gain=0.0), dict(action_gain=1.5, write_results=True)):
        with pytest.raises(SystemExit, match="action-gain"):
            evaluation.main(evaluation.Args(env_id="Flooring-v1", episodes=1, **bad))


def test_earlier_agents_rows_come_from_their_json_and_a_bad_spec_is_refused(tmp_path):
    r = dict(episodes=330, pick_success=1.0, pick_success_ci95=[0.988, 1.0], place_success=0.979,
             place_success_ci95=[0.957, 0.99])
    path = tmp_path / "clone.json"
    path.write_text(json.dumps({"command": "python scripts/evaluate.py --all", "tasks": {"Flooring-v1": r}}))
    beside = evaluation.read_beside((f"the clone={path}",))
    assert "| the clone | Flooring-v1 | 330 | 100.0 [98.8, 100.0] | 97.9 [95.7, 99.0] |" in evaluation.beside_table(beside)
    for spec in ("no-equals-sign", f"x={tmp_path / 'missing.json'}"):
        with pytest.raises(SystemExit, match="--beside"):
            evaluation.read_beside((spec,))


def test_the_written_section_tables_each_agent_s_failures_by_kind(tmp_path, monkeypatch):
    def task(failed: list) -> dict:
        episodes = [dict(seed=i, placed=True, held_at_end=True, final_place_dist=0.05, final_place_angle_deg=2.0)
                    for i in range(8)] + failed
        n, placed = len(episodes), sum(e["placed"] for e in episodes)
        return dict(episodes=n, pick_success=1.0, pick_success_ci95=evaluation.wilson(n, n), place_success=placed / n,
                    place_success_ci95=evaluation.wilson(placed, n), mean_return=2.0, mean_length=150.0,
                    policy_time_per_episode_s=0.05, episode_results=episodes)

    lost = dict(seed=9, placed=False, held_at_end=True, final_place_dist=1.2, final_place_angle_deg=90.0)
    dropped = dict(seed=9, placed=False, held_at_end=False, final_place_dist=0.6, final_place_angle_deg=10.0)
    ours = {"WindowInstallation-v1": task([lost]), "Flooring-v1": task([])}
    earlier = tmp_path / "clone.json"
    earlier.write_text(json.dumps({"command": "python scripts/evaluate.py --all", "tasks": {"WindowInstallation-v1": task([dropped])}}))
    monkeypatch.setattr(evaluation, "RESULTS_PATH", tmp_path / "RESULTS.md")
    evaluation.write_results(evaluation.Args(all=True), ours, evaluation.read_beside((f"the clone={earlier}",)))
    text = (tmp_path / "RESULTS.md").read_text()
    assert "| agent | WindowInstallation-v1 | Flooring-v1 |" in text
    assert "| this agent | 1 short and turned (1.2-1.2 m, 90-90 deg) | none |" in text
    assert "| the clone | 1 dropped (0.6-0.6 m) | - |" in text
