"""The dense reward's geometry is a rule over the site's goal slots, not a list of special cases
(ms_construction/envs/carry_geometry.py, ms_construction/goal_configurations.py):

- on every one of the nine slots: the turret sides its usable start paths leave from, a usable path from the side
  its task type's other slots are reached from (direct, or through a planned via where no direct one is clear),
  its mirror twin in the plane y = 0 where the site has one and the wrist branch that twin's mirror image keeps;
- on slots moved to new places: the twins and branches follow the poses (a window opening moved off its twin's
  mirror image loses it; a ceiling opening moved onto another's mirror image gains one);
- the projection the reward and the observation share is the one of the definition (every point of every path,
  brute force) on random configurations, and the same with and without the detours an obstacle scene's reward uses.
"""

import dataclasses
import json

import numpy as np
import pytest
import torch

from ms_construction import goal_configurations as gc
from ms_construction.envs.carry_geometry import (JOINT_MIRROR_SIGNS, PATH_DEVIATION_WEIGHT, VIA_DEVIATION_WEIGHT,
                                                 CarryGeometry, wrap)
from ms_construction.parameters import ELEMENT_KINDS


@pytest.fixture(scope="module")
def geometry() -> CarryGeometry:
    return CarryGeometry(torch.device("cpu"))


def test_every_slot_of_every_task_has_a_way_in_from_its_task_type_s_side(geometry):
    paths = gc.start_paths()
    usable = geometry.paths["usable"].view(paths.usable.shape).numpy()  # [kinds, slots, configurations, 2 sides]
    for k, kind in enumerate(ELEMENT_KINDS):
        sides = usable[k].any(1)  # [slots, 2]
        main = int(np.argmax(sides.sum(0)))  # the side most of the type's slots are reached from
        for slot in range(usable.shape[1]):
            assert sides[slot].any(), (kind, slot)
            assert sides[slot, main], f"{kind} slot {slot} has no usable path from its type's side {main}"
            direct = (usable[k, slot, :, main] & ~paths.planned[k, slot, :, main]).any()
            assert direct or paths.planned[k, slot, :, main].any(), (kind, slot)
            side_rule = geometry.path_sides(torch.tensor([k]), torch.tensor([slot]))[0].numpy()
            assert (side_rule == sides[slot]).all(), (kind, slot)
    # the shipped site: the window opening at y = +0.85 needs vias (its direct paths leave from +pi alone), and so
    # does paneling's bay at x = +0.68 (its direct paths from +pi run the panel into the partition's end)
    planned = {(ELEMENT_KINDS[k], int(slot)) for k, slot in zip(*np.nonzero(paths.planned.any(axis=(2, 3))))}
    assert planned == {("window", 2), ("paneling", 2)}


def test_mirror_twins_and_branches_on_the_nine_slots(geometry):
    twins, goals = gc.mirror_twins(), gc.load_manifest()["goal_poses"]
    for k, kind in enumerate(ELEMENT_KINDS):
        for slot, goal in enumerate(goals[kind]):
            mirrored = [s for s, g in enumerate(goals[kind]) if np.allclose(g[:3], [goal[0], -goal[1], goal[2]], atol=1e-3)]
            expected = mirrored[0] if goal[1] > 0 and mirrored else -1
            assert twins[k, slot] == expected, (kind, slot)
    assert (twins >= 0).sum() == 1, "the window openings at y = -0.85 and +0.85 are the site's one mirror pair"
    install, signs = gc.install_configurations(), np.asarray(JOINT_MIRROR_SIGNS, dtype=np.float32)
    for k, slot in zip(*np.nonzero(twins >= 0)):
        kept = geometry.kept[k, slot]
        assert kept.any() and not kept.all(), "the twin's mirror branch is kept, the other branch cut"
        mirror = install[k, slot, kept][:, :5] * signs[:5]
        assert np.abs(mirror - install[k, twins[k, slot], 0, :5]).max() < 0.05
        # a window's head stays up in the mirror: its installation is half a turn of joint 6 from the twin's image
        assert abs(abs(float(geometry.mirror_turn[k, slot])) - np.pi) < 1e-3
    assert (geometry.mirror_turn[torch.tensor(twins < 0)] == 0).all() and geometry.kept[twins < 0].all()


