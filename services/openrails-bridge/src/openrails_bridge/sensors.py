"""OpenRails' camera and depth sensors as binary output channels, one per sensor.

OpenRails' build for simulation takes its sensors from a JSON file at start (a list of
``{sensorName, sensorType, trainName, width, height, fov[, range]}``, what its Python client's
sensors write). Given the same file (``OPENRAILS_BRIDGE_SENSORS``), the bridge offers one
output channel per sensor, named as the sensor, of type Binary carrying a ``coupler.v1.Image``
(sensors.proto): no code per sensor, the file is the configuration.

Each step, after the last lockstep post, the bridge GETs ``/API/CAMERASENSOR/<name>`` of every
sensor, on its one aiohttp session, and checks the frame against the size the step reply's
``CameraSensors`` declares (``width * height`` times 3 bytes for RGB, 6 for depth). The Image
carries the bytes unchanged, the Coupler time, the encoding (``rgb8``, ``depth16-class-id``),
the intrinsics from ``h_scale``/``v_scale`` (fx = width / 2 * h_scale, fy = height / 2 *
v_scale, cx = width / 2 - 0.5, cy = height / 2 - 0.5) and a depth sensor's ``max_distance``;
the frame's bytes go into it without passing through protobuf (``image``).

Each colour sensor also has a labels channel, ``<name>_labels``: a ``coupler.v1.FrameLabels``
(sensors.proto) with the ground truth of the same frame -- every balise, signal and platform
edge in view, its box, pixels, distances and visible fraction -- read from ``GET
/API/CAMERASENSOR/<name>/LABELS`` right after the frame (the OpenRails mock's extension: the
same render). A simulator without it (404, as OpenRails) leaves the channel empty (0 bytes).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from coupler.adapter import ChannelMap
from coupler.channels import Causality, ValueType
from coupler.errors import ScenarioError
from coupler.messages import with_bytes
from coupler.v1.railway_pb2 import PixelBox
from coupler.v1.sensors_pb2 import CameraIntrinsics, FrameLabels, Image, ObjectClass, ObjectLabel
from coupler_railway.messages import (
    BYTES_PER_PIXEL,
    DEPTH16_CLASS_ID,
    FRAME_LABELS,
    FRAME_LABELS_BYTES,
    IMAGE,
    RGB8,
    image_bytes,
)
from coupler_railway.openrails.config import read_json

from .replies import CameraSensor, LabelsReply

SensorType = Literal["rgb", "depth"]
ENCODING: dict[SensorType, str] = {"rgb": RGB8, "depth": DEPTH16_CLASS_ID}
"""Image.encoding of each sensor type."""
FIELD = "sensors"
"""Where the frames are in ``OpenRailsAdapter.get_state()``: ``sensors.<name>``."""
LABELS_FIELD = "labels"
"""Where each colour sensor's labels are in ``get_state()``: ``labels.<name>``."""
LABELS_SUFFIX = "_labels"
"""A colour sensor's labels channel is named ``<sensor>_labels``."""
CLASSES = {
    "balise": ObjectClass.OBJECT_CLASS_BALISE,
    "signal": ObjectClass.OBJECT_CLASS_SIGNAL,
    "platform_edge": ObjectClass.OBJECT_CLASS_PLATFORM_EDGE,
}
MAX_SENSORS = 64
"""Most sensors the bridge reads (OpenRails' mock renders as many)."""
_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")


@dataclass(frozen=True)
class Sensor:
    """A sensor as the configuration file declares it."""

    name: str
    type: SensorType
    width: int
    height: int

    @property
    def frame_bytes(self) -> int:
        return self.width * self.height * BYTES_PER_PIXEL[ENCODING[self.type]]

    def channel(self) -> ChannelMap:
        """Its output channel: Binary, ``coupler.v1.Image``, declaring the largest frame of the
        sensor's size (``max_bytes``: the Image's other fields and width * height pixels)."""
        kind = "camera frame" if self.type == "rgb" else "depth frame (class/id, distance)"
        return ChannelMap(
            name=self.name,
            causality=Causality.OUTPUT,
            type=ValueType.BINARY,
            field=f"{FIELD}.{self.name}",
            message_type=IMAGE,
            max_bytes=image_bytes(self.width, self.height, ENCODING[self.type]),
            description=(
                f"OpenRails sensor '{self.name}': {kind}, {self.width} x {self.height}, "
                f"{ENCODING[self.type]} (empty until OpenRails has sent a step reply)"
            ),
        )

    @property
    def labelled(self) -> bool:
        """Whether the sensor has a labels channel (colour sensors do)."""
        return self.type == "rgb"

    def labels_channel(self) -> ChannelMap:
        """Its labels channel: Binary, ``coupler.v1.FrameLabels``."""
        return ChannelMap(
            name=self.name + LABELS_SUFFIX,
            causality=Causality.OUTPUT,
            type=ValueType.BINARY,
            field=f"{LABELS_FIELD}.{self.name}",
            message_type=FRAME_LABELS,
            max_bytes=FRAME_LABELS_BYTES,
            description=(
                f"Ground truth of sensor '{self.name}''s frame: every balise, signal and "
                f"platform edge in view (empty where OpenRails serves no labels)"
            ),
        )


