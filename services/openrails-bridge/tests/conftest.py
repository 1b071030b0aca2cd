"""Real servers on port 0: the OpenRails mock (or a tiny faulty OpenRails), and the bridge
served by a real ParticipantServer, driven through a RemoteParticipant.

    RemoteParticipant --gRPC--> ParticipantServer(bridge) --HTTP--> openrails_mock / tiny
"""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

import pytest
from aiohttp import web

from coupler.client import RemoteParticipant
from coupler.server import ParticipantServer
from openrails_bridge.__main__ import build
from openrails_bridge.config import BridgeSettings
from openrails_mock.api import create_app
from openrails_mock.config import MockConfig

Mock = Callable[..., AbstractAsyncContextManager[str]]
Bridge = Callable[..., AbstractAsyncContextManager[RemoteParticipant]]


@asynccontextmanager
async def serve_app(app: web.Application, port: int = 0) -> AsyncIterator[str]:
    """``app`` on 127.0.0.1, ``port`` (0: a free one); yields its base URL."""
    runner = web.AppRunner(app, shutdown_timeout=0.5)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", port)
    await site.start()
    port = runner.addresses[0][1]
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        await runner.cleanup()


@pytest.fixture
def mock() -> Mock:
    """The real OpenRails mock: ``async with mock(mode=..., loading_delay_s=...) as url``."""

    def _mock(port: int = 0, **config: Any) -> AbstractAsyncContextManager[str]:
        config.setdefault("loading_delay_s", 0.0)
        return serve_app(create_app(MockConfig(port=0, **config)), port)

    return _mock


@pytest.fixture
def bridge() -> Bridge:
    """The bridge on a real ParticipantServer: ``async with bridge(url, mode=...) as remote``;
    keywords are ``BridgeSettings`` but ``connect_timeout`` (how long to wait for SERVING)."""

    @asynccontextmanager
    async def _bridge(
        url: str, *, connect_timeout: float = 10.0, **settings: Any
    ) -> AsyncIterator[RemoteParticipant]:
        settings.setdefault("request_timeout_s", 2.0)
        settings.setdefault("ready_timeout_s", 5.0)
        server = ParticipantServer(build(BridgeSettings(openrails_url=url, **settings)))
        try:
            await server.start()
            async with RemoteParticipant(
                server.address, name="OpenRails", connect_timeout=connect_timeout
            ) as remote:
                yield remote
        finally:
            await server.stop(grace=0.1)

    return _bridge


@pytest.fixture
def closed_port() -> int:
    """A port nothing listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port
