"""OpenRails down, failing or hanging: UNAVAILABLE naming the URL, within the request timeout;
health NOT_SERVING with the reason while OpenRails cannot be reached.

    RemoteParticipant --gRPC--> bridge --HTTP--> closed port / openrails_mock (stopped)
                                             \\-> tiny OpenRails: 503 or a POST that never answers

The tiny server exists for what the mock cannot do: answer 503 and hang.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import pytest
from aiohttp import web

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError, ParticipantUnavailable
from coupler.testing import served
from openrails_bridge.__main__ import build
from openrails_bridge.config import BridgeSettings

from .support import Bridge, Handler, Mock, serve_app, tiny_openrails


def failing_step(how: str, release: asyncio.Event) -> Handler:
    """A POST /API/CABCONTROLS that answers 503, or hangs until ``release`` first."""

    async def step(request: web.Request) -> web.Response:
        if how == "hang":
            await release.wait()
        return web.Response(status=503, text="Service Unavailable: simulator paused")

    return step


@pytest.fixture
async def release() -> AsyncIterator[asyncio.Event]:
    event = asyncio.Event()
    yield event
    event.set()


async def test_openrails_down_at_step(mock: Mock, bridge: Bridge) -> None:
    """The mock goes away between two steps: the next DoStep is UNAVAILABLE naming the URL."""
    cm = mock()
    url = await cm.__aenter__()
    try:
        async with bridge(url) as remote:
            await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
            await remote.do_step(0.0, 0.2, {"throttle": 1.0})
            await cm.__aexit__(None, None, None)
            cm = None
            started = time.monotonic()
            with pytest.raises(ParticipantUnavailable) as caught:
                await remote.do_step(0.2, 0.2, {})
    finally:
        if cm is not None:
            await cm.__aexit__(None, None, None)
    assert time.monotonic() - started < 3.0
    assert caught.value.status == "UNAVAILABLE"
    assert f"OpenRails at {url}/API/CABCONTROLS" in str(caught.value)


async def test_openrails_down_at_start_then_up(mock: Mock, closed_port: int) -> None:
    """The bridge starts without OpenRails: health NOT_SERVING naming the URL, Initialize
    UNAVAILABLE naming it; once OpenRails answers, SERVING and runs go."""
    url = f"http://127.0.0.1:{closed_port}"
    settings = BridgeSettings(openrails_url=url, ready_timeout_s=0.5, request_timeout_s=0.5)
    started = time.monotonic()
    async with served(build(settings)) as server:  # does not wait for OpenRails
        assert time.monotonic() - started < 2.0
        with pytest.raises(ParticipantUnavailable) as waiting:
            async with RemoteParticipant(server.address, name="OpenRails", connect_timeout=0.5):
                pass
        with pytest.raises(ParticipantUnavailable) as initializing:
            await server.participant.initialize(RunSetup(run_id="t", start_time=0, step_size=0.2))
        async with (
            mock(port=closed_port),
            RemoteParticipant(server.address, name="OpenRails", connect_timeout=5.0) as remote,
        ):
            await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
            moving = await remote.do_step(0.0, 0.2, {"throttle": 1.0})
    health = str(waiting.value)
    assert "health is NOT_SERVING: cannot reach OpenRails at " in health
    assert f"{url}/API/READY: ClientConnectorError" in health
    assert f"OpenRails at {url} is not ready (cannot reach OpenRails at {url}/API/READY" in str(
        initializing.value
    )
    assert moving["speed"] > 0.0


async def test_openrails_gone_before_initialize(mock: Mock, bridge: Bridge) -> None:
    """OpenRails went away while the bridge was idle: Initialize is UNAVAILABLE naming the URL,
    health turns NOT_SERVING with the reason."""
    cm = mock()
    url = await cm.__aenter__()
    try:
        async with bridge(url) as remote:
            await cm.__aexit__(None, None, None)
            cm = None
            with pytest.raises(ParticipantUnavailable) as caught:
                await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
            with pytest.raises(ParticipantUnavailable) as health:
                await remote.wait_until_serving_once()
    finally:
        if cm is not None:
            await cm.__aexit__(None, None, None)
    assert caught.value.status == "UNAVAILABLE"
    assert f"cannot reach OpenRails at {url}/API/RESET" in str(caught.value)
    assert f"health is NOT_SERVING: cannot reach OpenRails at {url}/API/READY" in str(health.value)


async def test_error_answer_is_unavailable(release: asyncio.Event, bridge: Bridge) -> None:
    async with (
        serve_app(tiny_openrails(step=failing_step("503", release))) as url,
        bridge(url) as remote,
    ):
        await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
        with pytest.raises(ParticipantUnavailable) as caught:
            await remote.do_step(0.0, 0.2, {"throttle": 0.5})
    message = str(caught.value)
    assert f"OpenRails at {url}/API/CABCONTROLS answered 503" in message
    assert "simulator paused" in message


async def test_hanging_openrails_times_out(release: asyncio.Event, bridge: Bridge) -> None:
    """POST /API/CABCONTROLS never answers: DoStep fails after the 0.5 s request timeout."""
    async with serve_app(tiny_openrails(step=failing_step("hang", release))) as url:
        async with bridge(url, request_timeout_s=0.5) as remote:
            await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
            started = time.monotonic()
            with pytest.raises(ParticipantError) as caught:
                await remote.do_step(0.0, 0.2, {"throttle": 0.5})
            elapsed = time.monotonic() - started
        release.set()
    assert 0.4 <= elapsed < 2.0
    assert caught.value.status == "UNAVAILABLE"
    assert f"OpenRails at {url}/API/CABCONTROLS did not answer POST within 0.5 s" in str(
        caught.value
    )
