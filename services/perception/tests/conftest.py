"""Frames rendered by the OpenRails mock's renderer on the railway package's test line, and
the perception participant on a real gRPC server (port 0).

    mock renderer --Image--> RemoteParticipant --gRPC--> ParticipantServer(perception)
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from coupler.client import RemoteParticipant
from coupler.server import ParticipantServer
from coupler.v1.railway_pb2 import TrainState
from coupler.v1.sensors_pb2 import CameraIntrinsics, Image
from coupler_railway import Infrastructure, load_infrastructure
from openrails_mock.renderer import CameraModel, Renderer
from openrails_mock.scene import Scene
from perception.participant import PerceptionParticipant

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
CAMERA = CameraModel(width=800, height=600, fov_deg=45.0)


@pytest.fixture(scope="session")
def test_line() -> Infrastructure:
    return load_infrastructure(TEST_LINE)


@pytest.fixture(scope="session")
def renderer(test_line: Infrastructure) -> Renderer:
    return Renderer(Scene.of_infrastructure(test_line))


def frame(renderer: Renderer, front_m: float, time_s: float = 1.0) -> bytes:
    """The mock's 800 x 600 camera frame with the train's front ``front_m`` along the line,
    as the OpenRails bridge sends it."""
    fx, fy, cx, cy = CAMERA.intrinsics()
    return Image(
        sensor="front",
        time_s=time_s,
        width=CAMERA.width,
        height=CAMERA.height,
        encoding="rgb8",
        intrinsics=CameraIntrinsics(fx=fx, fy=fy, cx=cx, cy=cy),
        data=renderer.rgb(CAMERA, front_m).tobytes(),
    ).SerializeToString()


def state(distance_m: float, time_s: float = 1.0) -> bytes:
    return TrainState(time_s=time_s, distance_m=distance_m).SerializeToString()


@pytest.fixture
async def perception() -> AsyncIterator[RemoteParticipant]:
    server = ParticipantServer(PerceptionParticipant(), port=0)
    await server.start()
    try:
        async with RemoteParticipant(server.address, name="Perception") as remote:
            yield remote
    finally:
        await server.stop(grace=0.1)
