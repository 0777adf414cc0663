"""experiments/grasp_check.py: grasps from reach starts, its table and command, and its command line's errors."""

import json

import pytest

from experiments import grasp_check

SHIPPED = "assets/checkpoints/scratch_general_agent.pt"


def test_a_start_at_the_element_grasps_it_at_once_and_a_far_start_does_not():
    # radius 0: the plate starts right above the element, inside the pick tolerance: the grasp is made at the first
    # step, from the side the start was on; from anywhere on the way (radius 1), one step is too few
    assert grasp_check.grasps(grasp_check.Path(SHIPPED), "Flooring-v1", 0.0, episodes=2, max_steps=1) == (2, 0)
    assert grasp_check.grasps(grasp_check.Path(SHIPPED), "Flooring-v1", 1.0, episodes=2, max_steps=1) == (0, 0)


def test_the_table_and_json_hold_each_policy_task_and_radius(tmp_path, monkeypatch):
    calls = []

    def fake_grasps(path, env_id, radius, episodes, max_steps):
        calls.append((env_id, radius))
        return (3, 1) if radius == 0.5 else (episodes, 0)

    monkeypatch.setattr(grasp_check, "grasps", fake_grasps)
    monkeypatch.setattr(grasp_check, "load_checkpoint", lambda p: {"progress": {"global_step": 1234}})
    monkeypatch.setattr(grasp_check, "PAGE", tmp_path / "page.md")
    args = grasp_check.Args(policy=(f"a={SHIPPED}",), radii=(0.0, 0.5), episodes=4, out=tmp_path / "g.json")
    result = grasp_check.main(args)
    assert len(calls) == 3 * 2
    assert result["grasped_on_side"]["a"]["CeilingInstallation-v1"] == [4, 3]
    assert json.loads(args.out.read_text())["grasped_other_side"]["a"]["Flooring-v1"] == [0, 1]
    page = (tmp_path / "page.md").read_text()
    assert f"| a ({SHIPPED}) | 1,234 | WindowInstallation-v1 | 4 / 4 | 3 / 4 (+1 from the other side) |" in page
    assert f"`python -m experiments.grasp_check --policy a={SHIPPED} --radii 0.0 0.5 --episodes 4`" in page


def test_policies_are_named_label_equals_checkpoint_once_each():
    assert grasp_check.parse_policies((f"shipped={SHIPPED}",)) == {"shipped": grasp_check.Path(SHIPPED)}
    with pytest.raises(SystemExit, match="give LABEL=CHECKPOINT"):
        grasp_check.parse_policies((SHIPPED,))
    with pytest.raises(SystemExit, match="given twice"):
        grasp_check.parse_policies((f"a={SHIPPED}", f"a={SHIPPED}"))
    with pytest.raises(SystemExit, match="no file"):
        grasp_check.parse_policies(("x=campaign/none.pt",))
    with pytest.raises(SystemExit, match="each radius lies in"):
        grasp_check.main(grasp_check.Args(policy=(f"shipped={SHIPPED}",), radii=(1.5,), write=False))
