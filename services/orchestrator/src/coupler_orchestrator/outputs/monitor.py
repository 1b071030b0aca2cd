"""The live monitor of ``coupler run --monitor [HOST:]PORT``: a page served while the run goes.

It shows the run's status, simulated time, progress, real-time factor, each participant's step
latency (a live chart), live charts of the channels picked in the page and the latest frame of
each camera channel (``coupler.v1.Image``, ``/api/frame/<Component.channel>``, a PNG). It
follows the map server's rules: the run never waits for a browser.

- The run only hands its events to :class:`MonitorState` (an observer): O(1) per step, no
  network, no awaiting. History is kept decimated: at most ``points`` points per run (every
  point at first; when full, every other point is dropped and the stride doubles), so a run of
  a million steps keeps a bounded, evenly spread history of the numeric channels (never of
  frames or other large values: only the latest row holds those).
- A camera frame is encoded for a browser only when one asks for it, off the event loop, once
  per frame however many browsers ask.
- Each browser has a stream (server-sent events) that wakes four times a second and sends what
  is new since what that browser already has, read from the state at that moment: nothing
  queues up for a slow browser, and one whose socket stays full for ``write_timeout`` seconds
  is dropped (the page reconnects and starts over). At most ``max_streams`` streams go at once
  (16): a stream costs the run's process memory and time, so another page is answered 503 with
  a sentence until one closes.
- A page's first paint is fast however busy the run keeps this process: the page itself carries
  the run's status (header and layout, inlined into the HTML), and every stream's first frame is
  that small state again; the whole history follows in the second frame, so a late joiner sees
  the run so far.
"""

from __future__ import annotations

import asyncio
import bisect
import contextlib
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import structlog
from aiohttp import web

from coupler.channels import Value
from coupler.errors import CouplerError, ScenarioError
from coupler.ports import host_port, listening
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo, Steps
from coupler_orchestrator.outputs.frames import is_frame, png, read_image

log = structlog.get_logger("coupler.monitor")

STATIC = Path(__file__).parent.parent / "static"
NUMERIC = frozenset({"Real", "Integer", "Boolean", "Enumeration", "UInt64"})
"""Column types the page can chart."""


class MonitorError(CouplerError):
    """The monitor cannot serve (its address is taken, not an address)."""


class Decimated:
    """A time series of rows holding at most ``points`` points, evenly spread over the run."""

    def __init__(self, points: int) -> None:
        self.points = max(points, 2)
        self.times: list[float] = []
        self.rows: list[Sequence[Any]] = []
        self.stride = 1
        self._offered = 0

    def offer(self, time_s: float, row: Sequence[Any]) -> None:
        """Keep ``row`` if it falls on the stride (amortized O(1))."""
        offered, self._offered = self._offered, self._offered + 1
        if offered % self.stride:
            return
        self.times.append(time_s)
        self.rows.append(row)
        if len(self.times) >= self.points:
            self.times, self.rows = self.times[::2], self.rows[::2]
            self.stride *= 2

    def offer_all(self, times: Sequence[float], row: Callable[[int], Sequence[Any]]) -> None:
        """``offer`` each of ``times`` with ``row(j)``, made only for the points kept."""
        for j, time_s in enumerate(times):
            if self._offered % self.stride:
                self._offered += 1
            else:
                self.offer(time_s, row(j))

    def after(self, time_s: float) -> tuple[list[float], list[Sequence[Any]]]:
        """The points later than ``time_s``."""
        start = bisect.bisect_right(self.times, time_s)
        return self.times[start:], self.rows[start:]


