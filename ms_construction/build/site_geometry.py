"""Geometry of the construction site, its goal slots and its building elements.

Pure geometry (numpy, manifold3d, trimesh) of the parameters in `ms_construction.parameters`: no
simulator here. `scripts/build_assets.py` turns it into committed meshes; tasks read the committed
manifest, never this module, so a change here shows up as a stale asset until the assets are
rebuilt.

World frame: z up, the arm's pedestal stands at the origin on the ground slab (top at z = 0).
Sectors around the arm: the exterior wall with windows at +x, ceiling openings overhead at +y,
floor recesses at -y, the staging table at -x.

Every element has its own frame at its centre of mass: x along its length, y along its width
(a window's height), z through its thickness. Its grasp surface is the +z face; the suction plate's
tcp frame at grasp sits on that face with its z axis pointing into the element.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import manifold3d
import numpy as np
import trimesh
from transforms3d.euler import euler2mat
from transforms3d.quaternions import mat2quat

from ms_construction.parameters import ElementParams, SiteParams

MATERIALS = {
    # name: (base colour RGBA, metallic, roughness)
    "concrete": ((0.62, 0.61, 0.58, 1.0), 0.0, 0.9),
    "steel": ((0.38, 0.40, 0.43, 1.0), 0.8, 0.4),
    "safety": ((0.95, 0.75, 0.10, 1.0), 0.3, 0.5),
    "timber": ((0.66, 0.47, 0.28, 1.0), 0.0, 0.7),
    "gypsum": ((0.92, 0.92, 0.88, 1.0), 0.0, 0.8),
    "aluminium": ((0.80, 0.81, 0.83, 1.0), 0.9, 0.3),
    "glass": ((0.55, 0.75, 0.85, 0.45), 0.1, 0.05),
    "fibre_cement": ((0.78, 0.80, 0.80, 1.0), 0.0, 0.85),
}


# --------------------------------------------------------------------------------------------- #
# poses
# --------------------------------------------------------------------------------------------- #
def pose7(p, rot: np.ndarray) -> list[float]:
    """[x, y, z, qw, qx, qy, qz] from a position and a rotation matrix."""
    q = mat2quat(rot)
    q = q if q[0] >= 0 else -q
    return [round(float(v), 9) + 0.0 for v in (*p, *q)]


GRASP_IN_ELEMENT_ROT = euler2mat(np.pi, 0, 0)
"""tcp orientation at grasp, in the element frame: tcp z = element -z (pointing into the +z face)."""


def grasp_in_element(params: ElementParams) -> list[float]:
    """The tcp pose at grasp, in the element's frame (centre of its +z face)."""
    return pose7((0.0, 0.0, params.size[2] / 2), GRASP_IN_ELEMENT_ROT)


def goal_poses(p: SiteParams) -> dict[str, list[list[float]]]:
    """Installation pose of the element's own frame for every slot of every task type."""
    t_c = p.ceiling_panel.size[2]
    t_f = p.floor_panel.size[2]
    t_w = p.wall_panel.size[2]
    goals = {
        # flipped (grasp face down, towards the plate below), flush with the slab's underside
        "ceiling": [
            pose7((x, y, p.story_height + t_c / 2), euler2mat(0, 0, np.deg2rad(yaw)) @ euler2mat(np.pi, 0, 0))
            for x, y, yaw in p.ceiling_slots
        ],
        # standing up, grasp face towards the room (element z = world -x, element y = world z),
        # centred in the wall's thickness
        "window": [
            pose7(
                (p.wall_x + p.wall_thickness / 2, y, p.window_sill + p.clearance + p.window.size[1] / 2),
                np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
            )
            for y in p.window_ys
        ],
        # flat, top flush with the ground
        "flooring": [
            pose7((x, y, -t_f / 2), euler2mat(0, 0, np.deg2rad(yaw))) for x, y, yaw in p.floor_slots
        ],
        # standing up against the studs, grasp face towards the arm (element z = world -y, element y = world z),
        # flush with the boards around its bay
        "paneling": [
            pose7((x, p.partition_face_y - t_w / 2, p.panel_sill + p.clearance + p.wall_panel.size[1] / 2),
                  np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]))
            for x in p.panel_slots
        ],
    }
    return goals


