"""railML 2.x infrastructure reader: tracks with geo coordinates, gradients, balises, signals,
platform edges, ocps.

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
from coupler_railway.infrastructure import (
    Balise,
    BaliseGroup,
    Infrastructure,
    PlatformEdge,
    Signal,
    Station,
    Track,
)
from coupler_railway.track import GradientChange, SectionGeometry, TrackModel

_INTERPRETED = frozenset(
    {
        "railml", "infrastructure", "tracks", "track", "trackTopology", "trackBegin",
        "trackEnd", "connection", "bufferStop", "openEnd", "geoCoord", "trackElements",
        "geoMappings", "geoMapping", "gradientChanges", "gradientChange", "ocsElements",
        "balises", "balise", "baliseGroup", "baliseRef", "operationControlPoints", "ocp",
        "metadata", "signals", "signal", "platformEdges", "platformEdge",
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
    """Read a railML 2.x file into an :class:`Infrastructure`.

    ``tolerance_m`` bounds every disagreement between declared positions (pos, absPos) and
    coordinates, and how far a balise's coordinates may lie from the track.
    """
    return _Reader(Path(path), tolerance_m).read()


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

    # -- reading ----------------------------------------------------------------------------

    def read(self) -> Infrastructure:
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

        raw = self.chain([self.read_track(t) for t in _children(infra, "tracks", "track")], infra)
        model = self.build_model(raw)
        balise_elements = [
            (i, b)
            for i, r in enumerate(raw)
            for b in _children(r.element, "ocsElements", "balises", "balise")
        ]
        placed = {
            b.get("id", ""): self.place_balise(b, raw[i], i, model) for i, b in balise_elements
        }
        balises, groups = self.group_balises(raw, placed, model)
        stations = self.read_stations(infra, model)
        signals = [
            self.read_signal(s, r, model.sections[i].start_distance)
            for i, r in enumerate(raw)
            for s in _children(r.element, "ocsElements", "signals", "signal")
        ]
        edges = [
            self.read_platform_edge(e, r, model.sections[i].start_distance, model.length)
            for i, r in enumerate(raw)
            for e in _children(r.element, "trackElements", "platformEdges", "platformEdge")
        ]
        return Infrastructure(
            source=self.path,
            tracks=tuple(r.track for r in raw),
            model=model,
            balises=balises,
            groups=groups,
            stations=stations,
            warnings=tuple(self.warnings),
            signals=tuple(sorted(signals, key=lambda s: s.distance_m)),
            platform_edges=tuple(sorted(edges, key=lambda e: e.start_m)),
        )

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

    def chain(self, tracks: list[_RawTrack], infra: etree._Element) -> list[_RawTrack]:
        """Tracks in line order: trackEnd connection -> next trackBegin connection."""
        if not tracks:
            raise self.error(infra, "has no tracks", "add <tracks><track> elements")
        begins = {r.begin_connection.get("id"): r for r in tracks if r.begin_connection is not None}
        starts = [r for r in tracks if r.begin_connection is None]
        if len(starts) != 1:
            raise self.error(
                starts[1].element if len(starts) > 1 else tracks[0].element,
                f"the line must have exactly one track whose trackBegin has no connection, "
                f"found {len(starts)}",
                "connect the tracks end to begin into one line (trackEnd/connection ref = the "
                "next trackBegin/connection id and back)",
            )
        ordered = [starts[0]]
        while (connection := ordered[-1].end_connection) is not None:
            following = begins.get(connection.get("ref"))
            if (
                following is None
                or following.begin_connection is None
                or (following.begin_connection.get("ref") != connection.get("id"))
            ):
                raise self.error(
                    connection,
                    f"ref {connection.get('ref')!r} is not a trackBegin connection that refers "
                    "back to it",
                    "set ref to the next track's trackBegin/connection id and that one's ref to "
                    "this id",
                )
            if following in ordered:
                raise self.error(connection, "closes a loop", "the line must have two ends")
            ordered.append(following)
        for r in tracks:
            if r not in ordered:
                raise self.error(
                    r.element, "is not connected to the line", "chain it by connections"
                )
        for a, b in itertools.pairwise(ordered):
            gap = _distance(a.points[-1], b.points[0])
            if gap > self.tolerance:
                raise self.error(
                    b.points[0].element,
                    f"is {gap:.1f} m away from the end of track {a.track.id!r}",
                    "make the coordinates at the junction coincide",
                )
        return ordered

    def build_model(self, raw: list[_RawTrack]) -> TrackModel:
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

    def place_balise(
        self, element: etree._Element, raw: _RawTrack, index: int, model: TrackModel
    ) -> tuple[float, etree._Element]:
        track = raw.track
        section = model.sections[index]
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
        model: TrackModel,
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
            point = model.position(distance)
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

    def on_track(self, element: etree._Element, raw: _RawTrack) -> float:
        """Its pos/absPos offset from the trackBegin, required and within the track."""
        track = raw.track
        offset = self.offset(element, track, required=True)
        assert offset is not None
        if not 0.0 <= offset <= track.end_pos - track.begin_pos:
            raise self.error(
                element,
                f"lies off the track: offset {offset} m from trackBegin",
                f"place it on track {track.id!r} (pos 0..{track.end_pos - track.begin_pos})",
            )
        return offset

    def read_signal(self, element: etree._Element, raw: _RawTrack, start: float) -> Signal:
        """A signal by pos/absPos; it stands right of the track it faces (dir)."""
        direction = element.get("dir", "unknown")
        if direction not in _DIRECTIONS:
            raise self.error(
                element, f"dir {direction!r} is not one of {sorted(_DIRECTIONS)}", "fix dir"
            )
        return Signal(
            id=element.get("id", ""),
            name=element.get("name") or element.get("id", ""),
            distance_m=start + self.on_track(element, raw),
            direction=direction,
            side="left" if direction == "down" else "right",
            line=_line(element),
        )

    def read_platform_edge(
        self, element: etree._Element, raw: _RawTrack, start: float, line_length: float
    ) -> PlatformEdge:
        """A platform edge from pos/absPos over ``length`` metres, on ``side``, ``height``
        metres above the rails (default 0.76)."""
        begin = start + self.on_track(element, raw)
        length = self.number(element, "length")
        if length is None or length <= 0.0:
            raise self.error(element, "has no positive length", "give length in metres")
        if begin + length > line_length + self.tolerance:
            raise self.error(
                element,
                f"runs {begin + length - line_length:.1f} m past the end of the line",
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
            end_m=min(begin + length, line_length),
            side=side,
            height_m=height,
            line=_line(element),
        )

    def read_stations(self, infra: etree._Element, model: TrackModel) -> tuple[Station, ...]:
        stations: list[Station] = []
        for ocp in _children(infra, "operationControlPoints", "ocp"):
            geo = self.geo(ocp)
            if geo is None:
                self.warnings.append(
                    f'{self.file}:{ocp.sourceline}: <ocp id="{ocp.get("id")}"> has no '
                    "geoCoord and is not placed"
                )
                continue
            along, lateral = model.nearest(*geo)
            stations.append(
                Station(
                    id=ocp.get("id", ""),
                    name=ocp.get("name") or ocp.get("id", ""),
                    latitude_deg=geo[0],
                    longitude_deg=geo[1],
                    distance_m=along,
                    offset_m=lateral,
                    line=ocp.sourceline or 0,
                )
            )
        return tuple(sorted(stations, key=lambda s: s.distance_m))


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
