"""POST /API/RESET, the mock's extension: every run can start from the scenario's start.

test --HTTP--> openrails-mock: drive, RESET, drive again == a fresh mock driven the same way
"""

from __future__ import annotations

from typing import Any

import aiohttp

from openrails_mock.config import MockConfig
from openrails_mock.route import StraightRoute

from .support import FakeClock, Serve, body


async def drive(session: aiohttp.ClientSession) -> list[Any]:
    """Away in reverse, then forward with the brake half on: every control moved."""
    replies = []
    for controls in [{"DIRECTION": -1, "THROTTLE": 0.8}, {}, {"DIRECTION": 1, "TRAIN_BRAKE": 0.5}]:
        for i in range(40):
            posted = body(**controls) if i == 0 else body()
            async with session.post("/API/CABCONTROLS", json=posted) as resp:
                replies.append(await resp.json())
    async with session.get("/API/TIME") as resp:
        replies.append(await resp.json())
    return replies


def config(**changes: Any) -> MockConfig:
    return MockConfig(loading_delay_s=0.0, start_distance_m=1500.0, **changes)


def route() -> StraightRoute:
    return StraightRoute(length_m=4000.0, gradient_per_mille=-3.0)


async def test_reset_brings_back_the_start(serve: Serve) -> None:
    async with serve(config(), route=route()) as session:
        async with session.post("/API/RESET") as resp:
            assert resp.status == 200
            start = await resp.json()
        first = await drive(session)
        async with session.post("/API/RESET", json={}) as resp:
            assert await resp.json() == start
        again = await drive(session)
    assert again == first
    async with serve(config(), route=route()) as session:
        assert await drive(session) == first  # a fresh mock: the same run
    state = start["trains"]["PLAYER"]
    assert state["locomotiveState"]["distance"] == 0.0 and state["locomotiveState"]["v"] == 0.0


async def test_reset_with_options_is_refused_and_changes_nothing(serve: Serve) -> None:
    async with serve(config(), route=route()) as session:
        moved = await drive(session)
        async with session.post("/API/RESET", json={"StartTime": 0}) as resp:
            assert resp.status == 400
            assert 'takes no body, {} or {"Environment"' in (await resp.json())["error"]
        async with session.get("/API/TIME") as resp:
            assert await resp.json() == moved[-1]


async def test_without_reset_the_mock_answers_404_like_openrails(serve: Serve) -> None:
    async with (
        serve(config(reset=False), route=route()) as session,
        session.post("/API/RESET") as resp,
    ):
        assert resp.status == 404


async def test_stock_mode_reset_restarts_the_clock(serve: Serve) -> None:
    clock = FakeClock()
    async with serve(config(mode="stock"), route=route(), clock=clock) as session:
        async with session.post("/API/CABCONTROLS", json=[{"TypeName": "THROTTLE", "Value": 1}]):
            pass
        clock.now += 30.0
        async with session.get("/API/TIME") as resp:
            assert await resp.json() == 28830.0
        async with session.post("/API/RESET") as resp:
            train = (await resp.json())["trains"]["PLAYER"]
        assert train["locomotiveState"]["v"] == 0.0
        clock.now += 2.0
        async with session.get("/API/TIME") as resp:
            assert await resp.json() == 28802.0
