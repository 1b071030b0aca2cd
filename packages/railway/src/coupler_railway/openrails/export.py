"""railML -> OpenRails route folder: route file, track database, track sections, paths, world.

What is written and how it maps railML is described in docs/openrails-route.md. In short:

- every line of the railML network (tracks chained end to begin) is cut at its switches into
  track nodes of the track database (``NAME.tdb``): vector nodes, one junction node per switch,
  one end node per line end that is not at a switch;
- a vector node's geometry is the line's B-spline cut into straights and arcs
  (:mod:`coupler_railway.openrails.fit`), laid on the world grid by a :class:`WorldFrame`
  around the line's first point; its gradient is carried by each section's pitch;
- balises, signals and stations become track items, balises and signals also world objects;
- a path (``PATHS/*.pat``) runs from every line end to every other line end it can reach
  without reversing;
- besides, what OpenRails opens at start and draws: the environments and track types
  (:mod:`~coupler_railway.openrails.environment`), the junctions' track shapes
  (``OpenRails/tsection.dat``), terrain (:mod:`~coupler_railway.openrails.terrain`), shapes
  and textures (:mod:`~coupler_railway.openrails.shapes`, :mod:`~coupler_railway.openrails.ace`)
  and a placeholder train (:mod:`~coupler_railway.openrails.stock`).
"""

from __future__ import annotations

import itertools
import math
import os
import re
import shutil
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from coupler_railway.errors import RailMLError
from coupler_railway.infrastructure import Infrastructure, Network, Station, Switch
from coupler_railway.openrails import shapes
from coupler_railway.openrails.ace import write_ace
from coupler_railway.openrails.environment import (
    environment_entries,
    write_environments,
    write_track_types,
)
from coupler_railway.openrails.fit import FitError, Section, fit_error, fit_sections
from coupler_railway.openrails.stf import StfWriter, quote
from coupler_railway.openrails.stock import write_stock
from coupler_railway.openrails.terrain import TrackProfile, write_terrain
from coupler_railway.openrails.world import WorldFrame, WorldPoint, float32, world_file_name
from coupler_railway.railml import load_network

NONE = 4294967295
"""MSTS' 'no index' (0xFFFFFFFF)."""
FIRST_SECTION_INDEX = 40000
"""Route track sections (and dynamic track shapes) are numbered from here, above the indices
of the global track section file OpenRails installs."""
SIGNAL_TYPE = "CouplerMain"
"""The one signal type of the route's sigcfg.dat."""
SIGNAL_SHAPE = "CouplerSignal.s"
BALISE_SHAPE = "CouplerBalise.s"
SWITCH_SHAPE = "CouplerSwitch.s"
"""The shape a junction's TrackObj names: a switch stand beside the trunk (the rails through a
junction are the adjacent sections' dynamic track)."""
LIGHT_TEXTURE = "ltex.ace"
"""The signal lights' texture sigcfg.dat names (TEXTURES/, white)."""
SWITCH_PATH_M = 25.0
"""Length of each path of a junction's track shape (or the adjacent section's, if shorter)."""
ANIMATED = 0x00080000
"""StaticFlags bit of an object OpenRails keeps apart so it can be moved."""
PLATFORM_LENGTH_M = 100.0
"""Length of the platform written for a station (railML gives a station as one point)."""
SIGNAL_SIDE_M = 3.0
"""Signals stand this far to the right of the track, seen by the trains they apply to."""
_JUNCTION_PROBE_M = 20.0


class ExportError(ValueError):
    """The railML network cannot be written as an OpenRails route; names file:line and fix."""


@dataclass(frozen=True)
class RouteReport:
    """What :func:`export_route` wrote, and how closely the sections follow the B-spline."""

    folder: Path
    name: str
    vector_nodes: int
    junction_nodes: int
    end_nodes: int
    sections: int
    items: int
    paths: tuple[str, ...]
    origin: WorldPoint
    """Tile and offset of the route's origin (``RouteStart``): the first line's first point."""
    fit: FitError
    """Largest distances of the fitted sections from the B-spline (horizontal)."""
    slope_offset_m: float
    """Largest along-track shift OpenRails' pitched sections add (sections on a gradient are
    laid along the slope, so their horizontal footprint is shorter by ``1 - cos(pitch)``)."""
    altitude_m: float | None = None
    """The railML altitude of the first line's start (None: heights start at 0 there)."""
    terrain_tiles: int = 0
    """Terrain tiles written (TILES/*.t)."""
    consist: str = ""
    """The consist written (TRAINS/CONSISTS/...)."""


@dataclass
class _Segment:
    """One vector node: ``[start, end]`` of line ``line``."""

    index: int
    line: int
    start: float
    end: float
    sections: list[Section] = field(default_factory=list)
    begin: tuple[int, int] = (0, 1)
    """(node index, pin direction) at the start; direction 1: onto a junction's trunk or an
    end node, 0: onto a junction's branch side."""
    finish: tuple[int, int] = (0, 1)
    items: list[int] = field(default_factory=list)


@dataclass
class _Node:
    """A junction or end node."""

    index: int
    east: float
    north: float
    elevation: float
    heading: float
    pins: list[tuple[int, int]] = field(default_factory=list)
    """(vector node, 1 if it starts here else 0): the trunk (or only pin) first."""
    switch: Switch | None = None
    shape: int = 0
    """A junction's track shape (OpenRails/tsection.dat TrackShapes), numbered from 1."""


@dataclass(frozen=True)
class _Item:
    kind: str
    segment: int
    offset: float
    world: WorldPoint
    elevation: float
    heading: float
    """Direction of the vector node at the item, radians."""
    payload: dict[str, object]


