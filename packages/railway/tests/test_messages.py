"""The bounds the railway's participants declare (``Channel.max_bytes``) hold for the largest
messages there can be."""

from __future__ import annotations

import pytest

from coupler.v1.railway_pb2 import GeoPoint, TrainState
from coupler.v1.sensors_pb2 import CameraIntrinsics, Image
from coupler_railway.messages import (
    BYTES_PER_PIXEL,
    IMAGE_HEADER_BYTES,
    TRAIN_STATE_BYTES,
    image_bytes,
)


@pytest.mark.parametrize("encoding", sorted(BYTES_PER_PIXEL))
def test_an_image_is_at_most_its_declared_size(encoding: str) -> None:
    width, height = 64, 48
    data = bytes(width * height * BYTES_PER_PIXEL[encoding])
    largest = Image(
        sensor="s" * 64,
        time_s=-1e300,
        width=2**32 - 1,  # the largest varints the header can hold
        height=2**32 - 1,
        encoding=encoding,
        intrinsics=CameraIntrinsics(fx=1.5, fy=1.5, cx=-0.5, cy=-0.5),
        max_distance_m=1e300,
        data=data,
    )
    size = len(largest.SerializeToString())
    assert size - len(data) <= IMAGE_HEADER_BYTES
    assert size <= image_bytes(width, height, encoding)


def test_a_train_state_is_at_most_its_declared_size() -> None:
    largest = TrainState(
        time_s=1e300,
        position=GeoPoint(latitude_deg=-90.0, longitude_deg=-180.0, altitude_m=-1.0),
        heading_deg=359.9,
        distance_m=1e300,
        speed_mps=-1.0,
        acceleration_mps2=-1.0,
        track_node=-(2**31),
        track_offset_m=-1.0,
        direction=-1,
    )
    assert len(largest.SerializeToString()) <= TRAIN_STATE_BYTES
