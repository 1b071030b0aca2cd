"""``OpenRailsAdapter``: OpenRails' web API as a Coupler ``Adapter``, over ONE aiohttp session.

Two modes (``BridgeSettings.mode``):

- lockstep (OpenRails' build for simulation): ``connect`` polls GET /API/READY (425 until the
  route is loaded) with exponential backoff; a step of ``h`` posts POST /API/CABCONTROLS
  ``h / sim_step_s`` times, each applying every control and advancing one fixed step, and
  keeps the train record of the last reply. The reply has no lat/lon, so GET /API/MAP is read
  ONCE per step, after the last post: outputs exist only at communication points, and the
  intermediate positions would cost a request each for nothing.
- stock (upstream OpenRails): the simulation runs on the wall clock. A step posts the
  controls once, sleeps until the wall clock reaches the step's end (``step / speedup``,
  scheduled from Initialize so it never drifts), then polls GET /API/MAP and
  GET /API/TRAINDRIVINGDISPLAY. Speed comes from the display (signed by the reverser),
  acceleration is its difference quotient, distance its integral since Initialize; the
  track location is not published by stock OpenRails and stays 0.

``get_state()`` has the lockstep reply's fields (``locomotiveState.v``, ``trackLocation...``)
in both modes, plus ``MAP`` (raw) and the derived ``latitude``, ``longitude``, ``heading``,
``direction`` (reverser: 1, 0, -1), ``time`` and ``train_state`` (a serialized
``coupler.v1.TrainState``). aiohttp errors, timeouts and non-2xx answers become
``ParticipantUnavailable`` naming the URL in ONE place, ``_send``/``_check``.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import time as wallclock
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import aiohttp
import structlog

from coupler.adapter import Adapter
from coupler.channels import RunSetup, Value
from coupler.errors import ChannelValueError, ParticipantUnavailable, ScenarioError
from coupler.messages import encode_message
from coupler_railway.messages import TRAIN_STATE

from .config import BridgeSettings

log = structlog.get_logger("openrails_bridge")

STEP_TOLERANCE = 1e-9
"""Relative tolerance of "a whole multiple of the sim step"."""
RANGE_TOLERANCE = 1e-9
"""Values this far outside a control's range are clamped, not refused."""
_SPEED = re.compile(r"(-?\d+(?:\.\d+)?)\s*(km/h|mph|m/s)", re.IGNORECASE)
_SPEED_UNITS = {"km/h": 1 / 3.6, "mph": 0.44704, "m/s": 1.0}
_REVERSER = {"forward": 1, "reverse": -1, "n": 0, "neutral": 0}


@dataclass(frozen=True)
class _Answer:
    status: int
    text: str


@dataclass(frozen=True)
class ControlRange:
    """A cab control as GET /API/CABCONTROLS lists it."""

    type_name: str
    min_value: float
    max_value: float


class OpenRailsAdapter(Adapter):
    """OpenRails seen through its API field names; see the module docstring for the modes."""

    def __init__(
        self,
        settings: BridgeSettings,
        *,
        name: str = "OpenRails",
        channel_names: Mapping[str, str] | None = None,
    ) -> None:
        """``channel_names`` maps control fields (THROTTLE, ...) to channel names for errors."""
        self.settings = settings
        self.name = name
        self.base_url = _base_url(settings.openrails_url)
        self.channel_names = dict(channel_names or {})
        self.ranges: dict[str, ControlRange] = {}
        self._timeout = aiohttp.ClientTimeout(total=settings.request_timeout_s)
        self._session: aiohttp.ClientSession | None = None
        self._controls: dict[str, float] = {}
        self._train: dict[str, Any] | None = None
        self._map: dict[str, Any] | None = None
        self._reverser: int = 1
        self._time = 0.0
        self._stale = True
        # stock mode: the wall-clock schedule and the last poll (monotonic s, v, odometer)
        self._wall_start = 0.0
        self._sim_start = 0.0
        self._last_poll: tuple[float, float, float] | None = None

    # --- the Adapter interface ---------------------------------------------------------------

    async def connect(self) -> None:
        if self._session is None:
            self._session = aiohttp.ClientSession(timeout=self._timeout)
        await self._wait_ready()
        self.ranges = await self._read_ranges()
        log.info(
            "openrails_connected",
            url=self.base_url,
            mode=self.settings.mode,
            controls=sorted(self.ranges),
        )

    async def start(self, setup: RunSetup, parameters: Mapping[str, Value]) -> None:
        if self.settings.mode == "lockstep":
            self._steps(setup.step_size)
        self._controls = {}  # the run's start values follow in apply_inputs
        self._time = setup.start_time
        self._sim_start = setup.start_time
        self._wall_start = wallclock.monotonic()
        self._last_poll = None
        self._stale = True

    async def apply_inputs(self, inputs: Mapping[str, Value]) -> None:
        checked = {field: self._checked_control(field, value) for field, value in inputs.items()}
        self._controls.update({k: v for k, v in checked.items() if v is not None})
        if "DIRECTION" in self._controls:
            self._reverser = round(self._controls["DIRECTION"])

    async def advance(self, time: float, step: float) -> None:
        if self.settings.mode == "lockstep":
            for _ in range(self._steps(step)):
                self._train = self._train_of(await self._post_lockstep())
            self._map = await self._get_map()
            self._stale = False
        else:
            await self._check(
                "POST", "/API/CABCONTROLS", body=[self._control(t) for t in self._controls]
            )
            wall_end = self._wall_start + (time + step - self._sim_start) / self.settings.speedup
            await asyncio.sleep(max(0.0, wall_end - wallclock.monotonic()))
            await self._poll()
        self._time = time + step

    async def get_state(self) -> Mapping[str, Any]:
        if self._stale or self._train is None or self._map is None:
            await self._poll()
        assert self._train is not None and self._map is not None
        latlon = self._map.get("LatLon") or {}
        latitude = float(latlon.get("Lat", 0.0))
        longitude = float(latlon.get("Lon", 0.0))
        heading = float(self._map.get("DirectionDeg", 0.0))
        loco = self._train["locomotiveState"]
        track = self._train["trackLocation"]
        train_state = encode_message(
            TRAIN_STATE,
            {
                "time_s": self._time,
                "position": {"latitude_deg": latitude, "longitude_deg": longitude},
                "heading_deg": heading,
                "distance_m": float(loco["distance"]),
                "speed_mps": float(loco["v"]),
                "acceleration_mps2": float(loco["a"]),
                "track_node": int(track["trackNodeIndex"]),
                "track_offset_m": float(track["trackNodeOffset"]),
                "direction": self._reverser,
            },
        )
        return {
            **self._train,
            "MAP": self._map,
            "controls": dict(self._controls),
            "latitude": latitude,
            "longitude": longitude,
            "heading": heading,
            "direction": self._reverser,
            "time": self._time,
            "train_state": train_state,
        }

    async def shutdown(self) -> None:
        session, self._session = self._session, None
        if session is not None:
            await session.close()

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

    async def _post_lockstep(self) -> Any:
        body = {
            "Controls": [
                {"LocomotiveName": self.settings.locomotive, **self._control(t)}
                for t in self._controls
            ],
            "Commands": [],
            "SwitchCommands": {},
        }
        return await self._get_json("/API/CABCONTROLS", method="POST", body=body)

    def _train_of(self, reply: Any) -> dict[str, Any]:
        url = f"{self.base_url}/API/CABCONTROLS"
        trains = reply.get("trains") if isinstance(reply, dict) else None
        loco = self.settings.locomotive
        if not isinstance(trains, dict) or not isinstance(trains.get(loco), dict):
            names = sorted(trains) if isinstance(trains, dict) else []
            raise self._unavailable(
                f"OpenRails at {url} answered without train '{self.settings.locomotive}' "
                f"(trains: {names}); set OPENRAILS_BRIDGE_LOCOMOTIVE to the player train's name"
            )
        train: dict[str, Any] = trains[self.settings.locomotive]
        for key in ("locomotiveState", "trackLocation"):
            if not isinstance(train.get(key), dict):
                raise self._unavailable(f"OpenRails at {url} answered a train without '{key}'")
        return train

    async def _get_map(self) -> dict[str, Any]:
        answer = await self._get_json("/API/MAP")
        if not isinstance(answer, dict):
            raise self._unavailable(
                f"OpenRails at {self.base_url}/API/MAP answered {answer!r:.80}, not an object"
            )
        return answer

    async def _poll(self) -> None:
        """State from the GET endpoints: stock mode, and lockstep before the first step."""
        self._map, display = await asyncio.gather(
            self._get_map(), self._get_json("/API/TRAINDRIVINGDISPLAY?normalText=true")
        )
        speed, reverser = _read_display(display)
        if reverser is not None:
            self._reverser = reverser
        v = math.copysign(speed, -1.0 if self._reverser < 0 else 1.0)
        now = wallclock.monotonic()
        previous = self._train or {}
        if self.settings.mode == "lockstep":
            # OpenRails reports the odometer and track location only in step replies
            odometer = float(previous.get("locomotiveState", {}).get("distance", 0.0))
            a = 0.0
            track = previous.get("trackLocation") or _no_track()
        else:
            a, odometer = 0.0, 0.0
            if self._last_poll is not None:
                then, v0, odometer = self._last_poll
                dt = (now - then) * self.settings.speedup
                if dt > 0:
                    a = (v - v0) / dt
                    odometer += 0.5 * (abs(v0) + abs(v)) * dt
            track = _no_track()
        self._last_poll = (now, v, odometer)
        heading = float(self._map.get("DirectionDeg", 0.0))
        self._train = {
            **previous,
            "rotation": math.radians(heading),
            "locomotiveState": {
                **previous.get("locomotiveState", {}),
                "v": v,
                "a": a,
                "distance": odometer,
            },
            "trackLocation": track,
        }
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
        lo, hi = spec.min_value, spec.max_value
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

    async def _read_ranges(self) -> dict[str, ControlRange]:
        listed = await self._get_json("/API/CABCONTROLS")
        ranges: dict[str, ControlRange] = {}
        try:
            for item in listed:
                name = str(item["TypeName"])
                ranges.setdefault(
                    name, ControlRange(name, float(item["MinValue"]), float(item["MaxValue"]))
                )
        except (TypeError, KeyError, ValueError) as exc:
            raise self._unavailable(
                f"OpenRails at {self.base_url}/API/CABCONTROLS answered a list that is not "
                f"[{{TypeName, MinValue, MaxValue}}]: {listed!r:.120}"
            ) from exc
        return ranges

    # --- start-up ----------------------------------------------------------------------------

    async def _wait_ready(self) -> None:
        """Poll until OpenRails is ready, backing off 0.05 s -> 1 s, for ``ready_timeout_s``.

        Lockstep: GET /API/READY answers 200. Stock OpenRails has no READY: GET
        /API/CABCONTROLS answering 200 means a train is loaded.
        """
        path = "/API/READY" if self.settings.mode == "lockstep" else "/API/CABCONTROLS"
        deadline = wallclock.monotonic() + self.settings.ready_timeout_s
        delay, last = 0.05, "no answer"
        while True:
            remaining = deadline - wallclock.monotonic()
            try:
                limit = max(0.05, min(remaining, self.settings.request_timeout_s))
                answer = await self._send("GET", path, deadline_s=limit)
                if 200 <= answer.status < 300:
                    return
                last = f"answered {answer.status}"
            except ParticipantUnavailable as exc:
                cause = exc.__cause__
                last = f"{type(cause).__name__}: {cause}" if cause and str(cause) else "no answer"
            if wallclock.monotonic() + delay > deadline:
                log.warning("openrails_not_ready", url=self.base_url, last=last)
                raise self._unavailable(
                    f"OpenRails at {self.base_url}{path} not ready within "
                    f"{self.settings.ready_timeout_s:g} s ({last}); is OpenRails running with "
                    f"its web server on, and is OPENRAILS_BRIDGE_OPENRAILS_URL right?",
                    call="connect",
                )
            await asyncio.sleep(delay)
            delay = min(delay * 2, 1.0)

    # --- HTTP: the one place aiohttp errors and bad answers are translated ---------------------

    async def _get_json(self, path: str, *, method: str = "GET", body: Any = None) -> Any:
        answer = await self._check(method, path, body=body)
        try:
            return json.loads(answer.text)
        except ValueError as exc:
            raise self._unavailable(
                f"OpenRails at {self.base_url}{path} answered {answer.status} with a body that "
                f"is not JSON: {answer.text!r:.120}"
            ) from exc

    async def _check(self, method: str, path: str, *, body: Any = None) -> _Answer:
        """The answer if 2xx; ParticipantUnavailable naming the URL otherwise."""
        answer = await self._send(method, path, body=body)
        if not 200 <= answer.status < 300:
            log.warning("openrails_error", url=self.base_url, path=path, status=answer.status)
            raise self._unavailable(
                f"OpenRails at {self.base_url}{path} answered {answer.status} to {method}: "
                f"{answer.text.strip()[:300] or '(no body)'}"
            )
        return answer

    async def _send(
        self, method: str, path: str, *, body: Any = None, deadline_s: float | None = None
    ) -> _Answer:
        """One request with a deadline; transport failures become ParticipantUnavailable."""
        url = f"{self.base_url}{path}"
        if self._session is None:
            raise self._unavailable(f"not connected to OpenRails at {url}; connect() first")
        limit = self._timeout if deadline_s is None else aiohttp.ClientTimeout(total=deadline_s)
        try:
            async with self._session.request(method, url, json=body, timeout=limit) as response:
                return _Answer(response.status, await response.text())
        except TimeoutError as exc:
            total = limit.total if limit.total is not None else 0.0
            raise self._unavailable(
                f"OpenRails at {url} did not answer {method} within {total:g} s "
                f"(OPENRAILS_BRIDGE_REQUEST_TIMEOUT_S)"
            ) from exc
        except aiohttp.ClientError as exc:
            raise self._unavailable(
                f"cannot reach OpenRails at {url}: {type(exc).__name__}: {exc}"
            ) from exc

    def _unavailable(self, message: str, *, call: str = "step") -> ParticipantUnavailable:
        return ParticipantUnavailable(
            message, participant=self.name, call=call, status="UNAVAILABLE"
        )


def _base_url(url: str) -> str:
    """``http://host:port`` without a trailing ``/`` or ``/API``."""
    url = url.rstrip("/")
    return url[: -len("/API")] if url.endswith("/API") else url


def _no_track() -> dict[str, Any]:
    return {
        "trackNodeIndex": 0,
        "trackNodeLength": 0.0,
        "trackNodeOffset": 0.0,
        "trackVectorSectionIndex": 0,
        "movementDirection": 1,
    }


def _read_display(rows: Any) -> tuple[float, int | None]:
    """|speed| [m/s] and the reverser (1, 0, -1 or None) from TRAINDRIVINGDISPLAY rows."""
    speed, reverser = 0.0, None
    for row in rows if isinstance(rows, list) else []:
        if not isinstance(row, dict):
            continue
        label = str(row.get("FirstCol", "")).strip().lower()
        text = str(row.get("LastCol", ""))
        if label in ("speed", "sped") and (match := _SPEED.search(text)):
            speed = abs(float(match.group(1))) * _SPEED_UNITS[match.group(2).lower()]
        elif label in ("direction", "dirc"):
            reverser = _REVERSER.get(text.strip().lower(), reverser)
    return speed, reverser