# --------------------------------------------------------------------------------------------- #
# solids
# --------------------------------------------------------------------------------------------- #
def _box(size, center=(0, 0, 0), yaw_deg: float = 0.0) -> manifold3d.Manifold:
    b = manifold3d.Manifold.cube(list(map(float, size)), True)
    if yaw_deg:
        b = b.rotate([0.0, 0.0, float(yaw_deg)])
    return b.translate(list(map(float, center)))


def _box_between(lo, hi) -> manifold3d.Manifold:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return _box(hi - lo, (lo + hi) / 2)


@dataclass
class StaticPart:
    """One static body of the site: its solid, visual material and the volumes it must leave free."""

    name: str
    material: str
    solid: manifold3d.Manifold
    keep_free: list[tuple[np.ndarray, np.ndarray, float, int]] = field(default_factory=list)
    """oriented boxes (center, half sizes, yaw deg, through axis) that no collision hull may block:
    openings, recesses, the staging tray; elements enter them along the through axis."""
    task: Optional[str] = None
    """the task type the part is built for, in an env that has it among its task types (None: always)."""


def static_parts(p: SiteParams) -> list[StaticPart]:
    c = p.clearance
    parts = []

    # ground slab with floor recesses
    x0, x1, y0, y1 = p.ground_extent
    ground = _box_between((x0, y0, -p.ground_thickness), (x1, y1, 0.0))
    fl = p.floor_panel.size
    recess_free = []
    for x, y, yaw in p.floor_slots:
        size = (fl[0] + 2 * c, fl[1] + 2 * c, fl[2])
        ground = ground - _box((size[0], size[1], 2 * fl[2]), (x, y, 0.0), yaw)
        recess_free.append((np.array([x, y, -fl[2] / 2]), np.array(size) / 2, yaw, 2))
    parts.append(StaticPart("ground_slab", "concrete", ground, recess_free))

    # second-story slab with ceiling openings
    x0, x1, y0, y1 = p.slab_extent
    z0 = p.story_height
    slab = _box_between((x0, y0, z0), (x1, y1, z0 + p.slab_thickness))
    cl = p.ceiling_panel.size
    openings = []
    for x, y, yaw in p.ceiling_slots:
        size = (cl[0] + 2 * c, cl[1] + 2 * c, p.slab_thickness)
        slab = slab - _box((size[0], size[1], 3 * size[2]), (x, y, z0 + size[2] / 2), yaw)
        openings.append((np.array([x, y, z0 + size[2] / 2]), np.array(size) / 2, yaw, 2))
    parts.append(StaticPart("upper_slab", "concrete", slab, openings))

    # exterior wall with window openings
    wy0, wy1 = p.wall_y_extent
    wall = _box_between((p.wall_x, wy0, 0.0), (p.wall_x + p.wall_thickness, wy1, p.story_height))
    wd = p.window.size
    windows = []
    for y in p.window_ys:
        # the opening spans the wall's thickness: x is its depth, y its width, z its height
        size = (p.wall_thickness, wd[0] + 2 * c, wd[1] + 2 * c)
        center = (p.wall_x + p.wall_thickness / 2, y, p.window_sill + size[2] / 2)
        wall = wall - _box((3 * size[0], size[1], size[2]), center)
        windows.append((np.array(center), np.array(size) / 2, 0.0, 0))
    parts.append(StaticPart("exterior_wall", "concrete", wall, windows))

    # columns carrying the slab
    cols = [_box((p.column_size, p.column_size, p.story_height), (x, y, p.story_height / 2)) for x, y in p.column_xy]
    parts.append(StaticPart("columns", "concrete", manifold3d.Manifold.batch_boolean(cols, manifold3d.OpType.Add)))

    # steel staging table with a rim that keeps elements on it
    sx, sy = p.staging_center
    lx, ly = p.staging_size
    h = p.staging_height
    rim_h, rim_t = p.staging_rim
    top_t, leg = 0.04, 0.06
    pieces = [_box((lx, ly, top_t), (sx, sy, h - top_t / 2))]
    for dx in (-1, 1):
        for dy in (-1, 1):
            pieces.append(_box((leg, leg, h - top_t), (sx + dx * (lx / 2 - leg), sy + dy * (ly / 2 - leg), (h - top_t) / 2)))
    for dx in (-1, 1):
        pieces.append(_box((rim_t, ly, rim_h), (sx + dx * (lx - rim_t) / 2, sy, h + rim_h / 2)))
    for dy in (-1, 1):
        pieces.append(_box((lx, rim_t, rim_h), (sx, sy + dy * (ly - rim_t) / 2, h + rim_h / 2)))
    table = manifold3d.Manifold.batch_boolean(pieces, manifold3d.OpType.Add)
    tray = (np.array([sx, sy, h + rim_h]), np.array([lx / 2 - rim_t, ly / 2 - rim_t, rim_h]), 0.0, 2)
    parts.append(StaticPart("staging_table", "steel", table, [tray]))

    # precast Jersey barriers around the work cell (safety yellow)
    bx0, bx1, by = p.barrier_extent
    t = p.barrier_thickness
    bh = p.barrier_height
    barriers = [
        _box_between((bx0 - t, -by - t, 0.0), (bx0, by + t, bh)),
        _box_between((bx0, by, 0.0), (bx1, by + t, bh)),
        _box_between((bx0, -by - t, 0.0), (bx1, -by, bh)),
    ]
    parts.append(StaticPart("barriers", "safety", manifold3d.Manifold.batch_boolean(barriers, manifold3d.OpType.Add)))
    parts += partition(p)
    return parts


