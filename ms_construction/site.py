"""Puts the committed construction site and its building elements into a ManiSkill scene.

`ConstructionSiteSceneBuilder` is a ManiSkill SceneBuilder: `build()` adds the static site (visual
meshes with their materials, coacd convex parts for collision) to every parallel sub-scene;
A part built for one task type (the partition, for paneling) is built only in an env that has that
type among its task types. `initialize(env_idx)` puts the arm in its rest pose with a little noise. `build_element` makes one
15 kg element (ceiling panel, window or floor panel) as a dynamic actor.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import sapien
import torch

from mani_skill.utils.building.ground import build_ground
from mani_skill.utils.scene_builder import SceneBuilder
from mani_skill.utils.structs import Actor

from ms_construction.agents.construction_arm import REST_QPOS
from ms_construction.assets import ASSET_DIR, load_manifest

SITE_FRICTION = 0.8
"""concrete and steel against the elements."""


def render_material(manifest: dict, name: str) -> sapien.render.RenderMaterial:
    m = manifest["materials"][name]
    return sapien.render.RenderMaterial(base_color=m["rgba"], metallic=m["metallic"], roughness=m["roughness"])


class ConstructionSiteSceneBuilder(SceneBuilder):
    """The static construction site around the arm (the arm itself is the env's agent)."""

    def __init__(self, env, robot_init_qpos_noise: float = 0.02):
        super().__init__(env, robot_init_qpos_noise=robot_init_qpos_noise)
        self.manifest = load_manifest()

    def build(self):
        physx_material = sapien.physx.PhysxMaterial(SITE_FRICTION, SITE_FRICTION, 0.0)
        self.parts: dict[str, Actor] = {}
        for name, part in self.manifest["parts"].items():
            if part.get("task", self.env.TASKS[0]) not in self.env.TASKS:  # a part of another task's site
                continue
            builder = self.scene.create_actor_builder()
            builder.add_multiple_convex_collisions_from_file(str(ASSET_DIR / part["collision"]), material=physx_material)
            builder.add_visual_from_file(str(ASSET_DIR / part["visual"]))
            builder.initial_pose = sapien.Pose()
            self.parts[name] = builder.build_static(name=name)
        # open ground beyond the site, under the slab's top, so the site does not float in a void
        ground_top = -self.manifest["site_params"]["ground_thickness"]
        self.ground = build_ground(self.scene, floor_width=40, altitude=ground_top - 0.001)
        self.scene_objects = [*self.parts.values(), self.ground]

    def initialize(self, env_idx: torch.Tensor):
        b = len(env_idx)
        # torch's generator: ManiSkill seeds it per reset, for CPU and GPU alike
        rest = torch.as_tensor(REST_QPOS, dtype=torch.float32, device=self.env.device)
        qpos = rest + torch.randn(b, len(REST_QPOS), device=self.env.device) * self.robot_init_qpos_noise
        self.env.agent.reset(qpos)
        self.env.agent.robot.set_pose(sapien.Pose())


def build_element(scene, kind: str, name: str, scene_idxs: Optional[list[int]] = None, manifest: dict = None) -> Actor:
    """One building element as a dynamic actor: box collision, 15 kg with its box inertia.

    A window is an aluminium frame filled with glass; its collision is the outer box."""
    manifest = manifest or load_manifest()
    e = manifest["elements"][kind]
    lx, ly, lz = e["size"]
    half = np.array(e["size"]) / 2
    builder = scene.create_actor_builder()
    builder.add_box_collision(half_size=half, material=sapien.physx.PhysxMaterial(SITE_FRICTION, SITE_FRICTION, 0.0))
    body = render_material(manifest, e["material"])
    if kind == "window":
        fw = e["frame_width"]
        for sx in (-1, 1):  # stiles
            builder.add_box_visual(sapien.Pose([sx * (lx - fw) / 2, 0, 0]), [fw / 2, ly / 2, lz / 2], material=body)
        for sy in (-1, 1):  # head and sill
            builder.add_box_visual(sapien.Pose([0, sy * (ly - fw) / 2, 0]), [lx / 2 - fw, fw / 2, lz / 2], material=body)
        builder.add_box_visual(sapien.Pose(), [lx / 2 - fw, ly / 2 - fw, lz / 4], material=render_material(manifest, "glass"))
    else:
        builder.add_box_visual(half_size=half, material=body)
    # a stripe marks the grasp face (+z) so pictures show which side the plate takes
    builder.add_box_visual(sapien.Pose([0, 0, lz / 2]), [min(lx, ly) / 8, min(lx, ly) / 8, 0.001],
                           material=sapien.render.RenderMaterial(base_color=[0.1, 0.45, 0.9, 1]))
    builder.set_mass_and_inertia(e["mass"], sapien.Pose(), e["inertia"])
    if scene_idxs is not None:
        builder.set_scene_idxs(scene_idxs)
    builder.initial_pose = sapien.Pose(p=[0, 0, -5])
    return builder.build(name=name)
