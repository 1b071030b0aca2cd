"""A real map server (gRPC participant + aiohttp app, both on port 0) and a driver for it.

test (RemoteParticipant) --gRPC--> MapParticipant --RunState--> Feed --SSE--> browsers
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest

from coupler.client import RemoteParticipant
from coupler.server import ParticipantServer
from coupler_dev.browser import chromium
from coupler_railway import Infrastructure, load_infrastructure
from mapserver.__main__ import build_state
from mapserver.config import MapServerSettings
from mapserver.feed import Feed
from mapserver.participant import MapParticipant
from mapserver.web import create_app, start_site

from .support import TEST_LINE, MapService, Run


@pytest.fixture(scope="session")
def test_line() -> Infrastructure:
    return load_infrastructure(TEST_LINE)


@pytest.fixture
def settings() -> MapServerSettings:
    return MapServerSettings(railml=TEST_LINE, grpc_port=0, http_port=0, heartbeat_s=1.0)


@pytest.fixture
async def service(
    test_line: Infrastructure, settings: MapServerSettings
) -> AsyncIterator[MapService]:
    state = build_state(test_line, settings)
    feed = Feed(state, backlog=settings.client_backlog)
    server = ParticipantServer(MapParticipant(state), host="127.0.0.1", port=0)
    await server.start()
    runner, port = await start_site(create_app(feed, test_line, settings), "127.0.0.1", 0)
    try:
        yield MapService(state, feed, server, f"http://127.0.0.1:{port}/")
    finally:
        await server.stop(grace=0.5)
        await runner.cleanup()


@pytest.fixture
async def remote(service: MapService) -> AsyncIterator[RemoteParticipant]:
    async with RemoteParticipant(service.server.address, name="MapServer") as participant:
        yield participant


@pytest.fixture
def run(remote: RemoteParticipant, test_line: Infrastructure) -> Run:
    return Run(remote, test_line)


@pytest.fixture
async def browser() -> AsyncIterator[Any]:
    """Headless Chromium driven by Playwright (coupler_dev.browser)."""
    async with chromium() as launched:
        yield launched
