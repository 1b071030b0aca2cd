"""The run as the map shows it: train, status and balise readings, in plain Python.

``RunState`` turns each DoStep's inputs into the map's state and tells its listeners what
changed, as ``Event``s with increasing sequence numbers: ``step`` events (train and status)
may be coalesced (latest wins), ``reading`` and ``run`` events must not be dropped.
``snapshot()`` is the whole state so far, for a browser that joins or falls behind.

Balise readings come from whichever source the scenario connects, the richest one winning:
``passed_in_step`` (every balise crossed in the step, in travel order), then ``balise_reading``
(binary coupler.v1.BaliseReading), then ``balises_passed`` (a count) and last ``balise_id``
changes. A source counts as connected from the first step it carries something.
"""

from __future__ import annotations

import json
import math
import time as wallclock
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import structlog

from coupler.channels import RunSetup, Value
from coupler.errors import ChannelValueError
from coupler.messages import decode_message
from coupler_railway import TrackModel
from coupler_railway.messages import BALISE_READING, TRAIN_STATE
from mapserver.camera import CameraView
from mapserver.estimate import EstimateView

log = structlog.get_logger("mapserver.state")


@dataclass(frozen=True, kw_only=True)
class Reading:
    """One balise passed: a row of the readings table."""

    index: int
    """0-based number of the reading in its run; browsers use it to spot gaps."""
    time_s: float
    """Simulation time at which the balise was passed [s]."""
    balise_id: int
    group_id: int
    distance_m: float
    """Distance of the balise along the track [m]."""

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "time_s": self.time_s,
            "balise_id": self.balise_id,
            "group_id": self.group_id,
            "distance_m": self.distance_m,
        }


@dataclass(frozen=True)
class Event:
    """A change of the state (or the whole of it), as sent to browsers."""

    seq: int
    """Sequence number of the change; a snapshot carries the number of the last change in it."""
    kind: str
    """``snapshot``, ``step``, ``reading`` or ``run``."""
    data: dict[str, Any] = field(hash=False)

    @property
    def droppable(self) -> bool:
        """A later event of the same kind makes this one obsolete."""
        return self.kind == "step"

    @cached_property
    def json(self) -> str:
        """The event as one line of JSON, encoded once however many browsers receive it."""
        return json.dumps({"type": self.kind, "seq": self.seq, **self.data}, allow_nan=False)


Listener = Callable[[Event], None]


@dataclass
class _Train:
    latitude_deg: float
    longitude_deg: float
    distance_m: float
    speed_mps: float
    heading_deg: float | None


