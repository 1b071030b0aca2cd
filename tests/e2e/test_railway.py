"""The railway scenario end to end, every service a real local process on loopback.

    Driver (FMU, in-process) == throttle, brake ==> OpenRails bridge ==HTTP==> OpenRails mock
    OpenRails bridge == distance, speed ==> Driver
    OpenRails bridge == distance ==> TrackBalises (FMU host) == readings ==> Map server
    OpenRails bridge == lat/lon, speed, TrainState ==> Map server

The train runs from Annaberg-Buchholz to Schwarzenberg; every balise of the railML file must be
reported once, in order, at its distance, and the map server must have received every reading.
"""

from __future__ import annotations

import asyncio
import csv
import json
import socket
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from coupler.testing import free_port
from coupler_dev.browser import CHROMIUM, chromium
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.runner import RunOutcome, run_scenario
from coupler_orchestrator.tools.fleet import Fleet, FleetSpec, ServiceSpec
from coupler_railway import load_infrastructure

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "railway"
RAILML = SCENARIO / "data" / "annaberg-schwarzenberg.railml"
FMUS = ROOT / "build" / "fmus"
ROUTE = ROOT / "build" / "routes" / "annaberg-schwarzenberg"  # make setup exports it
PATH = "PATHS/ocp_ABU-ocp_SZB.pat"
ANTENNA_OFFSET = 39.7  # parameters.ssv: TrackBalises.antenna_offset
STOP_DISTANCE = 25908.3  # parameters.ssv: Driver.stop_distance
STEP = 1.0
SHORT = ("--stop-time", "120")
"""A short run: the first balises are passed within it."""
HAVE_CHROMIUM = CHROMIUM.exists()  # Debian's chromium: .ci/run installs it, else no browser part
ARTIFACT = ROOT / "test-artifacts" / "railway-map.png"

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def ports() -> dict[str, int]:
    return {name: free_port() for name in ("mock", "bridge", "balise", "map_grpc", "map_http")}


@asynccontextmanager
async def railway_fleet(
    ports: dict[str, int],
    monkeypatch: pytest.MonkeyPatch,
    *mock_options: str,
    without_openrails: bool = False,
) -> AsyncIterator[Fleet]:
    """The railway fleet on ``ports``; ``mock_options`` go to the OpenRails mock;
    ``without_openrails``: neither the mock nor the bridge (OpenRails is replayed)."""
    for fmu in ("Driver2.fmu", "TrackBalises.fmu"):
        if not (FMUS / fmu).exists():
            pytest.fail(f"{FMUS / fmu} is missing: run 'make setup' (make test does)")
    monkeypatch.setenv("BRIDGE_PORT", str(ports["bridge"]))
    monkeypatch.setenv("BALISE_PORT", str(ports["balise"]))
    monkeypatch.setenv("MAP_PORT", str(ports["map_grpc"]))
    monkeypatch.setenv("COUPLER_FMU_DIR", str(FMUS))
    p = {k: str(v) for k, v in ports.items()}
    spec = FleetSpec(
        root=ROOT,
        ssp=SCENARIO / "SystemStructure.ssd",
        out=ROOT / "results",
        services=(
            ServiceSpec(
                name="e2e-openrails-mock",
                command=(
                    "python",
                    "-m",
                    "openrails_mock",
                    "--port",
                    p["mock"],
                    "--mode",
                    "lockstep",
                    "--route",
                    str(ROUTE),
                    "--path",
                    PATH,
                    *mock_options,
                ),
                health=f"http://127.0.0.1:{p['mock']}/API/READY",
            ),
            ServiceSpec(
                name="e2e-openrails-bridge",
                command=(
                    "python",
                    "-m",
                    "openrails_bridge",
                    "--port",
                    p["bridge"],
                    "--openrails-url",
                    f"http://127.0.0.1:{p['mock']}",
                ),
                health=f"grpc://127.0.0.1:{p['bridge']}",
            ),
            ServiceSpec(
                name="e2e-balise-fmu",
                command=(
                    "python",
                    "-m",
                    "balise_fmu",
                    "--port",
                    p["balise"],
                    "--name",
                    "TrackBalises",
                    "--fmu",
                    str(FMUS / "TrackBalises.fmu"),
                ),
                health=f"grpc://127.0.0.1:{p['balise']}",
            ),
            ServiceSpec(
                name="e2e-mapserver",
                command=(
                    "python",
                    "-m",
                    "mapserver",
                    "--grpc-port",
                    p["map_grpc"],
                    "--http-port",
                    p["map_http"],
                    "--railml",
                    str(RAILML),
                ),
                health=f"grpc://127.0.0.1:{p['map_grpc']}",
            ),
        ),
    )
    if without_openrails:
        spec = replace(spec, services=tuple(s for s in spec.services if "openrails" not in s.name))
    async with Fleet(spec, health_timeout=60) as running:
        yield running


