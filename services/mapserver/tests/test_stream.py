"""The push stream over the real wire: DoSteps through gRPC, events out over SSE.

test --RemoteParticipant/gRPC--> MapParticipant --> RunState --> Feed --SSE--> EventStream
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import aiohttp
import pytest

from mapserver.config import MapServerSettings

from .support import (
    EXPECTED_IDS,
    TEST_LINE,
    BrowserModel,
    EventStream,
    MapService,
    Run,
    stalled_socket,
)


@asynccontextmanager
async def events(service: MapService) -> AsyncIterator[EventStream]:
    timeout = aiohttp.ClientTimeout(total=None, sock_read=30)
    async with (
        aiohttp.ClientSession(timeout=timeout) as session,
        session.get(service.url + "api/events") as response,
    ):
        assert response.status == 200
        assert response.content_type == "text/event-stream"
        yield EventStream(response)


async def test_stream_pushes_steps_and_readings_as_dosteps_arrive(
    service: MapService, run: Run
) -> None:
    browser = BrowserModel()
    async with events(service) as stream:
        first = await stream.next()
        assert first["type"] == "snapshot"
        assert first["run"]["status"] == "idle" and first["readings"] == []
        browser.apply(first)

        await run.start()
        started = await stream.until(lambda e: e["type"] == "run")
        assert started[-1]["reset"] and started[-1]["run"]["run_id"] == "test-run"

        await run.steps(10)  # 250 m: past balises 101 and 102, both in the step to 100..125 m
        for event in started + await stream.until(
            lambda e: e["type"] == "step" and e["run"]["time_s"] == 9.0
        ):
            browser.apply(event)
        assert browser.balise_ids == [101, 102]
        assert browser.readings[0] == {
            "index": 0,
            "time_s": 3.0,  # inputs of DoStep(t=3): the train reached 100 m during [2, 3]
            "balise_id": 101,
            "group_id": 10,
            "distance_m": 100.0,
        }
        assert browser.train is not None
        assert browser.train["distance_m"] == 250.0
        assert browser.run["status"] == "running" and browser.run["steps"] == 10

        await run.to_end()
        await run.participant.terminate("stop time reached")
        for event in await stream.until(lambda e: e["type"] == "run"):
            browser.apply(event)
        assert browser.balise_ids == EXPECTED_IDS
        assert browser.run["status"] == "ended"
        assert browser.run["reason"] == "stop time reached"


async def test_state_endpoint_is_the_snapshot(service: MapService, run: Run) -> None:
    await run.start()
    await run.to_end()
    async with aiohttp.ClientSession() as session, session.get(service.url + "api/state") as r:
        snapshot = await r.json()
    assert snapshot["type"] == "snapshot"
    assert [x["balise_id"] for x in snapshot["readings"]] == EXPECTED_IDS
    assert snapshot["train"]["distance_m"] == pytest.approx(run.length)
    assert snapshot["run"]["realtime_factor"] > 0


async def test_late_joiner_receives_the_whole_run_so_far(service: MapService, run: Run) -> None:
    await run.start()
    await run.steps(30)  # 750 m: 101, 102, 201 passed before anyone watches
    async with events(service) as early:
        pass  # a browser that came and went changes nothing
    del early
    async with events(service) as late:
        snapshot = await late.next()
        assert snapshot["type"] == "snapshot"
        assert [r["balise_id"] for r in snapshot["readings"]] == [101, 102, 201]
        assert snapshot["run"]["run_id"] == "test-run"
        assert snapshot["train"]["distance_m"] == 750.0
        browser = BrowserModel()
        browser.apply(snapshot)
        await run.to_end()
        for event in await late.until(lambda e: e.get("run", {}).get("time_s") == run.time_s - 1):
            browser.apply(event)
    assert browser.balise_ids == EXPECTED_IDS
    assert browser.snapshots == 1  # kept up: deltas only after the first snapshot


@pytest.fixture
def settings() -> MapServerSettings:
    # small backlog so a stalled browser overflows it quickly; long write timeout so it stays
    return MapServerSettings(
        railml=TEST_LINE,
        grpc_port=0,
        http_port=0,
        client_backlog=16,
        client_write_timeout_s=60,
        max_readings=1000,
    )


@pytest.mark.slow
async def test_slow_browser_does_not_slow_the_run(service: MapService, run: Run) -> None:
    chunk = 500
    many = "101:10:100;102:10:103;201:20:600"  # three readings a step: a busy stream

    def busy(values: dict[str, object]) -> dict[str, object]:
        return {**values, "passed_in_step": many}

    await run.start()
    t0 = time.monotonic()
    await run.steps(chunk, inputs=busy)
    baseline = time.monotonic() - t0

    sock = stalled_socket(service.http_port)
    try:
        for _ in range(500):
            if service.feed.subscribers:
                break
            await asyncio.sleep(0.01)
        (slow,) = service.feed.subscribers
        # drive until the stalled browser has clearly fallen behind (its socket buffers full)
        steps, t0 = 0, time.monotonic()
        while steps < 4 * chunk or (slow.resyncs == 0 and steps < 40 * chunk):
            await run.steps(chunk, inputs=busy)
            steps += chunk
        with_slow = time.monotonic() - t0
        print(
            f"DoSteps: {chunk} in {baseline:.2f} s alone; {steps} in {with_slow:.2f} s with a "
            f"stalled browser ({slow.resyncs} resyncs, {slow.coalesced} steps coalesced)"
        )
        assert slow.resyncs >= 1, "the browser never fell behind; the test proves nothing"
        assert slow.peak <= slow.backlog + 1  # bounded, however far behind
        # generous on purpose (seconds): the run must not wait for the browser
        assert with_slow < max(30.0, 10 * baseline * steps / chunk)

        # once it reads again it catches up with one snapshot holding every reading
        loop = asyncio.get_running_loop()
        total = service.state.readings_total
        browser = BrowserModel()
        buffer = b""
        while not browser.readings or browser.readings[-1]["index"] != total - 1:
            buffer += await asyncio.wait_for(loop.sock_recv(sock, 1 << 20), 10)
            *messages, buffer = buffer.split(b"\n\n")
            for message in messages:
                for line in message.split(b"\n"):
                    if line.startswith(b"data: "):
                        browser.apply(json.loads(line[6:]))
        assert total > service.state.max_readings  # the history is bounded too:
        assert len(browser.readings) == service.state.max_readings  # the newest ones are kept
        assert browser.readings[0]["index"] == total - service.state.max_readings
    finally:
        sock.close()
