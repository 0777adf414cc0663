"""experiments/unseen_openings.py: the recipe with goal openings held out of training, and its report."""

import json

import gymnasium as gym
import pytest
import torch

from baselines.ppo import ppo
from experiments import from_scratch as fs
from experiments import unseen_openings as uo
from ms_construction.envs import TASK_ENV_IDS


def test_the_run_is_the_recipe_with_the_held_out_openings_never_drawn_in_training(monkeypatch):
    run = uo.seed_run(3, num_envs=2)
    ppo.validate(run.args)
    recipe = fs.scratch_args(2, seed=3, exp_name="unseen_s3").flat()
    changed = {k for k, v in run.args.flat().items() if recipe[k] != v}
    assert changed == {"goal_slot_weights"} and "demonstrations: none" in run.method
    made = {}
    monkeypatch.setattr(ppo, "CPUVectorEnv", lambda env_id, n, kwargs, **_: made.setdefault(len(made), kwargs))
    ppo.make_envs(run.args, 2, torch.device("cpu"))
    ppo.make_envs(run.args, 2, torch.device("cpu"), eval_mode=True)
    drawn = []
    for kwargs in made.values():
        env = gym.make(run.args.env_id, num_envs=1, **kwargs)
        slots = set()
        for seed in range(40):
            env.reset(seed=seed)
            slots.add(int(env.unwrapped.goal_slot[0]))
        drawn.append(slots)
        env.close()
    training, evaluating = drawn
    assert training == set(uo.TRAINED) and evaluating == set(uo.TRAINED) | set(uo.HELD_OUT)


def test_the_report_tables_unseen_and_seen_openings_per_seed(tmp_path, monkeypatch):
    monkeypatch.setattr(uo, "EVAL_DIR", tmp_path)
    for seen, placed in ((False, 0.5), (True, 0.9)):
        tasks = {e: dict(place_success=placed, place_success_ci95=(placed - 0.1, placed + 0.05)) for e in TASK_ENV_IDS.values()}
        uo.evaluation_json(1, seen).write_text(json.dumps({"tasks": tasks}))
    body = uo.report(tmp_path / "RESULTS.md", seeds=(1, 2))
    assert "| 1 | never trained on (1) | 50.0 [40.0, 55.0] |" in body and "| 1 | trained on (0, 2) | 90.0" in body
    assert "unseen-openings" in (tmp_path / "RESULTS.md").read_text()
    with pytest.raises(SystemExit, match="--seed S"):
        uo.main(uo.Args())
