"""scripts/benchmark.py's command line: which trainings it measures and where their learner runs, the command it
records, where it writes."""

import pytest
import torch

import scripts.benchmark as bench


def test_trainings_default_to_every_training_and_reject_unknown_repeated_or_none():
    assert bench.trainings(bench.Args()) == [(steps, curiosity, "cpu") for steps, curiosity in bench.TRAINING]
    assert bench.trainings(bench.Args(trainings=("free-recipe", "free-none"))) == [("free", "recipe", "cpu"),
                                                                                  ("free", "none", "cpu")]
    with pytest.raises(SystemExit, match="unknown held-sac; allowed: free-none, free-icm"):
        bench.trainings(bench.Args(trainings=("free-recipe", "held-sac")))
    with pytest.raises(SystemExit, match="each once"):
        bench.trainings(bench.Args(trainings=("free-none", "free-none")))
    with pytest.raises(SystemExit, match="one or more"):
        bench.trainings(bench.Args(trainings=()))


def test_a_learner_on_the_gpu_is_asked_for_with_cuda_and_refused_without_a_gpu(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert bench.trainings(bench.Args(trainings=("free-recipe-cuda",))) == [("free", "recipe", "cuda")]
    with pytest.raises(SystemExit, match="unknown free-sac-cuda"):  # SAC's learner runs on the CPU only
        bench.trainings(bench.Args(trainings=("free-sac-cuda",)))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(SystemExit, match="needs a CUDA GPU"):
        bench.trainings(bench.Args(trainings=("free-recipe-cuda",)))


def test_sac_s_speed_and_split_are_its_rows_with_gradient_steps_in_them_as_the_recipe_trains(monkeypatch):
    from baselines.sac import sac
    from experiments.sac_recipe import sac_args

    seen = {}

    def main(a):
        seen.update(a=a)
        # rows every log_freq env steps: random actions (fast) until learning_starts, then gradient steps (slow); the
        # clock: 4 ms per env step in the envs, one gradient step per two env steps after learning_starts, 13 ms each
        rows = ["global_step,sps,env_s,update_s,updates"]
        for step in range(a.log_freq, a.total_timesteps + 1, a.log_freq):
            updates = max(0, step - a.learning_starts) // 2
            rows.append(f"{step},{1000 if step <= a.learning_starts else 50 + step // a.log_freq},{0.004 * step},"
                        f"{0.013 * updates},{updates}")
        path = bench.Path(a.log_dir) / a.exp_name / "progress.csv"
        path.parent.mkdir(parents=True)
        path.write_text("\n".join(rows) + "\n")

    monkeypatch.setattr(sac, "main", main)
    out = bench.sac_steps_per_second(3, 2)
    a, recipe = seen["a"], sac_args(1)
    assert (a.num_envs, a.eval_freq, a.save_model) == (2, 0, False)
    assert (a.utd, a.batch_size, a.reward_mode) == (recipe.utd, recipe.batch_size, recipe.reward_mode)
    # learning_starts 5,000 of rows of 2,000: the row at 6,000 straddles it; then 3 rows, at 8,000 / 10,000 / 12,000,
    # whose clock runs from the row at 6,000's
    assert a.total_timesteps == 12_000
    assert out == pytest.approx(dict(sps=55.0, num_envs=2, env_ms=4.0, update_ms=13.0, utd=0.5))


def test_sac_s_ceiling_is_its_gradient_steps_alone_and_its_share_is_of_the_same_round_s_simulation():
    rounds = [dict(env_ms=4.0, update_ms=10.0, utd=0.5), dict(env_ms=6.0, update_ms=20.0, utd=0.5)]
    table = bench.sac_table({2: rounds}, {2: [1000.0, 400.0]})
    row = table.splitlines()[-1].split(" | ")
    # ceilings 1 / (0.5 x 10 ms) = 200 and 1 / (0.5 x 20 ms) = 100 env steps/s; shares 200 / 1000 and 100 / 400
    assert row[1:6] == ["5.00", "15.0", "0.50", "12.50", "150"]
    assert row[6] == "0.23 (0.20-0.25) |"


@pytest.mark.parametrize("backend, learner, cuda", [("physx_cpu", None, False), ("physx_cpu", "cuda", True),
                                                    ("physx_cuda", None, True), ("physx_cpu", "cpu", False)])
def test_the_learner_runs_where_the_training_asks(monkeypatch, backend, learner, cuda):
    from baselines.ppo import ppo

    seen = {}

    def setup(run_args):
        seen["cuda"] = run_args.cuda
        raise RuntimeError("stop here")

    monkeypatch.setattr(ppo, "setup", setup)
    for curiosity in (None, "recipe"):
        with pytest.raises(RuntimeError, match="stop here"):
            bench.ppo_steps_per_second(1, backend, 2, curiosity=curiosity, learner=learner)
        assert seen["cuda"] is cuda, (curiosity, seen)


def test_recorded_command_names_what_differs_from_the_defaults_and_its_section_but_not_its_file():
    args = bench.Args(workers=(16,), trainings=("free-none", "free-recipe"), gpu=False, cpu_section="cpu-speed-16-cores",
                      out=bench.Path("/tmp/b.md"))
    assert bench.command(args) == ("python scripts/benchmark.py --workers 16 --trainings free-none free-recipe "
                                   "--no-gpu --cpu-section cpu-speed-16-cores")
    assert bench.command(bench.Args()) == "python scripts/benchmark.py"


def test_timing_counts_each_part_within_the_whole_a_call_inside_another_as_that_one_s_and_restores_the_methods(
        monkeypatch):
    ticks = iter(range(100))
    monkeypatch.setattr(bench.time, "perf_counter", lambda: float(next(ticks)))

    class Env:
        def make(self):
            return self.project()  # a first call's compilation: the start-up's

        def step(self):
            return self.obs() + self.project()

        def obs(self):
            return self.project()

        def project(self):
            return 1

    class Learner(Env):
        def whole(self):
            return self.make() + self.step() + self.obs()

    before = (Env.make, Env.step, Env.obs, Env.project, Learner.whole)
    spent = {}
    parts = [(Env, "make", "start"), (Learner, "step", "step"), (Env, "obs", "obs"), (Env, "project", "project"),
             (Learner, "whole", "whole")]
    with bench.timing(parts, spent, outer="whole", inner="project", apart="start"):
        assert Env().obs() == 1 and not spent, "outside the whole: not timed"
        assert Learner().whole() == 4
    assert (Env.make, Env.step, Env.obs, Env.project, Learner.whole) == before and "step" not in vars(Learner)
    # one tick per clock reading: whole 0-13 holds make 1-2 (its projection untimed), step 3-8 (its obs untimed, its
    # projections 4-5 and 6-7) and obs 9-12 (its projection 10-11)
    assert spent == {"whole": 13.0, "start": 1.0, "step": 5.0, "obs": 3.0, "project": 3.0}


def test_timing_restores_what_it_patched_when_a_part_names_no_method():
    class Env:
        def obs(self):
            return 1

    before = Env.obs
    with pytest.raises(AttributeError, match="Env has no no_such_method to time"):
        with bench.timing([(Env, "obs", "obs"), (Env, "no_such_method", "x")], {}, outer="w", inner="i", apart="a"):
            pass
    assert Env.obs is before and "obs" in vars(Env)


def test_the_split_table_has_a_row_per_part_the_rest_and_the_whole(monkeypatch):
    labels = [label for _, _, label in bench.step_parts() if label != bench.START_UP]

    def fake_split(iterations, num_envs, curiosity):
        ms = dict.fromkeys(labels, 0.5)
        ms[labels[-1]] = 10.0 if curiosity == "recipe" else 5.0
        return ms, 1000

    monkeypatch.setattr(bench, "step_split", fake_split)
    table = bench.split_table(bench.Args(workers=(2,)))
    rows = table.splitlines()
    assert rows[0].startswith("| ms per vector step (2 env processes) | plain PPO, sparse reward | the from-scratch recipe")
    assert len(rows) == 2 + len(labels) + 2
    # the rest: the whole less every part but the projection, which is inside the observation
    assert "| the rest: the rollout's bookkeeping, logs, evaluations | 1.00 | 6.00 | 6.0 |" in rows
    assert f"| **{labels[-1]}** | 5.00 | 10.00 | 2.0 |" in rows
    assert rows[-1] == "| env steps/s it makes | 400 | 200 | |"


def test_the_obstacle_section_measures_each_scene_against_the_site_as_built_in_one_run():
    args = bench.Args(steps=30, rounds=1, cpu=False, gpu=False, obstacles=True, obstacle_episode_steps=10)
    assert bench.command(args) == ("python scripts/benchmark.py --steps 30 --rounds 1 --no-cpu --no-gpu --obstacles "
                                   "--obstacle-episode-steps 10")
    body = bench.obstacle_section(args)
    rows = [line.split(" | ") for line in body.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert [r[0].removeprefix("| ") for r in rows] == [label for label, _, _ in bench.OBSTACLE_SCENES]
    assert rows[0][2] == "1.00 |" and all(float(r[1]) > 0 for r in rows)
    env = bench.make_training_env("moving", 0.5)
    assert env.unwrapped.obstacle_share == 0.5 and bool((env.unwrapped.near_goal_share > 0).all())
    env.close()
