"""experiments/eval_table.py: agents side by side from evaluate.py's JSONs, as a generated section of RESULTS."""

import json

import pytest

from experiments import eval_table


def result(place: float, ci: list[float], length: float) -> dict:
    return dict(episodes=200, place_success=place, place_success_ci95=ci, mean_length=length)


def test_one_row_per_agent_and_task_from_single_task_and_all_task_jsons(tmp_path):
    single = tmp_path / "window.json"
    single.write_text(json.dumps(dict(env_id="WindowInstallation-v1", **result(0.745, [0.68, 0.8], 191.7))))
    every = tmp_path / "all.json"
    every.write_text(json.dumps({"tasks": {"CeilingInstallation-v1": result(0.99, [0.964, 0.997], 150.2),
                                           "WindowInstallation-v1": result(0.97, [0.936, 0.986], 170.7)}}))
    results = tmp_path / "RESULTS.md"
    body = eval_table.main(eval_table.Args(rows=(f"nearest={single}", f"fixed={every}"), section="probe",
                                           write_results=True, results=results))
    assert f"| nearest | WindowInstallation-v1 | 200 | 74.5 [68.0, 80.0] | 192 | {single} |" in body
    assert f"| fixed | CeilingInstallation-v1 | 200 | 99.0 [96.4, 99.7] | 150 | {every} |" in body
    assert body.count("\n| fixed |") == 2
    assert "<!-- begin probe (generated) -->" in results.read_text()
    with pytest.raises(SystemExit, match="LABEL=JSON"):
        eval_table.main(eval_table.Args(rows=(str(single),)))