def _moved_manifest(**site_changes) -> dict:
    from ms_construction.build.site_geometry import goal_poses
    from ms_construction.parameters import SiteParams

    m = dict(gc.load_manifest())
    m["goal_poses"] = goal_poses(dataclasses.replace(SiteParams(), **site_changes))
    return m


@pytest.mark.parametrize("changes, twin_of", [
    (dict(window_ys=(-0.85, 0.0, 0.6)), {}),  # moved off its twin's mirror image: no twin left
    (dict(ceiling_slots=((0.62, 0.42, 30.0), (0.0, 0.78, 90.0), (0.62, -0.42, 150.0))), {("ceiling", 0): 2, ("window", 2): 0}),
])
def test_the_rule_follows_slots_moved_to_new_places(monkeypatch, changes, twin_of):
    """The mirror rule on a site whose goal slots moved (the poses alone: the rule reads nothing else). Where a moved
    slot gains a twin, the branch mask keeps that twin's mirror branch of its installation configurations (IK of the
    moved poses)."""
    moved = _moved_manifest(**changes)
    monkeypatch.setattr(gc, "load_manifest", lambda: moved)
    gc.install_configurations.cache_clear()
    try:
        twins = gc.mirror_twins()
        expected = {(k, slot): twin_of.get((kind, slot), -1) for k, kind in enumerate(ELEMENT_KINDS) for slot in range(3)}
        assert {key: int(twins[key]) for key in expected} == expected
        keep = gc.mirror_branch_mask(JOINT_MIRROR_SIGNS)
        install = gc.install_configurations()
        for (kind, slot), twin in twin_of.items():
            k = ELEMENT_KINDS.index(kind)
            mirror = install[k, slot, keep[k, slot]][:, :5] * np.asarray(JOINT_MIRROR_SIGNS[:5], dtype=np.float32)
            assert keep[k, slot].any() and np.abs(mirror - install[k, twin, 0, :5]).max() < 0.05
        assert keep[twins < 0].all()
    finally:
        gc.install_configurations.cache_clear()


def test_the_projection_is_the_least_cost_over_every_point_of_every_usable_path(geometry):
    """`project` (each segment's nearest point by joints 1-5, and every vertex) against brute force: the carry
    distance's definition, the least over 4,000 points of each segment of each usable path of weight x off-path
    distance + length left, on random configurations, turns, goal slots and grasp sides. The projection measures at
    a point of a path, so never below the definition (but for the brute force's resolution); joint 6 (compared
    modulo the element's symmetry) is not part of its nearest point, so it may measure a little above."""
    p, g = geometry.paths, torch.Generator().manual_seed(0)
    n = 64
    task, slot = torch.randint(3, (n,), generator=g), torch.randint(3, (n,), generator=g)
    side = torch.randint(-1, 2, (n,), generator=g)
    turn = (torch.rand(n, generator=g) - 0.5) * 0.5
    first = p["usable"][task, slot].float().argmax(-1)  # about the corner of the slot's first usable path
    qpos = p["waypoints"][task, slot, first, 2] + (torch.rand(n, 6, generator=g) - 0.5) * 3.0
    got = geometry.project(qpos, turn, task, slot, side).distance
    fractions = torch.linspace(0, 1, 4000)
    above = []
    for i in range(n):
        usable = p["usable"][task[i], slot[i]]
        on_side = torch.arange(len(usable)) % 2 == side[i]
        if (usable & on_side).any():
            usable = usable & on_side
        best = torch.inf
        for m in torch.nonzero(usable)[:, 0]:
            w = p["waypoints"][task[i], slot[i], m]  # [P, 6]
            seg = w[1:] - w[:-1]
            length = seg.abs().sum(-1)
            before = torch.cumsum(length, 0) - length
            weight = torch.full_like(length, PATH_DEVIATION_WEIGHT)
            if bool(p["planned"][task[i], slot[i], m]):
                weight[:-1] = VIA_DEVIATION_WEIGHT
            for j in range(len(seg)):
                point = w[j] + fractions[:, None] * seg[j]
                diff = qpos[i] - point
                diff[:, 5] = wrap(diff[:, 5] - turn[i], geometry.period[task[i]])
                cost = weight[j] * diff.abs().sum(-1) + before[j] + fractions * length[j]
                best = min(best, float(cost.min()))
        above.append(float(got[i]) - best)
    above = np.array(above)
    assert above.min() > -0.05, "never below the definition"
    assert (np.abs(above) < 1e-3).mean() >= 0.75, np.round(np.sort(above), 3)


