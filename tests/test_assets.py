"""The committed site and arm assets: present, current, reproducible, and physically sensible."""

import json
import shutil

import numpy as np
import pytest
import sapien
import trimesh
from transforms3d.quaternions import quat2mat

from ms_construction.build.asset_builder import build_assets
from ms_construction.assets import ARM_URDF_PATH, ASSET_DIR, AssetError, REBUILD_COMMAND, check_manifest, load_manifest
from ms_construction.parameters import ELEMENT_KINDS, SiteParams


def _hulls(obj_path):
    """Convex hulls (face normals and offsets) of a collision OBJ, one per 'o' object."""
    hulls, verts = [], []
    for line in open(obj_path):
        if line.startswith("o ") and verts:
            hulls.append(np.array(verts))
            verts = []
        elif line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:]])
    hulls.append(np.array(verts))
    out = []
    for v in hulls:
        h = trimesh.convex.convex_hull(v)
        out.append((h.face_normals, (h.face_normals * h.triangles[:, 0]).sum(1)))
    return out


def test_manifest_matches_files():
    m = load_manifest()
    check_manifest(m)
    assert set(m["parts"]) == {"ground_slab", "upper_slab", "exterior_wall", "columns", "staging_table", "barriers",
                               "partition_frame", "partition_boards"}
    assert {name for name, part in m["parts"].items() if "task" in part} == {"partition_frame", "partition_boards"}
    for kind in ELEMENT_KINDS:
        assert m["elements"][kind]["mass"] == 15.0
        assert len(m["goal_poses"][kind]) >= 3, "several slots per element type"


def test_site_parts_load_in_sapien_with_their_convex_parts():
    m = load_manifest()
    for name, part in m["parts"].items():
        shapes = sapien.physx.PhysxCollisionShapeConvexMesh.load_multiple(
            filename=str(ASSET_DIR / part["collision"]), scale=[1, 1, 1], material=sapien.physx.get_default_material()
        )
        assert len(shapes) == part["convex_parts"], name
        visual = trimesh.load(ASSET_DIR / part["visual"], force="mesh")
        visual.merge_vertices()  # stored unmerged for flat shading
        assert visual.is_watertight and visual.volume > 0, name


def test_arm_urdf_loads_with_six_revolute_joints():
    scene = sapien.Scene()
    loader = scene.create_urdf_loader()
    loader.fix_root_link = True
    robot = loader.load(str(ARM_URDF_PATH))
    joints = robot.get_active_joints()
    assert len(joints) == 6
    assert all(j.type.startswith("revolute") for j in joints)  # SAPIEN: "revolute_unwrapped" when limited
    assert all(np.isfinite(j.limits).all() for j in joints)
    names = [link.name for link in robot.get_links()]
    assert "tcp" in names and "suction_plate" in names
    # realistic masses and positive definite inertias on every moving link
    for link in robot.get_links()[1:8]:
        assert link.mass > 0 and np.all(np.asarray(link.inertia) > 0), link.name
    efforts = load_manifest()["arm"]["effort_limits"]
    # 400 N at the tool on the longest lever (about 1.8 m) bounds the shoulder from below
    assert efforts[1] >= 400 * 1.8


def test_openings_fit_their_elements_and_leave_clearance():
    """An element at its goal pose (shrunk by 5 mm) is inside no convex part of the site, and every
    opening is wider than its element by the clearance on each side."""
    m = load_manifest()
    p = SiteParams()
    hulls = [h for part in m["parts"].values() for h in _hulls(ASSET_DIR / part["collision"])]
    for kind in ELEMENT_KINDS:
        half = np.array(m["elements"][kind]["size"]) / 2 - 0.005
        grid = np.stack(np.meshgrid(*[np.linspace(-h, h, 9) for h in half], indexing="ij"), -1).reshape(-1, 3)
        for goal in m["goal_poses"][kind]:
            pts = grid @ quat2mat(goal[3:]).T + np.array(goal[:3])
            for normals, offsets in hulls:
                inside = ((pts @ normals.T - offsets) < -1e-6).all(1)
                assert not inside.any(), f"{kind} at {goal[:3]} intersects the site"
    c = p.clearance
    openings = {
        # part: (element size in the opening's plane, which half sizes of the opening hold it)
        "upper_slab": (p.ceiling_panel.size[:2], [0, 1]),
        "ground_slab": (p.floor_panel.size[:2], [0, 1]),
        "exterior_wall": (p.window.size[:2], [1, 2]),
    }
    for part, (size, axes) in openings.items():
        for box in m["parts"][part]["keep_free"]:
            np.testing.assert_allclose(2 * np.array(box["half_size"])[axes], np.array(size) + 2 * c)


def test_rebuild_reproduces_the_manifest(tmp_path):
    rebuilt = build_assets(tmp_path / "assets")
    committed = json.loads((ASSET_DIR / "manifest.json").read_text())
    assert rebuilt["files"] == committed["files"]
    assert rebuilt == committed


@pytest.fixture
def asset_copy(tmp_path):
    dst = tmp_path / "assets"
    shutil.copytree(ASSET_DIR, dst, ignore=shutil.ignore_patterns("checkpoints"))
    return dst


def test_missing_asset_names_the_rebuild_command(asset_copy):
    m = json.loads((asset_copy / "manifest.json").read_text())
    (asset_copy / "site" / "upper_slab_collision.obj").unlink()
    with pytest.raises(AssetError, match="missing") as e:
        check_manifest(m, asset_copy)
    assert REBUILD_COMMAND in str(e.value)
    with pytest.raises(AssetError, match="manifest missing"):
        load_manifest(asset_copy / "nope.json")


def test_modified_asset_is_refused(asset_copy):
    m = json.loads((asset_copy / "manifest.json").read_text())
    with open(asset_copy / "arm" / "construction_arm.urdf", "a") as f:
        f.write("<!-- edited by hand -->\n")
    with pytest.raises(AssetError, match="modified or stale") as e:
        check_manifest(m, asset_copy)
    assert REBUILD_COMMAND in str(e.value)


def test_stale_generator_parameters_are_refused(asset_copy):
    m = json.loads((asset_copy / "manifest.json").read_text())
    m["site_params"]["story_height"] = 3.0
    with pytest.raises(AssetError, match="stale") as e:
        check_manifest(m, asset_copy)
    assert REBUILD_COMMAND in str(e.value)


def test_every_element_can_travel_into_its_opening():
    """Swept along its installation axis from 0.25 m out to the goal (2 mm smaller than it is), no
    element touches a collision part: no convex hull bridges or narrows an opening."""
    from ms_construction.planning.site_check import install_sweep_hits

    hits = install_sweep_hits(load_manifest())
    assert len(hits) == sum(len(v) for v in load_manifest()["goal_poses"].values())
    blocked = {slot: found for slot, found in hits.items() if found}
    assert not blocked, blocked