@pytest.fixture
async def fleet(ports: dict[str, int], monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[Fleet]:
    async with railway_fleet(ports, monkeypatch) as running:
        yield running


def read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


def readings_of(rows: list[dict[str, str]]) -> list[tuple[float, int, int, float]]:
    """(time, balise id, group id, distance) of every balise crossing, in order."""
    found = []
    for row in rows:
        for item in filter(None, row["TrackBalises.passed_in_step"].split(";")):
            balise_id, group_id, distance = item.split(":")
            found.append((float(row["time"]), int(balise_id), int(group_id), float(distance)))
    return found


@pytest.mark.slow
async def test_train_passes_every_balise_in_order(
    fleet: Fleet, ports: dict[str, int], tmp_path: Path
) -> None:
    def start() -> Awaitable[RunOutcome]:
        return run_scenario(
            SCENARIO / "SystemStructure.ssd", RunOptions(run_id="e2e"), out_dir=tmp_path
        )

    if HAVE_CHROMIUM:
        outcome = await watch_in_chromium(f"http://127.0.0.1:{ports['map_http']}/", start)
    else:
        outcome = await start()
    summary: dict[str, Any] = json.loads(outcome.summary_json.read_text())
    assert summary["status"] == "completed", summary["reason"]
    assert summary["steps"] == 1800
    assert set(summary["participants"]) == {"Driver", "OpenRails", "TrackBalises", "Map"}
    assert summary["ssp"]["sha256"]

    rows = read_rows(outcome.results_csv)
    assert len(rows) == 1801
    assert {c["name"] for c in summary["columns"]} == set(rows[0]) - {"time"}

    # the train stands at the stop point at Schwarzenberg
    final = rows[-1]
    assert float(final["OpenRails.speed"]) == pytest.approx(0.0, abs=0.05)
    assert float(final["OpenRails.distance"]) == pytest.approx(STOP_DISTANCE, abs=5.0)

    # every balise, in order, exactly once, with its id, group and distance
    infrastructure = load_infrastructure(RAILML)
    expected = [(b.code, b.group, b.distance_m) for b in infrastructure.balises]
    readings = readings_of(rows)
    assert [(i, g) for _, i, g, _ in readings] == [(i, g) for i, g, _ in expected]
    for (_, _, _, reported), (_, _, distance) in zip(readings, expected, strict=True):
        assert reported == pytest.approx(distance, abs=1e-6)
    assert int(final["TrackBalises.balises_passed"]) == len(expected)

    # Jacobi: TrackBalises steps [t - h, t] on the position of t - h, so a reading at t is a
    # balise the antenna crossed between t - 2h and t - h: at most two steps of travel behind
    antenna = {float(r["time"]): float(r["OpenRails.distance"]) + ANTENNA_OFFSET for r in rows}
    speed = {float(r["time"]): float(r["OpenRails.speed"]) for r in rows}
    for time, _, _, distance in readings:
        assert antenna[time - 2 * STEP] < distance <= antenna[time - STEP]
        fastest = max(speed[time - 2 * STEP], speed[time - STEP], speed[time])
        assert 0.0 <= antenna[time] - distance <= 2 * STEP * fastest + 0.5

    # the map server received every reading
    url = f"http://127.0.0.1:{ports['map_http']}/api/state"
    async with aiohttp.ClientSession() as session, session.get(url) as response:
        state = await response.json()
    shown = [(r["balise_id"], r["group_id"]) for r in state["readings"]]
    assert shown == [(i, g) for i, g, _ in expected]


SAMPLE_TRAIN = """
window.trainSeen = [];
setInterval(() => {
  const at = window.coupler.trainLatLng();
  const last = window.trainSeen[window.trainSeen.length - 1];
  if (at && !(last && last[0] === at.lat && last[1] === at.lng)) {
    window.trainSeen.push([at.lat, at.lng]);
  }
}, 20);
"""
"""Every place the map shows the train at, sampled by the page every 20 ms."""


async def watch_in_chromium(url: str, start: Callable[[], Awaitable[RunOutcome]]) -> RunOutcome:
    """Debian's Chromium on the map during the run: the train moves across it while the run
    goes on, rows appear in order."""
    async with chromium() as browser:
        page = await browser.new_page(viewport={"width": 1280, "height": 760})
        await page.goto(url)
        await page.wait_for_function("window.coupler && window.coupler.ready")
        # the page samples the marker itself, from before the run starts: this test's
        # event loop is the run's, which lets it in only between steps (a few turns every
        # 20 ms when no step awaits)
        await page.evaluate(SAMPLE_TRAIN)
        run = asyncio.ensure_future(start())
        try:
            await page.wait_for_function("window.coupler.readingIds().length >= 3", timeout=120_000)
            await asyncio.wait_for(asyncio.shield(run), timeout=280)
        finally:
            outcome = await run
        expected = [b.code for b in load_infrastructure(RAILML).balises]
        await page.wait_for_function(
            f"window.coupler.readingIds().length >= {len(expected)}", timeout=30_000
        )
        late = await page.evaluate("window.coupler.trainLatLng()")
        seen = await page.evaluate("window.trainSeen")
        shown = await page.evaluate("window.coupler.readingIds()")
        ARTIFACT.parent.mkdir(exist_ok=True)
        await page.screenshot(path=str(ARTIFACT))
    assert len(seen) >= 3, f"the train was shown at {len(seen)} places during the run: {seen}"
    assert seen[-1] == [late["lat"], late["lng"]]
    return outcome
    assert [int(i) for i in shown] == expected


async def coupler_run(out: Path, *options: str) -> tuple[int, str]:
    """``coupler run`` of the railway scenario as its own process: exit code and stderr."""
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "coupler_orchestrator",
        "run",
        str(SCENARIO / "SystemStructure.ssd"),
        "--out",
        str(out),
        "--no-progress",
        *options,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )
    _, err = await process.communicate()
    assert process.returncode is not None
    return process.returncode, err.decode()


