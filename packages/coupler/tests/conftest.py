from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from coupler.examples.gain import GainParticipant
from coupler.server import ParticipantServer
from coupler.testing import served


@pytest.fixture
async def gain_server() -> AsyncIterator[ParticipantServer]:
    """The example participant on a real gRPC server, port 0."""
    async with served(GainParticipant()) as server:
        yield server
