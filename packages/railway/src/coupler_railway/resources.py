"""The resource files the TrackBalises C FMU reads: ``track.csv`` and ``balises.csv``.

Format (comma separated, ``\\n`` line ends, no quoting, one header line, numbers ``%.17g``):

- ``track.csv``: ``distance_m,latitude_deg,longitude_deg``; rows every ``spacing_m`` from 0,
  the last row exactly at the track length.
- ``balises.csv``: ``balise_id,group_id,position_in_group,distance_m``; integers in decimal,
  rows sorted by distance_m.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from coupler_railway.infrastructure import Infrastructure

TRACK_FILE = "track.csv"
BALISES_FILE = "balises.csv"


def _number(value: float) -> str:
    return "%.17g" % value  # noqa: UP031 -- the C reader's format, stated exactly


def write_fmu_resources(
    infrastructure: Infrastructure, directory: str | os.PathLike[str], *, spacing_m: float = 5.0
) -> tuple[Path, Path]:
    """Write ``track.csv`` and ``balises.csv`` into ``directory`` (created if missing)."""
    if not spacing_m > 0.0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m!r}")
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    length = infrastructure.model.length
    steps = math.floor(length / spacing_m + 1e-9)
    distances = np.arange(steps + 1, dtype=np.float64) * spacing_m
    if length - distances[-1] > 1e-9:
        distances = np.append(distances, length)
    else:
        distances[-1] = length
    points = infrastructure.model.coordinates(distances)
    track_lines = ["distance_m,latitude_deg,longitude_deg"] + [
        f"{_number(d)},{_number(lat)},{_number(lon)}"
        for d, (lat, lon) in zip(distances.tolist(), points.tolist(), strict=True)
    ]
    balise_lines = ["balise_id,group_id,position_in_group,distance_m"] + [
        f"{b.code},{b.group},{b.position_in_group},{_number(b.distance_m)}"
        for b in sorted(infrastructure.balises, key=lambda b: b.distance_m)
    ]
    track_path = folder / TRACK_FILE
    balises_path = folder / BALISES_FILE
    for path, lines in ((track_path, track_lines), (balises_path, balise_lines)):
        with path.open("w", encoding="ascii", newline="\n") as stream:
            stream.write("\n".join(lines) + "\n")
    return track_path, balises_path
