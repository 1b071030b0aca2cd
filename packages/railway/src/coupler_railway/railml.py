"""railML 2.x infrastructure reader: tracks with geo coordinates, gradients, balises, signals,
platform edges, switches, ocps.

The subset read and the representation choices are described in the package README. Every
element outside that subset is reported in ``Infrastructure.warnings``; every inconsistency
raises :class:`~coupler_railway.errors.RailMLError` naming file:line, the element and the fix.
"""

from __future__ import annotations

import itertools
import math
import os
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from coupler_railway.errors import RailMLError
from coupler_railway.frame import LocalFrame
from coupler_railway.infrastructure import (
    Balise,
    BaliseGroup,
    Infrastructure,
    Network,
    PlatformEdge,
    Signal,
    Station,
    Switch,
    Track,
)
from coupler_railway.track import GradientChange, SectionGeometry, TrackModel, TrackSection

_INTERPRETED = frozenset(
    {
        "railml", "infrastructure", "tracks", "track", "trackTopology", "trackBegin",
        "trackEnd", "connection", "bufferStop", "openEnd", "geoCoord", "trackElements",
        "geoMappings", "geoMapping", "gradientChanges", "gradientChange", "ocsElements",
        "balises", "balise", "baliseGroup", "baliseRef", "operationControlPoints", "ocp",
        "metadata", "connections", "switch", "signals", "signal", "platformEdges", "platformEdge",
    }
)  # fmt: skip
_DIRECTIONS = frozenset({"up", "down", "both", "none", "unknown"})
_SIDES = frozenset({"left", "right"})
PLATFORM_HEIGHT_M = 0.76
"""A platform edge's height when railML gives none (the European standard height)."""
_WGS84 = frozenset({"4326", "EPSG:4326", "urn:ogc:def:crs:EPSG::4326"})


def load_infrastructure(
    path: str | os.PathLike[str], *, tolerance_m: float = 5.0
) -> Infrastructure:
    """Read a railML 2.x file of one line into an :class:`Infrastructure`.

    ``tolerance_m`` bounds every disagreement between declared positions (pos, absPos) and
    coordinates, and how far a balise's coordinates may lie from the track. A file whose tracks
    form several lines joined by switches is refused: read it with :func:`load_network`.
    """
    return _Reader(Path(path), tolerance_m).read()


def load_network(path: str | os.PathLike[str], *, tolerance_m: float = 5.0) -> Network:
    """Read a railML 2.x file of lines joined by switches into a :class:`Network`.

    A file of one line gives a network of one line; the checks are those of
    :func:`load_infrastructure`, plus every switch's connection to the line it branches to.
    """
    return _Reader(Path(path), tolerance_m).read_network()


@dataclass(frozen=True)
class _Point:
    pos: float
    """Offset from the trackBegin [m]."""
    latitude_deg: float
    longitude_deg: float
    element: etree._Element


@dataclass(frozen=True)
class _RawTrack:
    track: Track
    element: etree._Element
    points: tuple[_Point, ...]
    begin_connection: etree._Element | None
    end_connection: etree._Element | None
    switches: tuple[etree._Element, ...]


@dataclass(frozen=True)
class _Line:
    tracks: list[_RawTrack]
    begin_switch: etree._Element | None
    """The switch connection the line's first trackBegin connects to, if any."""
    end_switch: etree._Element | None


def _local(element: etree._Element) -> str:
    return etree.QName(element).localname


def _children(element: etree._Element, *names: str) -> list[etree._Element]:
    """Descendants along the path of local names ``names`` (namespace-agnostic)."""
    current = [element]
    for name in names:
        current = [c for e in current for c in e if isinstance(c.tag, str) and _local(c) == name]
    return current


