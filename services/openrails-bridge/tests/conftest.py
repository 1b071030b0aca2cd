"""Real servers on port 0: the OpenRails mock (or a tiny faulty OpenRails), and the bridge
served by a real ParticipantServer, driven through a RemoteParticipant.

    RemoteParticipant --gRPC--> ParticipantServer(bridge) --HTTP--> openrails_mock / tiny
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

import pytest

from coupler.client import RemoteParticipant
from coupler.testing import free_port, served
from openrails_bridge.__main__ import build
from openrails_bridge.config import BridgeSettings
from openrails_mock.api import create_app
from openrails_mock.config import MockConfig

from .support import (
    Bridge,
    Mock,
    serve_app,
)


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
        participant = build(BridgeSettings(openrails_url=url, **settings))
        async with (
            served(participant) as server,
            RemoteParticipant(
                server.address, name="OpenRails", connect_timeout=connect_timeout
            ) as remote,
        ):
            yield remote

    return _bridge


@pytest.fixture
def closed_port() -> int:
    """A port nothing listens on."""
    return free_port()
