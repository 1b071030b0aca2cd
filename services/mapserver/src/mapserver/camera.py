"""The camera panel: the latest frame of a camera and the balises a perception saw in it.

Inputs: ``camera`` (a ``coupler.v1.Image``, rgb8) and ``detections`` (a
``coupler.v1.BaliseDetections``). A perception participant judges the frame of the step's
start, so its detections arrive a step after their frame; the view keeps the last few frames
and shows the one the latest detections belong to (by time), with their boxes, else the newest
frame. DoStep only reads a frame's header and keeps its bytes as they came (the pixels a view
of them, never copied: ``coupler.messages.without_bytes``); a frame is encoded as JPEG (Pillow)
when a browser asks for it, once.
"""

from __future__ import annotations

import io
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import structlog
from PIL import Image as PillowImage

from coupler.channels import Value
from coupler.messages import without_bytes
from coupler.v1.railway_pb2 import BaliseDetections
from coupler.v1.sensors_pb2 import Image
from coupler_railway.messages import RGB8

log = structlog.get_logger("mapserver.camera")

KEPT = 4
"""Frames kept to pair with detections that come a step or two after them."""
JPEG_QUALITY = 85


@dataclass(frozen=True)
class Frame:
    number: int
    """Counts the frames of the run from 1: the URL of its picture."""
    time_s: float
    sensor: str
    width: int
    height: int
    pixels: memoryview
    """The pixels, a view of the ``coupler.v1.Image`` bytes the step brought (not copied)."""


class CameraView:
    """The frames and detections of the current run."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._frames: OrderedDict[int, Frame] = OrderedDict()
        self._count = 0
        self._last_data = b""
        self._last_detections = b""
        self._detections: BaliseDetections | None = None
        self._jpeg: tuple[int, bytes] | None = None
        self._warned = False

    def update(self, inputs: dict[str, Value]) -> bool:
        """Take a step's ``camera`` and ``detections``; True when the view changed."""
        changed = False
        data = inputs.get("camera", b"")
        if isinstance(data, bytes) and data and data != self._last_data:
            self._last_data = data
            frame = self._frame(data)
            if frame is not None:
                self._frames[frame.number] = frame
                while len(self._frames) > KEPT:
                    self._frames.popitem(last=False)
                changed = True
        found = inputs.get("detections", b"")
        if isinstance(found, bytes) and found and found != self._last_detections:
            self._last_detections = found
            message = BaliseDetections()
            try:
                message.ParseFromString(found)
            except Exception as exc:  # a DecodeError: warn once, keep the frame
                self._warn(f"detections are not a coupler.v1.BaliseDetections: {exc}")
            else:
                self._detections = message
                changed = True
        return changed

    def shown(self) -> Frame | None:
        """The frame to show: the one the latest detections belong to, else the newest."""
        if not self._frames:
            return None
        if self._detections is not None:
            for frame in reversed(self._frames.values()):
                if abs(frame.time_s - self._detections.time_s) < 1e-9:
                    return frame
        return next(reversed(self._frames.values()))

    def to_json(self) -> dict[str, Any] | None:
        """What the page needs: the frame's number, size and time, and the boxes on it."""
        frame = self.shown()
        if frame is None:
            return None
        detections = self._detections
        boxes = []
        if detections is not None and abs(detections.time_s - frame.time_s) < 1e-9:
            boxes = [
                {
                    "left": d.box.left,
                    "top": d.box.top,
                    "right": d.box.right,
                    "bottom": d.box.bottom,
                    "distance_ahead_m": round(d.distance_ahead_m, 2),
                    "track_position_m": round(d.track_position_m, 2),
                    "confidence": round(d.confidence, 3),
                }
                for d in detections.detections
            ]
        return {
            "frame": frame.number,
            "time_s": frame.time_s,
            "sensor": frame.sensor,
            "width": frame.width,
            "height": frame.height,
            "detections": boxes,
            "judged": detections is not None and abs(detections.time_s - frame.time_s) < 1e-9,
        }

    def jpeg(self, number: int | None = None) -> bytes | None:
        """Frame ``number`` (or the shown one) as JPEG; None when there is none."""
        frame = self._frames.get(number) if number is not None else None
        frame = frame or self.shown()
        if frame is None:
            return None
        if self._jpeg is not None and self._jpeg[0] == frame.number:
            return self._jpeg[1]
        picture = PillowImage.frombytes("RGB", (frame.width, frame.height), frame.pixels)
        out = io.BytesIO()
        picture.save(out, format="JPEG", quality=JPEG_QUALITY)
        self._jpeg = (frame.number, out.getvalue())
        return self._jpeg[1]

    def _frame(self, data: bytes) -> Frame | None:
        """The frame ``data`` carries: its header parsed, its pixels a view of ``data``."""
        try:
            image, pixels = without_bytes(Image, data, "data")
        except Exception as exc:  # a DecodeError: warn once, the map goes on
            self._warn(f"camera is not a coupler.v1.Image: {exc}")
            return None
        if image.encoding != RGB8 or len(pixels) != image.width * image.height * 3:
            self._warn(
                f"camera frame of sensor '{image.sensor}' is '{image.encoding}' "
                f"{image.width} x {image.height} with {len(pixels)} bytes; the map shows "
                f"rgb8 frames of width * height * 3 bytes"
            )
            return None
        self._count += 1
        return Frame(self._count, image.time_s, image.sensor, image.width, image.height, pixels)

    def _warn(self, problem: str) -> None:
        if not self._warned:  # once per run: a bad input would otherwise log every step
            log.warning("camera_input_ignored", problem=problem)
            self._warned = True
