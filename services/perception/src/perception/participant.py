"""``PerceptionParticipant``: camera frames in, balise detections out.

Inputs (both Binary, start empty): ``image``, a ``coupler.v1.Image`` (rgb8) from a camera --
the OpenRails bridge offers one per sensor -- and ``train_state``, a ``coupler.v1.TrainState``
for the participant's own odometry: where along the line the camera is. Output
``detections``: a ``coupler.v1.BaliseDetections`` of every balise found in the frame (time =
the frame's), each with its pixel box, distance ahead, track position and confidence; and
``detection_count``.

Track position of a detection = ``track_offset`` + the train's distance travelled (TrainState,
of the same communication point as the frame) + the distance ahead: the camera is taken at
``track_offset`` along the line when the train has travelled 0 m, moving forward.

A step with an empty image (no frame yet) detects nothing; bytes that are not an Image, an
image that is not rgb8, whose data does not match its width and height, or whose intrinsics
are not a camera's (fx, fy finite and positive; cx, cy finite) are refused as
INVALID_ARGUMENT naming the channel. A frame gives at most ``max_detections`` detections (the
nearest); ``BaliseDetections.omitted`` says how many more it had.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from google.protobuf.message import DecodeError

from coupler.channels import Capabilities, Causality, Channel, Description, RunSetup, Value
from coupler.channels import ValueType as T
from coupler.errors import ChannelValueError
from coupler.messages import without_bytes
from coupler.participant import Participant, Values
from coupler.v1.railway_pb2 import BaliseDetection, BaliseDetections, PixelBox, TrainState
from coupler.v1.sensors_pb2 import Image
from coupler_railway.messages import (
    BALISE_DETECTIONS,
    IMAGE,
    MAX_FRAME,
    RGB8,
    TRAIN_STATE,
    TRAIN_STATE_BYTES,
    image_bytes,
)

from .detector import MAX_DETECTIONS, Intrinsics, Mask, Mounting, find, yellow_mask
from .learned import ModelError, PixelModel

NAME = "Perception"
DETECTORS = ("colour", "learned")
"""``detector``: the colour thresholds, or the learned pixel model (``learned.py``)."""
MODEL = Path("build/models/balise-pixels.json")
"""The learned detector's model file (``make detector-model``), from the working folder."""
LEARNED_MAX_WIDTH = 2.0
"""The learned detector drops blobs wider than this many balise widths at their distance."""
MAX_DETECTIONS_LIMIT = 10_000
"""The largest ``max_detections`` taken: 10,000 detections are a 0.5 MB answer."""


def _channel(
    name: str, causality: Causality, type: T, start: Value | None, unit: str = "", **more: Any
) -> Channel:
    return Channel(name=name, causality=causality, type=type, start=start, unit=unit, **more)


_IN, _OUT, _PAR = Causality.INPUT, Causality.OUTPUT, Causality.PARAMETER
CHANNELS = (
    _channel("image", _IN, T.BINARY, b"", message_type=IMAGE,
             max_bytes=image_bytes(*MAX_FRAME, RGB8),
             description="Camera frame (coupler.v1.Image, rgb8, up to 3840 x 2160); empty: no "
                         "frame yet"),
    _channel("train_state", _IN, T.BINARY, b"", message_type=TRAIN_STATE,
             max_bytes=TRAIN_STATE_BYTES,
             description="Train state of the frame's time: distance travelled (odometry)"),
    _channel("camera_height", _PAR, T.REAL, 2.5, "m",
             description="Camera above the top of the rails"),
    _channel("camera_pitch", _PAR, T.REAL, 4.0, "deg",
             description="Camera pitched down from the track's direction"),
    _channel("track_offset", _PAR, T.REAL, 0.0, "m",
             description="Camera's position along the line when the train has travelled 0 m"),
    _channel("max_range", _PAR, T.REAL, 40.0, "m",
             description="Balises farther ahead are not reported"),
    _channel("min_pixels", _PAR, T.INTEGER, 2,
             description="Smallest yellow blob taken for a balise [pixels]"),
    _channel("max_detections", _PAR, T.INTEGER, MAX_DETECTIONS,
             description="Detections reported per frame at most (the nearest); how many more "
                         "there were is the message's `omitted`"),
    _channel("detector", _PAR, T.STRING, "colour",
             description="Which detector: colour (yellow thresholds) or learned (a decision "
                         "tree over pixel colours, trained on the mock's labelled frames)"),
    _channel("detections", _OUT, T.BINARY, None, message_type=BALISE_DETECTIONS,
             description="Every balise found in the last frame (coupler.v1.BaliseDetections)"),
    _channel("detection_count", _OUT, T.INTEGER, None,
             description="How many balises the last frame showed"),
)  # fmt: skip


