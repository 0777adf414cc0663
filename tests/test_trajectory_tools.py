"""ManiSkill's own trajectory tools on the construction tasks: the state dict's layout and round trip,
replay by env states, and control mode conversion of a recorded expert episode
(`python scripts/replay_trajectory.py`, i.e. `python -m mani_skill.trajectory.replay_trajectory`)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from ms_construction.envs import ENV_IDS

from tests.helpers import PLAN_TRIES, SLOW_MACHINE_RRT_TIME, make_env

ROOT = Path(__file__).resolve().parents[1]
EXPERT_ENV = "Flooring-v1"
TASK_KEYS = ("task_id", "goal_slot", "held", "picked", "hold_pose_in_tcp", "tolerances")


def _leaves(d: dict, prefix: str = ""):
    for key, value in d.items():
        if isinstance(value, dict):
            yield from _leaves(value, f"{prefix}{key}/")
        else:
            yield f"{prefix}{key}", value


def _run(*args: str, timeout: int = 600) -> str:
    out = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, f"{' '.join(args)} failed:\n{out.stdout[-2000:]}\n{out.stderr[-4000:]}"
    return out.stdout + out.stderr


# ----------------------------------------------------------------------------------------------- #
# state dict
# ----------------------------------------------------------------------------------------------- #
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_state_leaves_are_batched_2d_and_set_state_dict_restores_them_exactly(env_id):
    env = make_env(env_id, control_mode="pd_joint_delta_pos")
    u = env.unwrapped
    env.reset(seed=1)
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        env.step(torch.rand(1, 6, generator=gen) * 2 - 1)
    state = u.get_state_dict()
    # a held, picked element on another slot and other tolerances: nothing at its reset value
    state["task"]["held"][:] = True
    state["task"]["picked"][:] = True
    state["task"]["goal_slot"][:] = (state["task"]["goal_slot"] + 1) % u._goal_table.shape[1]
    state["task"]["hold_pose_in_tcp"][:] = torch.tensor([[0.01, -0.02, 0.03, 0.0, 0.0, 0.0, 1.0]])
    state["task"]["tolerances"][:] = torch.tensor([[0.25, 0.2, 30.0]])
    u.set_state_dict(state)
    saved = u.get_state_dict()
    info = {k: v.clone() for k, v in u.evaluate().items()}

    leaves = dict(_leaves(saved))
    assert {f"task/{k}" for k in TASK_KEYS} <= set(leaves)
    for name, value in leaves.items():
        assert value.ndim == 2 and value.shape[0] == u.num_envs, f"{name}: shape {tuple(value.shape)}"
    assert all(saved["task"][k].shape[1] == 1 for k in ("task_id", "goal_slot", "held", "picked"))

    # somewhere else entirely (for the general task: another task type), then back
    for seed in range(2, 40):
        env.reset(seed=seed)
        if len(u.TASKS) == 1 or int(u.task_id[0]) != int(saved["task"]["task_id"][0, 0]):
            break
    assert not torch.equal(u.get_state_dict()["task"]["held"], saved["task"]["held"])
    u.set_state_dict(saved)
    restored = dict(_leaves(u.get_state_dict()))
    assert restored.keys() == leaves.keys()
    for name, value in leaves.items():
        assert restored[name].dtype == value.dtype and torch.equal(restored[name], value), name
    for key, value in u.evaluate().items():
        if key != "first_grasp":  # an event of the last step, not state
            assert torch.equal(value, info[key]), key

    # the earlier 1-D layout of the one-column leaves, and one env's rows as the replay tool gives
    # them (a trajectory step: every leaf without its env dimension), restore the same task state
    for layout in ("1-D", "row"):
        env.reset(seed=0)
        task = {k: v[:, 0] if layout == "1-D" and v.shape[1] == 1 else v for k, v in saved["task"].items()}
        if layout == "row":
            task = {k: v[0].numpy() for k, v in task.items()}
        u.set_state_dict(dict(saved, task=task))
        for key in TASK_KEYS:
            assert torch.equal(u.get_state_dict()["task"][key], saved["task"][key]), (layout, key)
    with pytest.raises(ValueError, match="hold_pose_in_tcp"):
        u.set_state_dict(dict(saved, task=dict(saved["task"], hold_pose_in_tcp=torch.zeros(1, 6))))
    env.close()


# ----------------------------------------------------------------------------------------------- #
# ManiSkill's replay tool on a recorded expert episode
# ----------------------------------------------------------------------------------------------- #
@pytest.fixture(scope="module")
def expert_traj(tmp_path_factory) -> Path:
    """One expert episode of Flooring-v1 (seed 0), recorded by scripts/run_expert.py. OMPL seeds its
    sampler from the clock: a run that does not place is run again (these tests are about the tool)."""
    out = tmp_path_factory.mktemp("expert")
    for _ in range(PLAN_TRIES):
        _run("scripts/run_expert.py", "--env-id", EXPERT_ENV, "--episodes", "1", "--seed", "0",
             "--save-trajectory", "--out", str(out), "--expert.rrt-time", str(SLOW_MACHINE_RRT_TIME))
        meta = json.loads((out / f"{EXPERT_ENV}.expert.json").read_text())
        if meta["episodes"][0]["success"]:
            return out / f"{EXPERT_ENV}.expert.h5"
    pytest.fail(f"the expert did not place Flooring-v1 seed 0 in {PLAN_TRIES} runs")


def _copy(traj: Path, dest: Path) -> Path:
    for suffix in (".h5", ".json"):
        shutil.copy(traj.with_suffix(suffix), dest / traj.with_suffix(suffix).name)
    return dest / traj.name


def _replay(traj: Path, *options: str) -> str:
    return _run("scripts/replay_trajectory.py", "--traj-path", str(traj), "--save-traj", *options)


def _episode(h5_path: Path) -> tuple[dict, dict]:
    """(the json's only episode, the h5's traj_0 as arrays)."""
    meta = json.loads(h5_path.with_suffix(".json").read_text())
    assert len(meta["episodes"]) == 1
    with h5py.File(h5_path) as f:
        assert "traj_0" in f, f"{h5_path.name}: no trajectory saved (the replay did not reach success)"
        traj = {}
        f["traj_0"].visititems(lambda name, d: traj.update({name: np.asarray(d)}) if isinstance(d, h5py.Dataset) else None)
    return meta["episodes"][0], traj


def test_replay_by_env_states_saves_the_episode_with_its_success(expert_traj, tmp_path):
    traj = _copy(expert_traj, tmp_path)
    log = _replay(traj, "--use-env-states", "-o", "state")
    assert "1/1=100.00% demos saved" in log, log[-2000:]
    original, orig = _episode(traj)
    episode, replayed = _episode(tmp_path / f"{EXPERT_ENV}.state.pd_joint_pos.physx_cpu.h5")
    assert episode["success"] and episode["control_mode"] == "pd_joint_pos"
    assert episode["elapsed_steps"] == original["elapsed_steps"]
    np.testing.assert_array_equal(replayed["actions"], orig["actions"])
    assert replayed["success"][-1] and replayed["success"].shape == orig["success"].shape
    # the state leaves the tool saved are [steps + 1, k], the task's included
    for key in TASK_KEYS:
        assert replayed[f"env_states/task/{key}"].ndim == 2
        assert len(replayed[f"env_states/task/{key}"]) == original["elapsed_steps"] + 1
    np.testing.assert_array_equal(replayed["env_states/task/task_id"], orig["env_states/task/task_id"])


@pytest.mark.parametrize("control_mode", ["pd_joint_delta_pos", "pd_ee_delta_pose"])
def test_converted_expert_episode_still_places_and_replays_from_its_actions(expert_traj, tmp_path, control_mode):
    traj = _copy(expert_traj, tmp_path)
    log = _replay(traj, "--use-first-env-state", "-c", control_mode, "-o", "none")
    assert "1/1=100.00% demos saved" in log, log[-2000:]
    converted_path = tmp_path / f"{EXPERT_ENV}.none.{control_mode}.physx_cpu.h5"
    episode, converted = _episode(converted_path)
    assert episode["success"] and episode["control_mode"] == control_mode
    assert converted["success"][-1]
    actions = converted["actions"]
    assert actions.shape == (episode["elapsed_steps"], 6) and np.abs(actions).max() <= 1 + 1e-6  # normalized
    # the converted trajectory is a trajectory of its own: its actions alone, from the seeded
    # reset, place again (no --discard-timeout: an ee step is capped at 5 cm, so the converted
    # pd_ee_delta_pose episode can outlast the 250-step limit)
    log = _replay(converted_path, "-o", "state")  # (another obs mode: another output file)
    assert "1/1=100.00% demos saved" in log, log[-2000:]
    episode, replayed = _episode(tmp_path / f"{EXPERT_ENV}.state.{control_mode}.physx_cpu.h5")
    assert episode["success"] and replayed["success"][-1]
    np.testing.assert_array_equal(replayed["actions"], actions)
