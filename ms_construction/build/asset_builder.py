"""Builds the committed assets: site meshes, coacd convex parts, the arm's URDF and SRDF, a manifest.

Collision: coacd approximates a concave part with convex hulls, and an approximate hull may bridge
an opening a few centimetres wider than its element. So each part is decomposed recursively: coacd
on the solid; if a hull enters one of the part's keep-free volumes (an opening, a recess, the
staging tray), the solid is cut along a face plane of that volume and each side is decomposed
again. The result is checked: no hull enters a keep-free volume by more than `INTRUSION_TOL`.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

import coacd
import manifold3d
import numpy as np
import trimesh
from trimesh.visual.material import PBRMaterial

from ms_construction.assets import ASSET_DIR, GENERATOR_VERSION, REBUILD_COMMAND, sha256
from ms_construction.build.arm_model import arm_srdf, arm_urdf, effort_limits
from ms_construction.build.site_geometry import (
    MATERIALS,
    StaticPart,
    box_planes,
    goal_poses,
    grasp_in_element,
    hull_intrusion,
    static_parts,
    to_trimesh,
)
from ms_construction.parameters import ELEMENT_KINDS, ArmParams, SiteParams

INTRUSION_TOL = 1e-3
"""m; how far a collision hull may enter an opening after decomposition."""
CUT_INSET = 2e-4
"""m; cuts are made this far inside an opening's face (well under INTRUSION_TOL)."""
MIN_PIECE_THICKNESS = 5e-3
"""m; a cut must leave at least this much material on both sides, along the cut's normal."""


@dataclass(frozen=True)
class CoacdSettings:
    threshold: float = 0.05
    """coacd concavity threshold."""
    preprocess_mode: str = "off"
    """the solids are already watertight manifolds (manifold3d booleans); remeshing would blur openings."""
    max_convex_hull: int = -1
    resolution: int = 2000
    mcts_iterations: int = 150
    seed: int = 0
    max_depth: int = 8
    """how many times a solid may be cut before decomposition gives up."""


def _material(name: str) -> PBRMaterial:
    rgba, metallic, roughness = MATERIALS[name]
    return PBRMaterial(
        name=name,
        baseColorFactor=[int(round(255 * c)) for c in rgba],
        metallicFactor=metallic,
        roughnessFactor=roughness,
        alphaMode="BLEND" if rgba[3] < 1 else "OPAQUE",
    )


def _coacd(solid: manifold3d.Manifold, s: CoacdSettings) -> list[np.ndarray]:
    mesh = to_trimesh(solid)
    parts = coacd.run_coacd(
        coacd.Mesh(mesh.vertices, mesh.faces),
        threshold=s.threshold,
        preprocess_mode=s.preprocess_mode,
        max_convex_hull=s.max_convex_hull,
        resolution=s.resolution,
        mcts_iterations=s.mcts_iterations,
        seed=s.seed,
    )
    return [np.asarray(v, dtype=np.float64) for v, _ in parts]


def _thickness(solid: manifold3d.Manifold, normal: np.ndarray) -> float:
    """Extent of a solid along a direction (0 for an empty one)."""
    if solid.is_empty():
        return 0.0
    heights = np.asarray(solid.to_mesh().vert_properties)[:, :3] @ np.asarray(normal)
    return float(heights.max() - heights.min())


def decompose(part: StaticPart, s: CoacdSettings) -> list[np.ndarray]:
    """Convex hull vertex sets covering `part.solid` and leaving its keep-free volumes free."""

    def worst(hulls):
        best = (0.0, None)
        for verts in hulls:
            for box in part.keep_free:
                d = hull_intrusion(verts, *box)
                if d > best[0]:
                    best = (d, box)
        return best

    def rec(solid: manifold3d.Manifold, depth: int) -> list[np.ndarray]:
        hulls = _coacd(solid, s)
        depth_in, box = worst(hulls)
        if depth_in <= INTRUSION_TOL:
            return hulls
        if depth >= s.max_depth:
            raise RuntimeError(f"{part.name}: a collision hull still enters an opening by {depth_in:.3f} m")
        for normal, offset in box_planes(*box[:3]):
            # cut just inside the opening: a cut in the face's own plane leaves degenerate slivers,
            # and a cut outside leaves thin rims that coacd thickens into the opening
            a, b = solid.split_by_plane(list(map(float, normal)), float(offset) - CUT_INSET)
            # a face flush with the part's own surface would cut off a sliver a hair thick, which
            # coacd turns into a membrane across the opening: only cuts into real thickness count
            if min(_thickness(a, normal), _thickness(b, normal)) > MIN_PIECE_THICKNESS:
                return rec(a, depth + 1) + rec(b, depth + 1)
        raise RuntimeError(f"{part.name}: no face plane of the entered opening cuts the solid")

    hulls = rec(part.solid, 0)
    depth_in, _ = worst(hulls)
    assert depth_in <= INTRUSION_TOL
    return hulls