class PerceptionParticipant(Participant):
    """Finds balises in each frame it is given; see the module docstring."""

    def __init__(self, *, model: Path = MODEL) -> None:
        self._model = model
        self._mask: Mask = yellow_mask
        self._max_width: float | None = None
        self._parameters: dict[str, Value] = {}
        self._inputs: dict[str, Value] = {}
        self._outputs: Values = {}

    async def describe(self) -> Description:
        return Description(
            name=NAME,
            channels=CHANNELS,
            capabilities=Capabilities(streaming=True, variable_step_size=True),
            implementation="coupler perception 0.1.0 (yellow blobs, ground-plane distance)",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        self._parameters = {**_starts(_PAR), **setup.parameters}
        bound = int(self._parameters["max_detections"])
        if not 1 <= bound <= MAX_DETECTIONS_LIMIT:
            raise ChannelValueError(
                f"parameter 'max_detections' is {bound}; it bounds the detections of one "
                f"frame: give 1 to {MAX_DETECTIONS_LIMIT}",
                channel="max_detections",
                expected=f"1 to {MAX_DETECTIONS_LIMIT}",
            )
        self._mask, self._max_width = self._detector(str(self._parameters["detector"]))
        self._inputs = {**_starts(_IN), **setup.inputs}
        self._outputs = self._perceive(self._inputs)
        return self._outputs

    def _detector(self, name: str) -> tuple[Mask, float | None]:
        if name == "colour":
            return yellow_mask, None
        if name != "learned":
            raise ChannelValueError(
                f"parameter 'detector' is {name!r}; give one of {', '.join(DETECTORS)}",
                channel="detector",
                expected=" or ".join(DETECTORS),
            )
        try:
            model = _model(self._model.resolve())
        except ModelError as exc:
            raise ChannelValueError(str(exc), channel="detector", expected="a model file") from None
        from . import pixels  # numba, for the learned detector alone

        pixels.warm()  # compiled (or loaded from numba's cache) here, not in the first step
        return model.mask, LEARNED_MAX_WIDTH

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self._inputs.update(inputs)
        self._outputs = self._perceive(self._inputs)
        return self._outputs

    async def terminate(self, reason: str = "") -> None:
        self._outputs = {}

    def _perceive(self, inputs: Mapping[str, Value]) -> Values:
        frame = inputs.get("image", b"")
        if not isinstance(frame, bytes) or not frame:
            return _result(BaliseDetections())
        image, data = _image(frame)
        intrinsics = _intrinsics(image)
        state = _train_state(inputs.get("train_state", b""))
        p = self._parameters
        pixels = np.frombuffer(data, dtype=np.uint8).reshape(image.height, image.width, 3)
        found = find(
            pixels,
            intrinsics,
            Mounting(height_m=float(p["camera_height"]), pitch_deg=float(p["camera_pitch"])),
            max_range_m=float(p["max_range"]),
            min_pixels=int(p["min_pixels"]),
            max_detections=int(p["max_detections"]),
            mask=self._mask,
            max_width_ratio=self._max_width,
        )
        camera_at = float(p["track_offset"]) + state.distance_m
        message = BaliseDetections(
            time_s=image.time_s,
            sensor=image.sensor,
            detections=[
                BaliseDetection(
                    time_s=image.time_s,
                    box=PixelBox(left=d.left, top=d.top, right=d.right, bottom=d.bottom),
                    distance_ahead_m=round(d.distance_ahead_m, 3),
                    track_position_m=round(camera_at + d.distance_ahead_m, 3),
                    confidence=d.confidence,
                )
                for d in found.detections
            ],
            omitted=found.omitted,
        )
        return _result(message)


def _image(frame: bytes) -> tuple[Image, memoryview]:
    """The Image in ``frame`` and its pixels (a view); ChannelValueError when it is none."""
    try:
        image, data = without_bytes(Image, frame, "data")  # the pixels a view, not copies
    except DecodeError:
        raise ChannelValueError(
            f"channel 'image' carries {len(frame)} bytes that are not a coupler.v1.Image "
            f"(connect a camera channel: the OpenRails bridge's sensor output)",
            channel="image",
            expected="coupler.v1.Image",
        ) from None
    if image.encoding != RGB8:
        raise ChannelValueError(
            f"channel 'image' carries a '{image.encoding}' frame of sensor "
            f"'{image.sensor}'; the detector reads '{RGB8}' (connect a camera, not a "
            f"depth sensor)",
            channel="image",
            expected=RGB8,
        )
    size = image.width * image.height * 3
    if len(data) != size:
        raise ChannelValueError(
            f"channel 'image': sensor '{image.sensor}' declares {image.width} x "
            f"{image.height} rgb8 ({size} bytes) but its data has {len(data)} bytes",
            channel="image",
            expected=f"{size} bytes",
        )
    return image, data


def _train_state(raw: Value) -> TrainState:
    """The TrainState in ``raw`` (empty: travelled 0 m); ChannelValueError when it is none."""
    state = TrainState()
    try:
        state.ParseFromString(raw if isinstance(raw, bytes) else b"")
    except DecodeError:
        raise ChannelValueError(
            f"channel 'train_state' carries {len(raw) if isinstance(raw, bytes) else 0} bytes "
            f"that are not a coupler.v1.TrainState (connect the OpenRails bridge's train_state)",
            channel="train_state",
            expected="coupler.v1.TrainState",
        ) from None
    return state


def _intrinsics(image: Image) -> Intrinsics:
    """The frame's camera; ChannelValueError for intrinsics no camera has (the distances
    would be NaN, or a division by zero)."""
    k = image.intrinsics
    focal_ok = all(math.isfinite(f) and f > 0 for f in (k.fx, k.fy))
    if not focal_ok or not all(math.isfinite(c) for c in (k.cx, k.cy)):
        raise ChannelValueError(
            f"channel 'image': sensor '{image.sensor}' has intrinsics fx={k.fx!r}, "
            f"fy={k.fy!r}, cx={k.cx!r}, cy={k.cy!r}; a camera's focal lengths are finite and "
            f"positive and its centre finite (pixels): fix the sensor's fov and size",
            channel="image",
            expected="fx, fy > 0 and finite; cx, cy finite",
        )
    return Intrinsics(fx=k.fx, fy=k.fy, cx=k.cx, cy=k.cy)


@cache
def _model(path: Path) -> PixelModel:
    """The model in ``path``, read once per process."""
    return PixelModel.load(path)


def _starts(causality: Causality) -> dict[str, Value]:
    return {c.name: c.start for c in CHANNELS if c.causality is causality and c.start is not None}


def _result(message: BaliseDetections) -> Values:
    return {
        "detections": message.SerializeToString(deterministic=True),
        "detection_count": len(message.detections),
    }
