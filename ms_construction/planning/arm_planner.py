"""mplib's RRTConnect and FCL collision checking for one collision model of the arm in the site."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import mplib
import numpy as np
from mplib.pymp.collision_detection import fcl

from ms_construction.agents.construction_arm import ARM_JOINTS
from ms_construction.planning.trajectory import densify


class ArmPlanner:
    """One mplib planner: the arm (URDF and SRDF text, see collision_model) among obstacles."""

    def __init__(self, urdf: str, srdf: str, workdir: Path, name: str, obstacles: dict[str, fcl.CollisionObject]):
        workdir = Path(workdir)
        (workdir / f"{name}.urdf").write_text(urdf)
        (workdir / f"{name}.srdf").write_text(srdf)
        self.mp = mplib.Planner(urdf=str(workdir / f"{name}.urdf"), srdf=str(workdir / f"{name}.srdf"),
                                move_group="tcp", user_joint_names=ARM_JOINTS)
        self.world = self.mp.planning_world
        self.world.set_use_point_cloud(False)
        self.world.set_use_attach(False)
        for key, obj in obstacles.items():
            self.mp.set_normal_object(key, obj)

    def set_obstacle(self, key: str, obj: fcl.CollisionObject) -> None:
        self.mp.set_normal_object(key, obj)

    def remove_obstacle(self, key: str) -> None:
        self.mp.remove_normal_object(key)

    def collides(self, q: np.ndarray) -> bool:
        """Whether the arm at `q` touches an obstacle or itself."""
        self.world.set_qpos_all(np.asarray(q, float))
        return self.world.collide()

    def collision_on(self, path: np.ndarray, max_step: float = 0.01) -> Optional[np.ndarray]:
        """A colliding configuration on the polyline `path`, checked every `max_step` rad (coarse
        to fine, so that a collision is usually found after a few checks), or None."""
        points = densify(np.asarray(path, float), max_step)
        i = np.arange(1, len(points) + 1)
        order = np.argsort(-(i & -i), kind="stable")  # by the largest power of two dividing i
        return next((points[k] for k in order if self.collides(points[k])), None)

    def path_collides(self, path: np.ndarray, max_step: float = 0.01) -> bool:
        return self.collision_on(path, max_step) is not None

    def contacts(self, q: np.ndarray) -> list[str]:
        """'link / object' for every contact at `q` (for failure reports)."""
        self.world.set_qpos_all(np.asarray(q, float))
        return [f"{c.link_name1} / {c.link_name2}" for c in self.world.collide_full()]

    def shortcut(self, path: np.ndarray) -> np.ndarray:
        """`path` with waypoints skipped wherever a straight segment past them is collision-free:
        from each kept waypoint, the farthest reachable one is kept next (RRT paths wander; OMPL's
        own simplification is slow and checks segments only at its coarse resolution)."""
        path = np.asarray(path, float)
        kept, i = [0], 0
        while i < len(path) - 1:
            j = len(path) - 1
            while j > i + 1 and self.path_collides(path[[i, j]]):
                j -= 1
            kept.append(j)
            i = j
        return path[kept]

    def rrt_connect(self, start: np.ndarray, goal: np.ndarray, time_limit: float) -> Optional[np.ndarray]:
        """A collision-free joint path [n, 6] from `start` to `goal` (both must be free), or None."""
        # OMPL's simplification takes most of the time and checks at OMPL's coarse resolution: the
        # caller shortcuts the raw path instead
        status, path = self.mp.planner.plan(np.asarray(start, float), [np.asarray(goal, float)],
                                            planner_name="RRTConnect", time=time_limit, range=0.0,
                                            no_simplification=True)
        return np.asarray(path) if status == "Exact solution" else None
