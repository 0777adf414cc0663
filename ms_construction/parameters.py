"""The parameters and constants that both the asset generators and the runtime read.

Plain dataclasses and numbers, no mesh library: `ms_construction.build` turns the parameters into
the committed assets (and records them in the manifest, which `assets.load_manifest` checks
against these), while the tasks, the expert and the learner read the run-time constants below
(element kinds, symmetries, start poses). Lengths in metres, angles in degrees, masses in kg.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

ELEMENT_KINDS = ("ceiling", "window", "flooring", "paneling")
"""Task types in the order of their `task_id` (0 ceiling, 1 window, 2 flooring, 3 paneling)."""
PAPER_KINDS = ELEMENT_KINDS[:3]
"""the paper's three task types: what the general task samples unless `tasks=` asks for paneling too."""


@dataclass(frozen=True)
class ElementParams:
    """One building element: a rigid box (a window is a frame with glass filling it)."""

    size: tuple[float, float, float]
    """length (x), width (y), thickness (z) in metres."""
    mass: float = 15.0
    """kg; the paper's elements all weigh 15 kg."""
    material: str = "gypsum"
    """visual material of the body (window: of the frame)."""
    frame_width: float = 0.0
    """window only: width of the frame profile around the glass, m."""


@dataclass(frozen=True)
class SiteParams:
    """Generator parameters of the site (all lengths in metres, angles in degrees)."""

    clearance: float = 0.02
    """gap between an installed element and its opening, on every side."""
    ceiling_panel: ElementParams = ElementParams((0.80, 0.60, 0.03), material="gypsum")
    """acoustic fibre-cement ceiling panel."""
    window: ElementParams = ElementParams((0.60, 0.80, 0.07), material="aluminium", frame_width=0.06)
    """double-glazed window: 0.6 m wide, 0.8 m tall, aluminium frame."""
    floor_panel: ElementParams = ElementParams((0.60, 0.60, 0.035), material="timber")
    """raised-access floor panel with a timber finish."""
    wall_panel: ElementParams = ElementParams((0.60, 1.00, 0.025), material="fibre_cement")
    """fibre-cement wall board (the gypsum-board class at 15 kg), 0.6 m wide (one stud bay), 1 m tall."""

    ground_extent: tuple[float, float, float, float] = (-2.3, 1.7, -2.3, 2.3)
    """ground slab footprint (x_min, x_max, y_min, y_max); its top is at z = 0."""
    ground_thickness: float = 0.2
    story_height: float = 2.4
    """clear height: the underside of the second-story slab."""
    slab_thickness: float = 0.2
    slab_extent: tuple[float, float, float, float] = (-2.0, 1.35, -2.0, 2.0)
    wall_x: float = 1.15
    """inner face of the exterior wall."""
    wall_thickness: float = 0.2
    wall_y_extent: tuple[float, float] = (-2.0, 2.0)
    window_sill: float = 0.88
    """height of the bottom of each window opening."""
    window_ys: tuple[float, ...] = (-0.85, 0.0, 0.85)
    """centres of the window openings along the wall."""
    ceiling_slots: tuple[tuple[float, float, float], ...] = ((0.62, 0.42, 30.0), (0.0, 0.78, 90.0), (-0.62, 0.42, 150.0))
    """(x, y, yaw) of each ceiling opening; yaw of the panel's length axis."""
    floor_slots: tuple[tuple[float, float, float], ...] = ((0.75, -1.1, 0.0), (0.0, -1.1, 0.0), (-0.75, -1.1, 0.0))
    """(x, y, yaw) of each floor recess."""

    partition_face_y: float = 1.70
    """y of the stud frame's face towards the arm: an interior partition parallel to the x axis, as near as the
    paper's task types' start paths allow (tests/test_paneling.py)."""
    partition_x_extent: tuple[float, float] = (-1.1, 1.15)
    """the partition runs from a free end to the exterior wall."""
    stud_size: tuple[float, float] = (0.05, 0.10)
    """steel stud: width along the partition (x), depth (y)."""
    panel_slots: tuple[float, ...] = (-0.68, 0.0, 0.68)
    """x of the centre of each bay left open in the partition's board layer; a wall panel installs into one."""
    panel_sill: float = 0.55
    """height of the bottom of each open bay."""

    staging_center: tuple[float, float] = (-1.15, 0.0)
    staging_size: tuple[float, float] = (1.1, 1.3)
    """table top (x, y) size."""
    staging_height: float = 0.5
    """top surface of the staging table."""
    staging_rim: tuple[float, float] = (0.05, 0.03)
    """barrier rim around the table top: height, thickness."""

    barrier_height: float = 0.8
    barrier_thickness: float = 0.3
    barrier_extent: tuple[float, float, float] = (-2.0, 1.15, 2.0)
    """Jersey barriers along x = x_min and y = +-y_abs, up to the wall at x_max."""
    column_xy: tuple[tuple[float, float], ...] = ((-1.55, 1.55), (-1.55, -1.55))
    column_size: float = 0.3

    def element(self, kind: str) -> ElementParams:
        return {"ceiling": self.ceiling_panel, "window": self.window, "flooring": self.floor_panel,
                "paneling": self.wall_panel}[kind]

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