class BaliseSources:
    """Decides which balise readings a step's inputs mean (see the module docstring)."""

    _LIST, _MESSAGE, _COUNT, _ID = 4, 3, 2, 1

    def __init__(self, balise_distances: Mapping[int, float]) -> None:
        self.balise_distances = balise_distances
        self.reset()

    def reset(self) -> None:
        self._source = self._ID
        self._last_count = 0
        self._last_id = 0
        self._last_message: tuple[float, int] | None = None
        self._warned = False

    def readings(
        self, time: float, inputs: Mapping[str, Value], distance: float
    ) -> list[tuple[float, int, int, float]]:
        """(time, balise id, group id, distance) of every balise passed, in travel order."""
        listed = self._listed(time, inputs.get("passed_in_step", ""), distance)
        message = self._message(inputs.get("balise_reading", b""), time)
        balise_id = _int(inputs.get("balise_id", 0))
        group_id = _int(inputs.get("group_id", 0))
        count = _int(inputs.get("balises_passed", 0))
        latest = [(time, balise_id, group_id, self.balise_distances.get(balise_id, distance))]

        if listed:
            self._source = max(self._source, self._LIST)
        elif inputs.get("balise_reading"):
            self._source = max(self._source, self._MESSAGE)
        elif count > 0:
            self._source = max(self._source, self._COUNT)

        if self._source == self._LIST:
            found = listed
        elif self._source == self._MESSAGE:
            found = message
        elif self._source == self._COUNT:
            found = latest if count > self._last_count and balise_id != 0 else []
        else:
            found = latest if balise_id != self._last_id and balise_id != 0 else []
        self._last_count = count
        self._last_id = balise_id
        return found

    def _listed(
        self, time: float, text: Value, distance: float
    ) -> list[tuple[float, int, int, float]]:
        if not isinstance(text, str) or not text.strip():
            return []
        found = []
        for entry in text.split(";"):
            if not entry.strip():
                continue
            parts = entry.split(":")
            try:
                balise_id = int(float(parts[0]))
                group_id = int(float(parts[1])) if len(parts) > 1 and parts[1].strip() else 0
                at = float(parts[2]) if len(parts) > 2 and parts[2].strip() else math.nan
            except ValueError:
                self._warn(f"passed_in_step entry {entry!r} is not id:group:distance")
                continue
            if not math.isfinite(at):
                at = self.balise_distances.get(balise_id, distance)
            found.append((time, balise_id, group_id, at))
        return found

    def _message(self, data: Value, time: float) -> list[tuple[float, int, int, float]]:
        if not isinstance(data, bytes) or not data:
            return []
        try:
            fields = decode_message(BALISE_READING, data)
        except ChannelValueError as exc:
            self._warn(f"balise_reading: {exc}")
            return []
        balise_id = int(fields.get("balise_id", 0))
        at_time = _num(fields.get("time_s", time))
        key = (at_time, balise_id)
        if balise_id == 0 or key == self._last_message:
            return []
        self._last_message = key
        distance = _num(fields.get("distance_m")) or self.balise_distances.get(balise_id, 0.0)
        return [(at_time, balise_id, int(fields.get("group_id", 0)), distance)]

    def _warn(self, problem: str) -> None:
        if not self._warned:  # once per run: a bad input would otherwise log every step
            log.warning("balise_input_ignored", problem=problem)
            self._warned = True


def _int(value: Value) -> int:
    return int(value) if isinstance(value, int | float) and math.isfinite(value) else 0


