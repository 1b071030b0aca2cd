"""The track database as OpenRails' traveller sees it: geometry along vector nodes, junction
states, and the way from one node to the next.

Geometry follows OpenRails' ``Traveller``: a vector section starts at its (tile, X, Y, Z),
heading AY (radians clockwise from north) and pitch AX (negative climbs); a straight runs
ahead, an arc of radius R turns right for a positive angle; a section on a gradient is laid
along the slope, so its horizontal run is ``cos(AX)`` of its length. A traveller leaving a
vector node enters the node its pin names; on a junction it takes pin 1 + SelectedRoute when
it came in through the trunk (pin 0), else the trunk.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from .routefolder import TILE_SIZE_M, RouteFolder, TrackNode, VectorSection

CAPTURE_M = 2.5
"""How far from a track a location may be and still be on it (OpenRails' capture range)."""
END_MARGIN_M = 0.5
"""How far beyond a section's ends a location may be and still be on it."""


@dataclass(frozen=True)
class Place:
    """A point of the track as OpenRails reports it."""

    tile_x: int
    tile_z: int
    x: float
    y: float
    z: float
    heading: float
    """Direction of the vector node there, radians clockwise from north."""
    grade: float
    """Gradient along the vector node's direction, per mille (positive climbs)."""
    section: int
    """Index of the vector section."""


def normalized(tile_x: int, tile_z: int, x: float, z: float) -> tuple[int, int, float, float]:
    """The tile holding a point given relative to another tile, and its offset there."""
    east = tile_x * TILE_SIZE_M + x
    north = tile_z * TILE_SIZE_M + z
    tx = math.floor(east / TILE_SIZE_M + 0.5)
    tz = math.floor(north / TILE_SIZE_M + 0.5)
    return tx, tz, east - tx * TILE_SIZE_M, north - tz * TILE_SIZE_M


def section_place(section: VectorSection, t: float) -> tuple[float, float, float, float]:
    """``(dx, dy, dz, heading)``: the point ``t`` metres into a section, relative to its start."""
    shape = section.shape
    if shape.radius == 0.0:
        right, ahead, turn = 0.0, t, 0.0
    else:
        sign = 1.0 if shape.angle > 0.0 else -1.0
        phi = t / shape.radius
        right, ahead, turn = (
            sign * shape.radius * (1.0 - math.cos(phi)),
            shape.radius * math.sin(phi),
            sign * phi,
        )
    level = ahead * math.cos(section.ax)
    dx = right * math.cos(section.ay) + level * math.sin(section.ay)
    dz = -right * math.sin(section.ay) + level * math.cos(section.ay)
    return dx, -ahead * math.sin(section.ax), dz, section.ay + turn


class TrackNetwork:
    """The nodes of a route and the state of its junctions."""

    def __init__(self, route: RouteFolder) -> None:
        self.route = route
        self.nodes = route.nodes
        self.selected: dict[int, int] = {i: self._main_route(i) for i in route.junctions}
        """Junction node -> SelectedRoute (0 or 1): at start its track shape's MainRoute, as
        OpenRails sets it (route 0 when the shape is missing: OpenRails warns "Missing
        TrackShape" and takes route 0)."""
        self._starts = {i: _cumulative(n) for i, n in self.nodes.items() if n.kind == "vector"}

    def _main_route(self, junction: int) -> int:
        shape = self.route.track_shapes.get(self.nodes[junction].shape or -1)
        return shape.main_route if shape is not None else 0

    def vector(self, index: int) -> TrackNode:
        node = self.nodes[index]
        if node.kind != "vector":
            raise ValueError(f"track node {index} is a {node.kind} node, not a vector node")
        return node

    def place(self, index: int, offset: float) -> Place:
        """The point ``offset`` metres from the start of vector node ``index``."""
        node = self.vector(index)
        starts = self._starts[index]
        k = min(max(bisect.bisect_right(starts, offset) - 1, 0), len(node.sections) - 1)
        section = node.sections[k]
        dx, dy, dz, heading = section_place(section, offset - starts[k])
        tx, tz, x, z = normalized(section.tile_x, section.tile_z, section.x + dx, section.z + dz)
        return Place(tx, tz, x, section.y + dy, z, heading, math.tan(-section.ax) * 1000.0, k)

    def leave(self, index: int, forward: bool) -> tuple[int, bool] | None:
        """The vector node (and the way along it) a traveller enters after leaving vector node
        ``index`` at its end (``forward``) or its start; None at an end node."""
        node = self.vector(index)
        pin = node.pins[1 if forward else 0]
        other = self.nodes[pin.link]
        if other.kind == "end":
            return None
        if other.kind == "vector":  # two vector nodes joined directly (not MSTS, but readable)
            return pin.link, pin.direction > 0
        through = (
            other.pins[other.in_pins + self.selected[other.index]]
            if pin.direction > 0
            else other.pins[0]
        )
        return through.link, through.direction > 0

    def junction_on(self, index: int, forward: bool) -> int | None:
        """The junction a traveller reaches leaving vector node ``index`` that way, if any."""
        pin = self.vector(index).pins[1 if forward else 0]
        return pin.link if self.nodes[pin.link].kind == "junction" else None

    def locate(
        self, tile_x: int, tile_z: int, x: float, z: float
    ) -> tuple[int, float, float] | None:
        """``(vector node, offset from its start, distance from the track)`` of the nearest
        track to a world point within the capture range, as OpenRails' traveller finds it."""
        best: tuple[int, float, float] | None = None
        for index, node in self.nodes.items():
            if node.kind != "vector":
                continue
            starts = self._starts[index]
            for k, section in enumerate(node.sections):
                east = (tile_x - section.tile_x) * TILE_SIZE_M + x - section.x
                north = (tile_z - section.tile_z) * TILE_SIZE_M + z - section.z
                found = _on_section(section, east, north)
                if found is not None and (best is None or found[1] < best[2]):
                    best = (index, starts[k] + found[0], found[1])
        return best


def _cumulative(node: TrackNode) -> list[float]:
    starts = [0.0]
    for section in node.sections[:-1]:
        starts.append(starts[-1] + section.shape.length)
    return starts


def _on_section(section: VectorSection, east: float, north: float) -> tuple[float, float] | None:
    """``(distance along, distance across)`` of a point relative to a section start, or None
    when it is not on the section (OpenRails' TryTrackSection, horizontal)."""
    shape = section.shape
    # turn so the section starts pointing north (+north), curving to the right (+east)
    c, s = math.cos(section.ay), math.sin(section.ay)
    right = east * c - north * s
    ahead = east * s + north * c
    if shape.radius == 0.0:
        along, across = ahead / max(math.cos(section.ax), 1e-9), abs(right)
    else:
        if shape.angle < 0.0:
            right = -right
        r = shape.radius
        across = abs(math.hypot(right - r, ahead) - r)
        phi = math.atan2(ahead, r - right)
        along = phi * r
    if across > CAPTURE_M or not -END_MARGIN_M <= along <= shape.length + END_MARGIN_M:
        return None
    return min(max(along, 0.0), shape.length), across
