"""The route the mock's train runs on: what the simulation needs of a track model.

``Route`` is the part of a track model the simulation uses; ``coupler_railway``'s
``TrackModel`` satisfies it as is, and so does a train's way through a route folder
(:class:`~openrails_mock.trackroute.TrackRoute`, which railML files reach through the
exporter). ``StraightRoute`` is a flat or evenly graded straight line for running the mock
without a route, and for tests.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from coupler.errors import ScenarioError
from coupler_railway import Infrastructure, RailMLError, load_infrastructure

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius, for the straight route's lat/lon."""


class RoutePoint(Protocol):
    """A point on the route (``coupler_railway.TrackPoint`` fits)."""

    @property
    def latitude_deg(self) -> float: ...
    @property
    def longitude_deg(self) -> float: ...
    @property
    def heading_deg(self) -> float:
        """Compass heading of increasing route distance: 0 north, 90 east."""
        ...

    @property
    def x_m(self) -> float:
        """Easting in the route's local metric frame."""
        ...

    @property
    def y_m(self) -> float:
        """Northing in the route's local metric frame."""
        ...


class RouteSection(Protocol):
    """One track of the route (``coupler_railway.TrackSection`` fits)."""

    @property
    def start_distance(self) -> float: ...
    @property
    def length(self) -> float: ...


class Route(Protocol):
    """A line of track measured by distance from its start (``coupler_railway.TrackModel``)."""

    @property
    def length(self) -> float: ...
    @property
    def sections(self) -> Sequence[RouteSection]: ...
    def position(self, distance: float) -> RoutePoint: ...
    def locate(self, distance: float) -> tuple[int, float]:
        """Index of the section holding ``distance`` and the offset into it, in metres."""
        ...

    def gradient(self, distance: float) -> float:
        """Gradient in per mille, positive uphill towards increasing distance."""
        ...


@dataclass(frozen=True, kw_only=True)
class StraightPoint:
    """A point on a ``StraightRoute``."""

    distance: float
    latitude_deg: float
    longitude_deg: float
    heading_deg: float
    x_m: float
    y_m: float


@dataclass(frozen=True, kw_only=True)
class StraightSection:
    """One section of a ``StraightRoute``."""

    track_id: str
    name: str
    start_distance: float
    length: float


class StraightRoute:
    """A straight line of equal sections with a constant gradient, from a geographic origin."""

    def __init__(
        self,
        *,
        length_m: float,
        section_length_m: float = 1000.0,
        gradient_per_mille: float = 0.0,
        origin_lat_deg: float = 50.5796,
        origin_lon_deg: float = 13.0024,
        heading_deg: float = 225.0,
    ) -> None:
        if length_m <= 0.0 or section_length_m <= 0.0:
            raise ValueError("a straight route needs a positive length and section length")
        self._length = length_m
        self._gradient = gradient_per_mille
        self._lat0 = origin_lat_deg
        self._lon0 = origin_lon_deg
        self._heading = heading_deg % 360.0
        count = math.ceil(length_m / section_length_m - 1e-9)
        self._sections = tuple(
            StraightSection(
                track_id=f"straight-{i + 1}",
                name=f"straight section {i + 1}",
                start_distance=i * section_length_m,
                length=min(section_length_m, length_m - i * section_length_m),
            )
            for i in range(count)
        )

    @property
    def length(self) -> float:
        return self._length

    @property
    def sections(self) -> Sequence[StraightSection]:
        return self._sections

    def position(self, distance: float) -> StraightPoint:
        d = min(max(distance, 0.0), self._length)
        x = d * math.sin(math.radians(self._heading))
        y = d * math.cos(math.radians(self._heading))
        lat = self._lat0 + math.degrees(y / EARTH_RADIUS_M)
        lon = self._lon0 + math.degrees(x / (EARTH_RADIUS_M * math.cos(math.radians(self._lat0))))
        return StraightPoint(
            distance=d, latitude_deg=lat, longitude_deg=lon, heading_deg=self._heading, x_m=x, y_m=y
        )

    def locate(self, distance: float) -> tuple[int, float]:
        d = min(max(distance, 0.0), self._length)
        for index in range(len(self._sections) - 1, -1, -1):
            section = self._sections[index]
            if d >= section.start_distance:
                return index, d - section.start_distance
        return 0, d

    def gradient(self, distance: float) -> float:
        return self._gradient


def load_infrastructure_file(path: Path) -> Infrastructure:
    """A railML infrastructure file read by ``coupler_railway``: the cameras' scene (its track,
    balises, signals and platform edges)."""
    try:
        return load_infrastructure(path)
    except (OSError, RailMLError) as exc:
        raise ScenarioError(
            f"cannot use {path} as the route (OPENRAILS_MOCK_RAILML): {exc}"
        ) from exc
