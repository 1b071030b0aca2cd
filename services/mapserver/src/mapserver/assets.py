"""``python -m mapserver.assets``: copy Leaflet from ``node_modules`` into ``static/vendor``.

The page loads Leaflet from the server's own static files, never from a CDN. ``npm ci`` in
``services/mapserver`` installs the pinned version; this step copies the files the page needs.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

STATIC = Path(__file__).parent / "static"
VENDOR = STATIC / "vendor" / "leaflet"
NODE_MODULES = Path(__file__).resolve().parents[2] / "node_modules"
"""``services/mapserver/node_modules`` in a source checkout."""
REQUIRED = ("leaflet.js", "leaflet.css", "images")
SETUP_HINT = (
    "run `make setup` (or: cd services/mapserver && npm ci --no-audit --no-fund "
    "&& uv run python -m mapserver.assets)"
)


def missing(vendor: Path | None = None) -> list[str]:
    """The Leaflet files absent from ``vendor`` (default: ours); empty when the page can work."""
    vendor = VENDOR if vendor is None else vendor
    return [name for name in REQUIRED if not (vendor / name).exists()]


def copy_leaflet(node_modules: Path = NODE_MODULES, vendor: Path = VENDOR) -> Path:
    """Copy leaflet.js, leaflet.css and images/ from ``node_modules/leaflet/dist``."""
    dist = node_modules / "leaflet" / "dist"
    absent = [name for name in REQUIRED if not (dist / name).exists()]
    if absent:
        raise FileNotFoundError(
            f"{dist} lacks {', '.join(absent)}: run `npm ci` in services/mapserver first"
        )
    vendor.mkdir(parents=True, exist_ok=True)
    for name in REQUIRED:
        source, target = dist / name, vendor / name
        if source.is_dir():
            shutil.copytree(source, target, dirs_exist_ok=True)
        else:
            shutil.copy2(source, target)
    return vendor


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m mapserver.assets", description=__doc__)
    parser.add_argument("--node-modules", type=Path, default=NODE_MODULES)
    args = parser.parse_args(argv)
    try:
        target = copy_leaflet(args.node_modules)
    except FileNotFoundError as exc:
        sys.exit(f"mapserver.assets: {exc}")
    print(f"Leaflet copied to {target}")


if __name__ == "__main__":
    main()
