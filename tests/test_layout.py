"""The package's layout: run time stays free of the build-time generators and mesh libraries."""

import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "ms_construction"
BUILD_ONLY = ("trimesh", "manifold3d", "coacd", "ms_construction.build")


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_runtime_modules_do_not_import_the_generators_or_mesh_libraries():
    runtime = [p for p in PACKAGE.rglob("*.py") if "build" not in p.relative_to(PACKAGE).parts]
    assert len(runtime) > 10
    offending = {
        str(p.relative_to(PACKAGE)): sorted(n for n in _imports(p) if n.split(".")[0] in BUILD_ONLY[:3] or n.startswith(BUILD_ONLY[3]))
        for p in runtime
    }
    assert not {k: v for k, v in offending.items() if v}


def test_importing_the_tasks_and_the_expert_loads_nothing_from_the_build_subpackage():
    code = ("import sys, ms_construction, ms_construction.planning; "
            "print(sorted(m for m in sys.modules if m.startswith('ms_construction.build')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_generators_see_the_same_parameters_as_the_runtime():
    from ms_construction import parameters
    from ms_construction.build import site_geometry

    goals = site_geometry.goal_poses(parameters.SiteParams())
    assert tuple(goals) == parameters.ELEMENT_KINDS
