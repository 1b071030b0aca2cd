"""Paths (``PATHS/*.pat``): where a train starts, which way it faces, and how it sets the
junctions it runs through.

A path is a chain of points (TrackPDPs, linked by TrPathNodes): the first is where the train's
rear stands, points flagged ``2 0`` are junctions, the others lie on the track. As OpenRails
does, the train faces the way that reaches the second point; between two points the path takes
the junction routes that lead on to the next point. A junction point with no junction of the
track database under it, a point off the track, or points no route joins are errors naming the
path file and the line of the point.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

from .stf import RouteError, read_stf
from .tdb import TrackNetwork

NO_NODE = 4294967295
JUNCTION_MATCH_M = 0.5
"""A junction point must be this close to its junction node (OpenRails: 0.1 m^2)."""
MAX_NODES = 10_000


@dataclass(frozen=True)
class TrainPath:
    """A path resolved on a track network."""

    file: Path
    node: int
    """Vector node where the path starts."""
    offset: float
    """Distance of the start from the node's start [m]."""
    forward: bool
    """The train faces the node's direction."""
    settings: dict[int, int]
    """Junction -> the route (SelectedRoute) the path takes through it."""


@dataclass(frozen=True)
class _Point:
    tile_x: int
    tile_z: int
    x: float
    y: float
    z: float
    junction: bool
    line: int


def load_path(network: TrackNetwork, file: str | Path) -> TrainPath:
    """Read a .pat file and resolve it on ``network``."""
    path = Path(file)
    root = read_stf(path)
    pdps = [
        _Point(
            b.integer(0, "tile x"),
            b.integer(1, "tile z"),
            b.real(2, "x"),
            b.real(3, "y"),
            b.real(4, "z"),
            b.integer(5, "the first flag") == 2,
            b.line,
        )
        for b in root.block("TrackPDPs").blocks("TrackPDP")
    ]
    nodes = root.block("TrackPath").block("TrPathNodes")
    chain: list[_Point] = []
    links = nodes.declared("TrPathNode", "path nodes")
    if not links:
        raise nodes.error("the path has no TrPathNode", "give it at least a start and an end")
    index, seen = 0, set()
    while index != NO_NODE:
        if index in seen or index >= len(links):
            raise links[min(index, len(links) - 1)].error(
                f"TrPathNode {index} is linked to but " + ("loops" if index in seen else "missing"),
                "link the path nodes from the first to the last (4294967295 ends it)",
            )
        seen.add(index)
        link = links[index]
        pdp = link.integer(3, "the TrackPDP index")
        if not 0 <= pdp < len(pdps):
            raise link.error(
                f"TrPathNode {index} names TrackPDP {pdp}, but the path has {len(pdps)}",
                "correct the TrackPDP index (the fourth value)",
            )
        chain.append(pdps[pdp])
        index = link.integer(1, "the next path node")
    if len(chain) < 2:
        raise nodes.error("the path has one point", "give it a start and an end point")
    return _resolve(network, path, chain)


def _junction_at(network: TrackNetwork, path: Path, point: _Point) -> int:
    for index in network.route.junctions:
        position = network.nodes[index].position
        if position is None:
            continue
        tx, tz, x, _, z = position
        dx = (point.tile_x - tx) * 2048.0 + point.x - x
        dz = (point.tile_z - tz) * 2048.0 + point.z - z
        if dx * dx + dz * dz <= JUNCTION_MATCH_M**2:
            return index
    raise RouteError(
        path,
        point.line,
        f"the path runs through a junction at tile {point.tile_x} {point.tile_z} x {point.x} "
        f"z {point.z}, but no junction node of {network.route.tdb_file.name} is there",
        "export the path with the route again, or move the point onto a junction",
    )


def _on_track(network: TrackNetwork, path: Path, point: _Point) -> tuple[int, float]:
    found = network.locate(point.tile_x, point.tile_z, point.x, point.z)
    if found is None:
        raise RouteError(
            path,
            point.line,
            f"the path point at tile {point.tile_x} {point.tile_z} x {point.x} z {point.z} is "
            "not on any track of the route",
            "move it onto the track (within 2.5 m)",
        )
    return found[0], found[1]


# a search state: the vector node entered and the way along it, and the choices made so far
_State = tuple[int, bool, dict[int, int]]


def _resolve(network: TrackNetwork, path: Path, chain: list[_Point]) -> TrainPath:
    node, offset = _on_track(network, path, chain[0])
    settings: dict[int, int] = {}
    best: tuple[bool, dict[int, int], _State | tuple[int, int, dict[int, int]]] | None = None
    for forward in (True, False):
        found = _search(network, path, (node, forward, {}), chain[1], start_offset=offset)
        if found is not None:
            best = (forward, *found)
            break
    if best is None:
        raise RouteError(
            path,
            chain[1].line,
            "no track leads from the path's start to its second point",
            "check the path's points against the route (they must be joined by track)",
        )
    facing, choices, arrived = best
    settings.update(choices)
    for point in chain[2:]:
        found = _search(network, path, arrived, point)
        if found is None:
            raise RouteError(
                path,
                point.line,
                "no route leads to this path point from the one before",
                "check the path's points and junction routes against the route",
            )
        choices, arrived = found
        settings.update(choices)
    return TrainPath(path, node, offset, facing, settings)


def _search(
    network: TrackNetwork,
    path: Path,
    state: _State | tuple[int, int, dict[int, int]],
    target: _Point,
    *,
    start_offset: float | None = None,
) -> tuple[dict[int, int], _State | tuple[int, int, dict[int, int]]] | None:
    """Breadth-first search from ``state`` to ``target``: the junction choices on the way and
    the state at the target. A state is either (vector node, forward, choices) or, at a
    junction, (junction node, entered pin, choices) encoded with a negative node index."""
    goal_junction = _junction_at(network, path, target) if target.junction else None
    goal_track = None if target.junction else _on_track(network, path, target)
    queue: deque[tuple[int, int | bool, dict[int, int]]] = deque([state])
    visited = 0
    first = True
    while queue and visited < MAX_NODES:
        visited += 1
        index, way, choices = queue.popleft()
        if index < 0:  # at a junction, entered through pin `way`
            junction = network.nodes[-index]
            exits = [1, 2] if way == 0 else [0]
            for way_out in exits:
                nxt = junction.pins[way_out]
                made = dict(choices)
                if way_out > 0:
                    made[junction.index] = way_out - 1
                queue.append((nxt.link, nxt.direction > 0, made))
            continue
        forward = bool(way)
        if goal_track is not None and index == goal_track[0]:
            ahead = (
                start_offset is None
                or not first
                or (goal_track[1] >= start_offset if forward else goal_track[1] <= start_offset)
            )
            if ahead:
                return choices, (index, forward, choices)
        first = False
        pin = network.vector(index).pins[1 if forward else 0]
        other = network.nodes[pin.link]
        if other.kind == "end":
            continue
        if other.kind == "vector":
            queue.append((pin.link, pin.direction > 0, choices))
            continue
        entered = next(i for i, p in enumerate(other.pins) if p.link == index)
        if pin.direction > 0:
            entered = 0
        if goal_junction == other.index:
            return choices, (-other.index, entered, choices)
        queue.append((-other.index, entered, choices))
    return None
