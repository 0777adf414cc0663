"""experiments/grasp_check.py: grasps from reach starts, and its command line's errors."""

import pytest

from experiments import grasp_check

SHIPPED = "assets/checkpoints/scratch_general_agent.pt"


def test_a_start_at_the_element_grasps_it_at_once_whatever_the_policy():
    # radius 0: the plate starts right above the element, inside the pick tolerance: the grasp is made at the first step
    assert grasp_check.grasps(grasp_check.Path(SHIPPED), "Flooring-v1", 0.0, episodes=2, max_steps=2) == 2


def test_policies_are_named_label_equals_checkpoint():
    assert grasp_check.parse_policies((f"shipped={SHIPPED}",)) == {"shipped": grasp_check.Path(SHIPPED)}
    with pytest.raises(SystemExit, match="give LABEL=CHECKPOINT"):
        grasp_check.parse_policies((SHIPPED,))
    with pytest.raises(SystemExit, match="no file"):
        grasp_check.parse_policies(("x=campaign/none.pt",))
    with pytest.raises(SystemExit, match="each radius lies in"):
        grasp_check.main(grasp_check.Args(policy=(f"shipped={SHIPPED}",), radii=(1.5,), write=False))