def _num(value: Any) -> float:
    """A finite float of a decoded message field (proto3 JSON writes NaN as "NaN"), else 0."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return 0.0
    return number if math.isfinite(number) else 0.0


def _real(value: Value | None, default: float = 0.0) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return default
    return float(value) if math.isfinite(value) else default


class RunState:
    """The current run's state; mutated by the participant, read by the web app."""

    def __init__(
        self,
        *,
        track: TrackModel | None = None,
        balise_distances: Mapping[int, float] | None = None,
        max_readings: int = 10_000,
        clock: Callable[[], float] = wallclock.monotonic,
    ) -> None:
        self.track = track
        self.max_readings = max_readings
        self.clock = clock
        self.listeners: list[Listener] = []
        self.seq = 0
        self.run_id = ""
        self.status = "idle"
        """``idle`` (no run yet), ``running`` or ``ended``."""
        self.reason = ""
        self.start_time = 0.0
        self.stop_time: float | None = None
        self.time_s = 0.0
        self.step_s = 0.0
        self.steps = 0
        self.realtime_factor: float | None = None
        self.train: _Train | None = None
        self.readings: deque[Reading] = deque(maxlen=max_readings)
        self.readings_total = 0
        self._inputs: dict[str, Value] = {}
        self._wall_start = 0.0
        self._sources = BaliseSources(balise_distances or {})
        self.camera = CameraView()
        """The latest camera frame and the balises a perception saw in it."""
        self.estimate = EstimateView(track)
        """A localisation's estimate and confidence interval beside the truth."""

    # --- changes, from the participant ------------------------------------------------------

    def start(self, setup: RunSetup, defaults: Mapping[str, Value]) -> None:
        """A new run: forget the previous one, take the start values of the inputs."""
        self.run_id = setup.run_id or "unnamed"
        self.status, self.reason = "running", ""
        self.start_time, self.stop_time = setup.start_time, setup.stop_time
        self.time_s, self.step_s, self.steps = setup.start_time, setup.step_size, 0
        self.realtime_factor = None
        self.readings.clear()
        self.readings_total = 0
        self._sources.reset()
        self.camera.reset()
        self.estimate.reset()
        self._inputs = {**defaults, **setup.inputs}
        self._wall_start = self.clock()
        self._apply(setup.start_time)
        self._emit("run", {"run": self._run_json(), "reset": True})
        self._emit("step", self._step_json())

    def step(self, time: float, step: float, inputs: Mapping[str, Value]) -> None:
        """Inputs of DoStep(time, step): values of the other participants at ``time``."""
        self._inputs.update(inputs)
        self.time_s, self.step_s = time, step
        self.steps += 1
        elapsed = self.clock() - self._wall_start
        self.realtime_factor = (time - self.start_time) / elapsed if elapsed > 0 else None
        self._apply(time)
        self._emit("step", self._step_json())

    def end(self, reason: str) -> None:
        """The run is over (Terminate, or the participant shutting down)."""
        if self.status != "running":
            return
        self.status, self.reason = "ended", reason
        self._emit("run", {"run": self._run_json(), "reset": False})

    def _apply(self, time: float) -> None:
        self.camera.update(self._inputs)
        self.estimate.update(self._inputs)
        self.train = self._train_of(self._inputs)
        distance = self.train.distance_m if self.train else _real(self._inputs.get("distance"))
        for at, balise_id, group_id, balise_distance in self._sources.readings(
            time, self._inputs, distance
        ):
            reading = Reading(
                index=self.readings_total,
                time_s=at,
                balise_id=balise_id,
                group_id=group_id,
                distance_m=balise_distance,
            )
            self.readings.append(reading)
            self.readings_total += 1
            self._emit("reading", {"reading": reading.to_json()})

    def _train_of(self, inputs: Mapping[str, Value]) -> _Train | None:
        data = inputs.get("train_state", b"")
        if isinstance(data, bytes) and data:
            try:
                fields = decode_message(TRAIN_STATE, data)
            except ChannelValueError as exc:
                log.warning("train_state_ignored", problem=str(exc))
            else:
                position = fields.get("position", {})
                latitude = _num(position.get("latitude_deg"))
                longitude = _num(position.get("longitude_deg"))
                if latitude or longitude:
                    return _Train(
                        latitude,
                        longitude,
                        _num(fields.get("distance_m")),
                        _num(fields.get("speed_mps")),
                        _num(fields.get("heading_deg")),
                    )
        latitude, longitude = _real(inputs.get("latitude")), _real(inputs.get("longitude"))
        distance, speed = _real(inputs.get("distance")), _real(inputs.get("speed"))
        if latitude or longitude:
            return _Train(latitude, longitude, distance, speed, None)
        if self.track is not None and 0.0 < distance <= self.track.length:
            point = self.track.position(distance)  # only the distance is connected
            return _Train(point.latitude_deg, point.longitude_deg, distance, speed, None)
        return None

    def _emit(self, kind: str, data: dict[str, Any]) -> None:
        self.seq += 1
        event = Event(self.seq, kind, data)
        for listener in self.listeners:
            listener(event)

    # --- views, for the web app -------------------------------------------------------------

    def _run_json(self) -> dict[str, Any]:
        return {
            "run_id": self.run_id,
            "status": self.status,
            "reason": self.reason,
            "start_time_s": self.start_time,
            "stop_time_s": self.stop_time,
            "time_s": self.time_s,
            "step_s": self.step_s,
            "steps": self.steps,
            "speed_mps": self.train.speed_mps if self.train else None,
            "realtime_factor": self.realtime_factor,
            "readings_total": self.readings_total,
        }

    def _train_json(self) -> dict[str, Any] | None:
        train = self.train
        if train is None:
            return None
        return {
            "latitude_deg": train.latitude_deg,
            "longitude_deg": train.longitude_deg,
            "distance_m": train.distance_m,
            "speed_mps": train.speed_mps,
            "heading_deg": train.heading_deg,
        }

    def _step_json(self) -> dict[str, Any]:
        return {
            "run": self._run_json(),
            "train": self._train_json(),
            "camera": self.camera.to_json(),
            "localisation": self.estimate.to_json(),
        }

    def snapshot(self) -> Event:
        """The whole state so far (readings: the last ``max_readings``), as one event."""
        return Event(
            self.seq,
            "snapshot",
            {
                "run": self._run_json(),
                "train": self._train_json(),
                "camera": self.camera.to_json(),
                "localisation": self.estimate.to_json(),
                "readings": [r.to_json() for r in self.readings],
            },
        )
