"""Write tests/data/test-line.railml: 1000 m straight east, then a 500 m radius quarter circle.

The geometry is made in the library's LocalFrame around the first point and converted with
its exact inverse, so the model's lengths are known exactly: 1000 m and 250*pi m.
Run: .venv/bin/python packages/railway/tools/make_test_line.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from lxml import etree

from coupler_railway.frame import LocalFrame

NS = "http://www.railml.org/schemas/2013"
FRAME = LocalFrame(50.0, 12.0)
RADIUS = 500.0
OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "test-line.railml"


def sub(parent: etree._Element, tag: str, **attributes: str) -> etree._Element:
    return etree.SubElement(parent, f"{{{NS}}}{tag}", attributes)


def geo(parent: etree._Element, x: float, y: float) -> None:
    lat, lon = FRAME.to_geographic(x, y)
    sub(parent, "geoCoord", coord=f"{float(lat)!r} {float(lon)!r}")


def arc(offset: float) -> tuple[float, float]:
    theta = offset / RADIUS
    return 1000.0 + RADIUS * math.sin(theta), RADIUS - RADIUS * math.cos(theta)


def main() -> None:
    root = etree.Element(f"{{{NS}}}railml", nsmap={None: NS}, version="2.2")
    root.addprevious(
        etree.Comment(
            " SYNTHETIC test line made by packages/railway/tools/make_test_line.py: track t1 is "
            "1000 m straight east, t2 a quarter circle of radius 500 m turning north "
            "(250*pi m). "
        )
    )
    infra = sub(root, "infrastructure", id="is1")
    tracks = sub(infra, "tracks")
    arc_length = RADIUS * math.pi / 2.0

    t1 = sub(tracks, "track", id="t1", name="Straight")
    topo = sub(t1, "trackTopology")
    begin = sub(topo, "trackBegin", id="t1b", pos="0", absPos="0")
    geo(begin, 0.0, 0.0)
    sub(begin, "bufferStop", id="t1stop")
    end = sub(topo, "trackEnd", id="t1e", pos="1000", absPos="1000")
    geo(end, 1000.0, 0.0)
    sub(end, "connection", id="c1", ref="c2")
    elements = sub(t1, "trackElements")
    mappings = sub(elements, "geoMappings")
    for pos in range(25, 1000, 25):
        geo(sub(mappings, "geoMapping", id=f"t1m{pos}", pos=str(pos)), float(pos), 0.0)
    gradients = sub(elements, "gradientChanges")
    sub(gradients, "gradientChange", id="t1g0", pos="0", slope="0")
    sub(gradients, "gradientChange", id="t1g1", pos="500", slope="10")
    balises = sub(sub(t1, "ocsElements"), "balises")
    sub(balises, "balise", id="b11", code="101", name="A1", pos="100", absPos="100", dir="up")
    sub(balises, "balise", id="b12", code="102", name="A2", pos="103", dir="up")
    sub(balises, "balise", id="b21", code="201", name="B1", pos="600", dir="down")
    for group_id, code, refs in (("g1", "10", ("b11", "b12")), ("g2", "20", ("b21",))):
        group = sub(balises, "baliseGroup", id=group_id, code=code, name=f"Group {code}")
        for ref in refs:
            sub(group, "baliseRef", ref=ref)

    t2 = sub(tracks, "track", id="t2", name="Curve")
    topo = sub(t2, "trackTopology")
    begin = sub(topo, "trackBegin", id="t2b", pos="0", absPos="1000")
    geo(begin, *arc(0.0))
    sub(begin, "connection", id="c2", ref="c1")
    end = sub(topo, "trackEnd", id="t2e", pos=repr(arc_length), absPos=repr(1000 + arc_length))
    geo(end, *arc(arc_length))
    sub(end, "bufferStop", id="t2stop")
    elements = sub(t2, "trackElements")
    mappings = sub(elements, "geoMappings")
    for i, offset in enumerate(np.linspace(0.0, arc_length, 79)[1:-1].tolist(), start=1):
        geo(sub(mappings, "geoMapping", id=f"t2m{i}", pos=repr(offset)), *arc(offset))
    gradients = sub(elements, "gradientChanges")
    sub(gradients, "gradientChange", id="t2g0", pos="0", slope="-5")
    balises = sub(sub(t2, "ocsElements"), "balises")
    sub(balises, "balise", id="b31", code="301", name="C1", pos="200", absPos="1200")
    sub(balises, "balise", id="b32", code="302", name="C2", absPos="1203")
    sub(balises, "balise", id="b33", code="303", name="C3", pos="206")
    geo(sub(balises, "balise", id="b41", code="401", name="D1 (coordinates only)"), *arc(500.0))
    for group_id, code, refs in (("g3", "30", ("b31", "b32", "b33")), ("g4", "40", ("b41",))):
        group = sub(balises, "baliseGroup", id=group_id, code=code, name=f"Group {code}")
        for ref in refs:
            sub(group, "baliseRef", ref=ref)

    ocps = sub(infra, "operationControlPoints")
    geo(sub(ocps, "ocp", id="ocpW", name="West"), 0.0, 0.0)
    geo(sub(ocps, "ocp", id="ocpN", name="North"), *arc(arc_length))

    OUT.parent.mkdir(parents=True, exist_ok=True)
    etree.ElementTree(root).write(
        str(OUT), pretty_print=True, xml_declaration=True, encoding="UTF-8"
    )


if __name__ == "__main__":
    main()
