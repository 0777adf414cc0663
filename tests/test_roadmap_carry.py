"""experiments/roadmap_carry.py, the probe of a carry measure that prescribes no route: its roadmap is a tree of clear
joint moves from the installation, seeded, and its measure falls along the tree toward the installation."""

import numpy as np

from experiments.roadmap_carry import Args, Roadmap, build, cost_to_go, wrapped
from ms_construction.goal_configurations import START_TURNS_DEG, _collides_at
from tests.helpers import make_env


def test_the_measure_falls_along_a_tree_edge_and_counts_the_offset_from_it_at_its_weight():
    nodes = np.zeros((3, 6))
    nodes[1, 0], nodes[2, 0] = 1.0, 2.0  # the installation, then two nodes out along joint 1
    road = Roadmap(nodes, np.array([0.0, 1.0, 2.0]), np.array([-1, 0, 1]), np.pi, 2)
    along = [cost_to_go(np.r_[x, 0, 0, 0, 0, 0], 0.0, road, 3.0) for x in np.linspace(2.0, 0.0, 9)]
    assert np.allclose(along, np.linspace(2.0, 0.0, 9))
    assert np.isclose(cost_to_go(np.r_[1.5, 0.2, 0, 0, 0, 0], 0.0, road, 3.0), 1.5 + 3 * 0.2)
    # joint 6 is compared modulo the element's symmetry, after the element's turn on the plate
    assert np.isclose(cost_to_go(np.r_[1.0, 0, 0, 0, 0, np.pi + 0.1], 0.1, road, 3.0), 1.0)


def test_the_roadmap_among_obstacles_is_a_seeded_tree_of_clear_moves_from_the_installation():
    env = make_env("WindowInstallation-v1", obstacles="static")
    env.reset(seed=1000005)
    u, args = env.unwrapped, Args()
    road = build(u, args, np.random.default_rng(0))
    again = build(u, args, np.random.default_rng(0))
    assert np.array_equal(road.nodes, again.nodes) and np.array_equal(road.parent, again.parent)
    reached = np.isfinite(road.to_go)
    assert (road.to_go == 0).sum() >= 1 and reached.sum() > 10
    planners = u._path_planners(int(u.task_id[0]), with_site=True)
    turns = [float(np.deg2rad(t)) for t in START_TURNS_DEG]
    for i in np.nonzero(reached & (road.parent >= 0))[0]:
        p = road.parent[i]
        step = wrapped(road.nodes[i] - road.nodes[p], road.period)
        assert np.isclose(road.to_go[i], road.to_go[p] + np.abs(step).sum(), atol=1e-5)
        # each node reads at most its tree length, and holds the element clear of the site and the obstacles
        assert cost_to_go(road.nodes[i], 0.0, road, 3.0) <= road.to_go[i] + 1e-5
        assert not _collides_at(planners, road.nodes[i], turns)
    env.close()
