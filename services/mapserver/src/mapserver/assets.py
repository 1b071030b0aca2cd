"""``python -m mapserver.assets``: copy Leaflet from ``node_modules`` into ``static/vendor``.

The page loads Leaflet from the server's own static files, never from a CDN. ``npm ci`` in
``services/mapserver`` installs the pinned version; this step copies the files the page needs.
"""

from __future__ import annotations

import sys
from pathlib import Path

from coupler_tools import vendor as vendor_files

STATIC = Path(__file__).parent / "static"
VENDOR = STATIC / "vendor" / "leaflet"
NODE_MODULES = Path(__file__).resolve().parents[2] / "node_modules"
"""``services/mapserver/node_modules`` in a source checkout."""
REQUIRED = ("leaflet.js", "leaflet.css", "images")
SETUP_HINT = (
    "run `make setup` (or: cd services/mapserver && npm ci --no-audit --no-fund "
    "&& .venv/bin/python -m mapserver.assets)"
)


def missing(vendor: Path | None = None) -> list[str]:
    """The Leaflet files absent from ``vendor`` (default: ours); empty when the page can work."""
    return vendor_files.missing(VENDOR if vendor is None else vendor, REQUIRED)


def copy_leaflet(node_modules: Path = NODE_MODULES, vendor: Path = VENDOR) -> Path:
    """Copy leaflet.js, leaflet.css and images/ from ``node_modules/leaflet/dist``."""
    return vendor_files.copy(node_modules / "leaflet" / "dist", REQUIRED, vendor)


def main(argv: list[str] | None = None) -> int:
    return vendor_files.command(
        "python -m mapserver.assets", "Leaflet", copy_leaflet, NODE_MODULES, argv
    )


if __name__ == "__main__":
    sys.exit(main())
