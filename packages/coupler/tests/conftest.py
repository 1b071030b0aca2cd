from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from coupler.examples.gain import GainParticipant
from coupler.server import ParticipantServer


@pytest.fixture
async def gain_server() -> AsyncIterator[ParticipantServer]:
    """The example participant on a real gRPC server, port 0."""
    server = ParticipantServer(GainParticipant())
    await server.start()
    yield server
    await server.stop(grace=0.1)
