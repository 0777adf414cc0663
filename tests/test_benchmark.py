"""scripts/benchmark.py's command line: which trainings it measures, the command it records, where it writes."""

import pytest
import torch

import scripts.benchmark as bench


def test_trainings_default_to_every_training_and_reject_unknown_ones_by_name():
    assert bench.trainings(bench.Args()) == [(steps, curiosity, "cpu") for steps, curiosity in bench.TRAINING]
    assert bench.trainings(bench.Args(trainings=("free-recipe", "free-none"))) == [("free", "recipe", "cpu"),
                                                                                  ("free", "none", "cpu")]
    with pytest.raises(SystemExit, match="unknown held-sac; allowed: free-none, free-icm"):
        bench.trainings(bench.Args(trainings=("free-recipe", "held-sac")))


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error where there is no CUDA GPU")
def test_a_learner_on_the_gpu_is_refused_without_one():
    with pytest.raises(SystemExit, match="needs a CUDA GPU"):
        bench.trainings(bench.Args(trainings=("free-recipe-cuda",)))


def test_recorded_command_names_what_differs_from_the_defaults_but_not_where_it_writes():
    args = bench.Args(workers=(16,), trainings=("free-none", "free-recipe"), gpu=False, cpu_section="cpu-speed-16-cores")
    assert bench.command(args) == ("python scripts/benchmark.py --workers 16 --trainings free-none free-recipe "
                                   "--no-gpu")
    assert bench.command(bench.Args()) == "python scripts/benchmark.py"