TOOL_FORCE_LIMIT = 400.0
"""N, the paper's force limit at the tool."""
G = 9.81


@dataclass(frozen=True)
class ArmParams:
    pedestal_height: float = 0.6
    shoulder_offset: tuple[float, float] = (0.15, 0.35)
    """shoulder axis from the turret joint: forward (x), up (z)."""
    upper_arm: float = 0.85
    forearm: tuple[float, float] = (0.35, 0.40)
    """elbow to forearm-roll joint, forearm-roll joint to wrist-pitch joint."""
    wrist_to_flange: float = 0.12
    flange_to_plate: float = 0.04
    plate_thickness: float = 0.03
    plate_size: float = 0.36
    """side of the square suction plate."""
    masses: tuple[float, ...] = (45.0, 25.0, 12.0, 8.0, 4.0, 1.0)
    """turret, upper arm, forearm, forearm roll, wrist, flange (kg)."""
    plate_mass: float = 6.0
    lower: tuple[float, ...] = (-3.2289, -1.4, -2.7, -3.14, -2.2, -6.1)
    upper: tuple[float, ...] = (3.2289, 1.9, 2.4, 3.14, 2.2, 6.1)
    # joint1 turns +-185 degrees like common arms of this class, so the staging table (at 180) is
    # reachable from both sides
    velocity: tuple[float, ...] = (2.0, 2.0, 2.0, 3.0, 3.0, 3.5)
    """rad/s, in the range of industrial arms of this payload class."""
    color: tuple[float, float, float, float] = (0.93, 0.45, 0.08, 1.0)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @property
    def wrist_to_tcp(self) -> float:
        return self.wrist_to_flange + self.flange_to_plate + self.plate_thickness


# --------------------------------------------------------------------------------------------- #
# the tasks' run-time constants
# --------------------------------------------------------------------------------------------- #
SYMMETRIES_DEG = {
    # rotations about the element's own z axis that leave its installation unchanged:
    "ceiling": (0.0, 180.0),  # a rectangle, finished face fixed (down)
    "window": (0.0,),  # head up and inside face in: no symmetry
    "flooring": (0.0, 90.0, 180.0, 270.0),  # a square, finish up
    "paneling": (0.0, 180.0),  # a rectangle, finished face fixed (towards the room)
}
START_XY_NOISE = 0.08
"""m; element start position on the staging table, uniform in +-this around the table centre (less along an axis
where the element would reach the table's rim: `start_xy_noise`)."""
START_YAW_NOISE_DEG = 15.0
START_YAW_DEG = {"ceiling": 90.0, "window": 0.0, "flooring": 0.0, "paneling": 0.0}
"""nominal yaw on the table: the long side along the table's long side (y)."""
START_RIM_GAP = 0.005
"""m; the least gap between an element on the staging table and the table's rim, at any start."""


def start_xy_noise(size: tuple[float, ...], yaw_deg: float, table_size: tuple[float, float],
                   rim_thickness: float) -> tuple[float, float]:
    """(x, y) half-ranges of an element's start position on the staging table: START_XY_NOISE, or less along an
    axis where the element's footprint (`size`, turned by its nominal yaw +- START_YAW_NOISE_DEG) would come
    within START_RIM_GAP of the rim. A start that overlaps the rim is thrown off the table by the solver."""
    corners = np.array([[sx * size[0] / 2, sy * size[1] / 2] for sx in (-1, 1) for sy in (-1, 1)])
    reach = np.zeros(2)
    for turn in np.linspace(-START_YAW_NOISE_DEG, START_YAW_NOISE_DEG, 31):
        a = np.deg2rad(yaw_deg + turn)
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        reach = np.maximum(reach, np.abs(corners @ rot.T).max(0))
    room = np.asarray(table_size) / 2 - rim_thickness - START_RIM_GAP - reach
    if (room <= 0).any():
        raise ValueError(f"an element of size {size[:2]} at yaw {yaw_deg:g} +- {START_YAW_NOISE_DEG:g} deg does not fit "
                         f"on the staging table {tuple(table_size)} inside its rim of {rim_thickness:g} m")
    return tuple(float(v) for v in np.minimum(START_XY_NOISE, room))
STORAGE_XY = {"ceiling": (-3.2, -1.2), "window": (-3.2, 0.0), "flooring": (-3.2, 1.2), "paneling": (-3.2, 2.4)}
"""general task: where the episode's unused elements wait, on the ground outside the barriers."""
DROP_CLEARANCE = 1e-3
"""m; an element is placed this far above the surface it starts on (table, storage ground) and
settles onto it, rather than starting in contact."""
HIDDEN_POSE = (0.0, 0.0, -10.0, 1.0, 0.0, 0.0, 0.0)
"""where the goal markers of the other task types wait: under the ground, out of every camera."""
