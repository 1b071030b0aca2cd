"""One track everywhere: balises passed on the mock's track database where the TrackBalises
FMU's B-spline puts them.

    railML --make setup--> build/routes/annaberg-schwarzenberg --> openrails-mock <--HTTP-- test
    railML --make setup--> build/fmus/TrackBalises.fmu (resources/balises.csv: B-spline)

The train runs the whole line on the route folder the fleet uses; at every step the test reads
the front's track location (node, offset) from the lockstep reply. A balise is passed when the
front's offset crosses the balise's track item (its node and TrItemSData offset); the route
distance there must equal the FMU's distance of that balise within 5 cm.
"""

from __future__ import annotations

import csv
import io
import itertools
import zipfile
from pathlib import Path

import aiohttp
import pytest
from aiohttp import web

from openrails_mock.api import create_app
from openrails_mock.config import MockConfig
from openrails_mock.routefolder import load_route

ROOT = Path(__file__).resolve().parents[2]
ROUTE = ROOT / "build" / "routes" / "annaberg-schwarzenberg"
PATH = Path("PATHS/ocp_ABU-ocp_SZB.pat")
FMU = ROOT / "build" / "fmus" / "TrackBalises.fmu"
TRAIN_LENGTH = 41.7
AGREEMENT_M = 0.05

pytestmark = pytest.mark.timeout(600)


def fmu_balises() -> dict[int, float]:
    """balise code -> distance along the line, from the FMU's own resources (its B-spline)."""
    with zipfile.ZipFile(FMU) as fmu:
        text = fmu.read("resources/balises.csv").decode("ascii")
    return {int(r["balise_id"]): float(r["distance_m"]) for r in csv.DictReader(io.StringIO(text))}


async def test_balise_passages_on_the_tdb_agree_with_the_fmu() -> None:
    assert ROUTE.is_dir() and FMU.is_file(), "run `make setup` first (it exports the route)"
    expected = fmu_balises()
    route = load_route(ROUTE)
    balises = {
        int(item.number): (node.index, item.offset)
        for node in route.nodes.values()
        for item in (route.items[i] for i in node.items)
        if item.kind == "SpeedPostItem" and item.number is not None
    }
    assert sorted(balises) == sorted(expected)

    app = create_app(MockConfig(route=ROUTE, path=PATH, loading_delay_s=0.0))
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    port = runner.addresses[0][1]
    steps: list[tuple[float, int, float]] = []  # front route distance, node, node offset
    try:
        async with aiohttp.ClientSession(base_url=f"http://127.0.0.1:{port}") as session:
            controls = {"THROTTLE": 1.0}
            for _ in range(20_000):
                payload = {
                    "Controls": [
                        {"LocomotiveName": "PLAYER", "TypeName": name, "Value": value}
                        for name, value in controls.items()
                    ],
                    "Commands": [],
                    "SwitchCommands": {},
                    "StepMs": 500,
                }
                async with session.post("/API/CABCONTROLS", json=payload) as response:
                    train = (await response.json())["trains"]["PLAYER"]
                state, location = train["locomotiveState"], train["trackLocation"]
                front = TRAIN_LENGTH + state["distance"]
                steps.append((front, location["trackNodeIndex"], location["trackNodeOffset"]))
                # cruise at about 80 km/h; the buffer stop at Schwarzenberg ends the run
                controls = {"THROTTLE": 1.0 if state["v"] < 22.0 else 0.0}
                if len(steps) > 2 and steps[-1][0] == steps[-2][0] and state["v"] == 0.0:
                    break
    finally:
        await runner.cleanup()
    assert steps[-1][0] > max(expected.values()), "the train did not pass every balise"

    differences = {}
    for code, (node, offset) in balises.items():
        for (s0, n0, o0), (s1, n1, o1) in itertools.pairwise(steps):
            if n0 == n1 == node and o0 <= offset < o1:
                passed = s0 + (offset - o0) * (s1 - s0) / (o1 - o0)
                differences[code] = passed - expected[code]
                break
    assert sorted(differences) == sorted(expected)
    worst = max(differences.items(), key=lambda kv: abs(kv[1]))
    print(
        f"{len(differences)} balises: passage distance on the mock's TDB track minus the "
        f"TrackBalises FMU's B-spline distance: max |difference| {abs(worst[1]) * 1000:.2f} mm "
        f"(balise {worst[0]})"
    )
    assert abs(worst[1]) <= AGREEMENT_M