class _Reader:
    def __init__(self, path: Path, tolerance_m: float) -> None:
        self.path = path
        self.file = str(path)
        self.tolerance = tolerance_m
        self.warnings: list[str] = []

    # -- errors and attribute access --------------------------------------------------------

    def error(self, element: etree._Element | None, problem: str, fix: str) -> RailMLError:
        if element is None:
            return RailMLError(self.file, None, None, problem, fix)
        ident = element.get("id")
        name = f'<{_local(element)} id="{ident}">' if ident else f"<{_local(element)}>"
        return RailMLError(self.file, element.sourceline, name, problem, fix)

    def number(self, element: etree._Element, attribute: str) -> float | None:
        text = element.get(attribute)
        if text is None:
            return None
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise self.error(
                element, f"attribute {attribute}={text!r} is not a number", "give a decimal value"
            )
        return value

    def integer(self, element: etree._Element, attribute: str, meaning: str) -> int:
        text = element.get(attribute)
        try:
            return int(text.strip()) if text is not None else int("missing")
        except ValueError:
            raise self.error(
                element,
                f"{attribute}={text!r} is not an integer, but it is the {meaning}",
                f'set {attribute}="<integer>", unique in the file',
            ) from None

    def geo(self, element: etree._Element) -> tuple[float, float] | None:
        coords = _children(element, "geoCoord")
        if not coords:
            return None
        geo = coords[0]
        epsg = geo.get("epsgCode")
        if epsg is not None and epsg not in _WGS84:
            raise self.error(geo, f"epsgCode {epsg!r} is not supported", "give WGS84 (4326)")
        try:
            values = [float(v) for v in (geo.get("coord") or "").split()]
        except ValueError:
            values = []
        if (
            len(values) < 2
            or not all(math.isfinite(v) for v in values)
            or not (-90.0 <= values[0] <= 90.0 and -180.0 <= values[1] <= 180.0)
        ):
            raise self.error(
                geo,
                f"coord={geo.get('coord')!r} is not a WGS84 'latitude longitude' pair",
                'write coord="50.5766 13.0104" (latitude first, decimal degrees)',
            )
        return values[0], values[1]

    def altitude(self, element: etree._Element) -> float | None:
        """The altitude [m] a geoCoord gives as its third value ("lat lon altitude"), if any."""
        coords = _children(element, "geoCoord")
        values = (coords[0].get("coord") or "").split() if coords else []
        if len(values) < 3:
            return None
        try:
            altitude = float(values[2])
        except ValueError:
            altitude = math.nan
        if not math.isfinite(altitude):
            raise self.error(
                coords[0],
                f"coord={coords[0].get('coord')!r} has {values[2]!r} as its altitude",
                'write the altitude in metres as the third value: coord="50.5766 13.0104 545.0"',
            )
        return altitude

    # -- reading ----------------------------------------------------------------------------

    def read(self) -> Infrastructure:
        network = self.read_network()
        if len(network.lines) != 1:
            starts = ", ".join(repr(line.tracks[0].id) for line in network.lines)
            raise RailMLError(
                self.file,
                None,
                None,
                f"has {len(network.lines)} lines (beginning with tracks {starts}) joined by "
                "switches; this reader takes one line",
                "read it with load_network (coupler-railway export-openrails does), or chain the "
                "tracks end to begin into one line",
            )
        return network.lines[0]

    def read_network(self) -> Network:
        parser = etree.XMLParser(
            resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False
        )
        try:
            root = etree.parse(self.file, parser).getroot()
        except etree.XMLSyntaxError as exc:
            raise RailMLError(
                self.file, exc.lineno, None, f"malformed XML: {exc.msg}", "fix the XML syntax"
            ) from exc
        except OSError as exc:  # lxml: unreadable file, or bytes invalid in its encoding
            raise RailMLError(
                self.file,
                None,
                None,
                f"cannot read it as XML: {exc}",
                "check that it is a railML file in UTF-8 (or the encoding it declares)",
            ) from exc
        if _local(root) != "railml":
            raise self.error(root, "the root element is not <railml>", "give a railML 2.x file")
        self.check_ids(root)
        self.report_unsupported(root)
        infrastructures = _children(root, "infrastructure")
        if not infrastructures:
            raise self.error(root, "has no <infrastructure>", "add <infrastructure><tracks>")
        infra = infrastructures[0]

        raw_lines = self.chain(
            [self.read_track(t) for t in _children(infra, "tracks", "track")], infra
        )
        frame: LocalFrame | None = None
        models: list[TrackModel] = []
        for raw in (line.tracks for line in raw_lines):
            models.append(self.build_model(raw, frame))
            frame = models[0].frame
        switches = self.place_switches(raw_lines, models)
        placed: dict[str, tuple[float, etree._Element]] = {}
        line_of: dict[str, int] = {}
        for index, (line, model) in enumerate(zip(raw_lines, models, strict=True)):
            for r, section in zip(line.tracks, model.sections, strict=True):
                for b in _children(r.element, "ocsElements", "balises", "balise"):
                    placed[b.get("id", "")] = self.place(b, r, section, model)
                    line_of[b.get("id", "")] = index
        balises, groups = self.group_balises(
            [r for line in raw_lines for r in line.tracks], placed, models, line_of
        )
        stations = self.read_stations(infra, models)
        lines = []
        for index, (line, model) in enumerate(zip(raw_lines, models, strict=True)):
            lines.append(
                Infrastructure(
                    source=self.path,
                    tracks=tuple(r.track for r in line.tracks),
                    model=model,
                    balises=tuple(b for b in balises if line_of[b.id] == index),
                    groups=tuple(g for g in groups if line_of[g.balise_ids[0]] == index),
                    stations=tuple(s for s, i in stations if i == index),
                    warnings=tuple(self.warnings),
                    signals=self.read_signals(line.tracks, model),
                    platform_edges=self.read_platform_edges(line.tracks, model),
                    switches=tuple(sorted(switches[index], key=lambda w: w.distance_m)),
                    altitude_m=self.start_altitude(line),
                )
            )
        return Network(source=self.path, lines=tuple(lines), warnings=tuple(self.warnings))

    def start_altitude(self, line: _Line) -> float | None:
        """The altitude of a line's first point (its first trackBegin's geoCoord), if given."""
        first = line.tracks[0].points[0]
        return self.altitude(first.element) if first.pos == 0.0 else None

    def check_ids(self, root: etree._Element) -> None:
        seen: dict[str, etree._Element] = {}
        for element in root.iter():
            if not isinstance(element.tag, str) or (ident := element.get("id")) is None:
                continue
            if ident in seen:
                raise self.error(
                    element,
                    f"duplicate id {ident!r} (first used at line {seen[ident].sourceline})",
                    "give every element a unique id",
                )
            seen[ident] = element

    def report_unsupported(self, root: etree._Element) -> None:
        found: Counter[str] = Counter()
        first: dict[str, int | None] = {}
        stack = [root]
        while stack:
            element = stack.pop()
            for child in element:
                if not isinstance(child.tag, str):
                    continue
                name = _local(child)
                if name == "metadata":
                    continue
                if (
                    name in _INTERPRETED
                    and etree.QName(child).namespace == etree.QName(root).namespace
                ):
                    stack.append(child)
                else:
                    found[name] += 1
                    first.setdefault(name, _line(child))
        for name in sorted(found, key=lambda n: first[n] or 0):
            self.warnings.append(
                f"{self.file}:{first[name]}: unsupported element <{name}> ignored "
                f"({found[name]} in the file)"
            )

    def read_track(self, element: etree._Element) -> _RawTrack:
        ident = element.get("id", "")
        begins = _children(element, "trackTopology", "trackBegin")
        ends = _children(element, "trackTopology", "trackEnd")
        if not begins or not ends:
            raise self.error(
                element, "has no trackTopology/trackBegin and trackEnd", "add both, with pos"
            )
        begin, end = begins[0], ends[0]
        begin_pos = self.number(begin, "pos") or 0.0
        end_pos = self.number(end, "pos")
        if end_pos is None or end_pos <= begin_pos:
            raise self.error(end, f"pos must exceed trackBegin pos {begin_pos}", "fix pos")
        track = Track(
            id=ident,
            name=element.get("name") or ident,
            begin_pos=begin_pos,
            end_pos=end_pos,
            begin_abs_pos=self.number(begin, "absPos"),
            end_abs_pos=self.number(end, "absPos"),
            line=element.sourceline or 0,
        )
        points: list[_Point] = []
        mappings = _children(element, "trackElements", "geoMappings", "geoMapping")
        for point, offset in (
            (begin, 0.0),
            *((m, self.offset(m, track, required=True)) for m in mappings),
            (end, end_pos - begin_pos),
        ):
            geo = self.geo(point)
            if geo is not None and offset is not None:
                points.append(_Point(offset, *geo, point))
        points.sort(key=lambda p: p.pos)
        if len(points) < 2:
            raise self.error(
                element,
                "has no coordinates (needs at least two geo points)",
                'add <geoCoord coord="lat lon"/> to trackBegin and trackEnd, or '
                "trackElements/geoMappings/geoMapping elements with pos and geoCoord",
            )
        for a, b in itertools.pairwise(points):
            if b.pos <= a.pos:
                raise self.error(
                    b.element, f"pos {b.pos + begin_pos} repeats a position", "fix pos"
                )
        connections = [_children(e, "connection") for e in (begin, end)]
        return _RawTrack(
            track,
            element,
            tuple(points),
            connections[0][0] if connections[0] else None,
            connections[1][0] if connections[1] else None,
            tuple(_children(element, "trackTopology", "connections", "switch")),
        )

    def offset(
        self, element: etree._Element, track: Track, *, required: bool = False
    ) -> float | None:
        """Position relative to the track begin from pos and/or absPos (checked to agree)."""
        pos = self.number(element, "pos")
        abs_pos = self.number(element, "absPos")
        from_pos = None if pos is None else pos - track.begin_pos
        from_abs = (
            None
            if abs_pos is None or track.begin_abs_pos is None
            else abs_pos - track.begin_abs_pos
        )
        if (
            from_pos is not None
            and from_abs is not None
            and (abs(from_pos - from_abs) > self.tolerance)
        ):
            raise self.error(
                element,
                f"pos {pos} and absPos {abs_pos} disagree by {abs(from_pos - from_abs):.3f} m "
                f"(track {track.id!r} begins at pos {track.begin_pos}, absPos "
                f"{track.begin_abs_pos}; tolerance {self.tolerance} m)",
                "correct pos or absPos",
            )
        value = from_pos if from_pos is not None else from_abs
        if value is None and required:
            raise self.error(element, "has no pos", "add pos (metres from trackBegin)")
        return value

    def chain(self, tracks: list[_RawTrack], infra: etree._Element) -> list[_Line]:
        """Tracks into lines: trackEnd connection -> next trackBegin connection. A line ends at
        a buffer stop or open end (no connection) or at a switch of another track."""
        if not tracks:
            raise self.error(infra, "has no tracks", "add <tracks><track> elements")
        begins = {r.begin_connection.get("id"): r for r in tracks if r.begin_connection is not None}
        switch_connections = {
            c.get("id"): (c, switch)
            for r in tracks
            for switch in r.switches
            for c in _children(switch, "connection")
        }

        def at_switch(connection: etree._Element) -> etree._Element | None:
            found = switch_connections.get(connection.get("ref"))
            if found is None:
                return None
            if found[0].get("ref") != connection.get("id"):
                raise self.error(
                    connection,
                    f"ref {connection.get('ref')!r} names a switch connection that does not refer "
                    "back to it",
                    f"set that switch connection's ref to {connection.get('id')!r}",
                )
            return found[0]

        starts = [
            r
            for r in tracks
            if r.begin_connection is None or at_switch(r.begin_connection) is not None
        ]
        if not starts:
            raise self.error(
                tracks[0].element,
                "no track begins a line (every trackBegin connects to another track's end)",
                "the line must have two ends: give its first track a trackBegin without a "
                "connection (a bufferStop or openEnd)",
            )
        starts.sort(key=lambda r: r.begin_connection is not None)
        lines: list[_Line] = []
        seen: set[int] = set()
        for first in starts:
            ordered = [first]
            seen.add(id(first))
            end_switch = None
            while (connection := ordered[-1].end_connection) is not None:
                end_switch = at_switch(connection)
                if end_switch is not None:
                    break
                following = begins.get(connection.get("ref"))
                if (
                    following is None
                    or following.begin_connection is None
                    or (following.begin_connection.get("ref") != connection.get("id"))
                ):
                    raise self.error(
                        connection,
                        f"ref {connection.get('ref')!r} is neither a trackBegin connection nor a "
                        "switch connection that refers back to it",
                        "set ref to the next track's trackBegin/connection id (or a switch "
                        "connection's id) and that one's ref to this id",
                    )
                if id(following) in seen:
                    raise self.error(connection, "closes a loop", "the line must have two ends")
                ordered.append(following)
                seen.add(id(following))
            begin_switch = (
                at_switch(first.begin_connection) if first.begin_connection is not None else None
            )
            lines.append(_Line(ordered, begin_switch, end_switch))
        for r in tracks:
            if id(r) not in seen:
                raise self.error(
                    r.element, "is not connected to the line", "chain it by connections"
                )
        self.check_junctions(lines)
        return lines

    def check_junctions(self, lines: list[_Line]) -> None:
        """Each track of a line begins where the one before it ends (within the tolerance)."""
        for line in lines:
            for a, b in itertools.pairwise(line.tracks):
                gap = _distance(a.points[-1], b.points[0])
                if gap > self.tolerance:
                    raise self.error(
                        b.points[0].element,
                        f"is {gap:.1f} m away from the end of track {a.track.id!r}",
                        "make the coordinates at the junction coincide",
                    )

    def build_model(self, raw: list[_RawTrack], frame: LocalFrame | None) -> TrackModel:
        gradients: list[GradientChange] = []
        for index, r in enumerate(raw):
            path = ("trackElements", "gradientChanges", "gradientChange")
            for change in _children(r.element, *path):
                offset = self.offset(change, r.track, required=True)
                slope = self.number(change, "slope")
                if slope is None or offset is None:
                    raise self.error(change, "has no slope", "add slope (per mille)")
                gradients.append(GradientChange(index, offset, slope))
        model = TrackModel.build(
            [
                SectionGeometry(
                    r.track.id,
                    r.track.name,
                    tuple(p.latitude_deg for p in r.points),
                    tuple(p.longitude_deg for p in r.points),
                )
                for r in raw
            ],
            gradients,
            frame=frame,
        )
        for r, section in zip(raw, model.sections, strict=True):
            declared = r.track.end_pos - r.track.begin_pos
            for point in r.points:
                along = model.project(point.latitude_deg, point.longitude_deg)
                expected = section.start_distance + point.pos
                if abs(along - expected) > self.tolerance:
                    raise self.error(
                        point.element,
                        f"pos {point.pos + r.track.begin_pos} disagrees with its coordinates, "
                        f"which lie "
                        f"{along - section.start_distance:.3f} m into track {r.track.id!r} "
                        f"(tolerance {self.tolerance} m)",
                        "correct pos/absPos or the geoCoord",
                    )
            if abs(section.length - declared) > self.tolerance:
                raise self.error(
                    r.element,
                    f"is declared {declared} m long but its coordinates span "
                    f"{section.length:.3f} m (tolerance {self.tolerance} m)",
                    "correct trackEnd pos or give coordinates up to the track's end",
                )
        return model

    def place(
        self, element: etree._Element, raw: _RawTrack, section: TrackSection, model: TrackModel
    ) -> tuple[float, etree._Element]:
        """Distance along the line of a balise or signal on ``raw`` (its ``section``)."""
        track = raw.track
        off_track = f"place it on track {track.id!r} (pos 0..{track.end_pos - track.begin_pos})"
        offset = self.offset(element, track)
        geo = self.geo(element)
        if offset is None and geo is None:
            raise self.error(element, "has neither pos/absPos nor geoCoord", "give pos")
        distance = None
        if offset is not None:
            if offset < 0.0 or offset > track.end_pos - track.begin_pos:
                raise self.error(
                    element, f"lies off the track: offset {offset} m from trackBegin", off_track
                )
            distance = min(section.start_distance + offset, model.length)
        if geo is not None:
            along, lateral = model.nearest(*geo)
            if lateral > self.tolerance:
                raise self.error(
                    element,
                    f"lies off the track: its coordinates are {lateral:.1f} m from it "
                    f"(tolerance {self.tolerance} m)",
                    "correct the geoCoord",
                )
            if distance is None:
                end = section.start_distance + section.length
                if not section.start_distance - self.tolerance <= along <= end + self.tolerance:
                    raise self.error(
                        element,
                        f"lies off the track: its coordinates project to {along:.1f} m along "
                        f"the line, outside track {track.id!r} "
                        f"({section.start_distance:.1f}..{end:.1f} m)",
                        "move it into the <track> it lies on",
                    )
                distance = along
            elif abs(along - distance) > self.tolerance:
                raise self.error(
                    element,
                    f"pos/absPos puts it at {distance:.3f} m but its coordinates at "
                    f"{along:.3f} m along the line (tolerance {self.tolerance} m)",
                    "correct pos/absPos or the geoCoord",
                )
        assert distance is not None
        return distance, element

    def group_balises(
        self,
        raw: list[_RawTrack],
        placed: dict[str, tuple[float, etree._Element]],
        models: list[TrackModel],
        line_of: dict[str, int],
    ) -> tuple[tuple[Balise, ...], tuple[BaliseGroup, ...]]:
        membership: dict[str, tuple[int, int, etree._Element]] = {}
        groups: list[BaliseGroup] = []
        group_codes: dict[int, etree._Element] = {}
        for r in raw:
            for group in _children(r.element, "ocsElements", "balises", "baliseGroup"):
                code = self.integer(group, "code", "numeric balise group id")
                if code in group_codes:
                    raise self.error(
                        group,
                        f"group code {code} is already used at line {group_codes[code].sourceline}",
                        "give every baliseGroup a unique integer code",
                    )
                group_codes[code] = group
                refs = [ref.get("ref", "") for ref in _children(group, "baliseRef")]
                if not refs:
                    raise self.error(group, "has no baliseRef", "add <baliseRef ref=balise id>")
                for rank, (ref, ref_element) in enumerate(
                    zip(refs, _children(group, "baliseRef"), strict=True), start=1
                ):
                    if ref not in placed:
                        raise self.error(ref_element, f"ref {ref!r} is no balise", "fix ref")
                    if ref in membership:
                        raise self.error(
                            ref_element,
                            f"balise {ref!r} is already in the group at line "
                            f"{membership[ref][2].sourceline}",
                            "put each balise in exactly one baliseGroup",
                        )
                    membership[ref] = (code, rank, group)
                if len({line_of[ref] for ref in refs}) > 1:
                    raise self.error(
                        group,
                        "has balises on lines joined by a switch",
                        "keep the balises of a group on one line",
                    )
                groups.append(
                    BaliseGroup(
                        id=group.get("id", ""),
                        code=code,
                        name=group.get("name") or group.get("id", ""),
                        type=group.get("type", ""),
                        balise_ids=tuple(refs),
                        distance_m=min(placed[ref][0] for ref in refs),
                        line=group.sourceline or 0,
                    )
                )
        balises: list[Balise] = []
        codes: dict[int, etree._Element] = {}
        for ident, (distance, element) in placed.items():
            code = self.integer(element, "code", "numeric balise id (FMU Integer channel)")
            if code in codes:
                raise self.error(
                    element,
                    f"balise code {code} is already used at line {codes[code].sourceline}",
                    "give every balise a unique integer code",
                )
            codes[code] = element
            if ident not in membership:
                raise self.error(
                    element,
                    "belongs to no baliseGroup",
                    f'add <baliseRef ref="{ident}"/> to a <baliseGroup>',
                )
            direction = element.get("dir", "unknown")
            if direction not in _DIRECTIONS:
                raise self.error(
                    element, f"dir {direction!r} is unknown", f"use one of {sorted(_DIRECTIONS)}"
                )
            point = models[line_of[ident]].position(distance)
            group_code, rank, _ = membership[ident]
            balises.append(
                Balise(
                    id=ident,
                    code=code,
                    name=element.get("name") or ident,
                    group=group_code,
                    position_in_group=rank,
                    distance_m=distance,
                    direction=direction,
                    latitude_deg=point.latitude_deg,
                    longitude_deg=point.longitude_deg,
                    line=element.sourceline or 0,
                )
            )
        balises.sort(key=lambda b: (b.distance_m, b.group, b.position_in_group))
        groups.sort(key=lambda g: (g.distance_m, g.code))
        return tuple(balises), tuple(groups)

    def read_stations(
        self, infra: etree._Element, models: list[TrackModel]
    ) -> list[tuple[Station, int]]:
        """Every ocp with coordinates, projected onto the nearest line: (station, line index)."""
        stations: list[tuple[Station, int]] = []
        for ocp in _children(infra, "operationControlPoints", "ocp"):
            geo = self.geo(ocp)
            if geo is None:
                self.warnings.append(
                    f'{self.file}:{ocp.sourceline}: <ocp id="{ocp.get("id")}"> has no '
                    "geoCoord and is not placed"
                )
                continue
            nearest = [model.nearest(*geo) for model in models]
            index = min(range(len(models)), key=lambda i: nearest[i][1])
            along, lateral = nearest[index]
            stations.append(
                (
                    Station(
                        id=ocp.get("id", ""),
                        name=ocp.get("name") or ocp.get("id", ""),
                        latitude_deg=geo[0],
                        longitude_deg=geo[1],
                        distance_m=along,
                        offset_m=lateral,
                        line=ocp.sourceline or 0,
                    ),
                    index,
                )
            )
        return sorted(stations, key=lambda s: (s[1], s[0].distance_m))

    def read_signals(self, raw: list[_RawTrack], model: TrackModel) -> tuple[Signal, ...]:
        signals: list[Signal] = []
        for r, section in zip(raw, model.sections, strict=True):
            for element in _children(r.element, "ocsElements", "signals", "signal"):
                distance, _ = self.place(element, r, section, model)
                direction = element.get("dir", "unknown")
                if direction not in _DIRECTIONS:
                    raise self.error(
                        element,
                        f"dir {direction!r} is unknown",
                        f"use one of {sorted(_DIRECTIONS)}",
                    )
                signals.append(
                    Signal(
                        id=element.get("id", ""),
                        name=element.get("name") or element.get("id", ""),
                        distance_m=distance,
                        direction=direction,
                        type=element.get("type", ""),
                        function=element.get("function", ""),
                        side="left" if direction == "down" else "right",
                        line=element.sourceline or 0,
                    )
                )
        return tuple(sorted(signals, key=lambda s: s.distance_m))

    def read_platform_edges(
        self, raw: list[_RawTrack], model: TrackModel
    ) -> tuple[PlatformEdge, ...]:
        edges = [
            self.read_platform_edge(element, r, section, model)
            for r, section in zip(raw, model.sections, strict=True)
            for element in _children(r.element, "trackElements", "platformEdges", "platformEdge")
        ]
        return tuple(sorted(edges, key=lambda e: e.start_m))

    def read_platform_edge(
        self, element: etree._Element, raw: _RawTrack, section: TrackSection, model: TrackModel
    ) -> PlatformEdge:
        """A platform edge from where it begins (pos/absPos or geoCoord) over ``length`` metres,
        on ``side``, ``height`` metres above the rails (default 0.76)."""
        begin, _ = self.place(element, raw, section, model)
        length = self.number(element, "length")
        if length is None or length <= 0.0:
            raise self.error(element, "has no positive length", "give length in metres")
        if begin + length > model.length + self.tolerance:
            raise self.error(
                element,
                f"runs {begin + length - model.length:.1f} m past the end of the line",
                "shorten it",
            )
        side = element.get("side")
        if side not in _SIDES:
            raise self.error(
                element, f"side {side!r} is not 'left' or 'right'", 'give side="left"/"right"'
            )
        height = self.number(element, "height")
        if height is None:
            height = PLATFORM_HEIGHT_M
        if not 0.0 < height <= 2.0:
            raise self.error(
                element, f"height {height} m is not in (0, 2]", "give height in metres"
            )
        return PlatformEdge(
            id=element.get("id", ""),
            name=element.get("name") or element.get("id", ""),
            start_m=begin,
            end_m=min(begin + length, model.length),
            side=side,
            height_m=height,
            line=_line(element),
        )

    def place_switches(self, lines: list[_Line], models: list[TrackModel]) -> list[list[Switch]]:
        """Every switch on its line, with the line that branches off it; checked to meet."""
        owner = {
            id(c): index
            for index, line in enumerate(lines)
            for c in (line.begin_switch, line.end_switch)
            if c is not None
        }
        found: list[list[Switch]] = [[] for _ in lines]
        for index, (line, model) in enumerate(zip(lines, models, strict=True)):
            for r, section in zip(line.tracks, model.sections, strict=True):
                for switch in r.switches:
                    connections = _children(switch, "connection")
                    if len(connections) != 1:
                        raise self.error(
                            switch,
                            f"has {len(connections)} connections",
                            "give a switch exactly one <connection> (to its branch track)",
                        )
                    connection = connections[0]
                    branch = owner.get(id(connection))
                    if branch is None:
                        raise self.error(
                            connection,
                            f"ref {connection.get('ref')!r} is not the trackBegin or trackEnd "
                            "connection of the first or last track of a line",
                            "set ref to the connection id of the branch track's trackBegin (or "
                            "trackEnd) and that one's ref to this id",
                        )
                    if branch == index:
                        raise self.error(
                            connection, "connects the line to itself", "branch to another line"
                        )
                    offset = self.offset(switch, r.track, required=True)
                    assert offset is not None
                    if not 0.0 <= offset <= section.length + self.tolerance:
                        raise self.error(
                            switch,
                            f"lies off its track: offset {offset} m from trackBegin",
                            f"place it on track {r.track.id!r}",
                        )
                    distance = min(section.start_distance + offset, model.length)
                    begins = lines[branch].begin_switch is connection
                    branch_model = models[branch]
                    there = branch_model.local_xy([0.0 if begins else branch_model.length])[0]
                    here = model.local_xy([distance])[0]
                    gap = math.hypot(*(there - here))
                    meets = lines[branch].tracks[0 if begins else -1].track.id
                    if gap > self.tolerance:
                        raise self.error(
                            switch,
                            f"is {gap:.1f} m away from the "
                            f"{'beginning' if begins else 'end'} of track "
                            f"{meets!r}"
                            f" that branches off it (tolerance {self.tolerance} m)",
                            "correct the switch's pos or the branch track's coordinates",
                        )
                    found[index].append(
                        Switch(
                            id=switch.get("id", ""),
                            name=switch.get("name") or switch.get("id", ""),
                            distance_m=distance,
                            branch=branch,
                            branch_begins=begins,
                            course=connection.get("course", ""),
                            line=switch.sourceline or 0,
                        )
                    )
        return found


def _distance(a: _Point, b: _Point) -> float:
    """Approximate ground distance between two points [m] (local equirectangular)."""
    north = math.radians(b.latitude_deg - a.latitude_deg) * 6371008.8
    east = (
        math.radians(b.longitude_deg - a.longitude_deg)
        * 6371008.8
        * math.cos(math.radians(a.latitude_deg))
    )
    return math.hypot(north, east)


def _line(element: etree._Element) -> int:
    line = element.sourceline
    return line if isinstance(line, int) else 0
