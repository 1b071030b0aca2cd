"""What every section shares: the result row, the sizes of a run, the scenarios (SSD files of
FMU chains and gain rings), `coupler run` timed from its first to its last communication point,
and the participant processes a section starts.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
SUITE = ROOT / "benchmarks" / "suite.py"
"""The suite's driver: sections start it again as a process (``--raw-server`` and the like)."""


FMUS = ROOT / "build" / "fmus"


STEP = 0.01


@dataclass
class Row:
    case: str
    coupler: float
    """Coupler's steps/s."""
    reference: str = ""
    reference_rate: float | None = None
    target: float | None = None
    """Minimum ratio coupler / reference."""
    note: str = ""
    equal: bool | None = None
    """Whether both computed the same results, where the row checks that (a FAIL if not)."""

    @property
    def ratio(self) -> float | None:
        return self.coupler / self.reference_rate if self.reference_rate else None

    @property
    def verdict(self) -> str:
        if self.equal is False:
            return "FAIL"
        if self.target is None or self.ratio is None:
            return ""
        return "PASS" if self.ratio >= self.target else "FAIL"


def median_of(samples: Sequence[float]) -> float:
    return float(statistics.median(samples))


def _connectors(kinds: Sequence[tuple[str, str, str]]) -> str:
    return "".join(
        f'<ssd:Connector name="{name}" kind="{kind}"><ssc:{type_}/></ssd:Connector>'
        for name, kind, type_ in kinds
    )


SOURCE = _connectors(
    [("ramp", "output", "Real"), ("sine", "output", "Real"), ("counter", "output", "Integer")]
)


FEEDTHROUGH = _connectors(
    [("real_in", "input", "Real")]
    + [(f"{k}_out", "output", t) for k, t in (("real", "Real"), ("int", "Integer"),
                                              ("bool", "Boolean"), ("string", "String"))]
)  # fmt: skip


GAIN_FMI2 = _connectors(
    [("u", "input", "Real"), ("y", "output", "Real"), ("x", "output", "Real"),
     ("count", "output", "Integer"), ("inverted", "output", "Boolean"),
     ("echo", "output", "String")]
)  # fmt: skip


GAIN = _connectors(
    [("u", "input", "Real"), ("y", "output", "Real"), ("x", "output", "Real"),
     ("count", "output", "Integer"), ("inverted", "output", "Boolean"),
     ("echo", "output", "String"), ("blob_out", "output", "Binary")]
)  # fmt: skip


def chain_ssd(folder: Path, n: int) -> Path:
    """Source2 -> Feedthrough2 x n, real_out -> real_in."""
    elements = [
        f'<ssd:Component name="Source" source="{FMUS / "Source2.fmu"}">'
        f"<ssd:Connectors>{SOURCE}</ssd:Connectors></ssd:Component>"
    ]
    connections = []
    before = ("Source", "ramp")
    for k in range(1, n + 1):
        elements.append(
            f'<ssd:Component name="Feed{k}" source="{FMUS / "Feedthrough2.fmu"}">'
            f"<ssd:Connectors>{FEEDTHROUGH}</ssd:Connectors></ssd:Component>"
        )
        connections.append(
            f'<ssd:Connection startElement="{before[0]}" startConnector="{before[1]}" '
            f'endElement="Feed{k}" endConnector="real_in"/>'
        )
        before = (f"Feed{k}", "real_out")
    return write_ssd(folder / f"chain{n}.ssd", elements, connections)


def ring_ssd(folder: Path, ports: Sequence[int | str], name: str = "ring") -> Path:
    """Gain participants at ``ports`` (a port on loopback, or an address), Gain_k.y ->
    Gain_k+1.u, the last one's y -> the first's u."""
    n = len(ports)
    elements = [
        f'<ssd:Component name="Gain{k}" type="application/x-coupler-grpc" '
        f'source="{address_of(port)}"><ssd:Connectors>{GAIN}</ssd:Connectors>'
        "</ssd:Component>"
        for k, port in enumerate(ports, start=1)
    ]
    connections = [
        f'<ssd:Connection startElement="Gain{k}" startConnector="y" '
        f'endElement="Gain{k % n + 1}" endConnector="u"/>'
        for k in range(1, n + 1)
    ]
    return write_ssd(folder / f"{name}{n}.ssd", elements, connections)