class MonitorState(Observer):
    """What the page shows, fed by the run's events (an observer)."""

    def __init__(self, *, points: int = 2000) -> None:
        self.points = points
        self.status = "waiting"
        """waiting, running, then the run's end status (completed, failed, ...)."""
        self.reason = ""
        self.waiting_for: dict[str, str] = {}
        """Participants not up yet: name -> 'address (reason)'."""
        self.info: RunInfo | None = None
        self.time: float | None = None
        self.row: Sequence[Value] = ()
        self.latency: list[float | None] = []
        """Each member's last step latency [ms]."""
        self.cost: list[float | None] = []
        """What each member's last step cost it, by its own account [ms] (None: not said)."""
        self.values = Decimated(points)
        self.latencies = Decimated(points)
        self._started = 0.0
        self._ended: float | None = None
        self._numeric: list[int] = []
        self._kept: dict[str, int] = {}
        """Numeric column -> its place in the rows the history keeps."""
        self._whole = True
        """Every column is numeric: the history keeps rows as they come."""
        self._frames: dict[str, int] = {}
        """Frame column -> its place in a row."""
        self._encoded: dict[str, tuple[object, bytes | None]] = {}
        """Frame column -> (the frame's value, its PNG): one encoding per frame."""
        self.version = 0
        """Bumped by every event (streams sleep while it stays the same)."""

    # the run's events ----------------------------------------------------------------------

    def waiting(self, name: str, address: str, reason: str) -> None:
        self.waiting_for[name] = f"{address} ({reason})"
        self.version += 1

    def started(self, info: RunInfo) -> None:
        self.info, self.status, self.reason = info, "running", ""
        self.waiting_for.clear()
        self.values, self.latencies = Decimated(self.points), Decimated(self.points)
        self.time, self.latency = None, [None] * len(info.members)
        self.cost = [None] * len(info.members)
        self._numeric = [i for i, c in enumerate(info.columns) if c.type in NUMERIC]
        self._whole = len(self._numeric) == len(info.columns)
        self._kept = {
            info.columns[i].name: i if self._whole else j for j, i in enumerate(self._numeric)
        }
        self._frames = {c.name: i for i, c in enumerate(info.columns) if is_frame(c)}
        self._encoded.clear()
        self._started, self._ended = time.monotonic(), None
        self.version += 1

    def stepped(self, time_s: float, row: Sequence[Value]) -> None:
        self.time, self.row = time_s, row
        self.values.offer(time_s, row if self._whole else [row[i] for i in self._numeric])
        self.version += 1

    def timed(self, seconds: Sequence[float | None]) -> None:
        self.latency = [None if s is None else s * 1e3 for s in seconds]
        if self.time is not None:
            self.latencies.offer(self.time, self.latency)

    def costed(self, seconds: Sequence[float | None], waited: Sequence[float | None]) -> None:
        self.cost = [None if s is None else s * 1e3 for s in seconds]

    def stepped_batch(self, steps: Steps) -> None:
        """Several steps: the rows (and latencies) the history keeps, and the last ones."""
        times = steps.times
        numeric = self._numeric

        def kept(j: int) -> Sequence[Value]:
            row = steps.row(j)
            return row if self._whole else [row[i] for i in numeric]

        def milliseconds(j: int) -> list[float | None]:
            return [None if s is None else s * 1e3 for s in steps.seconds(j)]

        self.values.offer_all(times, kept)
        self.latencies.offer_all(times, milliseconds)
        self.time, self.row = times[-1], steps.row(-1)
        self.latency = self.cost = milliseconds(-1)  # computed here: cost = latency
        self.version += 1

    def finished(self, end: RunEnd) -> None:
        self.status, self.reason = end.status, end.reason
        self._ended = time.monotonic()
        self.version += 1

    # what the page gets ---------------------------------------------------------------------

    def header(self) -> dict[str, Any]:
        """Status, times, progress and real-time factor."""
        info = self.info
        found: dict[str, Any] = {"status": self.status, "reason": self.reason}
        if self.waiting_for:
            found["waiting_for"] = self.waiting_for
        if info is None:
            return found
        now = self._ended if self._ended is not None else time.monotonic()
        elapsed = now - self._started
        reached = (self.time if self.time is not None else info.start_time) - info.start_time
        span = info.stop_time - info.start_time
        rtf = reached / elapsed if elapsed > 0 else None
        return found | {
            "run_id": info.run_id,
            "time": self.time,
            "start_time": info.start_time,
            "stop_time": info.stop_time,
            "progress": reached / span if span > 0 else 1.0,
            "elapsed_s": elapsed,
            "realtime_factor": rtf,
            "eta_s": (span - reached) / rtf if rtf and self._ended is None else None,
            "latency_ms": dict(zip(info.members, self.latency, strict=False)),
            "cost_ms": dict(zip(info.members, self.cost, strict=False)),
        }

    def layout(self) -> dict[str, Any]:
        """The run's participants and the channels the page may chart."""
        info = self.info
        if info is None:
            return {"members": [], "channels": [], "frames": []}
        return {
            "members": list(info.members),
            "channels": [
                {"name": info.columns[i].name, "unit": info.columns[i].unit} for i in self._numeric
            ],
            "frames": list(self._frames),
        }

    def first(self) -> dict[str, Any]:
        """The small state a page paints first: header and layout, no history."""
        return {"header": self.header(), "layout": self.layout()}

    def frame(
        self, since: tuple[float, float] | None, channels: Sequence[str]
    ) -> tuple[dict[str, Any], tuple[float, float]]:
        """What a stream sends: the header and, after the cursor ``since`` (None: from the
        start, with the layout and the picked names that are no chartable channel of the run),
        the latency and picked channels' points; and the new cursor."""
        frame: dict[str, Any] = {"header": self.header()}
        info = self.info
        if since is None:
            frame["layout"] = self.layout()
            if info is not None and (unknown := [n for n in channels if n not in self._kept]):
                frame["unknown_channels"] = unknown  # the page says so: a typo, another run
        latency_after, values_after = since or (-math.inf, -math.inf)
        if info is None:
            return frame, (latency_after, values_after)
        times, rows = self.latencies.after(latency_after)
        frame["latency"] = {
            "t": times,
            "series": {m: [r[i] for r in rows] for i, m in enumerate(info.members)},
        }
        picked = [(name, self._kept[name]) for name in channels if name in self._kept]
        times_v, rows_v = self.values.after(values_after)
        frame["values"] = {
            "t": times_v,
            "series": {name: [_number(r[i]) for r in rows_v] for name, i in picked},
        }
        return frame, (
            times[-1] if times else latency_after,
            times_v[-1] if times_v else values_after,
        )

    def has_frames(self, name: str) -> bool:
        """Whether ``name`` is a frame column of the run."""
        return name in self._frames

    async def latest_png(self, name: str) -> bytes | None:
        """The latest frame of the frame column ``name`` as a PNG; None while it has none (or
        one PNG cannot show). Encoded off the event loop, once per frame."""
        index = self._frames.get(name)
        if index is None or index >= len(self.row):
            return None
        value = self.row[index]
        cached = self._encoded.get(name)
        if cached is not None and cached[0] is value:
            return cached[1]
        encoded = await asyncio.get_running_loop().run_in_executor(None, _png_of, value)
        self._encoded[name] = (value, encoded)
        return encoded


