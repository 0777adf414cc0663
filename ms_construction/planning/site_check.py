"""Can each element enter its opening? Sweeps every element along its installation axis against
the site's convex collision parts, as the expert's install line does.

    python -m ms_construction.planning.site_check

The element (2 mm smaller than it is, as on the expert's straight lines) moves from `standoff`
before its goal to the goal along its own z axis (the plate's axis); a part it touches on the way
blocks that slot for the expert, and in PhysX for anything else that holds the element.
"""

from __future__ import annotations

import numpy as np
import sapien
from mplib.pymp.collision_detection import fcl

from ms_construction.assets import load_manifest
from ms_construction.planning.collision_model import box_object, site_collision_objects
from ms_construction.parameters import ELEMENT_KINDS


Hits = dict[tuple[str, int], dict[str, tuple[float, float]]]


def install_sweep_hits(manifest: dict, kinds=ELEMENT_KINDS, standoff: float = 0.25, nearest: float = 0.0,
                       shrink: float = 0.002, step: float = 0.002) -> Hits:
    """{(kind, slot): {collision part: (nearest, farthest) distance before the goal where it is hit}}
    for every goal slot of `kinds` (an empty dict where the way is free), sweeping from `standoff`
    to `nearest` before the goal."""
    site = site_collision_objects(manifest, ELEMENT_KINDS)  # every part, those of one task type's site too
    request = fcl.CollisionRequest()
    hits = {}
    for kind in kinds:
        size = np.asarray(manifest["elements"][kind]["size"], float) - 2 * shrink
        for slot, g in enumerate(manifest["goal_poses"][kind]):
            goal, found = sapien.Pose(g[:3], g[3:]), {}
            for d in np.arange(nearest, standoff + step / 2, step):
                box = box_object(size, goal * sapien.Pose([0, 0, d]))  # element z: towards the plate
                for name, part in site.items():
                    if fcl.collide(box, part, request).is_collision():
                        lo, hi = found.get(name, (d, d))
                        found[name] = (min(lo, d), max(hi, d))
            hits[(kind, slot)] = found
    return hits


def main() -> None:
    for (kind, slot), found in install_sweep_hits(load_manifest()).items():  # all the way in
        where = ", ".join(f"{name} at {lo:.3f}-{hi:.3f} m before the goal" for name, (lo, hi) in sorted(found.items()))
        print(f"{kind} slot {slot}: {where or 'free'}")


if __name__ == "__main__":
    main()