def export_route(
    railml: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    name: str | None = None,
    tolerance_m: float = 0.01,
    terrain: bool = True,
) -> RouteReport:
    """Write the OpenRails route folder ``out`` for the railML file ``railml``.

    ``name``: the route's name and file stem (default: the folder's name). ``tolerance_m``
    bounds the horizontal distance between the written track and the B-spline (half for the
    fit, half for the slope foreshortening). The folder is replaced if it exists and holds a
    route. Raises :class:`~coupler_railway.RailMLError` for a bad railML file and
    :class:`ExportError` for a network OpenRails cannot represent.

    ``terrain=False`` leaves the terrain out (``TILES/``, ``TERRTEX/``): a folder for readers of
    the track alone, such as the OpenRails mock, which never opens them; the terrain is most of
    the export's time (9 s of 11 for the railway scenario's 26 km line).
    """
    if not tolerance_m > 0.0:
        raise ValueError(f"tolerance_m must be positive, got {tolerance_m!r}")
    network = load_network(railml)
    folder = Path(out)
    route_name = name or folder.name
    if not route_name or any(c in route_name for c in ' \t"()/\\'):
        raise ExportError(
            f"route name {route_name!r} cannot be a file stem: give --name without spaces, "
            "quotes, parentheses or slashes"
        )
    builder = _Builder(network, route_name, tolerance_m)
    builder.build()
    _replace_folder(folder)
    return builder.write(folder, terrain=terrain)


def _replace_folder(folder: Path) -> None:
    if folder.exists():
        if not folder.is_dir():
            raise ExportError(f"{folder} exists and is not a folder: give --out a folder")
        if any(folder.iterdir()) and not any(folder.glob("*.trk")):
            raise ExportError(
                f"{folder} exists and holds no OpenRails route (no .trk file); not replacing "
                "it: give --out a new or empty folder"
            )
        shutil.rmtree(folder)
    folder.mkdir(parents=True)


