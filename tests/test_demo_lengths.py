"""experiments/demo_lengths.py: the expert's episode lengths per task from demonstrations files, as a section of RESULTS."""

import json

import numpy as np
import pytest

from ms_construction.planning.demos import save_demos

from experiments import demo_lengths


def demo(task: str, steps: int) -> dict:
    return dict(obs=np.zeros((steps, 3), np.float32), actions=np.zeros((steps, 6), np.float32),
                rewards=np.zeros(steps, np.float32), placed=True, task=task, seed=0, noise=0.0)


def test_lengths_per_task_and_label_files_counted_together(tmp_path):
    general, window = tmp_path / "general.npz", tmp_path / "window.npz"
    save_demos(general, [demo("ceiling", 150), demo("window", 210), demo("ceiling", 190)], tried=3)
    save_demos(window, [demo("window", 100)], tried=1)
    results = tmp_path / "RESULTS.md"
    out = demo_lengths.main(demo_lengths.Args(demos=(f"slow={general}", f"slow={window}", f"one={window}"),
                                              write_results=True, results=results))
    assert out["slow"]["ceiling"] == dict(episodes=2, mean=170.0, p95=pytest.approx(188.0), max=190, over_200=0.0)
    assert out["slow"]["window"]["episodes"] == 2 and out["slow"]["window"]["over_200"] == 0.5
    assert list(out["one"]) == ["window"]
    text = results.read_text()
    assert "| slow | window | 2 | 155 | 204 | 210 | 50.0% |" in text and "<!-- begin demo-lengths (generated) -->" in text
    kept = tmp_path / "kept.json"
    kept.write_text(json.dumps({"old": out["slow"], "one": {}}))
    again = demo_lengths.main(demo_lengths.Args(demos=(f"one={window}",), keep=kept, write_results=True, results=results))
    assert list(again) == ["old", "one"] and again["old"] == out["slow"] and again["one"] == out["one"]
    assert "| old | window | 2 | 155 | 204 | 210 | 50.0% |" in results.read_text()
    with pytest.raises(SystemExit, match="LABEL=NPZ"):
        demo_lengths.main(demo_lengths.Args(demos=(str(general),)))
