"""Camera and depth sensors, configured as OpenRails' build for simulation configures them.

OpenRails-for-simulation is started with a JSON file listing its sensors, one object each::

    [{"sensorName": "front", "sensorType": "rgb", "trainName": "PLAYER",
      "width": 800, "height": 600, "fov": 45.0},
     {"sensorName": "lidar", "sensorType": "depth", "trainName": "PLAYER",
      "width": 200, "height": 150, "fov": 45.0, "range": 200.0}]

(the keys of its Python client's ``get_configuration_data``). ``fov`` is the vertical field of
view in degrees, as XNA's perspective projection takes it; ``range`` (depth only) is the
distance that the depth values are scaled to. Every lockstep reply describes the sensors
under ``CameraSensors`` with the projection's scales (``h_scale`` = M11, ``v_scale`` = M22 of
the projection matrix) and, for depth sensors, ``max_distance``; ``GET
/API/CAMERASENSOR/<name>`` returns the frame (``frame_bytes`` long, see ``renderer``).

``load_sensors`` reads and checks such a file; every problem is a ``ScenarioError`` naming the
file, the entry and the key, with the fix.
"""

from __future__ import annotations

import math
import re
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from coupler.errors import ScenarioError
from coupler_railway.openrails.config import read_json

from .conditions import Conditions
from .renderer import CameraModel, ObjectLabel, Renderer, View

SensorType = Literal["rgb", "depth"]
SENSOR_TYPES: tuple[SensorType, ...] = ("rgb", "depth")
BYTES_PER_PIXEL = {"rgb": 3, "depth": 6}
"""RGB: red, green, blue bytes. Depth: three little-endian uint16 (class/id, distance,
intensity)."""
MAX_SIDE = 4096
"""Largest width or height the mock renders."""
MAX_PIXELS = 3840 * 2160
"""Largest frame the mock renders (a 4K frame: 25 MB of RGB)."""
DEFAULT_MAX_DISTANCE_M = 400.0
"""A depth sensor's range when its entry has none (OpenRails' ``DepthSensor`` default)."""
MAX_RANGE_M = 10_000.0
"""Longest depth range accepted."""
MAX_SENSORS = 64
"""Most sensors one simulation takes (every one is rendered each step it is asked for)."""
KEYS = ("sensorName", "sensorType", "trainName", "width", "height", "fov", "range")
"""Every key an entry may have."""
_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
"""Sensor names travel in a URL path (GET /API/CAMERASENSOR/<name>)."""


@dataclass(frozen=True, kw_only=True)
class SensorSpec:
    """One configured sensor."""

    name: str
    """``sensorName``: the key in ``CameraSensors`` and the last part of its GET path."""
    type: SensorType
    """``rgb`` (colour frames) or ``depth`` (class/id, distance and intensity per pixel)."""
    train_name: str
    """``trainName``: the train it rides on (``PLAYER``: the player train)."""
    width: int
    height: int
    fov_deg: float
    """Vertical field of view [deg]."""
    max_distance_m: float | None = None
    """Depth sensors: the distance 65535 stands for, and beyond which nothing is seen."""

    @property
    def v_scale(self) -> float:
        """M22 of the projection: 1 / tan(fov / 2)."""
        return 1.0 / math.tan(math.radians(self.fov_deg) / 2.0)

    @property
    def h_scale(self) -> float:
        """M11 of the projection: ``v_scale`` / aspect ratio (square pixels)."""
        return self.v_scale * self.height / self.width

    @property
    def frame_bytes(self) -> int:
        """Length of one frame."""
        return self.width * self.height * BYTES_PER_PIXEL[self.type]

    def description(self) -> dict[str, Any]:
        """The sensor's entry in a lockstep reply's ``CameraSensors``."""
        entry: dict[str, Any] = {
            "height": self.height,
            "width": self.width,
            "h_scale": self.h_scale,
            "v_scale": self.v_scale,
        }
        if self.max_distance_m is not None:
            entry["max_distance"] = self.max_distance_m
        return entry


def load_sensors(path: Path, *, train_name: str) -> tuple[SensorSpec, ...]:
    """The sensors of a configuration file; ScenarioError naming the file and the problem."""
    data = read_json(path, what="sensor configuration", setting="OPENRAILS_MOCK_SENSORS, --sensors")
    return parse_sensors(data, source=str(path), train_name=train_name)