class _Builder:
    def __init__(self, network: Network, name: str, tolerance_m: float) -> None:
        self.network = network
        self.name = name
        self.lines = network.lines
        self.file = str(network.source)
        self.fit_tolerance = tolerance_m / 2.0
        self.slope_budget = tolerance_m / 2.0
        self.frame = WorldFrame.around(self.lines[0].model.frame)
        self.segments: list[_Segment] = []
        self.nodes: list[_Node] = []
        self.paths: list[tuple[str, tuple[str, str], list[_Node]]] = []
        """The paths to write (``_plan_paths``)."""
        self.items: list[_Item] = []
        self.base_elevation: list[float] = []
        self.base_elevation = self._base_elevations()
        self.slope_offset = 0.0
        self.section_uid: dict[int, tuple[int, int, int]] = {}
        """id(section) -> (world tile x, z, UID) of the Dyntrack drawing it."""
        self.item_uid: dict[int, tuple[int, int, int]] = {}
        self.section_index: dict[int, int] = {}
        """id(section) -> its number in tsection.dat (and its dynamic track's)."""
        self.junction_uid: dict[int, tuple[int, int, int]] = {}
        """junction node index -> (world tile x, z, UID) of its TrackObj."""

    # -- geometry helpers ----------------------------------------------------------------

    def elevation(self, line: int, distance: float) -> float:
        """Height [m]: the first line's altitude at its start (railML; 0 when it gives none)
        plus the height integrated from the gradients."""
        return self.base_elevation[line] + self._climb(line, distance)

    def _climb(self, line: int, distance: float) -> float:
        """Height gained from the line's start to ``distance`` [m]."""
        height = 0.0
        for start, end, slope in _stretches(self.lines[line].model.gradient_steps, math.inf):
            if distance <= start:
                break
            height += slope / 1000.0 * (min(distance, end) - start)
        return height

    def _base_elevations(self) -> list[float]:
        """Each line's height at its start: the first line at 0, every other one continuing
        the height of the line it branches off (first switch found)."""
        bases: list[float | None] = [self.lines[0].altitude_m or 0.0]
        bases += [None] * (len(self.lines) - 1)
        changed = True
        while changed:
            changed = False
            for line, infra in enumerate(self.lines):
                for switch in infra.switches:
                    branch = switch.branch
                    at = 0.0 if switch.branch_begins else self.lines[branch].model.length
                    here = self._climb(line, switch.distance_m)
                    there = self._climb(branch, at)
                    known, unknown = bases[line], bases[branch]
                    if known is not None and unknown is None:
                        bases[branch] = known + here - there
                        changed = True
                    elif known is None and unknown is not None:
                        bases[line] = unknown + there - here
                        changed = True
        return [b if b is not None else 0.0 for b in bases]

    def heading(self, line: int, distance: float) -> float:
        return float(self.lines[line].model.headings([distance])[0])

    def point(self, line: int, distance: float) -> tuple[float, float]:
        east, north = (float(v) for v in self.lines[line].model.local_xy([distance])[0])
        return east, north

    # -- the graph ------------------------------------------------------------------------

    def build(self) -> None:
        line_segments: list[list[_Segment]] = []
        for index, line in enumerate(self.lines):
            cuts = []
            for switch in line.switches:
                if not 1.0 < switch.distance_m < line.model.length - 1.0:
                    raise ExportError(
                        f'{self.file}:{switch.line}: <switch id="{switch.id}">: lies '
                        f"{min(switch.distance_m, line.model.length - switch.distance_m):.1f} m "
                        "from the end of its line; a junction needs the line to run through "
                        "it: place the switch on the track that continues on both sides"
                    )
                cuts.append(switch.distance_m)
            bounds = [0.0, *sorted(cuts), line.model.length]
            own = []
            for start, end in itertools.pairwise(bounds):
                segment = _Segment(len(self.segments) + 1, index, start, end)
                self.segments.append(segment)
                own.append(segment)
            line_segments.append(own)
        first_node = len(self.segments) + 1

        def new_node(line: int, distance: float) -> _Node:
            east, north = self.point(line, distance)
            node = _Node(
                first_node + len(self.nodes),
                east,
                north,
                self.elevation(line, distance),
                self.heading(line, distance),
            )
            self.nodes.append(node)
            return node

        begins_at_switch: set[int] = set()
        ends_at_switch: set[int] = set()
        for index, line in enumerate(self.lines):
            for switch in line.switches:
                (begins_at_switch if switch.branch_begins else ends_at_switch).add(switch.branch)
                self._junction(new_node(index, switch.distance_m), switch, index, line_segments)
        for index, own in enumerate(line_segments):
            if index not in begins_at_switch:
                node = new_node(index, 0.0)
                node.pins.append((own[0].index, 1))
                own[0].begin = (node.index, 1)
            if index not in ends_at_switch:
                node = new_node(index, self.lines[index].model.length)
                node.pins.append((own[-1].index, 0))
                own[-1].finish = (node.index, 1)

        for segment in self.segments:
            model = self.lines[segment.line].model
            steps = model.gradient_steps
            caps = []
            for start, end, slope in _stretches(steps, model.length):
                shrink = 1.0 - math.cos(math.atan(slope / 1000.0))
                if shrink > 0.0:
                    caps.append((start, end, self.slope_budget / shrink))
            segment.sections = fit_sections(
                model,
                segment.start,
                segment.end,
                tolerance_m=self.fit_tolerance,
                cuts=[d for d, _ in steps],
                max_length=caps,
            )
            for section in segment.sections:
                slope = model.gradient(section.start + section.length / 2.0)
                shrink = 1.0 - math.cos(math.atan(slope / 1000.0))
                self.slope_offset = max(self.slope_offset, section.length * shrink)
        self._place_items(line_segments)
        self.paths = self._plan_paths()

    def _junction(
        self, node: _Node, switch: Switch, line: int, line_segments: list[list[_Segment]]
    ) -> None:
        """Pins of a switch's junction: trunk first, then the left and the right route."""
        before = next(s for s in line_segments[line] if abs(s.end - switch.distance_m) < 1e-9)
        after = next(s for s in line_segments[line] if abs(s.start - switch.distance_m) < 1e-9)
        branch_line = self.lines[switch.branch]
        branch = line_segments[switch.branch][0 if switch.branch_begins else -1]
        main_heading = self.heading(line, switch.distance_m)
        branch_heading = (
            self.heading(switch.branch, 0.0)
            if switch.branch_begins
            else self.heading(switch.branch, branch_line.model.length) + math.pi
        )
        forward = math.cos(branch_heading - main_heading) > 0.0
        node.switch = switch
        node.shape = sum(1 for n in self.nodes if n.switch is not None)  # numbered from 1
        trunk, straight = (before, after) if forward else (after, before)
        departing = main_heading if forward else main_heading + math.pi

        def probe(segment: _Segment) -> tuple[float, float]:
            """A point a little way along ``segment`` from the junction."""
            starts_here = segment is after or (segment is branch and switch.branch_begins)
            span = min(_JUNCTION_PROBE_M, segment.end - segment.start)
            distance = segment.start + span if starts_here else segment.end - span
            return self.point(segment.line, distance)

        def leftness(segment: _Segment) -> float:
            east, north = probe(segment)
            dx, dy = east - node.east, north - node.north
            return math.sin(departing) * dy - math.cos(departing) * dx

        outs = sorted((straight, branch), key=leftness, reverse=True)
        for segment in (trunk, *outs):
            starts_here = segment is after or (segment is branch and switch.branch_begins)
            node.pins.append((segment.index, 1 if starts_here else 0))
            direction = 1 if segment is trunk else 0
            if starts_here:
                segment.begin = (node.index, direction)
            else:
                segment.finish = (node.index, direction)
        node.heading = departing

    # -- items ----------------------------------------------------------------------------

    def _locate(self, line: int, distance: float, own: list[_Segment]) -> tuple[_Segment, Section]:
        segment = next(
            (s for s in own if s.start <= distance < s.end), own[-1] if own else self.segments[0]
        )
        section = next(
            (s for s in segment.sections if s.start <= distance < s.start + s.length),
            segment.sections[-1],
        )
        return segment, section

    def _item(
        self,
        kind: str,
        line: int,
        distance: float,
        own: list[_Segment],
        *,
        side: float = 0.0,
        **payload: object,
    ) -> _Item:
        segment, section = self._locate(line, distance, own)
        east, north = (float(v) for v in section.points(np.array([distance - section.start]))[0])
        heading = section.heading + section.curvature * (distance - section.start)
        east += side * math.cos(heading)
        north -= side * math.sin(heading)
        item = _Item(
            kind,
            segment.index,
            distance - segment.start,
            self.frame.world(east, north),
            self.elevation(line, distance),
            heading,
            dict(payload),
        )
        self.items.append(item)
        segment.items.append(len(self.items) - 1)
        return item

    def _place_items(self, line_segments: list[list[_Segment]]) -> None:
        for line, (infra, own) in enumerate(zip(self.lines, line_segments, strict=True)):
            for balise in infra.balises:
                self._item(
                    "balise",
                    line,
                    balise.distance_m,
                    own,
                    code=balise.code,
                    name=f"{balise.name} (balise {balise.code}, group {balise.group})",
                )
            for signal in infra.signals:
                facing_down = signal.direction == "down"
                self._item(
                    "signal",
                    line,
                    signal.distance_m,
                    own,
                    side=-SIGNAL_SIDE_M if facing_down else SIGNAL_SIDE_M,
                    direction=1 if facing_down else 0,
                    name=signal.name,
                )
            for station in infra.stations:
                self._platform(line, station, infra, own)

    def _platform(
        self, line: int, station: Station, infra: Infrastructure, own: list[_Segment]
    ) -> None:
        segment, _ = self._locate(line, station.distance_m, own)
        half = min(PLATFORM_LENGTH_M, segment.end - segment.start) / 2.0
        start = min(max(station.distance_m - half, segment.start), segment.end - 2.0 * half)
        first = len(self.items)
        for index, distance in enumerate((start, start + 2.0 * half)):
            self._item(
                "platform",
                line,
                min(distance, segment.end - 1e-6),
                own,
                name=station.name,
                linked=first + 1 - index,
            )

    # -- writing --------------------------------------------------------------------------

    def write(self, folder: Path, *, terrain: bool = True) -> RouteReport:
        world = self._world_objects()
        self._write_trk(folder)
        write_environments(folder)
        write_track_types(folder)
        self._write_tsection(folder)
        self._write_track_shapes(folder)
        self._write_tdb(folder, world)
        for tile, objects in world.items():
            self._write_world(folder, tile, objects)
        paths = self._write_paths(folder)
        self._write_signals(folder)
        self._write_shapes(folder)
        if terrain:
            write_terrain(folder, list(world), self._profile())
        stock = write_stock(folder)
        sections = [s for seg in self.segments for s in seg.sections]
        fits = [fit_error(self.lines[seg.line].model, seg.sections) for seg in self.segments]
        return RouteReport(
            folder=folder,
            name=self.name,
            vector_nodes=len(self.segments),
            junction_nodes=sum(1 for n in self.nodes if n.switch is not None),
            end_nodes=sum(1 for n in self.nodes if n.switch is None),
            sections=len(sections),
            items=len(self.items),
            paths=tuple(paths),
            origin=self.frame.origin,
            fit=FitError(max(f.max_lateral_m for f in fits), max(f.max_along_m for f in fits)),
            slope_offset_m=self.slope_offset,
            altitude_m=self.lines[0].altitude_m,
            terrain_tiles=len(world) if terrain else 0,
            consist=stock[0],
        )

    def _write_shapes(self, folder: Path) -> None:
        """The shapes the world files place (SHAPES/) and their textures (TEXTURES/), with
        the signal lights' texture sigcfg.dat names."""
        placed = {BALISE_SHAPE: shapes.balise(), SIGNAL_SHAPE: shapes.signal()}
        if any(n.switch is not None for n in self.nodes):
            placed[SWITCH_SHAPE] = shapes.switch_stand()
        textures = set()
        for name, shape in placed.items():
            shapes.save_shape(folder / "SHAPES" / name, shape)
            textures.update(shape.textures)
        for texture in sorted(textures):
            write_ace(folder / "TEXTURES" / texture, shapes.COLOURS[texture])
        write_ace(folder / "TEXTURES" / LIGHT_TEXTURE, (255, 255, 255, 255))

    def profile_points(self, line: int, spacing: float = 5.0) -> np.ndarray:
        """``(east, north, height)`` on the world plane every ``spacing`` metres along a
        line's B-spline, at every gradient change (so heights are linear between points) and
        at its end."""
        model = self.lines[line].model
        changes = [d for d, _ in model.gradient_steps if 0.0 < d < model.length]
        distances = np.unique(
            np.concatenate([np.arange(0.0, model.length, spacing), changes, [model.length]])
        )
        local = model.local_xy(distances)
        x0, z0 = self.frame.origin.absolute
        heights = [self.elevation(line, float(d)) for d in distances]
        return np.column_stack([local[:, 0] + x0, local[:, 1] + z0, heights])

    def _profile(self) -> TrackProfile:
        return TrackProfile(tuple(self.profile_points(i) for i in range(len(self.lines))))

    def _world_objects(self) -> dict[tuple[int, int], list[tuple[str, object]]]:
        """Every world object by tile, in UID order; assigns the UIDs the TDB refers to."""
        world: dict[tuple[int, int], list[tuple[str, object]]] = {}

        def add(tile: tuple[int, int], kind: str, thing: object) -> tuple[int, int, int]:
            objects = world.setdefault(tile, [])
            objects.append((kind, thing))
            return tile[0], tile[1], len(objects)

        for segment in self.segments:
            for section in segment.sections:
                point = self.frame.world(section.east, section.north)
                self.section_uid[id(section)] = add(
                    (point.tile_x, point.tile_z), "dyntrack", section
                )
        for index, item in enumerate(self.items):
            if item.kind in ("balise", "signal"):
                tile = (item.world.tile_x, item.world.tile_z)
                self.item_uid[index] = add(tile, item.kind, index)
        for node in self.nodes:
            if node.switch is not None:
                point = self.frame.world(node.east, node.north)
                self.junction_uid[node.index] = add((point.tile_x, point.tile_z), "switch", node)
        for tile_x, tile_z in list(world):
            for dx, dz in itertools.product((-1, 0, 1), repeat=2):
                world.setdefault((tile_x + dx, tile_z + dz), [])
        self.section_index = {
            id(section): FIRST_SECTION_INDEX + number
            for number, section in enumerate(
                s for segment in self.segments for s in segment.sections
            )
        }
        return dict(sorted(world.items()))

    def _write_trk(self, folder: Path) -> None:
        stf = StfWriter("JINX0r1t")
        stf.block("Tr_RouteFile")
        stf.line("RouteID", self.name)
        stf.line("Name", quote(self.name))
        stf.line("Description", quote(f"Exported from {Path(self.file).name} by coupler-railway"))
        stf.line("FileName", self.name)
        for token, value in (
            ("Electrified", "00000000"),
            ("Mountains", "00000000"),
            ("OverheadWireHeight", 0),
            ("PassengerRuleSet", 0),
            ("FreightRuleSet", 0),
            ("SignalSet", 0),
            ("GantrySet", 0),
            ("TrackGauge", 0),
            ("Era", 0),
            ("SpeedLimit", 27.7778),
        ):
            stf.line(token, value)
        stf.block("Environment")
        for entry, env in environment_entries():
            stf.line(entry, env)
        stf.end()
        stf.line("TerrainErrorScale", 1)
        origin = self.frame.origin
        stf.line("RouteStart", origin.tile_x, origin.tile_z, origin.x, origin.z)
        stf.line("MilepostUnitsKilometers")
        stf.end()
        stf.save(folder / f"{self.name}.trk")

    def _write_tsection(self, folder: Path) -> None:
        stf = StfWriter("JINX0T0t")
        sections = [s for segment in self.segments for s in segment.sections]
        stf.block("TrackSections", FIRST_SECTION_INDEX + len(sections) - 1)
        for section in sections:
            stf.line("TrackSection", *self._track_section(section))
        stf.end()
        stf.block("SectionIdx", len(sections))
        for section in sections:
            index = self.section_index[id(section)]
            stf.line("TrackPath", index, 1, index)
        stf.end()
        stf.save(folder / "tsection.dat")

    def switch_paths(self, node: _Node) -> list[tuple[float, float, float]]:
        """A junction's two paths, route 0 (left) then route 1 (right): ``(angle, length,
        curvature)``: the path's start direction from the junction's departing direction [deg,
        clockwise], and the first stretch of the route's adjacent section as seen from the
        junction (up to SWITCH_PATH_M; curvature positive to the right)."""
        segments = {s.index: s for s in self.segments}
        paths = []
        for vector, starts_here in node.pins[1:]:
            segment = segments[vector]
            if starts_here:
                section = segment.sections[0]
                curvature, heading = section.curvature, section.heading
            else:  # the route's section runs towards the junction: seen from it, reversed
                section = segment.sections[-1]
                curvature = -section.curvature
                heading = section.heading + section.curvature * section.length + math.pi
            angle = math.degrees(_heading(heading - node.heading))
            paths.append((angle, min(SWITCH_PATH_M, section.length), curvature))
        return paths

    def _write_track_shapes(self, folder: Path) -> None:
        """``OpenRails/tsection.dat`` in the global file's grammar, the file OpenRails reads
        instead of its installation's: the track sections of the junctions' paths (numbered
        from 1, two per junction) and one two-path track shape per junction. The dynamic
        track's sections stay in the route's own tsection.dat (numbered from 40000)."""
        junctions = [n for n in self.nodes if n.switch is not None]
        stf = StfWriter("JINX0F0t")  # the global file's type F (OpenRails does not check it)
        stf.block("TrackSections", 2 * len(junctions))
        for node in junctions:
            for route, (_, length, curvature) in enumerate(self.switch_paths(node)):
                stf.block("TrackSection", 2 * node.shape - 1 + route)
                if curvature == 0.0:
                    stf.line("SectionSize", 1.5, float32(length))
                else:
                    radius = 1.0 / abs(curvature)
                    stf.line("SectionSize", 1.5, 0)
                    degrees = math.copysign(math.degrees(length / radius), curvature)
                    stf.line("SectionCurve", float32(radius), float32(degrees))
                stf.end()
        stf.end()
        stf.block("TrackShapes", len(junctions))
        for node in junctions:
            stf.block("TrackShape", node.shape)
            stf.line("FileName", SWITCH_SHAPE)
            stf.line("NumPaths", 2)
            for route, (angle, _, _) in enumerate(self.switch_paths(node)):
                stf.line("SectionIdx", 1, 0, 0, 0, float32(angle), 2 * node.shape - 1 + route)
            stf.line("MainRoute", 0)  # SelectedRoute 0 (the left route) at start, as before
            stf.line("ClearanceDist", 0)
            stf.end()
        stf.end()
        stf.save(folder / "OpenRails" / "tsection.dat")

    def _track_section(self, section: Section) -> list[object]:
        """``SectionCurve ( c ) index a b`` of a route track section (or dynamic track)."""
        number = self.section_index[id(section)]
        if section.curvature == 0.0:
            return [_Raw("SectionCurve ( 0 )"), number, float32(section.length), 0]
        radius = float32(1.0 / abs(section.curvature))
        angle = float32(math.copysign(section.length / radius, section.curvature))
        return [_Raw("SectionCurve ( 1 )"), number, angle, radius]

    def _pitch(self, segment: _Segment, section: Section) -> float:
        """A section's pitch AX [rad]: ``-atan(gradient)``, negative climbs."""
        slope = self.lines[segment.line].model.gradient(section.start + section.length / 2.0)
        return -math.atan(slope / 1000.0)

    def _vector_section(self, segment: _Segment, section: Section) -> list[object]:
        point = self.frame.world(section.east, section.north)
        wf_x, wf_z, uid = self.section_uid[id(section)]
        index = self.section_index[id(section)]
        return [
            index,
            index,
            wf_x,
            wf_z,
            uid,
            0,
            1,
            "00",
            point.tile_x,
            point.tile_z,
            point.x,
            self.elevation(segment.line, section.start),
            point.z,
            self._pitch(segment, section),
            _heading(section.heading),
            0.0,
        ]

    def _write_tdb(
        self, folder: Path, world: dict[tuple[int, int], list[tuple[str, object]]]
    ) -> None:
        stf = StfWriter("JINX0T0t")
        stf.block("TrackDB")
        stf.line("Serial", 0)
        stf.block("TrackNodes", len(self.segments) + len(self.nodes))
        for segment in self.segments:
            stf.block("TrackNode", segment.index)
            stf.block("TrVectorNode")
            stf.block("TrVectorSections", len(segment.sections))
            for section in segment.sections:
                stf.values(*self._vector_section(segment, section))
            stf.end()
            if segment.items:
                stf.block("TrItemRefs", len(segment.items))
                for ref in sorted(segment.items, key=lambda i: self.items[i].offset):
                    stf.line("TrItemRef", ref)
                stf.end()
            stf.end()
            stf.block("TrPins", 1, 1)
            stf.line("TrPin", *segment.begin)
            stf.line("TrPin", *segment.finish)
            stf.end()
            stf.end()
        for node in self.nodes:
            stf.block("TrackNode", node.index)
            first = next(s for s in self.segments if s.index == node.pins[0][0])
            section = first.sections[0] if node.pins[0][1] == 1 else first.sections[-1]
            wf_x, wf_z, uid = self.section_uid[id(section)]
            point = self.frame.world(node.east, node.north)
            if node.switch is not None:
                # the junction's two-route track shape; its UiD names the TrackObj drawing it
                stf.line("TrJunctionNode", 0, node.shape, 0)
                wf_x, wf_z, uid = self.junction_uid[node.index]
            else:
                stf.line("TrEndNode", 0)
            stf.line(
                "UiD", wf_x, wf_z, uid, 0, point.tile_x, point.tile_z, point.x,
                node.elevation, point.z, 0.0, _heading(node.heading), 0.0,
            )  # fmt: skip
            stf.block("TrPins", 1, len(node.pins) - 1)
            for pin in node.pins:
                stf.line("TrPin", *pin)
            stf.end()
            stf.end()
        stf.end()
        if self.items:
            stf.block("TrItemTable", len(self.items))
            for index, item in enumerate(self.items):
                self._write_item(stf, index, item)
            stf.end()
        stf.end()
        stf.save(folder / f"{self.name}.tdb")

    def _write_item(self, stf: StfWriter, index: int, item: _Item) -> None:
        block = {"balise": "SpeedPostItem", "signal": "SignalItem", "platform": "PlatformItem"}
        stf.block(block[item.kind])
        stf.line("TrItemId", index)
        w = item.world
        stf.line("TrItemSData", item.offset, "00000002" if item.kind == "signal" else "00000000")
        stf.line("TrItemRData", w.x, item.elevation, w.z, w.tile_x, w.tile_z)
        stf.line("TrItemPData", w.x, w.z, w.tile_x, w.tile_z)
        payload = item.payload
        if item.kind == "balise":
            # a milepost whose number is the balise code (documented in openrails-route.md)
            stf.line("SpeedpostTrItemData", 0, int(str(payload["code"])), 0.0)
        elif item.kind == "signal":
            stf.line("TrSignalType", "00000000", int(str(payload["direction"])), 1.0, SIGNAL_TYPE)
        else:
            stf.line("PlatformName", quote(str(payload["name"])))
            stf.line("Station", quote(str(payload["name"])))
            stf.line("PlatformMinWaitingTime", 30)
            stf.line("PlatformNumPassengersWaiting", 0)
            stf.line("PlatformTrItemData", "00000000", int(str(payload["linked"])))
        stf.end()

    def _write_world(
        self, folder: Path, tile: tuple[int, int], objects: list[tuple[str, object]]
    ) -> None:
        stf = StfWriter("JINX0w2t")
        stf.block("Tr_Worldfile")
        for uid, (kind, thing) in enumerate(objects, start=1):
            if kind == "dyntrack":
                assert isinstance(thing, Section)
                self._write_dyntrack(stf, uid, tile, thing)
            elif kind == "switch":
                assert isinstance(thing, _Node)
                self._write_switch(stf, uid, thing)
            else:
                assert isinstance(thing, int)
                self._write_object(stf, uid, tile, kind, thing)
        stf.end()
        stf.save(folder / "WORLD" / world_file_name(*tile))

    def _write_dyntrack(
        self, stf: StfWriter, uid: int, tile: tuple[int, int], section: Section
    ) -> None:
        segment = next(s for s in self.segments if any(x is section for x in s.sections))
        stf.block("Dyntrack")
        stf.line("UiD", uid)
        stf.block("TrackSections")
        parts = self._track_section(section)
        empty = [[_Raw(f"SectionCurve ( {c} )"), NONE, 0, 0] for c in (0, 1, 0, 1, 0)]
        if section.curvature == 0.0:
            empty[0] = parts
        else:
            empty[1] = parts
        for part in empty:
            stf.line("TrackSection", *part)
        stf.end()
        stf.line("SectionIdx", self.section_index[id(section)])
        stf.line("Elevation", 0)
        stf.line("CollideFlags", 39)
        stf.line("StaticFlags", "00100000")
        point = self.frame.world(section.east, section.north)
        stf.line("Position", point.x, self.elevation(segment.line, section.start), point.z)
        # OpenRails draws dynamic track along the world object's orientation: the section's
        # heading and its pitch (the vector section's AX), so the rails follow the gradient
        stf.line("QDirection", *quaternion(section.heading, self._pitch(segment, section)))
        stf.line("VDbId", NONE)
        stf.end()

    def _write_switch(self, stf: StfWriter, uid: int, node: _Node) -> None:
        """A junction's TrackObj: its track shape, the junction it animates (JNodePosn), the
        switch stand shape, placed at the junction facing the trunk's departing direction."""
        point = self.frame.world(node.east, node.north)
        stf.block("TrackObj")
        stf.line("UiD", uid)
        stf.line("SectionIdx", node.shape)
        stf.line("Elevation", 0)
        stf.line("JNodePosn", point.tile_x, point.tile_z, point.x, node.elevation, point.z)
        stf.line("CollideFlags", 39)
        stf.line("FileName", SWITCH_SHAPE)
        stf.line("StaticFlags", "00100000")
        stf.line("Position", point.x, node.elevation, point.z)
        stf.line("QDirection", *quaternion(node.heading, 0.0))
        stf.line("VDbId", NONE)
        stf.end()

    def _write_object(
        self, stf: StfWriter, uid: int, tile: tuple[int, int], kind: str, index: int
    ) -> None:
        item = self.items[index]
        w = item.world
        if kind == "balise":
            stf.block("Static")
            stf.line("UiD", uid)
            stf.line("FileName", BALISE_SHAPE)
            stf.line("StaticFlags", f"{ANIMATED:08x}")
            stf.line("Position", w.x, item.elevation, w.z)
            stf.line("QDirection", *quaternion(item.heading, 0.0))
            stf.line("VDbId", NONE)
            stf.end()
            return
        facing = item.heading + (math.pi if item.payload["direction"] == 0 else 0.0)
        stf.block("Signal")
        stf.line("UiD", uid)
        stf.line("FileName", SIGNAL_SHAPE)
        stf.line("StaticFlags", "00000000")
        stf.line("Position", w.x, item.elevation, w.z)
        stf.line("QDirection", *quaternion(facing, 0.0))
        stf.line("VDbId", NONE)
        stf.line("SignalSubObj", "00000001")
        stf.block("SignalUnits", 1)
        stf.block("SignalUnit", 0)
        stf.line("TrItemId", 0, index)
        stf.end()
        stf.end()
        stf.end()

    def _write_signals(self, folder: Path) -> None:
        """A minimal sigcfg.dat (OpenRails needs one) with the route's one signal type."""
        stf = StfWriter("JINX0g0t")
        stf.block("LightTextures", 1)
        stf.line("LightTex", quote("ltex"), LIGHT_TEXTURE, 0, 0, 1, 1)
        stf.end()
        stf.block("LightsTab", 2)
        stf.block("LightsTabEntry", quote("Red Light"))
        stf.line("colour", 255, 255, 0, 0)
        stf.end()
        stf.block("LightsTabEntry", quote("Green Light"))
        stf.line("colour", 255, 0, 255, 0)
        stf.end()
        stf.end()
        stf.block("SignalTypes", 1)
        stf.block("SignalType", quote(SIGNAL_TYPE))
        stf.line("SignalFnType", "NORMAL")
        stf.line("SignalLightTex", quote("ltex"))
        stf.block("SignalLights", 2)
        for number, lamp in enumerate(("Red Light", "Green Light")):
            stf.block("SignalLight", number, quote(lamp))
            stf.line("Position", 0, 3 + number * 0.5, 0.1)
            stf.line("Radius", 0.15)
            stf.end()
        stf.end()
        stf.block("SignalDrawStates", 2)
        for number, (state, light) in enumerate((("Red", 0), ("Green", 1))):
            stf.block("SignalDrawState", number, quote(state))
            stf.block("DrawLights", 1)
            stf.line("DrawLight", light)
            stf.end()
            stf.end()
        stf.end()
        stf.block("SignalAspects", 2)
        stf.line("SignalAspect", "STOP", quote("Red"))
        stf.line("SignalAspect", "CLEAR_2", quote("Green"))
        stf.end()
        stf.line("SignalNumClearAhead", 2)
        stf.end()
        stf.end()
        stf.block("SignalShapes", 1)
        stf.block("SignalShape", quote(SIGNAL_SHAPE), quote("Coupler main signal"))
        stf.block("SignalSubObjs", 1)
        stf.block("SignalSubObj", 0, quote("HEAD1"), quote("Main head"))
        stf.line("SigSubType", "SIGNAL_HEAD")
        stf.line("SigSubSType", quote(SIGNAL_TYPE))
        stf.end()
        stf.end()
        stf.end()
        stf.end()
        stf.block("ScriptFiles")  # OpenRails' grammar: no count
        stf.line("ScriptFile", "sigscr.dat")
        stf.end()
        stf.save(folder / "sigcfg.dat")
        script = (
            f"SCRIPT {SIGNAL_TYPE}\r\n"
            "    if (block_state() ==# BLOCK_CLEAR) {\r\n"
            "        state = SIGASP_CLEAR_2;\r\n"
            "    } else {\r\n"
            "        state = SIGASP_STOP;\r\n"
            "    }\r\n"
            "    draw_state = def_draw_state(state);\r\n"
        )
        (folder / "sigscr.dat").write_bytes(b"\xff\xfe" + script.encode("utf-16-le"))

    # -- paths ----------------------------------------------------------------------------

    def _routes(self, start: _Node) -> list[tuple[_Node, list[_Node]]]:
        """Every end node reachable from end node ``start`` without reversing, with the
        junctions passed on the way."""
        by_index = {n.index: n for n in self.nodes}
        segments = {s.index: s for s in self.segments}
        found: list[tuple[_Node, list[_Node]]] = []
        queue: deque[tuple[int, int, list[_Node]]] = deque()
        vector, starts_here = start.pins[0]
        queue.append((vector, starts_here, []))
        while queue:
            vector, forward, passed = queue.popleft()
            segment = segments[vector]
            node_index, _ = segment.finish if forward else segment.begin
            node = by_index[node_index]
            if node.switch is None:
                if node is not start:
                    found.append((node, passed))
                continue
            entry = next(i for i, (v, _) in enumerate(node.pins) if v == vector)
            exits = [1, 2] if entry == 0 else [0]
            for pin in exits:
                nxt, starts = node.pins[pin]
                if len(passed) < len(self.nodes):
                    queue.append((nxt, starts, [*passed, node]))
        return found

    def _end_name(self, node: _Node) -> tuple[str, str]:
        """File stem (the id) and name of the station at a line end (within 200 m), else of the
        railML track there."""
        best: tuple[float, Station] | None = None
        for infra in self.lines:
            for station in infra.stations:
                east, north = (
                    float(v)
                    for v in infra.model.frame.to_local(station.latitude_deg, station.longitude_deg)
                )
                distance = math.hypot(east - node.east, north - node.north)
                if distance < 200.0 and (best is None or distance < best[0]):
                    best = (distance, station)
        if best is not None:
            station = best[1]
            return file_stem(station.id, self.file, station.line, "ocp"), station.name
        segment = next(s for s in self.segments if s.index == node.pins[0][0])
        tracks = self.lines[segment.line].tracks
        track = tracks[0] if node.pins[0][1] == 1 else tracks[-1]
        return file_stem(track.id, self.file, track.line, "track"), track.name

    def _plan_paths(self) -> list[tuple[str, tuple[str, str], list[_Node]]]:
        """Every path to write: (file stem, names of its ends, its nodes); worked out before
        anything is written, so an id that cannot name a file leaves no folder behind."""
        planned: list[tuple[str, tuple[str, str], list[_Node]]] = []
        stems: list[str] = []
        ends = [n for n in self.nodes if n.switch is None]
        for start in ends:
            for end, passed in self._routes(start):
                (first, first_name), (last, last_name) = self._end_name(start), self._end_name(end)
                stem = f"{first}-{last}"
                if stem in stems:  # two ends named alike (no station near)
                    stem = f"{stem}-{sum(w.startswith(stem) for w in stems) + 1}"
                stems.append(stem)
                planned.append((stem, (first_name, last_name), [start, *passed, end]))
        return planned

    def _write_paths(self, folder: Path) -> list[str]:
        for stem, names, nodes in self.paths:
            self._write_path(folder / "PATHS" / f"{stem}.pat", stem, names, nodes)
        return sorted(f"PATHS/{stem}.pat" for stem, _, _ in self.paths)

    def _write_path(
        self, path: Path, stem: str, names: tuple[str, str], nodes: list[_Node]
    ) -> None:
        stf = StfWriter("JINX0P0t")
        stf.line("Serial", 1)
        stf.block("TrackPDPs")
        for i, node in enumerate(nodes):
            point = self.frame.world(node.east, node.north)
            flags = (1, 1) if i in (0, len(nodes) - 1) else (2, 0)
            stf.line(
                "TrackPDP", point.tile_x, point.tile_z, point.x, node.elevation, point.z, *flags
            )
        stf.end()
        stf.block("TrackPath")
        stf.line("TrPathName", quote(stem))
        stf.line("Name", quote(f"{names[0]} - {names[1]}"))
        stf.line("TrPathStart", quote(names[0]))
        stf.line("TrPathEnd", quote(names[1]))
        stf.block("TrPathNodes", len(nodes))
        for i in range(len(nodes)):
            following = i + 1 if i + 1 < len(nodes) else NONE
            stf.line("TrPathNode", "00000000", following, NONE, i)
        stf.end()
        stf.end()
        stf.save(path)


