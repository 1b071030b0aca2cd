"""Stock mode (upstream OpenRails) against a real mock: wall-clock pacing, plain-list POST.

test --POST [controls]--> openrails-mock (stock, speedup 4) <--GET TIME/MAP/DISPLAY-- test
(time is a fake monotonic clock the test moves)
"""

from __future__ import annotations

import asyncio
import math
import sys

import aiohttp

from openrails_mock.config import MockConfig
from openrails_mock.physics import DB_CLASS_642
from openrails_mock.route import StraightRoute

from .support import FakeClock, Serve


def stock(**changes: object) -> MockConfig:
    return MockConfig(mode="stock", speedup=4.0, **changes)  # type: ignore[arg-type]


async def test_stock_mode_follows_the_wall_clock(serve: Serve) -> None:
    clock = FakeClock()
    route = StraightRoute(length_m=10_000.0, heading_deg=0.0)
    async with serve(stock(start_time_s=36_000.0), route=route, clock=clock) as session:
        async with session.get("/API/READY") as resp:
            assert resp.status == 404  # upstream OpenRails has no READY
        async with session.get("/API/MAP") as resp:
            lat0 = (await resp.json())["LatLon"]["Lat"]
        controls = [{"TypeName": "THROTTLE", "ControlIndex": 1, "Value": 1.0}]
        async with session.post("/API/CABCONTROLS", json=controls) as resp:
            assert resp.status == 200
            assert await resp.read() == b""
        clock.now += 5.0  # 5 s of wall time at speedup 4: 20 s simulated
        async with session.get("/API/TIME") as resp:
            assert math.isclose(await resp.json(), 36_020.0)
        async with session.get("/API/TRAINDRIVINGDISPLAY") as resp:
            rows = {r["FirstCol"]: r["LastCol"] for r in await resp.json()}
        async with session.get("/API/MAP") as resp:
            position = await resp.json()
    # 20 s from rest at full throttle: about 1.2 m/s^2 at first, power-limited above 18 km/h.
    speed_kmh = float(rows["SPED"].split()[0])
    assert 40.0 < speed_kmh < 80.0
    assert rows["THRO"] == "100%"
    assert position["LatLon"]["Lat"] > lat0  # heading north, so latitude grows
    assert position["DirectionDeg"] == 0.0


async def test_stock_mode_speed_matches_an_equal_lockstep_run(serve: Serve) -> None:
    """The same 20 s at full throttle, in stock (one catch-up) and lockstep (100 steps)."""
    clock = FakeClock()
    route = StraightRoute(length_m=10_000.0)
    async with serve(stock(), route=route, clock=clock) as session:
        async with session.post("/API/CABCONTROLS", json=[{"TypeName": "THROTTLE", "Value": 1}]):
            pass
        clock.now += 5.0
        async with session.get("/API/TRAINDRIVINGDISPLAY") as resp:
            stock_kmh = float({r["FirstCol"]: r["LastCol"] for r in await resp.json()}["SPED"][:-5])
    lockstep = MockConfig(loading_delay_s=0.0)
    async with serve(lockstep, route=route) as session:
        body = {"Controls": [{"LocomotiveName": "PLAYER", "TypeName": "THROTTLE", "Value": 1}]}
        for _ in range(100):
            async with session.post("/API/CABCONTROLS", json=body) as resp:
                v = (await resp.json())["trains"]["PLAYER"]["locomotiveState"]["v"]
    assert math.isclose(stock_kmh, v * 3.6, abs_tol=0.1)  # display rounds to 0.1 km/h


async def test_python_dash_m_serves_on_a_free_port() -> None:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "openrails_mock",
        "--port",
        "0",
        "--loading-delay-s",
        "0",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    try:
        assert process.stdout is not None
        line = ""
        while "listening on" not in line:
            line = (await asyncio.wait_for(process.stdout.readline(), 30)).decode()
            assert line, "the mock exited before listening"
        url = line.split()[-1]
        assert url.startswith("http://127.0.0.1:") and not url.startswith("http://127.0.0.1:0/")
        async with aiohttp.ClientSession() as session:
            async with session.get(f"{url}/READY") as resp:
                assert resp.status == 200
            async with session.get(f"{url}/CABCONTROLS") as resp:
                assert len(await resp.json()) == 5
            body = {"Controls": [], "Commands": [], "SwitchCommands": {}}
            async with session.post(f"{url}/CABCONTROLS", json=body) as resp:
                train = (await resp.json())["trains"]["PLAYER"]
        assert train["trainLength"]["length"] == DB_CLASS_642.length_m
    finally:
        process.terminate()
        await process.wait()


async def test_on_ipv6_it_prints_a_url_with_brackets() -> None:
    """``--host ::1``: the printed URL is one a client opens (it was http://::1:PORT/API)."""
    process = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "openrails_mock", "--host", "::1", "--port", "0"),
        *("--loading-delay-s", "0"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    try:
        assert process.stdout is not None
        line = ""
        while "listening on" not in line:
            line = (await asyncio.wait_for(process.stdout.readline(), 30)).decode()
            assert line, "the mock exited before listening"
        url = line.split()[-1]
        assert url.startswith("http://[::1]:"), url
        async with aiohttp.ClientSession() as session, session.get(f"{url}/READY") as resp:
            assert resp.status == 200
    finally:
        process.terminate()
        await process.wait()
