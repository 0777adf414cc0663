"""What the motion planner collides: the arm (optionally carrying an element) and the site.

The arm comes from the committed URDF and SRDF, rewritten for planning:
- every moving link's collision shapes are inflated by a margin, so that the path the PD
  controller actually follows (it lags its targets) keeps clear of what the plan just misses;
- the pedestal's floor plate is dropped: it lies on the ground slab, so FCL would report that
  contact in every configuration, and a static link touching the static site never matters;
- a held element becomes a link fixed to the tcp at its hold pose. mplib 0.1.1 checks an
  attached tool (`update_attached_box`) only against point clouds, neither against the site's
  convex parts nor against the arm's own links, and a 0.8 m panel swung through a flip can hit
  the forearm; as a link of the arm it is checked against both.

The site is the committed coacd convex parts (`assets/site/*_collision.obj`, one `o` object per
hull), the same shapes PhysX collides, as FCL convex objects.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Optional

import numpy as np
import sapien
from mplib.pymp.collision_detection import fcl
from transforms3d.euler import euler2quat, quat2euler

from ms_construction.assets import ARM_SRDF_PATH, ARM_URDF_PATH, ASSET_DIR
from ms_construction.parameters import PAPER_KINDS

ELEMENT_LINK = "element"
PLATE_LINK = "suction_plate"
STATIC_LINK = "base_link"


def _fmt(values) -> str:
    return " ".join(f"{float(v):.6g}" for v in values)


def planning_urdf(margin: float, element_size: Optional[np.ndarray] = None, hold: Optional[sapien.Pose] = None,
                  element_margin: float = 0.0) -> str:
    """The arm's URDF for planning: moving links inflated by `margin` (m); with `element_size`,
    an element box held at `hold` (element pose in the tcp frame) and inflated by `element_margin`
    on every side but the grasp face, which lies against the plate."""
    robot = ET.parse(ARM_URDF_PATH).getroot()
    for link in robot.findall("link"):
        for col in link.findall("collision"):
            box, cyl = col.find("geometry/box"), col.find("geometry/cylinder")
            if link.get("name") == STATIC_LINK:  # exact, but without what stands on the ground
                z = float(col.find("origin").get("xyz").split()[2])
                height = float(box.get("size").split()[2]) if box is not None else float(cyl.get("length"))
                if z - height / 2 <= 1e-6:
                    link.remove(col)
                continue
            if box is not None:
                box.set("size", _fmt(np.array(box.get("size").split(), float) + 2 * margin))
            if cyl is not None:
                cyl.set("radius", _fmt([float(cyl.get("radius")) + margin]))
                cyl.set("length", _fmt([float(cyl.get("length")) + 2 * margin]))
    if element_size is not None:
        m = element_margin
        size = np.asarray(element_size, float) + [2 * m, 2 * m, m]
        link = ET.SubElement(robot, "link", name=ELEMENT_LINK)
        col = ET.SubElement(link, "collision")
        # the element's own z axis points away from the plate: grow the box on that side only
        ET.SubElement(col, "origin", xyz=_fmt([0, 0, -m / 2]), rpy="0 0 0")
        ET.SubElement(ET.SubElement(col, "geometry"), "box", size=_fmt(size))
        joint = ET.SubElement(robot, "joint", name="element_joint", type="fixed")
        ET.SubElement(joint, "parent", link="tcp")
        ET.SubElement(joint, "child", link=ELEMENT_LINK)
        ET.SubElement(joint, "origin", xyz=_fmt(hold.p), rpy=_fmt(quat2euler(hold.q, "sxyz")))
    return ET.tostring(robot, encoding="unicode")


def planning_srdf(with_element: bool) -> str:
    """The committed SRDF; with an element, also its contact with the plate disabled (the plate does
    not collide with elements in the simulation either)."""
    robot = ET.parse(ARM_SRDF_PATH).getroot()
    if with_element:
        ET.SubElement(robot, "disable_collisions", link1=ELEMENT_LINK, link2=PLATE_LINK, reason="Adjacent")
    return ET.tostring(robot, encoding="unicode")


def load_convex_parts(obj_path) -> list[tuple[np.ndarray, np.ndarray]]:
    """(vertices, triangles) of every convex part of a collision OBJ (one `o` object per part)."""
    verts, parts = [], []
    for line in Path(obj_path).read_text().splitlines():
        if line.startswith("o "):
            parts.append([])
        elif line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            parts[-1].append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    verts = np.asarray(verts)
    out = []
    for faces in parts:
        faces = np.asarray(faces)
        used, local = np.unique(faces, return_inverse=True)  # OBJ indices are global: renumber per part
        out.append((verts[used], local.reshape(faces.shape).astype(np.int32)))
    return out


def site_collision_objects(manifest: dict, kinds=PAPER_KINDS) -> dict[str, fcl.CollisionObject]:
    """Every convex part of the static site as an FCL object, keyed `<part>/<index>`: the site of an env whose task
    types are `kinds` (a part built for one task type only is there when that type is among them)."""
    objects = {}
    for name, part in manifest["parts"].items():
        if part.get("task", kinds[0]) not in kinds:
            continue
        for i, (v, f) in enumerate(load_convex_parts(ASSET_DIR / part["collision"])):
            objects[f"{name}/{i}"] = fcl.CollisionObject(fcl.Convex(v, f), np.zeros(3), np.array([1.0, 0, 0, 0]))
    return objects


def box_object(size, pose: sapien.Pose) -> fcl.CollisionObject:
    return fcl.CollisionObject(fcl.Box(np.asarray(size, float)), np.asarray(pose.p, float), np.asarray(pose.q, float))


def obstacle_objects(env, lookahead_s: float = 0.0, margin: float = 0.0) -> dict[str, fcl.CollisionObject]:
    """The env's obstacles (its `obstacles` option; none without it) as FCL objects where they stand now: the stack,
    the post, and the worker's envelope swept over the next `lookahead_s` at its velocity now (a box from here to
    there as wide as it is), each grown by `margin` (m) on every side."""
    from ms_construction.envs.obstacles import POST_SIZE, STACK_SIZE, WORKER_HEIGHT, WORKER_RADIUS

    u = env.unwrapped if hasattr(env, "unwrapped") else env
    if not u.has_obstacles:
        return {}
    lay = u.obstacle_layout[0].cpu().numpy().astype(float)
    story = u._obstacle_site.story_height
    stack_z = lay[2] - STACK_SIZE[2] / 2
    stack = box_object(np.array(STACK_SIZE) + 2 * margin, sapien.Pose([lay[0], lay[1], stack_z], euler2quat(0, 0, lay[3])))
    post = box_object([POST_SIZE + 2 * margin, POST_SIZE + 2 * margin, story], sapien.Pose([lay[4], lay[5], story / 2]))
    xy = u.worker_xy()[0].cpu().numpy().astype(float)
    travel = u.worker_velocity()[0].cpu().numpy().astype(float) * lookahead_s
    length = float(np.linalg.norm(travel))
    heading = float(np.arctan2(travel[1], travel[0])) if length > 0 else 0.0
    centre = [*(xy + travel / 2), WORKER_HEIGHT / 2]
    worker = box_object([length + 2 * (WORKER_RADIUS + margin), 2 * (WORKER_RADIUS + margin), WORKER_HEIGHT + 2 * margin],
                        sapien.Pose(centre, euler2quat(0, 0, heading)))
    return dict(obstacle_stack=stack, obstacle_post=post, obstacle_worker=worker)

