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
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(SystemExit, match="needs a CUDA GPU"):
        bench.trainings(bench.Args(trainings=("free-recipe-cuda",)))


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
