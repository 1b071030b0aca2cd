"""The bridge against the real OpenRails mock in stock mode (wall clock, 10x speed-up).

    RemoteParticipant --gRPC--> bridge --POST controls, sleep, GET MAP/DISPLAY--> openrails_mock

The mock and the bridge agree on the speed-up, as they must with a real OpenRails.
"""

from __future__ import annotations

import time

import pytest

from coupler.channels import RunSetup
from coupler.messages import decode_message
from coupler_railway.messages import TRAIN_STATE

from .support import Bridge, Mock


async def test_stock_mode_paces_on_the_wall_clock(mock: Mock, bridge: Bridge) -> None:
    async with (
        mock(mode="stock", speedup=10.0) as url,
        bridge(url, mode="stock", speedup=10.0) as remote,
    ):
        description = await remote.describe()
        first = await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=1.0))
        started = time.monotonic()
        trace = []
        for k in range(10):
            trace.append(await remote.do_step(float(k), 1.0, {"throttle": 1.0}))
        elapsed = time.monotonic() - started
        await remote.terminate()

    assert description.capabilities.fixed_step_size == 0.0  # any step in stock mode
    assert first["speed"] == 0.0 and first["distance"] == 0.0
    # 10 simulated seconds at 10x: about one wall-clock second
    assert 0.9 <= elapsed < 2.5
    last = trace[-1]
    assert last["speed"] > 1.0
    assert last["acceleration"] > 0.0
    distances = [o["distance"] for o in trace]
    assert distances == sorted(distances) and distances[-1] > 5.0
    assert (last["latitude"], last["longitude"]) != (first["latitude"], first["longitude"])
    assert last["direction_state"] == 1
    assert last["track_node"] == 0  # stock OpenRails does not publish the track location
    state = decode_message(TRAIN_STATE, last["train_state"])
    assert state["time_s"] == pytest.approx(10.0)
    assert state["speed_mps"] == pytest.approx(last["speed"])


async def test_stock_mode_accepts_any_step(mock: Mock, bridge: Bridge) -> None:
    async with (
        mock(mode="stock", speedup=10.0) as url,
        bridge(url, mode="stock", speedup=10.0) as remote,
    ):
        await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.3))
        outputs = await remote.do_step(0.0, 0.3, {"throttle": 1.0, "direction": 1})
    assert outputs["speed"] >= 0.0