_UNSAFE = re.compile(r'[\x00-\x1f\x7f<>:"/\\|?*]')
_DEVICES = {
    "con",
    "prn",
    "aux",
    "nul",
    *(f"com{i}" for i in range(10)),
    *(f"lpt{i}" for i in range(10)),
}


def file_stem(ident: str, file: str, line: int, element: str) -> str:
    """A railML id as the stem of a file in the route folder (a path's ``PATHS/<from>-<to>``):
    the id as it is, or RailMLError naming its line when it could name a file elsewhere or
    none at all -- a path separator (``../../x``, ``/etc/x``, ``C:\\x``), ``..``, a control
    character, a character or device name Windows (OpenRails' platform) forbids."""
    if (
        not ident
        or ident in (".", "..")
        or _UNSAFE.search(ident)
        or ident != ident.strip()
        or ident.endswith(".")
        or ident.split(".")[0].lower() in _DEVICES
    ):
        shown = ident.encode("unicode_escape").decode("ascii")  # a newline as \n, on one line
        raise RailMLError(
            file,
            line,
            f'<{element} id="{shown}">',
            "its id names the route's path files, and this one cannot be a file name in the "
            "route folder (a path separator, '..', a control or reserved character)",
            "give it an id of letters, digits, '-', '_' and '.'",
        )
    return ident


def _stretches(
    steps: tuple[tuple[float, float], ...], length: float
) -> list[tuple[float, float, float]]:
    """``(start, end, slope)`` of every constant-gradient stretch from the gradient steps."""
    if not steps:
        return []
    ends = [d for d, _ in steps[1:]] + [length]
    return [(d, end, slope) for (d, slope), end in zip(steps, ends, strict=True)]


class _Raw(str):
    """Text written as is (a nested block on the same line)."""


def _heading(radians: float) -> float:
    """A heading wrapped to [-pi, pi) (OpenRails' AY)."""
    return (radians + math.pi) % (2.0 * math.pi) - math.pi


def quaternion(heading: float, pitch: float) -> tuple[float, float, float, float]:
    """QDirection ``(x, y, z, w)`` of an object turned ``heading`` clockwise from north about
    the vertical, then pitched by ``pitch`` about its own x axis (OpenRails' AX: negative
    raises its front, so its forward axis is ``(sin h cos p, -sin p, cos h cos p)``)."""
    sy, cy = math.sin(heading / 2.0), math.cos(heading / 2.0)
    sx, cx = math.sin(pitch / 2.0), math.cos(pitch / 2.0)
    return cy * sx, sy * cx, -sy * sx, cy * cx
