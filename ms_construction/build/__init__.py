"""Build time: the generators of the committed assets (site meshes, coacd parts, the arm's URDF).

Run once by `scripts/build_assets.py`; nothing at run time imports this subpackage, so the tasks,
the expert and the learner (and every vector-env worker process) load without the mesh libraries
(manifold3d, trimesh, coacd) that only the generators need.
"""
