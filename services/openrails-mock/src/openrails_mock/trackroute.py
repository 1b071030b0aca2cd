"""A train's way through the track database, as one line of route distance.

The train's physics moves it along one coordinate, the route distance ``s``: 0 where its path
starts, increasing the way the train faces. :class:`TrackRoute` maps ``s`` onto the track
database: a chain of legs (a vector node and the way along it), built from the path's start
both ways by following the junctions as they are set, to the buffer stops (end nodes). When
a junction is thrown, :meth:`TrackRoute.replan` rebuilds the chain beyond the stretch the
train occupies, so the train follows the junctions ahead of it; the legs under the train keep
their distances.

It is a :class:`~openrails_mock.route.Route` (length, sections, position, locate, gradient)
with what OpenRails reports besides: the track location in node terms and the world position.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from coupler_railway.frame import LocalFrame
from coupler_railway.openrails.world import WorldPoint, geographic_of_world

from .paths import TrainPath
from .simulation import TrackLocation, WorldPosition
from .tdb import Place, TrackNetwork

MAX_LEGS = 10_000
"""A chain stops growing after this many legs (a loop of track has no buffer stop)."""


@dataclass(frozen=True)
class Leg:
    """A vector node run one way, from ``start`` to ``start + length`` of route distance."""

    node: int
    forward: bool
    start: float
    length: float

    @property
    def start_distance(self) -> float:  # the Route protocol's section
        return self.start

    def offset(self, distance: float) -> float:
        """Offset from the node's start of the route distance ``distance``."""
        into = distance - self.start
        return into if self.forward else self.length - into


@dataclass(frozen=True, kw_only=True)
class TrackPoint:
    """A point of the route in the mock's terms (``RoutePoint``)."""

    distance: float
    latitude_deg: float
    longitude_deg: float
    heading_deg: float
    x_m: float
    y_m: float


class Geography:
    """Latitude/longitude of world points: a local metric frame around the route's RouteStart,
    whose own coordinates come from the Goode projection OpenRails places routes on."""

    def __init__(self, start: tuple[int, int, float, float]) -> None:
        self.origin = WorldPoint(start[0], start[1], start[2], start[3])
        latitude, longitude = geographic_of_world(self.origin)
        self.frame = LocalFrame(latitude, longitude)

    def local(self, place: Place) -> tuple[float, float]:
        east, north = WorldPoint(place.tile_x, place.tile_z, place.x, place.z).absolute
        x0, z0 = self.origin.absolute
        return east - x0, north - z0


class TrackRoute:
    """One train's chain of legs through the network, from buffer stop to buffer stop."""

    def __init__(self, network: TrackNetwork, path: TrainPath, geography: Geography) -> None:
        self.network = network
        self.geography = geography
        length = network.vector(path.node).length
        into = path.offset if path.forward else length - path.offset
        self.legs: list[Leg] = [Leg(path.node, path.forward, -into, length)]
        self._extend()

    # -- the chain ------------------------------------------------------------------------

    def _extend(self) -> None:
        """Grow the chain both ways to the buffer stops, following the junctions."""
        while len(self.legs) < MAX_LEGS:
            last = self.legs[-1]
            following = self.network.leave(last.node, last.forward)
            if following is None:
                break
            node, forward = following
            self.legs.append(
                Leg(node, forward, last.start + last.length, self.network.vector(node).length)
            )
        while len(self.legs) < MAX_LEGS:
            first = self.legs[0]
            preceding = self.network.leave(first.node, not first.forward)
            if preceding is None:
                break
            node, backward = preceding
            length = self.network.vector(node).length
            self.legs.insert(0, Leg(node, not backward, first.start - length, length))
        self._starts = [leg.start for leg in self.legs]

    def replan(self, rear: float, front: float) -> None:
        """Rebuild the chain beyond ``[rear, front]`` (the train) from the junctions' states."""
        keep = [
            leg
            for leg in self.legs
            if leg.start + leg.length >= rear - 1e-9 and leg.start <= front + 1e-9
        ]
        self.legs = keep or [self._leg(front)]
        self._extend()

    def junctions_between(self, rear: float, front: float) -> set[int]:
        """Junctions the train stands on (between its legs)."""
        found = set()
        for a, b in zip(self.legs, self.legs[1:], strict=False):
            if rear < b.start < front:
                junction = self.network.junction_on(a.node, a.forward)
                if junction is not None:
                    found.add(junction)
        return found

    # -- the Route protocol ---------------------------------------------------------------

    @property
    def begin(self) -> float:
        """Route distance of the buffer stop behind the path's start (<= 0)."""
        return self.legs[0].start

    @property
    def length(self) -> float:
        """Route distance of the buffer stop ahead (the far end of the chain)."""
        last = self.legs[-1]
        return last.start + last.length

    @property
    def sections(self) -> list[Leg]:
        return self.legs

    def _index(self, distance: float) -> int:
        return min(max(bisect.bisect_right(self._starts, distance) - 1, 0), len(self.legs) - 1)

    def _leg(self, distance: float) -> Leg:
        return self.legs[self._index(distance)]

    def place(self, distance: float) -> tuple[Leg, Place]:
        leg = self._leg(distance)
        offset = min(max(leg.offset(distance), 0.0), leg.length)
        return leg, self.network.place(leg.node, offset)

    def position(self, distance: float) -> TrackPoint:
        leg, place = self.place(distance)
        east, north = self.geography.local(place)
        latitude, longitude = self.geography.frame.to_geographic(east, north)
        heading = place.heading if leg.forward else place.heading + math.pi
        return TrackPoint(
            distance=distance,
            latitude_deg=float(latitude),
            longitude_deg=float(longitude),
            heading_deg=math.degrees(heading) % 360.0,
            x_m=east,
            y_m=north,
        )

    def locate(self, distance: float) -> tuple[int, float]:
        index = self._index(distance)
        return index, distance - self.legs[index].start

    def gradient(self, distance: float) -> float:
        leg, place = self.place(distance)
        return place.grade if leg.forward else -place.grade

    # -- what OpenRails reports besides ---------------------------------------------------

    def track_location(self, distance: float) -> TrackLocation:
        """``trackLocation`` of a traveller facing the train's way at ``distance``."""
        leg, place = self.place(distance)
        return TrackLocation(
            track_node_index=leg.node,
            track_node_length=leg.length,
            track_node_offset=min(max(distance - leg.start, 0.0), leg.length),
            track_vector_section_index=place.section,
            movement_direction="Forward" if leg.forward else "Backward",
        )

    def world_position(self, distance: float) -> WorldPosition:
        _, place = self.place(distance)
        return WorldPosition(
            tile_x=place.tile_x, tile_z=place.tile_z, x=place.x, y=place.y, z=place.z
        )

    def distance_of(self, node: int, offset: float) -> float | None:
        """Route distance of a point of vector node ``node`` on the chain, if it is on it."""
        for leg in self.legs:
            if leg.node == node:
                return leg.start + (offset if leg.forward else leg.length - offset)
        return None