def _png_of(value: object) -> bytes | None:
    image = read_image(value) if isinstance(value, bytes) else None
    return None if image is None else png(image, level=1)


def _number(value: Value) -> float | None:
    if isinstance(value, (int, float)):
        number = float(value)
        return number if math.isfinite(number) else None
    return None


@dataclass(frozen=True, kw_only=True)
class MonitorSettings:
    interval_s: float = 0.25
    """How often a stream looks for news."""
    write_timeout_s: float = 10.0
    """A browser whose socket stays full this long is dropped."""
    max_streams: int = 16
    """Streams served at once; one more is answered 503."""


STATE: web.AppKey[MonitorState] = web.AppKey("state", MonitorState)
SETTINGS: web.AppKey[MonitorSettings] = web.AppKey("settings", MonitorSettings)
STREAMS: web.AppKey[set[asyncio.Event]] = web.AppKey("streams", set)
PAGE: web.AppKey[str] = web.AppKey("page", str)
SSE_HEADERS = {"Content-Type": "text/event-stream", "Cache-Control": "no-store"}


def application(state: MonitorState, settings: MonitorSettings | None = None) -> web.Application:
    app = web.Application()
    app[STATE] = state
    app[SETTINGS] = settings or MonitorSettings()
    app[STREAMS] = set()
    app[PAGE] = (STATIC / "monitor.html").read_text(encoding="utf-8")
    app.router.add_get("/", _index)
    app.router.add_get("/api/state", _state)
    app.router.add_get("/api/events", _events)
    app.router.add_get("/api/frame/{channel}", _frame)
    app.router.add_static("/static/", STATIC, append_version=False)
    app.on_shutdown.append(_close_streams)
    return app


async def _close_streams(app: web.Application) -> None:
    for stop in app[STREAMS]:
        stop.set()


PAGE_STATE = "<!-- the run's state -->"
"""Where the page's HTML receives the run's state at the time it is served."""


async def _index(request: web.Request) -> web.StreamResponse:
    """The page, with the run's state inlined: the first paint needs no other request."""
    state = json.dumps(request.app[STATE].first(), separators=(",", ":")).replace("</", "<\\/")
    page = request.app[PAGE].replace(
        PAGE_STATE, f'<script id="state" type="application/json">{state}</script>'
    )
    return web.Response(text=page, content_type="text/html", headers={"Cache-Control": "no-store"})


async def _state(request: web.Request) -> web.Response:
    channels = [c for c in request.query.get("channels", "").split(",") if c]
    frame, _ = request.app[STATE].frame(None, channels)
    return web.json_response(frame)


async def _frame(request: web.Request) -> web.Response:
    """The latest frame of a camera channel as a PNG; 404 naming the run's camera channels
    when it is none of them, 204 while it has no frame yet."""
    state, name = request.app[STATE], request.match_info["channel"]
    if not state.has_frames(name):
        known = ", ".join(state.layout()["frames"]) or "none"
        raise web.HTTPNotFound(text=f"'{name}' is not a camera channel of this run ({known})")
    encoded = await state.latest_png(name)
    if encoded is None:
        return web.Response(status=204, headers={"Cache-Control": "no-store"})
    return web.Response(
        body=encoded, content_type="image/png", headers={"Cache-Control": "no-store"}
    )


async def _events(request: web.Request) -> web.StreamResponse:
    """One browser's stream: the small state first (painted at once), then the whole history,
    then what is new, at its own pace."""
    state, settings = request.app[STATE], request.app[SETTINGS]
    channels = [c for c in request.query.get("channels", "").split(",") if c]
    streams = request.app[STREAMS]
    if len(streams) >= settings.max_streams:
        return web.Response(
            status=503,
            text=f"the monitor serves at most {settings.max_streams} live pages at once and "
            f"{len(streams)} are open; close one and reload this page\n",
            headers={"Retry-After": "10", "Cache-Control": "no-store"},
        )
    stop = asyncio.Event()
    streams.add(stop)  # the slot is taken before the first await
    response = web.StreamResponse(headers=SSE_HEADERS)
    cursor: tuple[float, float] | None = None
    seen = -1
    try:
        await response.prepare(request)
        first = json.dumps(state.first(), separators=(",", ":"))
        await asyncio.wait_for(
            response.write(f"data: {first}\n\n".encode()), settings.write_timeout_s
        )
        while not stop.is_set():
            transport = request.transport
            if transport is None or transport.is_closing():
                break  # the page has gone: its slot is free at once, news or not
            if state.version != seen:
                seen = state.version
                frame, cursor = state.frame(cursor, channels)
                body = f"data: {json.dumps(frame, separators=(',', ':'))}\n\n".encode()
                await asyncio.wait_for(response.write(body), settings.write_timeout_s)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), settings.interval_s)
    except (ConnectionError, TimeoutError):
        pass  # gone, or stalled: the page reconnects and gets the history again
    finally:
        request.app[STREAMS].discard(stop)
    return response


def parse_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, port); the host defaults to 127.0.0.1 (this machine only)."""
    host, _, port = text.rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    if not port.isdigit() or not 0 <= int(port) < 65536:
        raise MonitorError(
            f"--monitor {text}: not [HOST:]PORT; e.g. --monitor 8090 or --monitor 0.0.0.0:8090"
        )
    return host, int(port)


class MonitorServer:
    """The monitor's web server, for the life of a ``with`` block."""

    def __init__(self, address: str, state: MonitorState | None = None) -> None:
        self.host, self.port = parse_address(address)
        self.state = state or MonitorState()
        self._runner: web.AppRunner | None = None
        self._app: web.Application | None = None

    @property
    def url(self) -> str:
        host = {"0.0.0.0": "127.0.0.1", "::": "::1", "": "127.0.0.1"}.get(self.host, self.host)
        return f"http://{host_port(host, self.port)}/"

    async def __aenter__(self) -> MonitorServer:
        self._app = application(self.state)
        runner = web.AppRunner(self._app, access_log=None, shutdown_timeout=1.0)
        await runner.setup()
        try:
            with listening(self.host, self.port, "the monitor"):
                await web.TCPSite(runner, self.host, self.port).start()
        except ScenarioError as exc:
            await runner.cleanup()
            raise MonitorError(f"--monitor: {exc} (--monitor 0 takes any free port)") from None
        bound: Any = runner.addresses[0]
        self.port = int(bound[1])
        self._runner = runner
        log.info("monitor_serving", url=self.url)
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._runner is not None:
            if (
                self._app is not None and self._app[STREAMS]
            ):  # let open pages get the run's last frame
                await asyncio.sleep(2 * self._app[SETTINGS].interval_s + 0.1)
            await self._runner.cleanup()
            self._runner = None
