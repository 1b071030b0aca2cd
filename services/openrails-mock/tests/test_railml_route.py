"""The mock on the project's railML files: exported to route folders first, one way in.

    railML --coupler_railway export--> route folder --> openrails-mock (lockstep) <--HTTP-- test

The train's track is the exported track database; it must lie on the railML B-spline (within
the exporter's 1 cm) and report the B-spline's geographic coordinates.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from coupler.errors import ScenarioError
from coupler_railway import load_infrastructure, load_network
from coupler_railway.openrails.export import export_route
from coupler_railway.openrails.world import WorldFrame
from openrails_mock.config import MockConfig
from openrails_mock.world import ROUTE_CACHE, open_world

from .support import Serve, body

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
SCENARIO = ROOT / "scenarios/railway/data/annaberg-schwarzenberg.railml"


async def test_railml_mode_runs_on_the_exported_track(serve: Serve) -> None:
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
    location = train["trackLocation"]
    # one vector node from buffer stop to buffer stop, laid the way the line runs
    assert (location["trackNodeIndex"], location["movementDirection"]) == (1, "Forward")
    assert location["trackNodeLength"] == pytest.approx(model.length, abs=1e-3)
    assert location["trackNodeOffset"] == pytest.approx(front, abs=1e-6)
    assert location["trackVectorSectionIndex"] > 0
    assert train["rearTrackLocation"]["trackNodeOffset"] == pytest.approx(front - 41.7, abs=1e-6)
    point = model.position(front)
    assert math.isclose(position["LatLon"]["Lat"], point.latitude_deg, abs_tol=2e-7)
    assert math.isclose(position["LatLon"]["Lon"], point.longitude_deg, abs_tol=2e-7)
    assert math.isclose(position["DirectionDeg"], point.heading_deg, abs_tol=0.05)
    assert math.isclose(train["rotation"], math.radians(point.heading_deg), abs_tol=1e-3)
    # location: the lead car's centre (two cars of 20.85 m) on the railML track, within 1 cm
    # (the route's origin: the line's first point on OpenRails' tile grid)
    lead = model.position(front - 41.7 / 4)
    origin = WorldFrame.around(model.frame).origin.absolute
    x = train["location"]["tileX"] * 2048.0 + train["location"]["x"] - origin[0]
    z = train["location"]["tileZ"] * 2048.0 + train["location"]["z"] - origin[1]
    assert math.hypot(x - lead.x_m, z - lead.y_m) < 0.01
    assert train["location"]["y"] > 0.0  # the line climbs 10 per mille from 500 m


@pytest.fixture(scope="module")
def scenario_route(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("routes") / "annaberg-schwarzenberg"
    export_route(SCENARIO, out)
    return out


async def test_scenario_route_drives_from_annaberg(serve: Serve, scenario_route: Path) -> None:
    path = Path("PATHS/ocp_ABU-ocp_SZB.pat")
    config = MockConfig(route=scenario_route, path=path, loading_delay_s=0.0)
    async with serve(config) as session:
        async with session.post("/API/CABCONTROLS", json=body(THROTTLE=1.0)) as resp:
            train = (await resp.json())["trains"]["PLAYER"]
        for _ in range(300):  # one minute
            async with session.post("/API/CABCONTROLS", json=body()) as resp:
                train = (await resp.json())["trains"]["PLAYER"]
        async with session.get("/API/MAP") as resp:
            position = await resp.json()
    state = train["locomotiveState"]
    assert state["v"] > 10.0 and state["distance"] > 300.0
    assert train["trackLocation"]["trackNodeIndex"] == 1
    assert train["location"]["y"] != 0.0  # the line climbs or falls
    front = 41.7 + state["distance"]
    point = load_infrastructure(SCENARIO).model.position(front)
    assert math.isclose(position["LatLon"]["Lat"], point.latitude_deg, abs_tol=2e-7)
    assert math.isclose(position["LatLon"]["Lon"], point.longitude_deg, abs_tol=2e-7)


def test_missing_railml_names_the_file(tmp_path: Path) -> None:
    from openrails_mock.api import create_app

    missing = tmp_path / "nowhere.railml"
    with pytest.raises(ScenarioError, match=r"nowhere\.railml"):
        create_app(MockConfig(railml=missing))


JUNCTION = ROOT / "packages/railway/tests/data/junction.railml"


@pytest.mark.parametrize(("switch", "node"), [(0, 2), (1, 3)])
async def test_exported_junction_left_and_right(
    serve: Serve, tmp_path: Path, switch: int, node: int
) -> None:
    """The exporter's junction (node 4: route 0 the left one, on along the main line; route 1
    the right one, the branch) thrown by SwitchCommands on the path West-East."""
    export_route(JUNCTION, tmp_path / "junction")
    config = MockConfig(route=tmp_path / "junction", path=Path("PATHS/W-E.pat"), loading_delay_s=0)
    async with serve(config) as session:
        for _ in range(400):
            payload = body(THROTTLE=1.0) | {"SwitchCommands": {"4": switch}}
            async with session.post("/API/CABCONTROLS", json=payload) as resp:
                train = (await resp.json())["trains"]["PLAYER"]
            if train["locomotiveState"]["distance"] > 330.0:
                break
    assert train["trackLocation"]["trackNodeIndex"] == node
    front = 41.7 + train["locomotiveState"]["distance"]
    assert train["trackLocation"]["trackNodeOffset"] == pytest.approx(front - 300.0, abs=1e-3)
    lines = load_network(JUNCTION).lines
    model = lines[0].model if node == 2 else lines[1].model
    expected = model.position(front if node == 2 else front - 300.0)
    assert train["rotation"] == pytest.approx(
        math.remainder(math.radians(expected.heading_deg), math.tau), abs=1e-3
    )


def test_an_exported_route_is_kept_and_exported_anew_when_the_file_changes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / "cache"
    monkeypatch.setenv(ROUTE_CACHE, str(cache))
    railml = tmp_path / "line.railml"
    railml.write_bytes(TEST_LINE.read_bytes())
    first = open_world(None, railml=railml)
    [kept] = cache.iterdir()  # one folder, no partial one left
    assert kept.stat().st_mode & 0o777 == 0o700
    tdb = kept / "line" / "line.tdb"
    written = tdb.stat().st_mtime_ns
    again = open_world(None, railml=railml)  # from the cache: not written again
    assert list(cache.iterdir()) == [kept] and tdb.stat().st_mtime_ns == written
    assert again.folder.folder == first.folder.folder == kept / "line"
    assert (again.player.node, again.player.offset) == (first.player.node, first.player.offset)
    railml.write_text(railml.read_text().replace("SYNTHETIC", "Synthetic"), encoding="utf-8")
    open_world(None, railml=railml)  # another file: exported anew, beside the first
    assert len(list(cache.iterdir())) == 2


def test_a_cache_that_cannot_be_written_exports_to_a_temporary_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    monkeypatch.setenv(ROUTE_CACHE, str(blocked / "cache"))
    world = open_world(None, railml=TEST_LINE)
    assert world.player.node >= 0 and blocked.read_text() == "not a folder"
    monkeypatch.setenv(ROUTE_CACHE, "")  # no cache at all
    assert open_world(None, railml=TEST_LINE).player.node == world.player.node