@pytest.mark.slow
async def test_two_runs_against_one_fleet_are_identical(fleet: Fleet, tmp_path: Path) -> None:
    """The bridge resets OpenRails at Initialize: a second ``coupler run`` against the fleet
    that is still up starts from the scenario's start again, and records the same bytes."""
    for name in ("first", "second"):
        code, stderr = await coupler_run(tmp_path / name)
        assert code == 0, stderr
    first = (tmp_path / "first" / "results.csv").read_bytes()
    second = (tmp_path / "second" / "results.csv").read_bytes()
    rows = read_rows(tmp_path / "second" / "results.csv")
    assert len(rows) == 1801
    assert float(rows[1]["OpenRails.distance"]) < 1.0  # at the start, not at the buffer stop
    assert int(rows[1]["TrackBalises.balises_passed"]) == 0
    assert second == first


@pytest.mark.slow
async def test_without_reset_the_second_run_is_refused(
    ports: dict[str, int], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A simulator that cannot reset (the mock with --no-reset, as OpenRails' builds): the
    second run fails at Initialize with what to do, instead of starting mid-track."""
    async with railway_fleet(ports, monkeypatch, "--no-reset"):
        code, stderr = await coupler_run(tmp_path / "first", "--stop-time", "20")
        assert code == 0, stderr
        code, stderr = await coupler_run(tmp_path / "second", "--stop-time", "20")
    assert code != 0
    url = f"http://127.0.0.1:{ports['mock']}"
    assert f"OpenRails at {url} cannot reset its simulation (POST /API/RESET answered 404)" in (
        stderr
    )
    assert "Restart OpenRails" in stderr
    assert "Traceback" not in stderr
    summary = json.loads((tmp_path / "second" / "summary.json").read_text())
    assert summary["status"] == "failed" and "Restart OpenRails" in summary["reason"]


@pytest.mark.slow
async def test_replayed_openrails_gives_the_same_results(
    ports: dict[str, int], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Record the OpenRails bridge, then run the scenario again without OpenRails:

        recording run:  Driver, OpenRails bridge (+ mock), TrackBalises, Map   --record OpenRails
        replayed run:   Driver, replay of OpenRails (in-process), TrackBalises, Map  (fresh)

    The mock and the bridge are stopped; results.csv of the replayed run is the recorded run's,
    byte for byte (OpenRails' columns and every downstream participant's)."""
    recorded, replayed = tmp_path / "recorded", tmp_path / "replayed"
    async with railway_fleet(ports, monkeypatch):
        code, stderr = await coupler_run(recorded, *SHORT, "--record", "OpenRails")
        assert code == 0, stderr
    with pytest.raises(OSError):  # the mock is gone
        socket.create_connection(("127.0.0.1", ports["mock"]), timeout=1).close()
    fresh = {name: free_port() for name in ports}
    async with railway_fleet(fresh, monkeypatch, without_openrails=True) as fleet:
        assert not any("openrails" in s.name for s in fleet.spec.services)
        code, stderr = await coupler_run(replayed, *SHORT, "--replay", f"OpenRails={recorded}")
        assert code == 0, stderr
        # another step than the recording's is refused before anything runs
        refused, why = await coupler_run(
            tmp_path / "refused", *SHORT, "--step", "0.4", "--replay", f"OpenRails={recorded}"
        )
    summary = json.loads((replayed / "summary.json").read_text())
    assert summary["implementations"]["OpenRails"].startswith("coupler replay of")
    before, after = (json.loads((d / "summary.json").read_text()) for d in (recorded, replayed))
    size = (recorded / "recordings" / "OpenRails.crec").stat().st_size
    print(
        f"railway {SHORT[1]} s: recorded run {before['wall_time_s']:.3f} s, replayed "
        f"{after['wall_time_s']:.3f} s (x{before['wall_time_s'] / after['wall_time_s']:.1f}); "
        f"OpenRails.crec {size} bytes"
    )
    rows = read_rows(replayed / "results.csv")
    assert len(rows) == int(SHORT[1]) + 1
    assert readings_of(rows), "the short run should pass at least one balise"
    assert (replayed / "results.csv").read_bytes() == (recorded / "results.csv").read_bytes()
    assert refused == 1
    assert f"has t0=0 s, h=1 s, {SHORT[1]} steps to {SHORT[1]} s; the run asks h=0.4 s" in why
