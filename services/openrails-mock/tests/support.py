"""What the OpenRails mock's tests share besides fixtures (those are in conftest.py): a served
mock's request bodies and clock, and the files of a route folder written by hand
(test_route_folder.py, test_route_fuzz.py):

    node 5 (end) --[1: 200 m east]--> junction 4 --[2: 300 m east]--> node 6 (end)
                                                 \\--[3: arc R 200 m, 30 deg right]--> node 7 (end)

Junction 4: route 0 (pin 2, the left route) runs on east, route 1 (pin 3) turns right.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager
from typing import Any

import aiohttp

Serve = Callable[..., AbstractAsyncContextManager[aiohttp.ClientSession]]


def body(**controls: float) -> dict[str, Any]:
    """A lockstep POST /API/CABCONTROLS body setting ``controls`` of the PLAYER train."""
    return {
        "Controls": [
            {"LocomotiveName": "PLAYER", "TypeName": name, "ControlIndex": 1, "Value": value}
            for name, value in controls.items()
        ],
        "Commands": [],
        "SwitchCommands": {},
    }


class FakeClock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


TILE = (-5354, 14849)
RADIUS, TURN = 200.0, math.radians(30.0)
CAR = 41.7 / 2.0  # two cars of the default consist: the lead car's centre is CAR / 2 behind


def arc(s: float) -> tuple[float, float]:
    """x east, z north of the branch, ``s`` metres past the junction."""
    phi = s / RADIUS
    return 200.0 + RADIUS * math.sin(phi), -RADIUS * (1.0 - math.cos(phi))


ARC_END = arc(RADIUS * TURN)
ROUTE_FILE = """SIMISA@@@@@@@@@@JINX0r1t______

Tr_RouteFile (
    RouteID ( hand )
    Name ( "A route written by hand" )
    FileName ( hand )
    RouteStart ( -5354 14849 0 0 )
)
"""
SECTIONS = f"""SIMISA@@@@@@@@@@JINX0T0t______

TrackSections ( 1002
    TrackSection ( SectionCurve ( 0 ) 1000 200 0 )
    TrackSection ( SectionCurve ( 0 ) 1001 300 0 )
    TrackSection ( SectionCurve ( 1 ) 1002 {TURN!r} {RADIUS!r} )
)
"""
EAST = math.pi / 2.0


def tdb(pin_of_node_1: int = 5) -> str:
    def section(index: int, x: float, uid: int) -> str:
        return f"{index} {index} -5354 14849 {uid} 0 1 00 -5354 14849 {x} 0 0 0 {EAST!r} 0"

    return f"""SIMISA@@@@@@@@@@JINX0T0t______

TrackDB (
    Serial ( 0 )
    TrackNodes ( 7
        TrackNode ( 1
            TrVectorNode ( TrVectorSections ( 1 {section(1000, 0.0, 3)} ) )
            TrPins ( 1 1 TrPin ( {pin_of_node_1} 1 ) TrPin ( 4 1 ) )
        )
        TrackNode ( 2
            TrVectorNode ( TrVectorSections ( 1 {section(1001, 200.0, 4)} ) )
            TrPins ( 1 1 TrPin ( 4 0 ) TrPin ( 6 1 ) )
        )
        TrackNode ( 3
            TrVectorNode ( TrVectorSections ( 1 {section(1002, 200.0, 5)} ) )
            TrPins ( 1 1 TrPin ( 4 0 ) TrPin ( 7 1 ) )
        )
        TrackNode ( 4
            TrJunctionNode ( 0 30 0 )
            UiD ( -5354 14849 4 0 -5354 14849 200 0 0 0 {EAST!r} 0 )
            TrPins ( 1 2 TrPin ( 1 0 ) TrPin ( 2 1 ) TrPin ( 3 1 ) )
        )
        TrackNode ( 5
            TrEndNode ( 0 )
            UiD ( -5354 14849 3 0 -5354 14849 0 0 0 0 {EAST!r} 0 )
            TrPins ( 1 0 TrPin ( 1 1 ) )
        )
        TrackNode ( 6
            TrEndNode ( 0 )
            UiD ( -5354 14849 4 0 -5354 14849 500 0 0 0 {EAST!r} 0 )
            TrPins ( 1 0 TrPin ( 2 0 ) )
        )
        TrackNode ( 7
            TrEndNode ( 0 )
            UiD ( -5354 14849 5 0 -5354 14849 {ARC_END[0]!r} 0 {ARC_END[1]!r} 0 2.0943951 0 )
            TrPins ( 1 0 TrPin ( 3 0 ) )
        )
    )
)
"""


def pat(name: str, points: list[tuple[float, float, str]]) -> str:
    pdps = "\n".join(f"    TrackPDP ( -5354 14849 {x!r} 0 {z!r} {f} )" for x, z, f in points)
    nodes = "\n".join(
        f"        TrPathNode ( 00000000 {i + 1 if i + 1 < len(points) else 4294967295} "
        f"4294967295 {i} )"
        for i in range(len(points))
    )
    return f"""SIMISA@@@@@@@@@@JINX0P0t______

Serial ( 1 )
TrackPDPs (
{pdps}
)
TrackPath (
    TrPathName ( "{name}" )
    Name ( "{name}" )
    TrPathNodes ( {len(points)}
{nodes}
    )
)
"""


WORLD = """SIMISA@@@@@@@@@@JINX0w2t______

Tr_Worldfile (
    Static ( UiD ( 1 ) FileName ( box.s ) StaticFlags ( 00080000 ) Position ( 250 0 5 )
             QDirection ( 0 0 0 1 ) VDbId ( 4294967295 ) )
    Static ( UiD ( 2 ) FileName ( rock.s ) StaticFlags ( 00000000 ) Position ( 100 0 8 )
             QDirection ( 0 0 0 1 ) VDbId ( 4294967295 ) )
    Dyntrack ( UiD ( 3 ) SectionIdx ( 1000 ) Position ( 0 0 0 )
               QDirection ( 0 0.7071068 0 0.7071068 ) )
)
"""


def utf16(text: str) -> bytes:
    return b"\xff\xfe" + text.replace("\n", "\r\n").encode("utf-16-le")