def parse_sensors(data: object, *, source: str, train_name: str) -> tuple[SensorSpec, ...]:
    """The sensors of a parsed configuration (a JSON list of objects)."""
    if not isinstance(data, list):
        raise ScenarioError(
            f"{source}: the sensor configuration must be a JSON list of sensors, "
            f'[{{"sensorName": ..., "sensorType": "rgb", ...}}], not {type(data).__name__}'
        )
    if len(data) > MAX_SENSORS:
        raise ScenarioError(
            f"{source}: {len(data)} sensors, more than the {MAX_SENSORS} the mock renders; "
            f"configure the sensors the run reads"
        )
    specs: dict[str, SensorSpec] = {}
    for index, entry in enumerate(data):
        spec = _sensor(entry, f"{source}: sensor {index}", train_name)
        if spec.name in specs:
            raise ScenarioError(
                f"{source}: sensor {index}: sensorName {spec.name!r} is used twice; "
                f"give every sensor its own name"
            )
        specs[spec.name] = spec
    return tuple(specs.values())


def _sensor(entry: object, where: str, train_name: str) -> SensorSpec:
    if not isinstance(entry, dict):
        raise ScenarioError(f"{where}: must be an object with {', '.join(KEYS[:-1])}")
    unknown = sorted(set(entry) - set(KEYS))
    if unknown:
        raise ScenarioError(f"{where}: unknown key {unknown[0]!r}; an entry has {', '.join(KEYS)}")
    missing = [k for k in KEYS[:-1] if k not in entry]
    if missing:
        raise ScenarioError(f"{where}: {missing[0]!r} is missing")
    name = entry["sensorName"]
    if not isinstance(name, str) or not _NAME.match(name):
        raise ScenarioError(
            f"{where}: sensorName must be 1 to 64 letters, digits, '_', '.' or '-' (it is "
            f"part of the URL /API/CAMERASENSOR/<name>), got {name!r}"
        )
    where = f"{where} ({name!r})"
    kind = entry["sensorType"]
    if kind not in SENSOR_TYPES:
        raise ScenarioError(
            f"{where}: unknown sensorType {kind!r}; the sensor types are "
            f"{' and '.join(repr(t) for t in SENSOR_TYPES)}"
        )
    train = entry["trainName"]
    if train not in ("PLAYER", train_name):
        raise ScenarioError(
            f"{where}: trainName {train!r} is not a train of this simulation; the mock has "
            f"one train, 'PLAYER' (named {train_name!r})"
        )
    width = _integer(entry["width"], "width", where, MAX_SIDE)
    height = _integer(entry["height"], "height", where, MAX_SIDE)
    if width * height > MAX_PIXELS:
        raise ScenarioError(
            f"{where}: {width} x {height} is {width * height} pixels, more than the "
            f"{MAX_PIXELS} (3840 x 2160) the mock renders; configure a smaller frame"
        )
    fov = _number(entry["fov"], "fov", where)
    if not 0.0 < fov < 180.0:
        raise ScenarioError(
            f"{where}: fov is the vertical field of view in degrees, between 0 and 180 "
            f"(exclusive), got {fov:g}"
        )
    max_distance: float | None = None
    if kind == "depth":
        max_distance = (
            _number(entry["range"], "range", where) if "range" in entry else DEFAULT_MAX_DISTANCE_M
        )
        if not 0.0 < max_distance <= MAX_RANGE_M:
            raise ScenarioError(
                f"{where}: range is the depth sensor's reach in metres, in (0, "
                f"{MAX_RANGE_M:g}], got {max_distance:g}"
            )
    elif "range" in entry:
        raise ScenarioError(f"{where}: range applies to depth sensors only; remove it")
    return SensorSpec(
        name=name,
        type=kind,
        train_name=train,
        width=width,
        height=height,
        fov_deg=fov,
        max_distance_m=max_distance,
    )