def address_of(server: int | str) -> str:
    """A participant's address: ``grpc://127.0.0.1:PORT`` for a port, else as given."""
    return f"grpc://127.0.0.1:{server}" if isinstance(server, int) else server


def write_ssd(path: Path, elements: Sequence[str], connections: Sequence[str]) -> Path:
    path.write_text(
        f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="{path.stem}"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">
  <ssd:System name="{path.stem}">
    <ssd:Elements>
      {chr(10).join(elements)}
    </ssd:Elements>
    <ssd:Connections>
      {chr(10).join(connections)}
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="1.0"/>
</ssd:SystemStructureDescription>
""",
        encoding="utf-8",
    )
    return path


class Clock:
    """Times a run from its first to its last communication point, and the first one."""

    def __init__(self, begun: float) -> None:
        from coupler_orchestrator.observer import Observer, Steps

        class Observe(Observer):
            def stepped(inner, time_s: float, row: Sequence[Any]) -> None:
                self.reached(1)

            def stepped_batch(inner, steps: Steps) -> None:  # several steps told at once
                self.reached(len(steps.times))

        self.begun = begun
        self.first: float | None = None
        self.last = 0.0
        self.points = 0
        self.observer = Observe()

    def reached(self, points: int) -> None:
        """``points`` more communication points, the last one now."""
        now = time.perf_counter()
        if self.first is None:
            self.first = now
        self.last, self.points = now, self.points + points

    @property
    def rate(self) -> float:
        assert self.first is not None
        return (self.points - 1) / (self.last - self.first)


async def coupler_run(ssd: Path, steps: int, out: Path, *, step_socket: bool = True) -> Clock:
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.runner import run_scenario

    clock = Clock(time.perf_counter())
    options = RunOptions(
        stop_time=steps * STEP,
        step_size=STEP,
        run_id=f"bench-{time.time_ns()}",
        step_socket=step_socket,
    )
    outcome = await run_scenario(  # runs repeat into one folder: each replaces the last
        ssd, options, out_dir=out, replace=True, observers=[clock.observer]
    )
    if outcome.end.status != "completed":
        raise RuntimeError(f"{ssd.name}: {outcome.end.status}: {outcome.end.reason}")
    return clock


@contextlib.contextmanager
def processes(commands: Sequence[Sequence[str]]) -> Iterator[list[subprocess.Popen[bytes]]]:
    started = [
        subprocess.Popen(c, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
        for c in commands
    ]
    try:
        yield started
    finally:
        for process in started:
            process.terminate()
        for process in started:
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()


def free_ports(count: int) -> list[int]:
    from coupler_orchestrator.tools.fleet import free_port

    return [free_port() for _ in range(count)]


async def serving(ports: Sequence[int | str], within: float = 180.0) -> None:
    from coupler.errors import CouplerError
    from coupler.health import probe

    async def one(port: int | str) -> None:
        deadline = time.monotonic() + within
        while True:
            try:
                await probe(address_of(port), connect_timeout=2.0)
                return
            except CouplerError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.2)

    await asyncio.gather(*(one(p) for p in ports))


def gains(ports: Sequence[int]) -> list[list[str]]:
    return [[sys.executable, "-m", "coupler.examples", "gain", "--port", str(p)] for p in ports]


def cpu_s(pid: int) -> float:
    """A process's CPU time so far, user and system [s] (/proc/<pid>/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid: int, field: str = "VmRSS") -> float:
    """A process's resident memory [MB] (``VmHWM``: its peak since it started its program;
    getrusage's ``ru_maxrss`` would count the parent's too, as Linux keeps it across exec)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    return 0.0


@dataclass(frozen=True)
class Sizes:
    chain_steps: int
    remote_steps: int
    repeats: int
    scale_steps: int
    rss_steps: int
    render_positions: int
    frame_steps: int
    perception_stop_s: float


async def interleaved(
    repeats: int, *measures: Callable[[], Awaitable[float | None]]
) -> list[float | None]:
    """Medians of each measure, run in turns (so a busy moment hits them alike)."""
    samples: list[list[float]] = [[] for _ in measures]
    for _ in range(repeats):
        for found, measure in zip(samples, measures, strict=True):
            value = await measure()
            if value is not None:
                found.append(value)
    return [median_of(s) if s else None for s in samples]
