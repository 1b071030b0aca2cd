"""Railway columns for ``coupler campaign``: each run's balise detections checked against the
track model (``[[derive]] function = "coupler_railway.campaign:balise_detections"``)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from functools import cache
from pathlib import Path
from typing import Protocol

from coupler_railway.infrastructure import Infrastructure
from coupler_railway.railml import load_infrastructure


class FinishedRun(Protocol):
    """What the campaign hands a derive function (coupler_orchestrator.tools.campaign.Finished)."""

    @property
    def directory(self) -> Path: ...
    @property
    def variant(self) -> Mapping[str, float | int | str | bool]: ...
    @property
    def root(self) -> Path: ...
    @property
    def columns(self) -> Mapping[str, Sequence[str]]: ...


@cache
def _infrastructure(path: Path) -> Infrastructure:
    return load_infrastructure(path)


def balise_detections(
    run: FinishedRun,
    *,
    railml: str,
    antenna_offset: float = 39.7,
    distance: str = "OpenRails.distance",
    passed: str = "TrackBalises.balises_passed",
) -> dict[str, float | int]:
    """How many balises the run detected (``passed``'s last value) and how many the track model
    says its antenna went over: every balise at most ``distance + antenna_offset`` metres along
    the line (the variant's ``TrackBalises.antenna_offset`` when it sets one). Under Jacobi the
    balise FMU sees the train's distance one step late, so the distance it last saw is taken.
    """
    infrastructure = _infrastructure(run.root / railml)
    offset = float(run.variant.get("TrackBalises.antenna_offset", antenna_offset))
    distances = run.columns[distance]
    algorithm = json.loads((run.directory / "summary.json").read_text())["algorithm"]
    seen = distances[-2] if algorithm == "jacobi" and len(distances) > 1 else distances[-1]
    reach = float(seen) + offset
    return {
        "distance_m": float(distances[-1]),
        "balises_total": len(infrastructure.balises),
        "balises_expected": sum(1 for b in infrastructure.balises if b.distance_m <= reach),
        "balises_detected": int(run.columns[passed][-1]),
    }
