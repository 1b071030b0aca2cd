"""Write scenarios/railway/data/annaberg-schwarzenberg.railml (SYNTHETIC, approximate data).

The line Annaberg-Buchholz unt Bf - Schwarzenberg (Erzgebirge): station positions are rough
public geography; between stations the route is a smooth made-up meander whose amplitude is
scaled so the line is about 26 km long. Positions (pos/absPos) are computed with the
library's own track model, so the file is self-consistent. Not surveyed; not for operation.
Run: .venv/bin/python packages/railway/tools/make_annaberg_schwarzenberg.py
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
from lxml import etree

from coupler_railway.frame import LocalFrame
from coupler_railway.track import SectionGeometry, TrackModel

NS = "http://www.railml.org/schemas/2013"
OUT = (
    Path(__file__).resolve().parents[3]
    / "scenarios"
    / "railway"
    / "data"
    / "annaberg-schwarzenberg.railml"
)
TARGET_LENGTH_M = 26_000.0
SPACING_M = 300.0

# (id, name, latitude, longitude, elevation [m], bow [m], wiggle [m]) -- bow and wiggle shape
# the stretch from this station to the next (relative weights, scaled to the target length).
STATIONS = [
    ("ABU", "Annaberg-Buchholz unt Bf", 50.5766, 13.0104, 540.0, 250.0, 30.0),
    ("ABS", "Annaberg-Buchholz Süd", 50.5652, 12.9985, 575.0, -600.0, 60.0),
    ("SLT", "Schlettau", 50.5588, 12.9535, 610.0, 700.0, -80.0),
    ("SCB", "Scheibenberg", 50.5418, 12.9162, 640.0, -800.0, 80.0),
    ("MKB", "Markersbach", 50.5312, 12.8718, 560.0, 500.0, -60.0),
    ("RAS", "Raschau", 50.5330, 12.8343, 480.0, -350.0, 40.0),
    ("GRS", "Grünstädtel", 50.5392, 12.8092, 450.0, 280.0, -30.0),
    ("SZB", "Schwarzenberg (Erzgebirge)", 50.5447, 12.7857, 430.0, 0.0, 0.0),
]
FRAME = LocalFrame(STATIONS[0][2], STATIONS[0][3])


def route(scale: float) -> list[np.ndarray]:
    """Dense (n, 2) local polylines, one per stretch between consecutive stations."""
    stretches = []
    for a, b in itertools.pairwise(STATIONS):
        ax, ay = (float(v) for v in FRAME.to_local(a[2], a[3]))
        bx, by = (float(v) for v in FRAME.to_local(b[2], b[3]))
        t = np.linspace(0.0, 1.0, 2001)
        chord = math.hypot(bx - ax, by - ay)
        nx, ny = -(by - ay) / chord, (bx - ax) / chord
        lateral = scale * (a[5] * np.sin(np.pi * t) + a[6] * np.sin(3.0 * np.pi * t))
        stretches.append(
            np.column_stack([ax + (bx - ax) * t + nx * lateral, ay + (by - ay) * t + ny * lateral])
        )
    return stretches


def length(stretches: list[np.ndarray]) -> float:
    return float(sum(np.hypot(*np.diff(s, axis=0).T).sum() for s in stretches))


def resample(stretch: np.ndarray) -> np.ndarray:
    """Points about SPACING_M apart along ``stretch``, both ends included."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(stretch, axis=0).T))])
    targets = np.linspace(0.0, s[-1], max(4, math.ceil(s[-1] / SPACING_M) + 1))
    return np.column_stack(
        [np.interp(targets, s, stretch[:, 0]), np.interp(targets, s, stretch[:, 1])]
    )


def sub(parent: etree._Element, tag: str, **attributes: str) -> etree._Element:
    return etree.SubElement(parent, f"{{{NS}}}{tag}", attributes)


def geo(
    parent: etree._Element, latitude: float, longitude: float, altitude: float | None = None
) -> None:
    height = "" if altitude is None else f" {altitude:.3f}"
    sub(parent, "geoCoord", coord=f"{latitude:.8f} {longitude:.8f}{height}")


def num(value: float) -> str:
    return f"{value:.3f}"