def partition(p: SiteParams) -> list[StaticPart]:
    """An interior partition under construction, built for paneling only: steel studs between a floor and a ceiling
    track (the frame), boarded on the far side and on the near side but for one bay per panel slot, where the studs
    show and a wall panel goes, flush with the boards around it."""
    x0, x1 = p.partition_x_extent
    face, (stud_w, depth) = p.partition_face_y, p.stud_size
    w, h, t = p.wall_panel.size
    c, top, track = p.clearance, p.story_height, 0.04
    frame = [_box_between((x0, face, 0.0), (x1, face + depth, track)),
             _box_between((x0, face, top - track), (x1, face + depth, top))]
    studs = {x0 + stud_w / 2, x1 - stud_w / 2}
    for x in p.panel_slots:  # a stud under each edge of a bay and one behind its middle
        studs |= {round(x - w / 2 - c, 6), round(x, 6), round(x + w / 2 + c, 6)}
    frame += [_box((stud_w, depth, top), (x, face + depth / 2, top / 2)) for x in sorted(studs)]
    boards = _box_between((x0, face - t, 0.0), (x1, face, top))
    bays = []
    for x in p.panel_slots:
        size = (w + 2 * c, t, h + 2 * c)
        center = (x, face - t / 2, p.panel_sill + size[2] / 2)
        boards = boards - _box((size[0], 3 * t, size[2]), center)
        bays.append((np.array(center), np.array(size) / 2, 0.0, 1))
    boards = boards + _box_between((x0, face + depth, 0.0), (x1, face + depth + t, top))
    return [StaticPart("partition_frame", "steel", manifold3d.Manifold.batch_boolean(frame, manifold3d.OpType.Add),
                       task="paneling"),
            StaticPart("partition_boards", "gypsum", boards, bays, task="paneling")]


def to_trimesh(solid: manifold3d.Manifold) -> trimesh.Trimesh:
    m = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts), process=True)


def box_planes(center, half, yaw_deg) -> list[tuple[np.ndarray, float]]:
    """The six face planes (normal, offset) of an oriented box, normals pointing out."""
    R = euler2mat(0, 0, np.deg2rad(yaw_deg))
    planes = []
    for i in range(3):
        for s in (-1.0, 1.0):
            n = s * R[:, i]
            planes.append((n, float(n @ center + half[i])))
    return planes


def hull_intrusion(vertices: np.ndarray, center, half, yaw_deg, through_axis: int) -> float:
    """How far (m) a convex hull blocks an opening: an oriented box an element passes through along
    its `through_axis` (box frame). 0 if the hull does not reach into the box along that axis;
    otherwise its overlap with the box across the opening (the smaller of the two lateral overlaps),
    so a thin membrane spanning the opening counts in full.

    Separating-axis test on the box's face axes: exact for hulls that lie on one side of each of the
    box's face planes, as the decomposition's pieces do; conservative otherwise."""
    R = euler2mat(0, 0, np.deg2rad(yaw_deg))
    local = (np.asarray(vertices) - center) @ R
    overlaps = [min(local[:, i].max(), half[i]) - max(local[:, i].min(), -half[i]) for i in range(3)]
    if overlaps[through_axis] <= 1e-6:
        return 0.0
    return max(0.0, float(min(o for i, o in enumerate(overlaps) if i != through_axis)))