def _integer(value: object, key: str, where: str, limit: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ScenarioError(f"{where}: {key} must be a whole number of pixels, got {value!r}")
    if not 1 <= value <= limit:
        raise ScenarioError(f"{where}: {key} must be 1 to {limit} pixels, got {value}")
    return value


def _number(value: object, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)


def sensor_names(specs: Sequence[SensorSpec]) -> str:
    """The configured names, for messages."""
    return ", ".join(repr(s.name) for s in specs) or "none"


MAX_CACHED_BYTES = 64 * 1024 * 1024
"""Most bytes of frames kept for the current state (beyond: rendered per request)."""


@dataclass(frozen=True)
class Shot:
    """What a frame shows: the train's front on the line, and the state besides the place."""

    distance_m: float
    view: View


@dataclass(frozen=True)
class Rendered:
    """A sensor's frame as served, and its labels (colour sensors)."""

    data: bytes
    labels: tuple[ObjectLabel, ...] = ()
    exposure_ms: float = 0.0
    gain: float = 0.0


class Cameras:
    """The configured sensors' frames: rendered on request, once per state.

    Frames of the current state only are kept (a new step drops the last one's), at most
    ``max_cached_bytes`` of them; one frame renders at a time (requests for the same frame
    wait for it instead of rendering it again), so memory stays at one render's worth."""

    def __init__(
        self,
        specs: Sequence[SensorSpec],
        renderer: Renderer,
        *,
        max_cached_bytes: int = MAX_CACHED_BYTES,
    ) -> None:
        self.specs = {spec.name: spec for spec in specs}
        self.renderer = renderer
        self.max_cached_bytes = max_cached_bytes
        self._lock = threading.Lock()
        self._state: object = None
        self._cache: dict[str, Rendered] = {}
        self.renders = 0
        """Frames rendered so far."""

    @property
    def cached_bytes(self) -> int:
        return sum(len(r.data) for r in self._cache.values())

    def set_conditions(self, conditions: Conditions) -> None:
        """Render under ``conditions`` from now on."""
        with self._lock:
            if conditions != self.renderer.conditions:
                self.renderer = self.renderer.with_conditions(conditions)
            self._state, self._cache = None, {}

    def warm(self) -> None:
        """Compile the renderer's kernels (or load them from numba's cache) with two tiny
        frames, so that the first step's frames take as long as any other."""
        tiny = CameraModel(width=16, height=12, fov_deg=45.0)
        self.renderer.render(tiny, 0.0, View(speed_mps=1.0))
        self.renderer.depth(tiny, 0.0, 100.0)

    def descriptions(self) -> dict[str, dict[str, Any]]:
        """``CameraSensors`` of a lockstep reply."""
        return {name: spec.description() for name, spec in self.specs.items()}

    def _key(self, shot: Shot) -> object:
        """What a frame depends on: the place; the time too where the conditions make the
        frame change with it; the speed with motion blur."""
        c = self.renderer.conditions
        return (
            shot.distance_m,
            shot.view.elapsed_s if c.changes_with_time else None,
            shot.view.clock_s if c.light == "sun" else None,
            shot.view.speed_mps if c.motion_blur else None,
        )

    def cached(self, name: str, shot: Shot) -> Rendered | None:
        """The frame ``frame`` would return if it is already rendered, else None: the
        server answers it without handing the request to a thread."""
        if self._state != self._key(shot):
            return None
        return self._cache.get(name)

    def frame(self, name: str, shot: Shot) -> Rendered:
        """The raw frame of sensor ``name`` for ``shot`` (KeyError for an unknown name): RGB
        bytes with labels, or little-endian uint16 triples."""
        spec = self.specs[name]
        with self._lock:
            key = self._key(shot)
            if key != self._state:
                self._state, self._cache = key, {}
            found = self._cache.get(name)
            if found is not None:
                return found
            rendered = self._render(spec, shot)
            if self.cached_bytes + len(rendered.data) <= self.max_cached_bytes:
                self._cache[name] = rendered
            return rendered

    def _render(self, spec: SensorSpec, shot: Shot) -> Rendered:
        camera = CameraModel(width=spec.width, height=spec.height, fov_deg=spec.fov_deg)
        self.renders += 1
        if spec.type == "rgb":
            frame = self.renderer.render(camera, shot.distance_m, shot.view)
            data = frame.pixels.tobytes()
            rendered = Rendered(data, frame.labels, frame.exposure_ms, frame.gain)
        else:
            assert spec.max_distance_m is not None
            pixels = self.renderer.depth(camera, shot.distance_m, spec.max_distance_m)
            rendered = Rendered(pixels.astype("<u2", copy=False).tobytes())
        assert len(rendered.data) == spec.frame_bytes, (spec.name, len(rendered.data))
        return rendered
