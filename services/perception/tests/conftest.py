"""Frames rendered by the OpenRails mock's renderer on the railway package's test line, and
the perception participant on a real gRPC server (port 0).

    mock renderer --Image--> RemoteParticipant --gRPC--> ParticipantServer(perception)
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from coupler.client import RemoteParticipant
from coupler.server import ParticipantServer
from coupler_railway import Infrastructure, load_infrastructure
from openrails_mock.renderer import Renderer
from openrails_mock.scene import Scene
from perception.participant import PerceptionParticipant

from .support import TEST_LINE


@pytest.fixture(scope="session")
def test_line() -> Infrastructure:
    return load_infrastructure(TEST_LINE)


@pytest.fixture(scope="session")
def renderer(test_line: Infrastructure) -> Renderer:
    return Renderer(Scene.of_infrastructure(test_line))


@pytest.fixture
async def perception() -> AsyncIterator[RemoteParticipant]:
    server = ParticipantServer(PerceptionParticipant(), port=0)
    await server.start()
    try:
        async with RemoteParticipant(server.address, name="Perception") as remote:
            yield remote
    finally:
        await server.stop(grace=0.1)