def _write_collision(hulls: list[np.ndarray], path: Path) -> None:
    """One OBJ with a named object per convex hull (SAPIEN loads each as a convex shape)."""
    lines = ["# convex parts from coacd; generated by scripts/build_assets.py"]
    offset = 1
    for i, verts in enumerate(hulls):
        hull = trimesh.convex.convex_hull(verts)
        lines.append(f"o hull_{i}")
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in hull.vertices]
        lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in hull.faces]
        offset += len(hull.vertices)
    path.write_text("\n".join(lines) + "\n")


def _write_visual(part: StaticPart, path: Path) -> None:
    mesh = to_trimesh(part.solid)
    mesh.unmerge_vertices()  # flat shading: a box's faces must not share averaged normals
    mesh.visual = trimesh.visual.TextureVisuals(material=_material(part.material))
    path.write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(mesh)))


def _element_record(p: SiteParams, kind: str) -> dict:
    e = p.element(kind)
    lx, ly, lz = e.size
    inertia = [e.mass / 12 * (ly**2 + lz**2), e.mass / 12 * (lx**2 + lz**2), e.mass / 12 * (lx**2 + ly**2)]
    return {
        "size": list(e.size),
        "mass": e.mass,
        "inertia": inertia,
        "density": e.mass / (lx * ly * lz),
        "material": e.material,
        "frame_width": e.frame_width,
        "grasp_pose": grasp_in_element(e),
        "grasp_surface": {"normal": [0.0, 0.0, 1.0], "center": [0.0, 0.0, lz / 2], "size": [lx, ly]},
    }


def build_assets(
    out_dir: Path = ASSET_DIR,
    site: SiteParams = SiteParams(),
    arm: ArmParams = ArmParams(),
    settings: CoacdSettings = CoacdSettings(),
    progress=lambda msg: None,
) -> dict:
    """Write every asset under `out_dir` and its manifest; return the manifest."""
    out_dir = Path(out_dir)
    site_dir, arm_dir = out_dir / "site", out_dir / "arm"
    for d in (site_dir, arm_dir):
        if d.exists():
            shutil.rmtree(d)
        d.mkdir(parents=True)

    parts = {}
    for part in static_parts(site):
        progress(f"decomposing {part.name} with coacd")
        hulls = decompose(part, settings)
        _write_visual(part, site_dir / f"{part.name}.glb")
        _write_collision(hulls, site_dir / f"{part.name}_collision.obj")
        parts[part.name] = {
            "visual": f"site/{part.name}.glb",
            "collision": f"site/{part.name}_collision.obj",
            "material": part.material,
            "convex_parts": len(hulls),
            "keep_free": [{"center": c.tolist(), "half_size": h.tolist(), "yaw_deg": y, "through_axis": a}
                          for c, h, y, a in part.keep_free],
            **({"task": part.task} if part.task else {}),
        }

    progress("writing the arm's URDF and SRDF")
    (arm_dir / "construction_arm.urdf").write_text(arm_urdf(arm))
    (arm_dir / "construction_arm.srdf").write_text(arm_srdf(arm))

    manifest = {
        "generator_version": GENERATOR_VERSION,
        "site_params": site.to_dict(),
        "arm_params": arm.to_dict(),
        "coacd": asdict(settings),
        "command": REBUILD_COMMAND,
        "parts": parts,
        "elements": {k: _element_record(site, k) for k in ELEMENT_KINDS},
        "goal_poses": goal_poses(site),
        "staging": {
            "center": [*site.staging_center, site.staging_height],
            "size": list(site.staging_size),
            "rim": list(site.staging_rim),
        },
        "arm": {"urdf": "arm/construction_arm.urdf", "srdf": "arm/construction_arm.srdf", "effort_limits": effort_limits(arm)},
        "materials": {k: {"rgba": list(v[0]), "metallic": v[1], "roughness": v[2]} for k, v in MATERIALS.items()},
    }
    files = [f"site/{f.name}" for f in sorted(site_dir.iterdir())] + [f"arm/{f.name}" for f in sorted(arm_dir.iterdir())]
    manifest["files"] = {rel: sha256(out_dir / rel) for rel in files}
    manifest = json.loads(json.dumps(manifest))
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest
