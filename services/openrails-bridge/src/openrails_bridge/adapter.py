"""``OpenRailsAdapter``: OpenRails' web API as a Coupler ``Adapter`` (requests: ``client``).

Two modes (``BridgeSettings.mode``):

- lockstep (OpenRails' build for simulation): a step of ``h`` posts POST /API/CABCONTROLS
  ``h / sim_step_s`` times, each applying every control and advancing one fixed step, and
  keeps the train record of the last reply. The reply has no lat/lon, so GET /API/MAP is read
  ONCE per step, after the last post: outputs exist only at communication points, and the
  intermediate positions would cost a request each for nothing. And only when the train has
  moved: MAP answers where the player locomotive stands and heads, so while the reply's pose
  (``location``, ``rotation``, ``trackLocation``, odometer) is the one MAP was last read at,
  the answer is that one (a standing train at a signal or in a station costs no request).
- stock (upstream OpenRails): the simulation runs on the wall clock. A step posts the
  controls once, sleeps until the wall clock reaches the step's end (``step / speedup``,
  scheduled from Initialize so it never drifts), then polls GET /API/MAP and
  GET /API/TRAINDRIVINGDISPLAY. Speed comes from the display (signed by the reverser),
  acceleration is its difference quotient, distance its integral since Initialize; the
  track location is not published by stock OpenRails and stays 0.

Readiness: ``connect`` never waits. A watcher polls GET /API/READY (lockstep; GET
/API/CABCONTROLS in stock mode) with backoff until OpenRails answers, reads the control ranges
and tells health SERVING; until then health is NOT_SERVING with the reason, naming the URL. A
request that cannot reach OpenRails starts the watcher again. Initialize waits for readiness
at most ``ready_timeout_s``, then is UNAVAILABLE naming the URL.

Each run starts from the scenario's start: Initialize posts POST /API/RESET (the mock's
extension). A simulator without it (404/405, as OpenRails' builds) is used as it stands if its
train stands where this bridge first found it, else Initialize fails saying to restart
OpenRails.

``get_state()`` has the lockstep reply's fields (``locomotiveState.v``, ``trackLocation...``)
in both modes, plus ``MAP`` (raw) and the derived ``latitude``, ``longitude``, ``heading``,
``direction`` (reverser: 1, 0, -1), ``time``, ``train_state`` (a serialized
``coupler.v1.TrainState``) and ``sensors.<name>``: the latest frame of each configured camera
or depth sensor as a serialized ``coupler.v1.Image`` (lockstep only; ``sensors``), fetched
once per step after the last post, beside GET /API/MAP.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import time as wallclock
from collections.abc import Awaitable, Mapping, Sequence
from typing import Any

import structlog

from coupler.adapter import Adapter
from coupler.channels import RunSetup, Value
from coupler.costs import waiting
from coupler.errors import ChannelValueError, ParticipantUnavailable, ScenarioError
from coupler.grid import step_end
from coupler.participant import HealthReport
from coupler.v1.railway_pb2 import GeoPoint, TrainState
from coupler_railway.messages import FRAME_LABELS_BYTES

from .client import OpenRailsClient
from .config import BridgeSettings
from .replies import (
    CONTROLS,
    DISPLAY,
    CameraSensor,
    ControlValue,
    DisplayRow,
    LabelsReply,
    LatLonDirection,
    LocomotiveState,
    StepReply,
    TrackLocation,
    Train,
    TrainLength,
    WorldPosition,
)
from .sensors import Sensor, frame_labels, image

log = structlog.get_logger("openrails_bridge")

STEP_TOLERANCE = 1e-9
"""Relative tolerance of "a whole multiple of the sim step"."""
RANGE_TOLERANCE = 1e-9
"""Values this far outside a control's range are clamped, not refused."""
START_PLACE_TOLERANCE_M = 1.0
"""Without reset: how far from where it was first found the train may stand at Initialize."""
STANDSTILL_MPS = 0.01
"""Without reset: a train slower than this stands."""
EARTH_RADIUS_M = 6_371_008.8
ENVIRONMENT = "Environment."
"""Parameter fields under this prefix are the run's environment, sent with POST /API/RESET
(``Environment.weather``: the mock's condition ``weather``)."""
NO_RESET = (404, 405)
"""Answers to POST /API/RESET of a simulator that has no reset."""
_SPEED = re.compile(r"(-?\d+(?:\.\d+)?)\s*(km/h|mph|m/s)", re.IGNORECASE)
_SPEED_UNITS = {"km/h": 1 / 3.6, "mph": 0.44704, "m/s": 1.0}
_REVERSER = {"forward": 1, "reverse": -1, "n": 0, "neutral": 0}
_NO_TRACK = TrackLocation(
    trackNodeIndex=0,
    trackNodeLength=0.0,
    trackNodeOffset=0.0,
    trackVectorSectionIndex=0,
    movementDirection="Forward",
)
_NOWHERE = WorldPosition(x=0.0, y=0.0, z=0.0)


class OpenRailsAdapter(Adapter):
    """OpenRails seen through its API field names; see the module docstring for the modes."""

    def __init__(
        self,
        settings: BridgeSettings,
        *,
        name: str = "OpenRails",
        channel_names: Mapping[str, str] | None = None,
        sensors: Sequence[Sensor] = (),
    ) -> None:
        """``channel_names`` maps control fields (THROTTLE, ...) to channel names for errors;
        ``sensors`` are the camera and depth sensors OpenRails was started with."""
        self.settings = settings
        self.sensors = tuple(sensors)
        self.name = name
        self.base_url = _base_url(settings.openrails_url)
        self.channel_names = dict(channel_names or {})
        self.ranges: dict[str, ControlValue] = {}
        self.client = OpenRailsClient(
            self.base_url,
            participant=name,
            request_timeout_s=settings.request_timeout_s,
            max_body_bytes=settings.max_body_bytes,
            on_unreachable=self._lost,
        )
        self._controls: dict[str, float] = {}
        self._train: Train | None = None
        self._map: LatLonDirection | None = None
        self._map_pose: Pose | None = None  # the train's pose when _map was read (lockstep)
        self._reverser: int = 1
        self._time = 0.0
        self._stale = True
        # the sensors as the last step reply describes them, and their latest frames
        self._described: Mapping[str, CameraSensor] = {}
        self._frames: dict[str, bytes] = {sensor.name: b"" for sensor in self.sensors}
        self._labels: dict[str, bytes] = {s.name: b"" for s in self.sensors if s.labelled}
        self._serves_labels = True  # until OpenRails answers 404 to a labels request
        self._environment: dict[str, Value] = {}
        # readiness: why OpenRails cannot take a run (None: it can), and who to tell
        self._reason: str | None = f"connecting to OpenRails at {self.base_url}"
        self._ready = asyncio.Event()
        self._report: HealthReport | None = None
        self._watcher: asyncio.Task[None] | None = None
        # without reset: where the train stood when this bridge first found it (lat, lon)
        self._start_place: tuple[float, float] | None = None
        # stock mode: the wall-clock schedule and the last poll (monotonic s, v, odometer)
        self._wall_start = 0.0
        self._sim_start = 0.0
        self._last_poll: tuple[float, float, float] | None = None

    # --- the Adapter interface ---------------------------------------------------------------

    async def connect(self) -> None:
        """One look at OpenRails; if it is not ready, the watcher keeps looking."""
        await self.client.open()
        await self._set_reason(await self._probe())
        if self._reason is not None:
            self._watch()

    async def watch_health(self, report: HealthReport) -> None:
        self._report = report
        await report(self._reason)

    async def start(self, setup: RunSetup, parameters: Mapping[str, Value]) -> None:
        await self._until_ready()
        if self.settings.mode == "lockstep":
            self._steps(setup.step_size)
        self._controls = {}  # the run's start values follow in apply_inputs
        self._time = setup.start_time
        self._sim_start = setup.start_time
        self._wall_start = wallclock.monotonic()
        self._last_poll = None
        self._stale = True
        self._frames = {sensor.name: b"" for sensor in self.sensors}
        self._labels = {s.name: b"" for s in self.sensors if s.labelled}
        self._environment = _environment(parameters)
        await self._reset()

    async def apply_inputs(self, inputs: Mapping[str, Value]) -> None:
        checked = {field: self._checked_control(field, value) for field, value in inputs.items()}
        self._controls.update({k: v for k, v in checked.items() if v is not None})
        if "DIRECTION" in self._controls:
            self._reverser = round(self._controls["DIRECTION"])

    async def advance(self, time: float, step: float) -> None:
        end = step_end(time, step)  # on the run's decimal grid, as the orchestrator records it
        with waiting():  # OpenRails' time (its physics, its rendering): summary.json waited_ms
            if self.settings.mode == "lockstep":
                for _ in range(self._steps(step)):
                    self._train = await self._post_lockstep()
                assert self._train is not None  # a step is one post or more
                self._map, self._frames = await _together(
                    self._map_of(self._train), self._fetch_frames(end)
                )
                self._stale = False
            else:
                answer = await self.client.send(
                    "POST", "/API/CABCONTROLS", body=[self._control(t) for t in self._controls]
                )
                self.client.check(answer, "POST", "/API/CABCONTROLS")
                wall_end = self._wall_start + (end - self._sim_start) / self.settings.speedup
                await asyncio.sleep(max(0.0, wall_end - wallclock.monotonic()))
                await self._poll()
        self._time = end

    async def get_state(self) -> Mapping[str, Any]:
        if self._stale or self._train is None or self._map is None:
            await self._poll()
        assert self._train is not None and self._map is not None
        train, where = self._train, self._map
        latitude, longitude = where.LatLon.Lat, where.LatLon.Lon
        heading = where.DirectionDeg
        loco, track = train.locomotiveState, train.trackLocation
        train_state = TrainState(  # built directly: json_format.ParseDict took 4x as long
            time_s=self._time,
            position=GeoPoint(latitude_deg=latitude, longitude_deg=longitude),
            heading_deg=heading,
            distance_m=loco.distance,
            speed_mps=loco.v,
            acceleration_mps2=loco.a,
            track_node=track.trackNodeIndex,
            track_offset_m=track.trackNodeOffset,
            direction=self._reverser,
        ).SerializeToString(deterministic=True)
        return {
            **train.model_dump(),
            "MAP": where.model_dump(),
            "controls": dict(self._controls),
            "latitude": latitude,
            "longitude": longitude,
            "heading": heading,
            "direction": self._reverser,
            "time": self._time,
            "train_state": train_state,
            "sensors": dict(self._frames),
            "labels": dict(self._labels),
        }

    async def shutdown(self) -> None:
        watcher, self._watcher = self._watcher, None
        if watcher is not None:
            watcher.cancel()
        await self.client.close()

    # --- readiness ---------------------------------------------------------------------------

    def _watch(self) -> None:
        """Start the watcher unless it runs."""
        if self._watcher is None or self._watcher.done():
            self._watcher = asyncio.get_running_loop().create_task(
                self._watch_until_ready(), name="openrails-watcher"
            )

    async def _watch_until_ready(self) -> None:
        """Probe with backoff (0.05 s doubling to 1 s) until OpenRails is ready."""
        delay = 0.05
        while True:
            await self._set_reason(await self._probe())
            if self._reason is None:
                return
            await asyncio.sleep(delay)
            delay = min(delay * 2, 1.0)

    def _lost(self, reason: str) -> None:
        """A request could not reach OpenRails: not ready until the watcher finds it again
        (its first probe reports why)."""
        self._ready.clear()
        self._watch()

    async def _probe(self) -> str | None:
        """None when OpenRails can take a run (the control ranges read), else why not.

        Lockstep: GET /API/READY answers 200. Stock OpenRails has no READY: GET
        /API/CABCONTROLS answering 200 means a train is loaded.
        """
        path = "/API/READY" if self.settings.mode == "lockstep" else "/API/CABCONTROLS"
        try:
            answer = await self.client.send("GET", path, call="connect")
            if answer.status == 425:
                return f"OpenRails at {self.base_url}{path} answered 425: still loading the route"
            self.client.check(answer, "GET", path, call="connect")
            self.ranges = await self._read_ranges()
        except ParticipantUnavailable as exc:
            return exc.detail
        return None

    async def _set_reason(self, reason: str | None) -> None:
        """Readiness found by a probe, told to health (which logs a NOT_SERVING reason)."""
        if reason is None and self._reason is not None:
            log.info("openrails_ready", url=self.base_url, controls=sorted(self.ranges))
        self._reason = reason
        if reason is None:
            self._ready.set()
        else:
            self._ready.clear()
        if self._report is not None:
            await self._report(reason)

    async def _until_ready(self) -> None:
        """Wait for readiness at most ``ready_timeout_s``; UNAVAILABLE naming the URL after."""
        if self._ready.is_set():
            return
        self._watch()
        limit = self.settings.ready_timeout_s
        try:
            await asyncio.wait_for(self._ready.wait(), limit)
        except TimeoutError:
            raise self.client.error(
                f"OpenRails at {self.base_url} is not ready ({self._reason}; waited {limit:g} s, "
                f"OPENRAILS_BRIDGE_READY_TIMEOUT_S): is OpenRails running with its web server "
                f"on, and is OPENRAILS_BRIDGE_OPENRAILS_URL right?",
                call="initialize",
            ) from None

    # --- each run from the scenario's start --------------------------------------------------

    async def _reset(self) -> None:
        """POST /API/RESET, with the run's environment (its time and conditions, from the
        SSD's parameters) when one is set; without a reset, make sure the train stands where
        the run starts."""
        body = {"Environment": self._environment} if self._environment else None
        answer = await self.client.send("POST", "/API/RESET", body=body, call="initialize")
        if answer.status in NO_RESET:
            if self._environment:
                raise ScenarioError(
                    f"OpenRails at {self.base_url} cannot reset (POST /API/RESET answered "
                    f"{answer.status}), so it cannot take this run's environment "
                    f"({', '.join(sorted(self._environment))}): OpenRails takes its time, "
                    f"season and weather on its command line at start; start it with them, "
                    f"or use services/openrails-mock"
                )
            await self._check_at_start(answer.status)
            return
        if answer.status == 400 and self._environment:
            raise ScenarioError(
                f"OpenRails at {self.base_url} refused this run's environment: "
                f"{_error_text(answer.text)} (the OpenRails participant's parameters)"
            )
        self.client.check(answer, "POST", "/API/RESET", call="initialize")
        self._reverser = 1
        self._train = None
        if self.settings.mode == "lockstep" and answer.body.strip():
            reply = self.client.parse(answer, "/API/RESET", StepReply, call="initialize")
            self._train = self._train_of(reply, "/API/RESET")
            self._described = reply.CameraSensors
            self._map_pose = None  # a reset may put back any train: read MAP afresh
            self._map, self._frames = await _together(
                self._map_of(self._train), self._fetch_frames(self._time, call="initialize")
            )
            self._stale = False

    async def _check_at_start(self, status: int) -> None:
        """No reset: the run starts where the train stands, which must be where this bridge
        first found it, standing; ParticipantUnavailable saying to restart OpenRails if not.
        The odometer and track location are unknown until the first step: 0."""
        self._train = None
        await self._poll()
        assert self._train is not None and self._map is not None
        here = (self._map.LatLon.Lat, self._map.LatLon.Lon)
        speed = abs(self._train.locomotiveState.v)
        if self._start_place is None:
            self._start_place = here
            log.warning(
                "openrails_cannot_reset",
                url=self.base_url,
                detail="each run starts where the train stands; restart OpenRails between runs",
            )
        away = _metres_between(here, self._start_place)
        if away > START_PLACE_TOLERANCE_M or speed > STANDSTILL_MPS:
            raise self.client.error(
                f"OpenRails at {self.base_url} cannot reset its simulation (POST /API/RESET "
                f"answered {status}) and its train is not at the scenario's start ({away:.0f} m "
                f"from where this bridge first found it, at {speed:.1f} m/s): the run would "
                f"start where the last one ended. Restart OpenRails so that it loads the "
                f"scenario afresh, then run again (or use a simulator that answers POST "
                f"/API/RESET, as services/openrails-mock does)",
                call="initialize",
            )

    # --- modes -------------------------------------------------------------------------------

    def _steps(self, step: float) -> int:
        """How many lockstep posts make ``step``; ScenarioError unless a whole multiple."""
        sim = self.settings.sim_step_s
        n = round(step / sim)
        if n < 1 or abs(n * sim - step) > STEP_TOLERANCE * max(1.0, step):
            raise ScenarioError(
                f"step size {step:g} s is not a whole multiple of OpenRails' lockstep step "
                f"{sim:g} s (OPENRAILS_BRIDGE_SIM_STEP_S); use a step of k * {sim:g} s"
            )
        return n

    async def _post_lockstep(self) -> Train:
        body = {
            "Controls": [
                {"LocomotiveName": self.settings.locomotive, **self._control(t)}
                for t in self._controls
            ],
            "Commands": [],
            "SwitchCommands": {},
        }
        reply = await self.client.fetch("POST", "/API/CABCONTROLS", StepReply, body=body)
        self._described = reply.CameraSensors
        return self._train_of(reply, "/API/CABCONTROLS")

    def _train_of(self, reply: StepReply, path: str) -> Train:
        loco = self.settings.locomotive
        train = reply.trains.get(loco)
        if train is None:
            raise self.client.error(
                f"OpenRails at {self.base_url}{path} answered without train '{loco}' "
                f"(trains: {sorted(reply.trains)}); set OPENRAILS_BRIDGE_LOCOMOTIVE to the "
                f"player train's name"
            )
        return train

    async def _fetch_frames(self, time_s: float, *, call: str = "step") -> dict[str, bytes]:
        """Every sensor's current frame as a serialized Image, fetched side by side; each
        colour sensor's labels beside its frame (into ``_labels``)."""
        frames = await _together(*(self._frame_and_labels(s, time_s, call) for s in self.sensors))
        return {sensor.name: frame for sensor, frame in zip(self.sensors, frames, strict=True)}

    async def _frame_and_labels(self, sensor: Sensor, time_s: float, call: str) -> bytes:
        if not sensor.labelled:
            return await self._frame(sensor, time_s, call)
        # side by side: OpenRails renders the frame once and answers both from that render
        frame, self._labels[sensor.name] = await _together(
            self._frame(sensor, time_s, call), self._frame_labels(sensor, time_s, call)
        )
        return frame

    async def _frame_labels(self, sensor: Sensor, time_s: float, call: str) -> bytes:
        """GET /API/CAMERASENSOR/<name>/LABELS as a serialized FrameLabels; empty when
        OpenRails has no labels (404: asked once per run, then not again)."""
        if not self._serves_labels:
            return b""
        path = f"/API/CAMERASENSOR/{sensor.name}/LABELS"
        answer = await self.client.send("GET", path, call=call)
        if answer.status == 404:
            self._serves_labels = False
            return b""
        self.client.check(answer, "GET", path, call=call)
        reply = self.client.parse(answer, path, LabelsReply, call=call)
        data = frame_labels(sensor, reply, time_s)
        if len(data) > FRAME_LABELS_BYTES:
            raise self.client.error(
                f"OpenRails at {self.base_url}{path} labels {len(reply.objects)} objects, "
                f"{len(data)} bytes: more than the channel's {FRAME_LABELS_BYTES}",
                call=call,
            )
        return data

    async def _frame(self, sensor: Sensor, time_s: float, call: str) -> bytes:
        """GET /API/CAMERASENSOR/<name>, checked against the size ``CameraSensors`` declares."""
        described = self._described.get(sensor.name)
        if described is None:
            raise self.client.error(
                f"OpenRails at {self.base_url} has no camera sensor '{sensor.name}' "
                f"(its step reply's CameraSensors: {sorted(self._described) or 'none'}): start "
                f"OpenRails with the sensor configuration the bridge reads "
                f"({self.settings.sensors}, OPENRAILS_BRIDGE_SENSORS)",
                call=call,
            )
        if (described.width, described.height) != (sensor.width, sensor.height):
            raise self.client.error(
                f"OpenRails at {self.base_url} describes camera sensor '{sensor.name}' as "
                f"{described.width} x {described.height}, but {self.settings.sensors} "
                f"(OPENRAILS_BRIDGE_SENSORS) configures {sensor.width} x {sensor.height}: give "
                f"the bridge the file OpenRails was started with",
                call=call,
            )
        size = sensor.frame_bytes
        path = f"/API/CAMERASENSOR/{sensor.name}"
        declared = (
            f"the {size} bytes CameraSensors declares for sensor '{sensor.name}' "
            f"({sensor.width} x {sensor.height} {sensor.type})"
        )
        answer = await self.client.send("GET", path, call=call, limit=(size, declared))
        self.client.check(answer, "GET", path, call=call)
        if answer.size != size:
            raise self.client.error(
                f"OpenRails at {self.base_url}{path} answered a frame of {answer.size} "
                f"bytes, but CameraSensors declares sensor '{sensor.name}' {sensor.width} x "
                f"{sensor.height} {sensor.type}: {size} bytes",
                call=call,
            )
        return image(sensor, described, answer.pieces, time_s)

    async def _get_map(self) -> LatLonDirection:
        return await self.client.fetch("GET", "/API/MAP", LatLonDirection)

    async def _map_of(self, train: Train) -> LatLonDirection:
        """GET /API/MAP for ``train`` as a step reply left it; the last answer again while the
        train stands where that answer was read (see the module docstring)."""
        pose = _pose(train)
        if self._map is not None and pose == self._map_pose:
            return self._map
        where = await self._get_map()
        self._map_pose = pose
        return where

    async def _poll(self) -> None:
        """State from the GET endpoints: stock mode, and lockstep before the first step."""
        where, rows = await asyncio.gather(
            self._get_map(),
            self.client.fetch("GET", "/API/TRAINDRIVINGDISPLAY?normalText=true", DISPLAY),
        )
        self._map, self._map_pose = where, None
        speed, reverser = _read_display(rows)
        if reverser is not None:
            self._reverser = reverser
        v = math.copysign(speed, -1.0 if self._reverser < 0 else 1.0)
        now = wallclock.monotonic()
        previous = self._train
        if self.settings.mode == "lockstep":
            # OpenRails reports the odometer and track location only in step replies
            odometer = previous.locomotiveState.distance if previous else 0.0
            a = 0.0
            track = previous.trackLocation if previous else _NO_TRACK
        else:
            a, odometer = 0.0, 0.0
            if self._last_poll is not None:
                then, v0, odometer = self._last_poll
                dt = (now - then) * self.settings.speedup
                if dt > 0:
                    a = (v - v0) / dt
                    odometer += 0.5 * (abs(v0) + abs(v)) * dt
            track = _NO_TRACK
        self._last_poll = (now, v, odometer)
        self._train = Train(
            location=previous.location if previous else _NOWHERE,
            trackLocation=track,
            rearTrackLocation=previous.rearTrackLocation if previous else track,
            rotation=math.radians(where.DirectionDeg),
            locomotiveState=LocomotiveState(
                v=v, a=a, distance=odometer, wheelslip=False, wheelskid=False
            ),
            trainLength=previous.trainLength if previous else TrainLength(length=0.0),
        )
        self._stale = False

    # --- controls ----------------------------------------------------------------------------

    def _checked_control(self, field: str, value: Value) -> float | None:
        """The value to send for ``field``; None when the cab lacks it and it is 0."""
        channel = self.channel_names.get(field, field)
        number = float(value)
        spec = self.ranges.get(field)
        if spec is None:
            if number == 0.0:
                return None
            raise ChannelValueError(
                f"channel '{channel}': OpenRails' locomotive has no cab control {field} "
                f"(it has {', '.join(sorted(self.ranges)) or 'none'})",
                channel=channel,
            )
        lo, hi = spec.MinValue, spec.MaxValue
        slack = RANGE_TOLERANCE * max(1.0, hi - lo)
        if not lo - slack <= number <= hi + slack:
            raise ChannelValueError(
                f"channel '{channel}' ({field}) takes values in [{lo:g}, {hi:g}], got {number:g}",
                channel=channel,
                expected=f"[{lo:g}, {hi:g}]",
            )
        return min(max(number, lo), hi)

    def _control(self, type_name: str) -> dict[str, Any]:
        return {
            "TypeName": type_name,
            "ControlIndex": self.settings.control_index,
            "Value": self._controls[type_name],
        }

    async def _read_ranges(self) -> dict[str, ControlValue]:
        listed = await self.client.fetch("GET", "/API/CABCONTROLS", CONTROLS, call="connect")
        ranges: dict[str, ControlValue] = {}
        for item in listed:
            ranges.setdefault(item.TypeName, item)
        return ranges


Pose = tuple[WorldPosition, float, TrackLocation, float]
"""Where a step reply puts a train: location, rotation, front track location, odometer."""


def _pose(train: Train) -> Pose:
    return (train.location, train.rotation, train.trackLocation, train.locomotiveState.distance)


async def _together(*calls: Awaitable[Any]) -> list[Any]:
    """Like asyncio.gather, but the first failure cancels the other requests (and waits for
    them) before it is raised: no request outlives the step that made it."""
    tasks = [asyncio.ensure_future(call) for call in calls]
    try:
        return list(await asyncio.gather(*tasks))
    except BaseException:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        raise


def _environment(parameters: Mapping[str, Value]) -> dict[str, Any]:
    """The run's environment from the parameters under ``Environment.``; ``conditions`` (a
    JSON object) is spread out, the named parameters win over it. An empty String is unset
    (what an FMI master -- the exported FMU -- gives a String parameter it has no value for)."""
    environment: dict[str, Any] = {
        field.removeprefix(ENVIRONMENT): value
        for field, value in parameters.items()
        if field.startswith(ENVIRONMENT) and value != ""
    }
    extra = environment.pop("conditions", "")
    if not extra:
        return environment
    try:
        spread = json.loads(str(extra))
    except ValueError as exc:
        raise ScenarioError(
            f"parameter conditions is not a JSON object of conditions: {exc}; e.g. "
            f'{{"noise": true, "jpeg_quality": 60}}'
        ) from None
    if not isinstance(spread, dict):
        raise ScenarioError(
            f"parameter conditions must be a JSON object of conditions, got {extra!r}"
        )
    return {**spread, **environment}


def _error_text(text: str) -> str:
    """The ``error`` of a JSON error answer, else the text (shortened)."""
    try:
        value = json.loads(text)
    except ValueError:
        return text[:300]
    return str(value.get("error", text))[:300] if isinstance(value, dict) else text[:300]


def _base_url(url: str) -> str:
    """``http://host:port`` without a trailing ``/`` or ``/API``."""
    url = url.rstrip("/")
    return url[: -len("/API")] if url.endswith("/API") else url


def _metres_between(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Great-circle distance between two (lat, lon) in degrees."""
    (lat1, lon1), (lat2, lon2) = (tuple(map(math.radians, p)) for p in (a, b))
    h = math.sin((lat2 - lat1) / 2) ** 2
    h += math.cos(lat1) * math.cos(lat2) * math.sin((lon2 - lon1) / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(h)))


def _read_display(rows: list[DisplayRow]) -> tuple[float, int | None]:
    """|speed| [m/s] and the reverser (1, 0, -1 or None) from TRAINDRIVINGDISPLAY rows."""
    speed, reverser = 0.0, None
    for row in rows:
        label = row.FirstCol.strip().lower()
        text = row.LastCol
        if label in ("speed", "sped") and (match := _SPEED.search(text)):
            speed = abs(float(match.group(1))) * _SPEED_UNITS[match.group(2).lower()]
        elif label in ("direction", "dirc"):
            reverser = _REVERSER.get(text.strip().lower(), reverser)
    return speed, reverser
