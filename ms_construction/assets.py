"""Where the committed assets live, and the check that they are present and current.

Loading never generates anything: the site meshes, their coacd convex parts and the arm's URDF
are built once by `scripts/build_assets.py` and committed with a manifest (generator parameters,
coacd settings, file hashes). `load_manifest()` refuses a missing or stale asset with an error
that names the command that rebuilds it.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

from ms_construction.parameters import ArmParams, SiteParams

ASSET_DIR = Path(__file__).resolve().parent.parent / "assets"
MANIFEST_PATH = ASSET_DIR / "manifest.json"
ARM_URDF_PATH = ASSET_DIR / "arm" / "construction_arm.urdf"
ARM_SRDF_PATH = ASSET_DIR / "arm" / "construction_arm.srdf"
REBUILD_COMMAND = "python scripts/build_assets.py"

GENERATOR_VERSION = 3
"""Bump when the generator's output changes for unchanged parameters."""


class AssetError(RuntimeError):
    """A committed asset is missing, modified or out of date with the generator."""


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def expected_header() -> dict:
    """What the manifest must record for the assets to be current with this code."""
    return {
        "generator_version": GENERATOR_VERSION,
        "site_params": SiteParams().to_dict(),
        "arm_params": ArmParams().to_dict(),
    }


def _normalize(obj):
    # JSON turns tuples into lists; compare like with like
    return json.loads(json.dumps(obj))


def check_manifest(manifest: dict, asset_dir: Path = ASSET_DIR) -> None:
    """Raise AssetError unless every file is present with its recorded hash and the recorded
    generator parameters are this code's."""
    fix = f"Rebuild the assets with: {REBUILD_COMMAND}"
    for key, value in _normalize(expected_header()).items():
        if manifest.get(key) != value:
            raise AssetError(f"assets are stale: manifest '{key}' differs from the generator's current value. {fix}")
    for rel, digest in manifest["files"].items():
        path = asset_dir / rel
        if not path.is_file():
            raise AssetError(f"asset missing: {path}. {fix}")
        if sha256(path) != digest:
            raise AssetError(f"asset modified or stale: {path} does not match its manifest hash. {fix}")


@functools.lru_cache(maxsize=None)
def _load_cached(path: str, mtime_ns: int) -> dict:
    manifest = json.loads(Path(path).read_text())
    check_manifest(manifest, Path(path).parent)
    return manifest


def load_manifest(path: Path = MANIFEST_PATH) -> dict:
    """The checked site manifest (cached per file version)."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"asset manifest missing: {path}. Rebuild the assets with: {REBUILD_COMMAND}")
    return _load_cached(str(path), path.stat().st_mtime_ns)
