"""The bridge against the real OpenRails mock in lockstep mode.

    RemoteParticipant --gRPC--> bridge --POST /API/CABCONTROLS x h/0.2--> openrails_mock

Each test starts its own mock and bridge on free ports.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import aiohttp
import pytest
from aiohttp import web

from coupler.channels import Causality, RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError
from coupler.messages import decode_message
from coupler_railway.messages import TRAIN_STATE
from openrails_mock.api import SERVER, create_app
from openrails_mock.config import MockConfig

from .support import Bridge, Mock, serve_app


async def test_describe_lists_channels_and_fixed_step(mock: Mock, bridge: Bridge) -> None:
    async with mock() as url, bridge(url) as remote:
        description = await remote.describe()
    assert [c.name for c in description.of(Causality.OUTPUT)] == [
        "distance",
        "speed",
        "acceleration",
        "latitude",
        "longitude",
        "heading",
        "track_node",
        "track_offset",
        "direction_state",
        "wheelslip",
        "wheelskid",
        "train_state",
    ]
    assert [c.name for c in description.of(Causality.INPUT)] == [
        "throttle",
        "brake",
        "dynamic_brake",
        "direction",
    ]
    assert description.channel("train_state").message_type == TRAIN_STATE
    assert description.capabilities.fixed_step_size == pytest.approx(0.2)


async def test_throttle_moves_the_train(mock: Mock, bridge: Bridge) -> None:
    async with mock() as url, bridge(url) as remote:
        first = await remote.initialize(
            RunSetup(run_id="t", start_time=0.0, step_size=1.0, inputs={"throttle": 1.0})
        )
        assert first["speed"] == 0.0
        assert first["latitude"] != 0.0 and first["longitude"] != 0.0
        trace = [first]
        for k in range(10):
            trace.append(await remote.do_step(float(k), 1.0, {}))
        await remote.terminate()

    last = trace[-1]
    assert last["speed"] > 1.0
    assert last["acceleration"] > 0.0
    distances = [o["distance"] for o in trace[1:]]
    assert distances == sorted(distances) and distances[-1] > distances[0] > 0.0
    assert last["track_node"] >= 1 and last["track_offset"] > 0.0
    assert last["direction_state"] == 1
    assert (last["latitude"], last["longitude"]) != (first["latitude"], first["longitude"])
    state = decode_message(TRAIN_STATE, last["train_state"])
    assert state["time_s"] == pytest.approx(10.0)
    assert state["speed_mps"] == pytest.approx(last["speed"])
    assert state["distance_m"] == pytest.approx(last["distance"])
    assert state["position"]["latitude_deg"] == pytest.approx(last["latitude"])
    assert state["track_node"] == last["track_node"]
    assert state["direction"] == 1


async def test_each_step_posts_h_over_sim_step_times(mock: Mock, bridge: Bridge) -> None:
    """One 1 s step and five 0.2 s steps advance the same mock identically."""
    async with mock() as url_a, mock() as url_b, bridge(url_a) as a, bridge(url_b) as b:
        await a.initialize(RunSetup(run_id="a", start_time=0.0, step_size=1.0))
        await b.initialize(RunSetup(run_id="b", start_time=0.0, step_size=0.2))
        big = await a.do_step(0.0, 1.0, {"throttle": 0.8})
        small = {}
        for k in range(5):
            small = await b.do_step(k * 0.2, 0.2, {"throttle": 0.8})
    assert big["speed"] > 0.0
    assert big["speed"] == pytest.approx(small["speed"])
    assert big["distance"] == pytest.approx(small["distance"])


async def test_brake_stops_the_train(mock: Mock, bridge: Bridge) -> None:
    async with mock() as url, bridge(url) as remote:
        await remote.initialize(
            RunSetup(run_id="t", start_time=0.0, step_size=2.0, inputs={"throttle": 1.0})
        )
        for k in range(5):
            moving = await remote.do_step(2.0 * k, 2.0, {})
        t = 10.0
        for _ in range(20):
            stopped = await remote.do_step(t, 2.0, {"throttle": 0.0, "brake": 1.0})
            t += 2.0
    assert moving["speed"] > 1.0
    assert stopped["speed"] == pytest.approx(0.0, abs=1e-6)
    assert stopped["distance"] > moving["distance"]


async def test_step_not_a_multiple_is_invalid_argument(mock: Mock, bridge: Bridge) -> None:
    async with mock() as url, bridge(url) as remote:
        with pytest.raises(ParticipantError) as caught:
            await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.3))
    assert caught.value.status == "INVALID_ARGUMENT"
    assert "0.3 s" in str(caught.value) and "0.2 s" in str(caught.value)


async def test_control_out_of_range_is_invalid_argument(mock: Mock, bridge: Bridge) -> None:
    async with mock() as url, bridge(url) as remote:
        await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
        with pytest.raises(ParticipantError) as caught:
            await remote.do_step(0.0, 0.2, {"throttle": 1.5})
    assert caught.value.status == "INVALID_ARGUMENT"
    assert "'throttle'" in str(caught.value) and "[0, 1]" in str(caught.value)


async def test_connect_waits_for_ready(mock: Mock, bridge: Bridge) -> None:
    """READY answers 425 for 1 s: the bridge starts serving only after it turned 200."""
    started = time.monotonic()
    async with mock(loading_delay_s=1.0) as url, bridge(url) as remote:
        waited = time.monotonic() - started
        outputs = await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
        outputs = await remote.do_step(0.0, 0.2, {"throttle": 1.0})
    assert 0.9 <= waited < 4.0
    assert outputs["speed"] > 0.0


async def run_once(remote: RemoteParticipant, run_id: str) -> list[dict[str, Any]]:
    """Away in reverse, then forward with the brake half on: every control moved."""
    trace = [
        await remote.initialize(
            RunSetup(run_id=run_id, start_time=0.0, step_size=1.0, inputs={"throttle": 0.6})
        )
    ]
    for k, inputs in enumerate([{"direction": -1}, {}, {}, {"direction": 1, "brake": 0.5}, {}]):
        trace.append(await remote.do_step(float(k), 1.0, inputs))
    await remote.terminate()
    return trace


async def test_each_run_starts_from_the_scenario_start(mock: Mock, bridge: Bridge) -> None:
    """The mock resets at every Initialize: a second run repeats the first bit for bit."""
    async with mock(start_distance_m=2000.0) as url, bridge(url) as remote:
        first = await run_once(remote, "1")
        second = await run_once(remote, "2")
    assert first[2]["speed"] < 0.0 and first[-1]["distance"] > 0.0  # it went somewhere
    assert second == first
    assert second[0]["distance"] == 0.0 and second[0]["direction_state"] == 1


async def test_without_reset_a_moved_train_fails_initialize(mock: Mock, bridge: Bridge) -> None:
    """A simulator that cannot reset (404, as OpenRails' builds): the first run starts where
    the train stands; the next one is refused, naming the URL and the fix."""
    async with mock(reset=False, start_distance_m=2000.0) as url, bridge(url) as remote:
        first = await run_once(remote, "1")
        with pytest.raises(ParticipantError) as caught:
            await remote.initialize(RunSetup(run_id="2", start_time=0.0, step_size=1.0))
        message = str(caught.value)
    assert caught.value.status == "UNAVAILABLE"
    assert f"OpenRails at {url} cannot reset its simulation (POST /API/RESET answered 404)" in (
        message
    )
    assert "Restart OpenRails" in message
    assert first[-1]["distance"] > 1.0


async def test_without_reset_a_restarted_openrails_runs_again(
    mock: Mock, bridge: Bridge, closed_port: int
) -> None:
    """... and once OpenRails is restarted (a new one on the same port), runs go again."""
    cm = mock(port=closed_port, reset=False)
    url = await cm.__aenter__()
    try:
        async with bridge(url) as remote:
            first = await run_once(remote, "1")
            await cm.__aexit__(None, None, None)
            cm = mock(port=closed_port, reset=False)  # OpenRails restarted: back at the start
            await cm.__aenter__()
            again = await run_once(remote, "2")
    finally:
        await cm.__aexit__(None, None, None)
    assert again == first


async def test_map_is_read_only_when_the_train_moved_and_outputs_stay_exact(
    bridge: Bridge,
) -> None:
    """A train that runs, brakes and stands: every step's latitude, longitude and heading are
    what GET /API/MAP answers at that step, while the bridge reads MAP only after steps in
    which the train moved (and once at Initialize)."""
    app = create_app(MockConfig(port=0, loading_delay_s=0.0))
    maps_read = []

    @web.middleware
    async def count(request: web.Request, handler: Any) -> web.StreamResponse:
        if request.path == "/API/MAP":
            maps_read.append(request.app[SERVER].simulation.snapshot().state.odometer_m)
        response: web.StreamResponse = await handler(request)
        return response

    app.middlewares.append(count)
    async with serve_app(app) as url, bridge(url) as remote, aiohttp.ClientSession() as http:

        async def openrails_map() -> tuple[float, float, float]:
            async with http.get(f"{url}/API/MAP") as answer:
                where = await answer.json()
            maps_read.pop()  # the test's own request
            return where["LatLon"]["Lat"], where["LatLon"]["Lon"], where["DirectionDeg"]

        def seen(outputs: Mapping[str, Any]) -> tuple[float, float, float]:
            return outputs["latitude"], outputs["longitude"], outputs["heading"]

        outputs = await remote.initialize(
            RunSetup(run_id="t", start_time=0.0, step_size=1.0, inputs={"throttle": 1.0})
        )
        assert seen(outputs) == await openrails_map()
        moved = []
        for k in range(40):
            controls = {"throttle": 1.0} if k < 10 else {"throttle": 0.0, "brake": 1.0}
            before = outputs["distance"]
            outputs = await remote.do_step(float(k), 1.0, controls)
            assert seen(outputs) == await openrails_map(), f"step {k}"
            moved.append(outputs["distance"] != before)
        await remote.terminate()

    assert outputs["speed"] == 0.0 and moved[0] and not moved[-1]  # it ran, then stood
    assert len(maps_read) == 1 + sum(moved)
