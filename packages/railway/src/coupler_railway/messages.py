"""The railway's structured values, registered with Coupler's message registry.

Importing this module makes the messages of ``railway.proto`` (``coupler.v1.TrainState``,
``BaliseReading``, ``GeoPoint``, ``BaliseDetections``) and of ``sensors.proto``
(``coupler.v1.Image``, a camera or depth frame; ``FrameLabels``, its ground truth) known
to ``coupler.messages``: binary channels carrying them can be encoded, decoded and written
as JSON in results. The message names live here and nowhere else.
"""

from __future__ import annotations

from coupler.messages import register
from coupler.v1.railway_pb2 import (
    BaliseDetection,
    BaliseDetections,
    BaliseReading,
    GeoPoint,
    TrainState,
)
from coupler.v1.sensors_pb2 import FrameLabels, Image, ObjectLabel

register(
    TrainState,
    BaliseReading,
    GeoPoint,
    BaliseDetection,
    BaliseDetections,
    Image,
    ObjectLabel,
    FrameLabels,
)

TRAIN_STATE = TrainState.DESCRIPTOR.full_name
"""Full name of the train state message (``coupler.v1.TrainState``)."""
BALISE_READING = BaliseReading.DESCRIPTOR.full_name
"""Full name of the balise reading message."""
GEO_POINT = GeoPoint.DESCRIPTOR.full_name
"""Full name of the WGS84 point message."""
BALISE_DETECTIONS = BaliseDetections.DESCRIPTOR.full_name
"""Full name of the message of every balise a perception participant saw in one frame."""
IMAGE = Image.DESCRIPTOR.full_name
"""Full name of a camera or depth frame (``coupler.v1.Image``, sensors.proto)."""
FRAME_LABELS = FrameLabels.DESCRIPTOR.full_name
"""Full name of a camera frame's ground truth (``coupler.v1.FrameLabels``, sensors.proto)."""
FRAME_LABELS_BYTES = 256 * 1024
"""The largest serialized ``FrameLabels`` a labels channel carries: about 2500 objects (a label
is about 100 bytes); a frame shows a few dozen."""

RGB8 = "rgb8"
"""``Image.encoding`` of 8-bit RGB pixels, rows top to bottom."""
DEPTH16_CLASS_ID = "depth16-class-id"
"""``Image.encoding`` of OpenRails' depth frames: (class << 13 | id, distance, intensity) as
little-endian uint16 per pixel."""
BYTES_PER_PIXEL = {RGB8: 3, DEPTH16_CLASS_ID: 6}
"""Size of one pixel of each encoding."""

IMAGE_HEADER_BYTES = 256
"""What a serialized ``Image`` carries besides its pixels, at most [bytes]: every field's key
and length, a sensor name of up to 64 bytes (what the OpenRails bridge allows), the longest
encoding above, the numbers and the intrinsics -- 158 bytes, rounded up."""
MAX_FRAME = (3840, 2160)
"""The largest frame (width, height) the railway's participants take in: 4K UHD."""
TRAIN_STATE_BYTES = 128
"""A serialized ``TrainState`` at most [bytes]: every field set, its integers negative (105
bytes), rounded up."""


def image_bytes(width: int, height: int, encoding: str) -> int:
    """The largest serialized ``Image`` of ``width`` x ``height`` pixels of ``encoding``: what a
    channel carrying such frames declares as its largest value (``Channel.max_bytes``)."""
    return IMAGE_HEADER_BYTES + width * height * BYTES_PER_PIXEL[encoding]
