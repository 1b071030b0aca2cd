"""Write tests/data/junction.railml: a main line with a switch and a branch (SYNTHETIC).

Main line: track m1, 600 m straight east, then m2, a 400 m curve of radius 800 m turning left
(north). A switch on m1 at pos 300 (railML ``orientation="outgoing"``, ``course="right"``)
where track b1 begins: 100 m of radius 300 m turning right (south), then 250 m straight.
Balises on both lines, a signal before the switch and one on the branch, gradients on the
main line, three ocps at the line ends. Geometry in the library's LocalFrame around the first
point, so arc lengths are known; positions are those arc lengths.
Run: .venv/bin/python packages/railway/tools/make_junction.py
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from lxml import etree

from coupler_railway.frame import LocalFrame

NS = "http://www.railml.org/schemas/2013"
FRAME = LocalFrame(50.58, 13.0)
OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "junction.railml"

MAIN_STRAIGHT = 600.0
MAIN_RADIUS, MAIN_CURVE = 800.0, 400.0
SWITCH_POS = 300.0
BRANCH_RADIUS, BRANCH_CURVE, BRANCH_STRAIGHT = 300.0, 100.0, 250.0

Point = tuple[float, float]


def sub(parent: etree._Element, tag: str, **attributes: str) -> etree._Element:
    return etree.SubElement(parent, f"{{{NS}}}{tag}", attributes)


def geo(parent: etree._Element, point: Point) -> None:
    lat, lon = FRAME.to_geographic(*point)
    sub(parent, "geoCoord", coord=f"{float(lat)!r} {float(lon)!r}")


def main_curve(t: float) -> Point:
    a = t / MAIN_RADIUS
    return MAIN_STRAIGHT + MAIN_RADIUS * math.sin(a), MAIN_RADIUS - MAIN_RADIUS * math.cos(a)


def branch(t: float) -> Point:
    if t <= BRANCH_CURVE:
        a = t / BRANCH_RADIUS
        return SWITCH_POS + BRANCH_RADIUS * math.sin(a), -BRANCH_RADIUS + BRANCH_RADIUS * math.cos(
            a
        )
    a = BRANCH_CURVE / BRANCH_RADIUS
    x, y = branch(BRANCH_CURVE)
    return x + (t - BRANCH_CURVE) * math.cos(a), y - (t - BRANCH_CURVE) * math.sin(a)


def track(
    tracks: etree._Element,
    ident: str,
    name: str,
    length: float,
    at: Callable[[float], Point],
    *,
    begin_abs: float = 0.0,
) -> tuple[etree._Element, etree._Element, etree._Element]:
    """A track with geoMappings every 10 m; returns (track, trackBegin, trackEnd)."""
    element = sub(tracks, "track", id=ident, name=name)
    topology = sub(element, "trackTopology")
    begin = sub(topology, "trackBegin", id=f"{ident}b", pos="0", absPos=repr(begin_abs))
    geo(begin, at(0.0))
    end = sub(
        topology, "trackEnd", id=f"{ident}e", pos=repr(length), absPos=repr(begin_abs + length)
    )
    geo(end, at(length))
    mappings = sub(sub(element, "trackElements"), "geoMappings")
    count = math.ceil(length / 10.0)
    for i, pos in enumerate(np.linspace(0.0, length, count + 1)[1:-1].tolist(), start=1):
        geo(sub(mappings, "geoMapping", id=f"{ident}m{i}", pos=repr(pos)), at(pos))
    return element, begin, end


def balises(
    parent: etree._Element, group: tuple[str, int], rows: list[tuple[str, int, float]]
) -> None:
    for ident, code, pos in rows:
        sub(parent, "balise", id=ident, code=str(code), name=ident.upper(), pos=repr(pos), dir="up")
    element = sub(parent, "baliseGroup", id=group[0], code=str(group[1]), name=group[0].upper())
    for ident, _, _ in rows:
        sub(element, "baliseRef", ref=ident)


def main() -> None:
    root = etree.Element(f"{{{NS}}}railml", nsmap={None: NS}, version="2.2")
    root.addprevious(
        etree.Comment(
            " SYNTHETIC junction made by packages/railway/tools/make_junction.py: main line m1 "
            "(600 m straight east) + m2 (400 m, radius 800 m, left); a switch on m1 at 300 m "
            "where branch b1 begins (100 m, radius 300 m, right, then 250 m straight). "
        )
    )
    infra = sub(root, "infrastructure", id="is1")
    tracks = sub(infra, "tracks")

    m1, m1_begin, m1_end = track(tracks, "m1", "Main west", MAIN_STRAIGHT, lambda t: (t, 0.0))
    sub(m1_begin, "bufferStop", id="m1stop")
    sub(m1_end, "connection", id="m1c", ref="m2c")
    topology = m1.find(f"{{{NS}}}trackTopology")
    assert topology is not None
    switch = sub(sub(topology, "connections"), "switch", id="sw1", name="W1", pos=repr(SWITCH_POS))
    sub(switch, "connection", id="sw1c", ref="b1c", orientation="outgoing", course="right")
    elements = m1.find(f"{{{NS}}}trackElements")
    assert elements is not None
    gradients = sub(elements, "gradientChanges")
    sub(gradients, "gradientChange", id="m1g0", pos="0", slope="0")
    sub(gradients, "gradientChange", id="m1g1", pos="400", slope="12")
    ocs = sub(m1, "ocsElements")
    balises(sub(ocs, "balises"), ("g1", 1), [("b11", 11, 100.0), ("b12", 12, 103.0)])
    sub(
        sub(ocs, "signals"),
        "signal",
        id="s1",
        name="A",
        pos="250",
        dir="up",
        type="main",
        function="entry",
    )

    m2, m2_begin, m2_end = track(
        tracks, "m2", "Main east", MAIN_CURVE, main_curve, begin_abs=MAIN_STRAIGHT
    )
    sub(m2_begin, "connection", id="m2c", ref="m1c")
    sub(m2_end, "bufferStop", id="m2stop")
    elements = m2.find(f"{{{NS}}}trackElements")
    assert elements is not None
    sub(sub(elements, "gradientChanges"), "gradientChange", id="m2g0", pos="0", slope="-8")
    balises(sub(sub(m2, "ocsElements"), "balises"), ("g2", 2), [("b21", 21, 200.0)])

    b1, b1_begin, b1_end = track(tracks, "b1", "Branch", BRANCH_CURVE + BRANCH_STRAIGHT, branch)
    sub(b1_begin, "connection", id="b1c", ref="sw1c")
    sub(b1_end, "bufferStop", id="b1stop")
    ocs = sub(b1, "ocsElements")
    balises(sub(ocs, "balises"), ("g3", 3), [("b31", 31, 150.0), ("b32", 32, 153.0)])
    sub(sub(ocs, "signals"), "signal", id="s2", name="B", pos="300", dir="down", type="main")

    ocps = sub(infra, "operationControlPoints")
    geo(sub(ocps, "ocp", id="W", name="West"), (0.0, 0.0))
    geo(sub(ocps, "ocp", id="E", name="East"), main_curve(MAIN_CURVE))
    geo(sub(ocps, "ocp", id="S", name="South"), branch(BRANCH_CURVE + BRANCH_STRAIGHT))

    OUT.parent.mkdir(parents=True, exist_ok=True)
    etree.ElementTree(root).write(
        str(OUT), pretty_print=True, xml_declaration=True, encoding="UTF-8"
    )


if __name__ == "__main__":
    main()
