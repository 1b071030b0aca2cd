"""What the perception tests share besides fixtures (those are in conftest.py): the camera,
rendered frames and train states, the camera's intrinsics as the detector takes them.
"""

from __future__ import annotations

from pathlib import Path

from coupler.v1.railway_pb2 import TrainState
from coupler.v1.sensors_pb2 import CameraIntrinsics, Image
from openrails_mock.renderer import CameraModel, Renderer
from perception.detector import Intrinsics

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
CAMERA = CameraModel(width=800, height=600, fov_deg=45.0)


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


def intrinsics() -> Intrinsics:
    """``CAMERA``'s intrinsics, as the detector takes them."""
    fx, fy, cx, cy = CAMERA.intrinsics()
    return Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy)
