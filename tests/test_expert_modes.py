"""experiments/expert_modes.py: the expert's final arm configurations per goal slot, and an agent's failures per slot."""

import json
from pathlib import Path

import gymnasium as gym
import h5py
import numpy as np
import pytest

import ms_construction  # noqa: F401

from experiments import expert_modes


def write_trajectories(path: Path, episodes: list[tuple[int, list[float], float, bool]]) -> None:
    """ManiSkill's trajectory layout, as RecordEpisode writes it: per episode the arm's state (its qpos at
    13:19) over the steps, the task state's goal slot and the success flags."""
    with h5py.File(path, "w") as f:
        for i, (slot, final_q, turn, success) in enumerate(episodes):
            steps = 5
            arm = np.zeros((steps, 25), dtype=np.float32)
            arm[:, 13:19] = np.linspace(np.zeros(6), final_q, steps)
            arm[2, 13] = turn  # the base joint's largest excursion, on the way
            ep = f.create_group(f"traj_{i}")
            ep.create_dataset("env_states/articulations/construction_arm", data=arm)
            ep.create_dataset("env_states/task/goal_slot", data=np.full((steps, 1), slot))
            ep.create_dataset("success", data=np.array([False] * (steps - 1) + [success]))


def test_the_expert_s_branches_and_turns_per_goal_slot(tmp_path):
    a, flipped = [-0.73, 0.57, -0.07, -1.08, -0.86, -0.84], [-0.73, 0.57, -0.07, 2.06, 0.86, 2.47]
    path = tmp_path / "WindowInstallation-v1.expert.h5"
    write_trajectories(path, [(0, a, 3.1, True), (0, flipped, -3.1, True), (0, [x + 0.1 for x in a], 3.1, True),
                              (1, a, 3.1, True), (1, flipped, 3.1, False)])  # a failed episode is not counted
    slots = expert_modes.modes(path, tol=0.5)
    assert [b["count"] for b in slots["0"]["final_branches"]] == [2, 1]
    assert slots["0"]["final_branches"][1]["q"] == flipped
    assert slots["0"]["base_turn"] == {"+": 2, "-": 1}
    assert slots["1"]["episodes"] == 1 and len(slots["1"]["final_branches"]) == 1


def test_an_agent_s_failures_are_counted_per_goal_slot_and_written_beside_the_expert_s(tmp_path):
    env = gym.make("WindowInstallation-v1", obs_mode="state", num_envs=1, sim_backend="physx_cpu")
    slot_of = {}
    for seed in range(1_000_000, 1_000_006):
        env.reset(seed=seed)
        slot_of[seed] = str(int(env.unwrapped.goal_slot.item()))
    env.close()
    episodes = [dict(seed=seed, placed=seed % 2 == 0) for seed in slot_of]
    (tmp_path / "agent.json").write_text(json.dumps({"tasks": {"WindowInstallation-v1": {"episode_results": episodes}}}))
    counts = expert_modes.failures_by_slot("WindowInstallation-v1", episodes)
    assert sum(c[0] for c in counts.values()) == 6 and sum(c[1] for c in counts.values()) == 3
    for slot, (n, failed) in counts.items():
        assert n == sum(s == slot for s in slot_of.values())
        assert failed == sum(s == slot and seed % 2 for seed, s in slot_of.items())

    traj = tmp_path / "WindowInstallation-v1.expert.h5"
    write_trajectories(traj, [(int(s), [0.0] * 6, 1.0, True) for s in sorted(set(slot_of.values()))])
    results = tmp_path / "RESULTS.md"
    out = expert_modes.main(expert_modes.Args(traj=(traj,), agent=(f"agent={tmp_path / 'agent.json'}",),
                                              write_results=True, results=results))
    assert out["WindowInstallation-v1"]["failed_by_slot"] == {"agent": counts}
    text = results.read_text()
    assert "<!-- begin expert-modes (generated) -->" in text and "| goal slot |" in text and "| agent |" in text
    with pytest.raises(SystemExit, match="LABEL=JSON"):
        expert_modes.main(expert_modes.Args(traj=(traj,), agent=("no-such-file",)))


def test_placed_per_slot_reads_the_record_s_slot_or_the_reset_s():
    """Records that name their goal slot are counted by it; older ones by the slot a reset with their seed draws."""
    named = [dict(seed=0, goal_slot=s, placed=p) for s, p in ((2, False), (0, True), (2, True), (0, True), (1, False))]
    assert expert_modes.placed_per_slot("WindowInstallation-v1", named) == "2/2, 0/1, 1/2"
    env = gym.make("WindowInstallation-v1", obs_mode="state", num_envs=1, sim_backend="physx_cpu")
    slots = []
    for seed in range(1_000_000, 1_000_006):
        env.reset(seed=seed)
        slots.append(int(env.unwrapped.goal_slot.item()))
    env.close()
    unnamed = [dict(seed=1_000_000 + i, placed=True) for i in range(6)]
    expected = ", ".join(f"{slots.count(s)}/{slots.count(s)}" for s in sorted(set(slots)))
    assert expert_modes.placed_per_slot("WindowInstallation-v1", unnamed) == expected
