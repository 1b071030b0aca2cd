"""What the map server's tests share besides fixtures (those are in conftest.py): the service on
a free port, a run driving it, its event stream, the browser's model of it.
"""

from __future__ import annotations

import asyncio
import json
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiohttp

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.server import ParticipantServer
from coupler_railway import Infrastructure
from mapserver.feed import Feed
from mapserver.state import RunState

REPO = Path(__file__).resolve().parents[3]
TEST_LINE = REPO / "packages" / "railway" / "tests" / "data" / "test-line.railml"
EXPECTED_IDS = [101, 102, 201, 301, 302, 303, 401]


@dataclass
class MapService:
    state: RunState
    feed: Feed
    server: ParticipantServer
    url: str

    @property
    def http_port(self) -> int:
        return int(self.url.rsplit(":", 1)[1].strip("/"))


@dataclass
class TrackBalisesEmulation:
    """What the TrackBalises FMU outputs for a train at ``distance``: position and balises."""

    infrastructure: Infrastructure
    distance: float = 0.0
    passed: int = 0
    last: tuple[int, int] = (0, 0)

    def move_to(self, distance: float, speed: float) -> dict[str, Any]:
        crossed = [
            b for b in self.infrastructure.balises if self.distance < b.distance_m <= distance
        ]
        self.distance = distance
        self.passed += len(crossed)
        if crossed:
            self.last = (crossed[-1].code, crossed[-1].group)
        point = self.infrastructure.model.position(distance)
        return {
            "latitude": point.latitude_deg,
            "longitude": point.longitude_deg,
            "distance": distance,
            "speed": speed,
            "balise_id": self.last[0],
            "group_id": self.last[1],
            "balises_passed": self.passed,
            "passed_in_step": ";".join(f"{b.code}:{b.group}:{b.distance_m:.3f}" for b in crossed),
        }


@dataclass
class Run:
    """Drives a run over the test line through the real gRPC wire."""

    participant: RemoteParticipant
    infrastructure: Infrastructure
    run_id: str = "test-run"
    step_s: float = 1.0
    speed_mps: float = 25.0
    time_s: float = 0.0
    fmu: TrackBalisesEmulation = field(init=False)

    def __post_init__(self) -> None:
        self.fmu = TrackBalisesEmulation(self.infrastructure)

    async def start(self) -> None:
        length = self.infrastructure.model.length
        await self.participant.initialize(
            RunSetup(
                run_id=self.run_id,
                start_time=0.0,
                step_size=self.step_s,
                stop_time=length / self.speed_mps,
            )
        )

    async def steps(
        self,
        count: int,
        *,
        pace_s: float = 0.0,
        inputs: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    ) -> None:
        """``count`` DoSteps, the train advancing speed * step each (stopping at the end)."""
        for _ in range(count):
            distance = min(self.fmu.distance + self.speed_mps * self.step_s, self.length)
            values = self.fmu.move_to(distance, self.speed_mps)
            if inputs is not None:
                values = inputs(values)
            await self.participant.do_step(self.time_s, self.step_s, values)
            self.time_s += self.step_s
            if pace_s:
                await asyncio.sleep(pace_s)

    async def to_end(self, *, pace_s: float = 0.0) -> None:
        while self.fmu.distance < self.length:
            await self.steps(1, pace_s=pace_s)

    @property
    def length(self) -> float:
        return self.infrastructure.model.length


class EventStream:
    """A minimal SSE client: yields the JSON of each message."""

    def __init__(self, response: aiohttp.ClientResponse) -> None:
        self.response = response

    async def next(self, within: float = 10.0) -> dict[str, Any]:
        data: list[str] = []
        deadline = time.monotonic() + within
        while True:
            remaining = deadline - time.monotonic()
            raw = await asyncio.wait_for(self.response.content.readline(), max(remaining, 0.01))
            if not raw:
                raise EOFError("stream closed")
            line = raw.decode().rstrip("\n")
            if line.startswith("data: "):
                data.append(line[6:])
            elif line == "" and data:
                event: dict[str, Any] = json.loads("\n".join(data))
                return event

    async def until(
        self, predicate: Callable[[dict[str, Any]], bool], within: float = 10.0
    ) -> list[dict[str, Any]]:
        """Every event up to and including the first that satisfies ``predicate``."""
        seen = []
        deadline = time.monotonic() + within
        while True:
            event = await self.next(max(deadline - time.monotonic(), 0.01))
            seen.append(event)
            if predicate(event):
                return seen


class BrowserModel:
    """Applies events as app.js does; the state a browser would show."""

    def __init__(self) -> None:
        self.seq = 0
        self.readings: list[dict[str, Any]] = []
        self.run: dict[str, Any] = {}
        self.train: dict[str, Any] | None = None
        self.snapshots = 0

    def apply(self, event: dict[str, Any]) -> None:
        if event["type"] == "snapshot":
            self.snapshots += 1
            self.seq = event["seq"]
            self.readings = list(event["readings"])
            self.run, self.train = event["run"], event["train"]
            return
        assert event["seq"] > self.seq, f"event out of order: {event['seq']} after {self.seq}"
        self.seq = event["seq"]
        if event["type"] == "reading":
            expected = self.readings[-1]["index"] + 1 if self.readings else 0
            assert event["reading"]["index"] == expected, "a reading was lost"
            self.readings.append(event["reading"])
        elif event["type"] == "step":
            self.run, self.train = event["run"], event["train"]
        elif event["type"] == "run":
            if event["reset"]:
                self.readings = []
            self.run = event["run"]

    @property
    def balise_ids(self) -> list[int]:
        return [r["balise_id"] for r in self.readings]


def stalled_socket(port: int, path: str = "/api/events") -> socket.socket:
    """A client that asks for ``path`` and then never reads (tiny receive buffer)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    sock.setblocking(False)
    sock.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
    return sock


def page_errors(page: Any) -> list[str]:
    """Script errors and console errors of ``page``, collected from now on."""
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    return errors