def load_sensors(path: Path) -> tuple[Sensor, ...]:
    """The sensors of OpenRails' sensor configuration file; ScenarioError naming the file,
    the entry and the fix. Keys the bridge does not need (trainName, fov, range) are
    OpenRails' business and not checked here."""
    where = f"{path} (OPENRAILS_BRIDGE_SENSORS)"
    data = read_json(
        path, what="sensor configuration", setting="OPENRAILS_BRIDGE_SENSORS, --sensors"
    )
    if not isinstance(data, list):
        raise ScenarioError(f"{where}: must be a JSON list of sensors, as given to OpenRails")
    if len(data) > MAX_SENSORS:
        raise ScenarioError(
            f"{where}: {len(data)} sensors, more than the {MAX_SENSORS} the bridge reads each "
            f"step; configure the sensors the run reads"
        )
    sensors: dict[str, Sensor] = {}
    for index, entry in enumerate(data):
        at = f"{where}: sensor {index}"
        if not isinstance(entry, dict):
            raise ScenarioError(f"{at}: must be an object with sensorName, sensorType, ...")
        name = entry.get("sensorName")
        if not isinstance(name, str) or not _NAME.match(name):
            raise ScenarioError(
                f"{at}: sensorName must be 1 to 64 letters, digits, '_', '.' or '-', got {name!r}"
            )
        kind = entry.get("sensorType")
        if not isinstance(kind, str) or kind not in ENCODING:
            raise ScenarioError(
                f"{at} ({name!r}): unknown sensorType {kind!r}; the sensor types are 'rgb' "
                f"and 'depth'"
            )
        size = [entry.get(k) for k in ("width", "height")]
        if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size):
            raise ScenarioError(
                f"{at} ({name!r}): width and height must be positive whole numbers of pixels, "
                f"got {size[0]!r} x {size[1]!r}"
            )
        if name in sensors:
            raise ScenarioError(f"{at}: sensorName {name!r} is used twice")
        sensors[name] = Sensor(name, kind, int(size[0]), int(size[1]))  # type: ignore[arg-type]
    return tuple(sensors.values())


def image(sensor: Sensor, described: CameraSensor, data: Sequence[bytes], time_s: float) -> bytes:
    """A frame as a serialized ``coupler.v1.Image``: its header (every field but ``data``)
    serialized, followed by the frame's bytes in the pieces they arrived in (``data``), joined
    once (``coupler.messages.with_bytes``: the bytes protobuf would write, without the pixels
    passing through it)."""
    width, height = described.width, described.height
    header = Image(
        sensor=sensor.name,
        time_s=time_s,
        width=width,
        height=height,
        encoding=ENCODING[sensor.type],
        intrinsics=CameraIntrinsics(
            fx=width / 2.0 * described.h_scale,
            fy=height / 2.0 * described.v_scale,
            cx=width / 2.0 - 0.5,
            cy=height / 2.0 - 0.5,
        ),
        max_distance_m=described.max_distance or 0.0,
    )
    return with_bytes(header, "data", *data)


def frame_labels(sensor: Sensor, reply: LabelsReply, time_s: float) -> bytes:
    """The labels of a frame as a serialized ``coupler.v1.FrameLabels``."""
    labels = FrameLabels(
        sensor=sensor.name,
        time_s=time_s,
        width=reply.width,
        height=reply.height,
        exposure_ms=reply.exposureMs,
        gain=reply.gain,
    )
    for item in reply.objects:
        label = ObjectLabel(
            object_class=CLASSES.get(item.class_, ObjectClass.OBJECT_CLASS_UNSPECIFIED),
            id=item.id,
            name=item.name,
            pixels=item.pixels,
            unoccluded_pixels=item.unoccludedPixels,
            snow_pixels=item.snowPixels,
            distance_along_m=item.distanceAlong,
            distance_m=item.distance,
            transmittance=item.transmittance,
            visible_fraction=item.visibleFraction,
        )
        if item.pixels > 0:
            left, top, right, bottom = item.box
            label.box.CopyFrom(PixelBox(left=left, top=top, right=right, bottom=bottom))
        labels.objects.append(label)
    return labels.SerializeToString(deterministic=True)
