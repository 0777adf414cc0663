"""Generate the construction site and the arm (meshes, coacd collision parts, URDF, manifest).

    python scripts/build_assets.py            # rebuild assets/ in place
    python scripts/build_assets.py --out /tmp/assets

Rebuilding with unchanged parameters reproduces the committed manifest byte for byte.
"""

from dataclasses import dataclass
from pathlib import Path

import tyro

from ms_construction.build.asset_builder import CoacdSettings, build_assets
from ms_construction.assets import ASSET_DIR


@dataclass
class Args:
    out: Path = ASSET_DIR
    """where to write the assets (site/, arm/, manifest.json)."""
    coacd: CoacdSettings = CoacdSettings()
    """coacd settings; the defaults are what the committed assets were built with."""


def main(args: Args) -> None:
    manifest = build_assets(args.out, settings=args.coacd, progress=lambda m: print(f"[build_assets] {m}", flush=True))
    n = sum(p["convex_parts"] for p in manifest["parts"].values())
    print(f"[build_assets] wrote {len(manifest['files'])} files ({n} convex parts) and {args.out / 'manifest.json'}")


if __name__ == "__main__":
    main(tyro.cli(Args))