def main() -> None:
    lo, hi = 0.0, 4.0
    for _ in range(60):
        mid = (lo + hi) / 2.0
        lo, hi = (mid, hi) if length(route(mid)) < TARGET_LENGTH_M else (lo, mid)
    stretches = [resample(s) for s in route(lo)]
    geometry = []
    for a, b, points in zip(STATIONS, STATIONS[1:], stretches, strict=False):
        lat, lon = FRAME.to_geographic(points[:, 0], points[:, 1])
        lat, lon = np.round(lat, 8), np.round(lon, 8)
        geometry.append(
            SectionGeometry(f"tr_{a[0]}_{b[0]}", f"{a[1]} - {b[1]}", tuple(lat), tuple(lon))
        )
    model = TrackModel.build(geometry)
    print(f"length {model.length:.1f} m, {len(model.point_distances)} points")

    root = etree.Element(f"{{{NS}}}railml", nsmap={None: NS}, version="2.2")
    root.addprevious(
        etree.Comment(
            " SYNTHETIC DATA made by the Coupler project "
            "(packages/railway/tools/make_annaberg_schwarzenberg.py): the line Annaberg-Buchholz "
            "unt Bf - Schwarzenberg (Erzgebirge) via Schlettau, Scheibenberg, Markersbach, "
            "Raschau, Grünstädtel. Station positions approximate public geography; the route "
            "between them, the gradients, mileage, all balises, signals and platform edges "
            "are MADE UP. Not surveyed, not for navigation or operation. "
        )
    )
    infra = sub(root, "infrastructure", id="is_erzgebirge")
    tracks = sub(infra, "tracks")
    group_code = 100
    last = len(model.sections) - 1
    for index, (section, shape) in enumerate(zip(model.sections, geometry, strict=True)):
        a, b = STATIONS[index], STATIONS[index + 1]
        start, end = section.start_distance, section.start_distance + section.length
        track = sub(tracks, "track", id=section.track_id, name=section.name)
        topo = sub(track, "trackTopology")
        begin = sub(topo, "trackBegin", id=f"{section.track_id}_b", pos="0", absPos=num(start))
        # the line's altitude at its start (railML's third coord value; the rest of the
        # line's heights follow from the gradients)
        geo(begin, shape.latitudes_deg[0], shape.longitudes_deg[0], a[4] if index == 0 else None)
        if index == 0:
            sub(begin, "bufferStop", id=f"{section.track_id}_stop")
        else:
            sub(begin, "connection", id=f"{section.track_id}_cb", ref=f"{section.track_id}_ce0")
        end_element = sub(
            topo, "trackEnd", id=f"{section.track_id}_e", pos=num(section.length), absPos=num(end)
        )
        geo(end_element, shape.latitudes_deg[-1], shape.longitudes_deg[-1])
        if index == last:
            sub(end_element, "bufferStop", id=f"{section.track_id}_stop")
        else:
            following = model.sections[index + 1].track_id
            sub(end_element, "connection", id=f"{following}_ce0", ref=f"{following}_cb")

        elements = sub(track, "trackElements")
        mappings = sub(elements, "geoMappings")
        first = int(np.searchsorted(model.point_distances, start - 1e-6))
        for k, (lat, lon) in enumerate(
            zip(shape.latitudes_deg[1:-1], shape.longitudes_deg[1:-1], strict=True), start=1
        ):
            distance = float(model.point_distances[first + k])
            mapping = sub(
                mappings,
                "geoMapping",
                id=f"{section.track_id}_m{k}",
                pos=num(distance - start),
                absPos=num(distance),
            )
            geo(mapping, lat, lon)
        # Platform edges at the stations (heights as on the line: 0.55 m): at the stretch's
        # start for its first station, at its end for the last one.
        edges = sub(elements, "platformEdges")
        platforms = [(20.0, a)] + ([(section.length - 150.0, b)] if index == last else [])
        for k, (pos, station) in enumerate(platforms):
            sub(
                edges,
                "platformEdge",
                id=f"pe_{station[0]}_{k}",
                name=f"{station[1]} Gleis 1",
                pos=num(pos),
                absPos=num(start + pos),
                length="130",
                side="right" if index % 2 == 0 else "left",
                height="0.55",
            )
        grade = (b[4] - a[4]) / section.length * 1000.0
        gradients = sub(elements, "gradientChanges")
        for k, (fraction, factor) in enumerate(((0.0, 1.25), (0.4, 0.6), (0.8, 1.25))):
            sub(
                gradients,
                "gradientChange",
                id=f"{section.track_id}_g{k}",
                pos=num(fraction * section.length),
                slope=f"{grade * factor:.2f}",
            )

        # Balise groups (relative to this stretch): (offset from start or -offset from end,
        # number of balises, direction, group type).
        layout = [
            (120.0, 2, "down", "signal"),
            (320.0, 3, "up", "signal"),
            (section.length / 2.0, 1, "both", "infill"),
            (-320.0, 3, "up", "signal"),
            (-120.0, 2, "down", "signal"),
        ]
        ocs = sub(track, "ocsElements")
        # Signals: the exit signal after the stretch's first station, the entry signal before
        # the next one (both facing up, standing on the right), and the opposite entry signal.
        signals = sub(ocs, "signals")
        for name, pos, direction in (
            (f"{a[0]} exit", 180.0, "up"),
            (f"{b[0]} entry", section.length - 260.0, "up"),
            (f"{a[0]} entry (down)", 260.0, "down"),
        ):
            sub(
                signals,
                "signal",
                id=f"sig_{section.track_id}_{len(signals)}",
                name=name,
                pos=num(pos),
                absPos=num(start + pos),
                dir=direction,
            )
        balises = sub(ocs, "balises")
        groups = []
        for offset, count, direction, kind in layout:
            base = offset if offset >= 0.0 else section.length + offset
            refs = []
            for n in range(count):
                pos = base + 3.0 * n
                code = group_code * 10 + n
                ident = f"bal_{code}"
                point = model.position(start + pos)
                balise = sub(
                    balises,
                    "balise",
                    id=ident,
                    code=str(code),
                    name=f"{a[0] if pos < section.length / 2 else b[0]} BG{group_code}-{n + 1}",
                    pos=num(pos),
                    absPos=num(start + pos),
                    dir=direction,
                )
                geo(balise, point.latitude_deg, point.longitude_deg)
                refs.append(ident)
            groups.append((group_code, kind, refs))
            group_code += 1
        for code, kind, refs in groups:
            group = sub(balises, "baliseGroup", id=f"bg_{code}", code=str(code), type=kind)
            group.set("name", f"BG {code}")
            for ref in refs:
                sub(group, "baliseRef", ref=ref)

    ocps = sub(infra, "operationControlPoints")
    station_distances = [0.0, *(s.start_distance + s.length for s in model.sections)]
    for station, distance in zip(STATIONS, station_distances, strict=True):
        point = model.position(min(distance, model.length))
        ocp = sub(ocps, "ocp", id=f"ocp_{station[0]}", name=station[1])
        geo(ocp, point.latitude_deg, point.longitude_deg)

    OUT.parent.mkdir(parents=True, exist_ok=True)
    etree.ElementTree(root).write(
        str(OUT), pretty_print=True, xml_declaration=True, encoding="UTF-8"
    )


if __name__ == "__main__":
    main()
