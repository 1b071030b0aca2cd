"""``python -m coupler_orchestrator.assets``: copy uPlot from ``node_modules`` into
``static/vendor``, from where ``coupler plot -o FILE.html`` inlines it into every page.

``npm ci`` in ``services/orchestrator`` installs the pinned version (``make assets`` does both).
"""

from __future__ import annotations

import sys
from pathlib import Path

from coupler_tools import vendor as vendor_files

VENDOR = Path(__file__).parent / "static" / "vendor" / "uplot"
NODE_MODULES = Path(__file__).resolve().parents[2] / "node_modules"
"""``services/orchestrator/node_modules`` in a source checkout."""
UPLOT_FILES = ("uPlot.iife.min.js", "uPlot.min.css")
SETUP_HINT = (
    "run `make assets` (or `make setup`; by hand: cd services/orchestrator && npm ci "
    "--no-audit --no-fund && .venv/bin/python -m coupler_orchestrator.assets)"
)


def copy_uplot(node_modules: Path = NODE_MODULES, vendor: Path = VENDOR) -> Path:
    """Copy uPlot's browser build from ``node_modules/uplot/dist``."""
    return vendor_files.copy(node_modules / "uplot" / "dist", UPLOT_FILES, vendor)


def main(argv: list[str] | None = None) -> int:
    return vendor_files.command(
        "python -m coupler_orchestrator.assets", "uPlot", copy_uplot, NODE_MODULES, argv
    )


if __name__ == "__main__":
    sys.exit(main())