def test_the_site_as_built_measures_the_same_with_and_without_the_detours(geometry, monkeypatch):
    """The detours (StartPaths.detour) are for a site's obstacles alone: without them the projection (carry distance,
    offsets) and the reach distance are the same to the bit on random configurations of every task type, slot and
    grasp side."""
    import ms_construction.envs.carry_geometry as cg

    assert geometry.paths["detour"].any()  # (the shipped paths, read before the patch below)
    monkeypatch.setattr(cg, "start_paths", lambda: gc.cached_start_paths(json.dumps(gc.load_vias())))
    without = CarryGeometry(torch.device("cpu"))
    assert not without.paths["detour"].any()
    g, n = torch.Generator().manual_seed(1), 2000
    qpos = (torch.rand(n, 6, generator=g) * 2 - 1) * torch.tensor([3.3, 1.5, 2.0, 3.0, 2.0, 3.2])
    task = torch.randint(len(ELEMENT_KINDS), (n,), generator=g)
    slot, side = torch.randint(3, (n,), generator=g), torch.randint(-1, 2, (n,), generator=g)
    turn = torch.rand(n, generator=g) - 0.5
    a, b = geometry.project(qpos, turn, task, slot, side), without.project(qpos, turn, task, slot, side)
    for f in dataclasses.fields(a):
        assert torch.equal(getattr(a, f.name), getattr(b, f.name)), f.name
    assert torch.equal(geometry.reach_distance(qpos, task, slot), without.reach_distance(qpos, task, slot))


def test_start_paths_are_cached_on_disk_under_the_hash_of_what_they_are_computed_from(tmp_path, monkeypatch):
    monkeypatch.setenv(gc.CACHE_ENV, str(tmp_path))
    vias = json.dumps(gc.load_vias())
    computed = gc.cached_start_paths(vias)
    [written] = tmp_path.glob("start_paths-*.npz")
    read = gc.cached_start_paths(vias)
    for f in dataclasses.fields(computed):
        np.testing.assert_array_equal(getattr(read, f.name), getattr(computed, f.name))
    # another input is another file, never the stale one: other vias or detours, or a changed source file
    monkeypatch.setattr(gc, "_start_paths", lambda *inputs: computed)
    gc.cached_start_paths(json.dumps({}))
    gc.cached_start_paths(vias, json.dumps(gc.load_vias(gc.DETOURS_PATH)))
    assert len(list(tmp_path.glob("start_paths-*.npz"))) == 3 and written.is_file()
    source = tmp_path / "code.py"
    source.write_text("A = 1\n")
    inputs = gc.cache_inputs()
    monkeypatch.setattr(gc, "cache_inputs", lambda: inputs + [source])
    gc.cached_start_paths(vias)
    source.write_text("A = 2\n")
    gc.cached_start_paths(vias)
    assert len(list(tmp_path.glob("start_paths-*.npz"))) == 5
    # an unreadable file is computed again (and written whole)
    written.write_bytes(b"not a cache")
    monkeypatch.setattr(gc, "cache_inputs", lambda: inputs)
    read = gc.cached_start_paths(vias)
    np.testing.assert_array_equal(read.waypoints, computed.waypoints)
