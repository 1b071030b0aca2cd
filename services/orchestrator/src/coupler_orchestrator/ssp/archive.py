""".ssp archives: extracted safely (``coupler.archives``) and checked for their SSD."""

from __future__ import annotations

import threading
from pathlib import Path

from coupler.archives import DEFAULT_BUDGET_BYTES, Budget
from coupler.archives import extract as extract_zip
from coupler.errors import ScenarioError

MAX_EXTRACTED_BYTES = DEFAULT_BUDGET_BYTES
"""Default limit on the total uncompressed size of an .ssp archive (and its FMUs)."""
SSD_NAME = "SystemStructure.ssd"


def extract(
    archive: Path,
    target: Path,
    *,
    max_bytes: int = MAX_EXTRACTED_BYTES,
    budget: Budget | None = None,
    cancelled: threading.Event | None = None,
) -> Path:
    """Extract ``archive`` into ``target``; return the path of its SystemStructure.ssd."""
    extract_zip(archive, target, budget=budget or Budget.of(max_bytes), cancelled=cancelled)
    ssd = target.resolve() / SSD_NAME
    if not ssd.is_file():
        raise ScenarioError(
            f"{archive.name}: the archive has no {SSD_NAME} at its root; an .ssp must contain one"
        )
    return ssd
