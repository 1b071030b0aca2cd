"""The mock on real railML routes, read by coupler_railway.

railML --coupler_railway--> TrackModel --> openrails-mock (lockstep) <--HTTP-- test
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from coupler.errors import ScenarioError
from coupler_railway import load_infrastructure
from openrails_mock.config import MockConfig

from .conftest import Serve, body

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
SCENARIO = ROOT / "scenarios/railway/data/annaberg-schwarzenberg.railml"


async def test_test_line_track_nodes_follow_the_railml_tracks(serve: Serve) -> None:
    model = load_infrastructure(TEST_LINE).model
    config = MockConfig(railml=TEST_LINE, loading_delay_s=0.0, start_distance_m=995.0)
    async with serve(config) as session:
        async with session.post("/API/CABCONTROLS", json=body(THROTTLE=1.0)) as resp:
            train = (await resp.json())["trains"]["PLAYER"]
        for _ in range(20):
            async with session.post("/API/CABCONTROLS", json=body()) as resp:
                train = (await resp.json())["trains"]["PLAYER"]
        async with session.get("/API/MAP") as resp:
            position = await resp.json()
    front = 995.0 + train["locomotiveState"]["distance"]
    section, offset = model.locate(front)
    assert train["trackLocation"]["trackNodeIndex"] == section + 1 == 2  # crossed into t2
    assert math.isclose(train["trackLocation"]["trackNodeOffset"], offset, abs_tol=1e-6)
    assert math.isclose(train["trackLocation"]["trackNodeLength"], model.sections[1].length)
    assert train["rearTrackLocation"]["trackNodeIndex"] == 1
    point = model.position(front)
    assert math.isclose(position["LatLon"]["Lat"], point.latitude_deg, abs_tol=1e-9)
    assert math.isclose(position["LatLon"]["Lon"], point.longitude_deg, abs_tol=1e-9)
    assert math.isclose(position["DirectionDeg"], point.heading_deg, abs_tol=1e-9)
    assert math.isclose(train["rotation"], math.radians(point.heading_deg), abs_tol=1e-9)
    # location: the lead car's centre (two cars of 20.85 m), east in its 2048 m tile
    lead = model.position(front - 41.7 / 4)
    assert math.isclose(train["location"]["x"], lead.x_m, abs_tol=1e-6)
    assert math.isclose(train["location"]["z"], lead.y_m, abs_tol=1e-6)


async def test_scenario_route_drives_from_annaberg(serve: Serve) -> None:
    config = MockConfig(railml=SCENARIO, loading_delay_s=0.0)
    async with serve(config) as session:
        async with session.post("/API/CABCONTROLS", json=body(THROTTLE=1.0)) as resp:
            train = (await resp.json())["trains"]["PLAYER"]
        for _ in range(300):  # one minute
            async with session.post("/API/CABCONTROLS", json=body()) as resp:
                train = (await resp.json())["trains"]["PLAYER"]
    state = train["locomotiveState"]
    assert state["v"] > 10.0 and state["distance"] > 300.0
    assert train["trackLocation"]["trackNodeIndex"] >= 1
    assert train["location"]["y"] != 0.0  # the line climbs or falls: elevation from gradients


def test_missing_railml_names_the_file(tmp_path: Path) -> None:
    from openrails_mock.api import create_app

    missing = tmp_path / "nowhere.railml"
    with pytest.raises(ScenarioError, match=r"nowhere\.railml"):
        create_app(MockConfig(railml=missing))
