"""`make bench`: Coupler against the floors and peers, every figure measured in this one run.

    make bench                  # quick (under 5 min on two cores)
    make bench ARGS=--full      # more steps, 100 participants longer
    suite.py --smoke            # every section with the fewest steps: runs, measures nothing
    suite.py --sections sockets # some sections only

Cases (steps/s, median of the repetitions; Coupler and its reference interleaved):

- in-process FMU chain xN: Source2 feeding N Feedthrough2 (real_out -> real_in), every output
  recorded, `coupler`'s runner, the FMUs stepped by the native FMU step (C; with
  COUPLER_NATIVE_STEPS=0 through Python, one ctypes call per FMI call); against a
  hand-written FMPy FMU2Slave loop over the same FMUs (every output read each step) and
  libcosim (libcosimpy, C++) with the same connections;
- in-process FMU chain x2 and x10 against a bare C loop (benchmarks/cloop): the same FMI calls
  and the same results.csv text, formatted by the same shortest round-trip algorithm, nothing
  else; ten times the chains' steps; both files must be byte-identical (else the row FAILs);
- in-process FMU chain x2 and x10 against OpenMCx (C; the binary named by $OPENMCX, else the
  rows are skipped, saying so): the same chains with OpenMCx's task annotation (Jacobi,
  ``parallel_single_thread``), OpenMCx's simulation phase timed as it reports it; and a check:
  every value of OpenMCx's result files equals Coupler's results.csv within 1e-9 of the
  column's largest magnitude (a row whose results differ FAILs);
- remote xN: N example gain participants, each its own process, chained y -> u in a ring,
  Jacobi, over the native step channel when it is built (COUPLER_NATIVE_STEPS=0 measures the
  grpc.aio path instead); against raw grpc.aio round trips to N trivial servers (processes
  answering the same messages: unary DoStep and the bidi StepStream) and, for N = 1, mosaik 3
  with one remote simulator over its TCP API (a local source and sink around it);
- remote x1 over UDS: remote x1 with the gain participant on a unix socket (``--socket``, as
  ``coupler fleet`` serves local participants) against the same over TCP, and against a raw
  grpc.aio StepStream to a trivial server on a unix socket;
- remote x1 against a bare stream (section participant_side): remote x1 against a bare grpc.aio
  StepStream of empty messages to a trivial server (the participant runtime's own work);
- many: 100 gain participants served PER_HOST to a process (``--gain-host``), one run stepping
  them in lockstep, against 100 bare grpc.aio streams to trivial servers grouped the same way;
  and the time from launching the processes to the run's first step;
- proxy FMU x1: the gain participant exported by `coupler export-fmu` (FMI 2, its C++ binary
  calling the participant over its StepStream) run in-process by Coupler and by a hand-written
  FMPy loop, against `coupler run` driving the same participant directly (its stream);
- scale: 100 gain participants in one run: steps/s, RSS per participant process, time from the
  run's start to its first step for 1, 10 and 100 participants;
- memory: the orchestrator's RSS after 1e4 and after 1e5 steps of remote x1 (its own process);
  the peak RSS of replaying 10 steps of a 160 MB recording (its own process) against its RSS
  before it opened the recording (a replay holds one block, not the file);
- the watched run: `coupler run` of Source2 alone (1e5 steps, its own process, as a user runs
  it: a parent watching the run's process for a crash) against the same command run unwatched
  (`cli.main.main()` called directly), wall time as steps/s;
- the command line's start: `coupler --help`, median of five [s].
- camera frames x1: an 800 x 600 RGB frame (1.44 MB) per 0.2 s step from the OpenRails mock
  (a standing train) through the bridge (HTTP GET, its sensor channel) and the orchestrator
  into the map server, `coupler run` at 5 Hz simulated, unpaced; against two bare grpc.aio
  bidi streams moving the same bytes per step (one frame out of a server, one into another).
  The bridge and the map serve gRPC on unix sockets, as `coupler fleet` serves local
  participants, and so do the two raw servers (the mock stays on HTTP over TCP, as
  OpenRails);
- render: the OpenRails mock's camera frames on the Annaberg-Schwarzenberg line (one core,
  this process's CPU time): an 800 x 600 RGB frame in the clear scene against 25 ms and with
  every condition on against 40 ms (issue 44's targets), every condition's worst frame against
  the 200 ms of one OpenRails lockstep step (issue 38), what each condition costs alone, and
  an 800 x 600 RGB with a 200 x 150 depth frame per position against the 200 ms step.

Prints one table with each ratio, its target and PASS/FAIL, and writes build/bench.json. Not a
test: nothing here asserts; the figures go into docs/performance.md.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
FMUS = ROOT / "build" / "fmus"
OUT = ROOT / "build" / "bench.json"
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


# ----------------------------------------------------------------------------- scenarios


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
    return _ssd(folder / f"chain{n}.ssd", elements, connections)


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
    return _ssd(folder / f"{name}{n}.ssd", elements, connections)


def address_of(server: int | str) -> str:
    """A participant's address: ``grpc://127.0.0.1:PORT`` for a port, else as given."""
    return f"grpc://127.0.0.1:{server}" if isinstance(server, int) else server


def _ssd(path: Path, elements: Sequence[str], connections: Sequence[str]) -> Path:
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


# ------------------------------------------------------------------------------ OpenMCx

OPENMCX_STEPS = 20000
"""The most steps the OpenMCx rows run (200 s simulated): OpenMCx's summed time drifts from the
exact grid as it goes, past 1e-9 of the Source's sine amplitude by t = 335 s (a 600 s run: 1.0e-9
at a zero crossing), where the check could no longer tell a wrong result from the drift."""

OPENMCX_TOLERANCE = 1e-9
"""Largest difference between OpenMCx's value and Coupler's, relative to the column's largest
magnitude: OpenMCx gives its FMUs a summed time (t + h + h ...), Coupler the exact grid, which
shows only where a value crosses zero (docs/openmcx.md)."""


def openmcx_missing(binary: str) -> str:
    """Why ``$OPENMCX`` cannot run; empty when it can."""
    if not binary:
        return (
            "OPENMCX is not set (the path of an openmcx binary; docs/performance.md says how to "
            "build one)"
        )
    if not (Path(binary).is_file() and os.access(binary, os.X_OK)):
        return f"OPENMCX={binary} is not an executable file"
    return ""


def openmcx_chain_ssd(folder: Path, n: int, steps: int) -> Path:
    """``chain_ssd``'s chain for ``steps`` steps, with OpenMCx's task annotation: its Jacobi
    scheme (``parallel_single_thread``, Coupler's default; OpenMCx's own default runs a thread
    per component) and the step. In a folder of its own: OpenMCx writes beside it."""
    own = folder / f"openmcx-chain{n}"
    own.mkdir(exist_ok=True)
    task = (
        '<ssd:Annotations><ssc:Annotation type="com.avl.model.connect.ssp.task" '
        'xmlns:mc="com.avl.model.connect.ssp.task"><mc:Task stepType="parallel_single_thread" '
        f'deltaTime="{STEP}" endType="end_time"/></ssc:Annotation></ssd:Annotations>'
    )
    text = chain_ssd(own, n).read_text(encoding="utf-8")
    text = text.replace(
        '<ssd:DefaultExperiment startTime="0.0" stopTime="1.0"/>',
        f'<ssd:DefaultExperiment startTime="0.0" stopTime="{steps * STEP:.2f}">{task}'
        "</ssd:DefaultExperiment>",
    )
    path = own / "chain.ssd"
    path.write_text(text, encoding="utf-8")
    return path


def openmcx_rate(binary: str, ssd: Path, steps: int) -> float:
    """Steps/s of OpenMCx's simulation phase (the wall time it reports after "Simulation
    done.": its stepping loop with its result files, not reading, unpacking and initializing;
    as Coupler's first to last communication point). Results in ``results/`` beside the SSD."""
    import re

    for made in ("results", "temp"):  # OpenMCx refuses to unpack into an existing folder
        shutil.rmtree(ssd.parent / made, ignore_errors=True)
    done = subprocess.run(
        [binary, "-r", "results", "-t", "temp", "-L", "openmcx.log", ssd.name],
        cwd=ssd.parent,
        capture_output=True,
        text=True,
        check=False,
    )
    found = re.search(r"Simulation done\.[^\n]*\n[^\n]*\n[^\n]*Wall-Time:\s*([\d.]+)s", done.stdout)
    if done.returncode != 0 or found is None:
        raise RuntimeError(f"OpenMCx failed on {ssd} ({done.returncode}): {done.stdout[-1500:]}")
    return steps / float(found.group(1))


def openmcx_differences(results: Path, coupler_csv: Path) -> tuple[list[str], float]:
    """Where OpenMCx's result files (``<Component>_res.csv``) and Coupler's results.csv differ
    by more than OPENMCX_TOLERANCE, and the largest difference seen (of the column's scale)."""
    import csv

    with coupler_csv.open(newline="") as file:
        ours = list(csv.DictReader(file))
    problems: list[str] = []
    worst = 0.0
    for path in sorted(results.glob("*_res.csv")):
        component = path.name.removesuffix("_res.csv")
        with path.open(newline="") as file:
            lines = list(csv.reader(file))
        header, theirs = [h.strip() for h in lines[1]], lines[3:]
        if len(theirs) != len(ours):
            problems.append(f"{path.name}: {len(theirs)} rows, Coupler's {len(ours)}")
            continue
        for j, name in enumerate(header[1:], start=1):
            column = f"{component}.{name}"
            if column not in ours[0]:
                problems.append(f"{path.name}: {name}, which Coupler's results.csv has not")
                continue
            pairs = [
                (_value(r[j]), _value(row[column])) for r, row in zip(theirs, ours, strict=True)
            ]
            scale = max((abs(a) for a, _ in pairs if isinstance(a, float)), default=0.0) or 1.0
            for (a, b), r in zip(pairs, theirs, strict=True):
                if isinstance(a, float) and isinstance(b, float):
                    error = abs(a - b) / scale
                    worst = max(worst, error)
                    if error <= OPENMCX_TOLERANCE:
                        continue
                elif a == b:
                    continue
                problems.append(f"{column} at t={r[0].strip()}: Coupler {b!r}, OpenMCx {a!r}")
                break
    if not any(results.glob("*_res.csv")):
        problems.append(f"OpenMCx wrote no result files into {results}")
    return problems, worst


def _value(text: str) -> float | str:
    """A result file's value: a number (booleans as 1 and 0), else the text."""
    text = text.strip().strip('"')
    if text.lower() in ("true", "false"):
        return float(text.lower() == "true")
    try:
        return float(text)
    except ValueError:
        return text


# ------------------------------------------------------------------------------ Coupler


class _Clock:
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


async def coupler_run(ssd: Path, steps: int, out: Path, *, step_socket: bool = True) -> _Clock:
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.runner import run_scenario

    clock = _Clock(time.perf_counter())
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


# ------------------------------------------------------------------------- FMPy and libcosim


def fmpy_slave(path: Path, name: str) -> tuple[Any, Any]:
    """An FMI 2 FMU initialized at t = 0 by FMPy's FMU2Slave, and its model description."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    description = read_model_description(path)
    slave = FMU2Slave(
        guid=description.guid,
        unzipDirectory=extract(path),
        modelIdentifier=description.coSimulation.modelIdentifier,
        instanceName=name,
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, description


def free_slave(slave: Any) -> None:
    """End an FMPy slave and remove the folder ``fmpy.extract`` unpacked its FMU into."""
    try:
        slave.terminate()
        slave.freeInstance()
    finally:
        shutil.rmtree(slave.unzipDirectory, ignore_errors=True)


def fmpy_loop(n: int, steps: int) -> float:
    """Steps/s of a hand-written FMPy loop: Source2 -> Feedthrough2 x n, every output read."""
    slaves = []
    for k, name in enumerate(["Source2"] + ["Feedthrough2"] * n):
        slave, description = fmpy_slave(FMUS / f"{name}.fmu", f"{name}{k}")
        outputs = [v for v in description.modelVariables if v.causality == "output"]
        by_type: dict[str, list[int]] = {}
        for variable in outputs:
            by_type.setdefault(variable.type, []).append(variable.valueReference)
        ramp = next(v.valueReference for v in outputs if v.name in ("ramp", "real_out"))
        slaves.append((slave, by_type, ramp))
    real_in = 3  # Feedthrough2's real_in
    getters = {"Real": "getReal", "Integer": "getInteger", "Boolean": "getBoolean"}
    t = 0.0
    started = time.perf_counter()
    for k in range(steps):
        t = k * STEP
        values = []
        for slave, by_type, ramp in slaves:
            for kind, refs in by_type.items():
                if kind == "String":
                    slave.getString(refs)
                else:
                    getattr(slave, getters[kind])(refs)
            values.append(slave.getReal([ramp])[0])
        for (slave, _, _), value in zip(slaves[1:], values, strict=False):
            slave.setReal([real_in], [value])
        for slave, _, _ in slaves:
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=STEP)
    rate = steps / (time.perf_counter() - started)
    for slave, _, _ in slaves:
        free_slave(slave)
    return rate


def libcosim_loop(n: int, steps: int) -> float | None:
    """Steps/s of libcosim (C++) on the same chain, last values of every slave observed."""
    try:
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimSlave import CosimLocalSlave
    except ImportError:
        return None
    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_step_size(step_size=int(STEP * 1e9))
    indices = []
    for k, name in enumerate(["Source2"] + ["Feedthrough2"] * n):
        slave = CosimLocalSlave(fmu_path=str(FMUS / f"{name}.fmu"), instance_name=f"{name}{k}")
        indices.append(execution.add_local_slave(slave))
    ramp, real_out, real_in = 5, 8, 3
    for k in range(1, len(indices)):
        output = ramp if k == 1 else real_out
        execution.connect_real_variables(indices[k - 1], output, indices[k], real_in)
    execution.add_observer(CosimObserver.create_last_value())
    execution.step(10)
    started = time.perf_counter()
    execution.step(steps)
    return steps / (time.perf_counter() - started)


# ------------------------------------------------------------------- the exported proxy FMU


def export_gain(folder: Path, port: int) -> Path | None:
    """The example gain participant exported as an FMI 2 FMU (coupler export-fmu), pointing at
    ``port``; None without coupler-native (which holds the proxy's binaries)."""
    from coupler.examples.gain import GainParticipant
    from coupler_orchestrator.tools.export_fmu import ProxyMissing, proxy_binaries, write_fmu

    try:
        binaries = proxy_binaries()
    except ProxyMissing:
        return None
    description = asyncio.run(GainParticipant().describe())
    address = f"grpc://127.0.0.1:{port}"
    return write_fmu(description, address=address, out=folder / "GainProxy.fmu",
                     binaries=binaries).path  # fmt: skip


def proxy_ssd(folder: Path, fmu: Path) -> Path:
    """The exported gain FMU in-process, its y fed back to its u (remote x1's ring)."""
    element = (
        f'<ssd:Component name="Gain1" type="application/x-fmu-sharedlibrary" source="{fmu}">'
        f"<ssd:Connectors>{GAIN_FMI2}</ssd:Connectors></ssd:Component>"
    )
    connection = (
        '<ssd:Connection startElement="Gain1" startConnector="y" endElement="Gain1" '
        'endConnector="u"/>'
    )
    return _ssd(folder / "proxy1.ssd", [element], [connection])


def fmpy_proxy_loop(fmu: Path, steps: int) -> float:
    """Steps/s of a hand-written FMPy loop over the exported gain FMU: set u, step, read
    every output (what remote x1 exchanges, less the binary channel FMI 2 has not)."""
    slave, description = fmpy_slave(fmu, "Gain1")
    refs = {v.name: v.valueReference for v in description.modelVariables}
    y = 0.0
    started = time.perf_counter()
    for k in range(steps):
        slave.setReal([refs["u"]], [y])
        slave.doStep(currentCommunicationPoint=k * STEP, communicationStepSize=STEP)
        y, _ = slave.getReal([refs["y"], refs["x"]])
        slave.getInteger([refs["count"]])
        slave.getBoolean([refs["inverted"]])
        slave.getString([refs["echo"]])
    rate = steps / (time.perf_counter() - started)
    free_slave(slave)
    return rate


# --------------------------------------------------------------------------- processes


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


# ---------------------------------------------------------------------------- raw gRPC floor


def _raw_messages() -> tuple[Any, Any]:
    """A request and a response of the sizes the gain participant exchanges."""
    from coupler.v1 import component_pb2 as pb

    request = pb.DoStepRequest(
        current_time=0.0, step_size=STEP, run_id="bench", run_secret=bytes(32)
    )
    request.inputs.add(channel="u", real=1.0)
    response = pb.DoStepResponse()
    for name, kind, value in [
        ("y", "real", 4.0),
        ("x", "real", 0.01),
        ("count", "integer", 0),
        ("inverted", "boolean", True),
        ("echo", "text", ""),
        ("blob_out", "binary", b""),
    ]:
        response.outputs.add(channel=name, **{kind: value})
    return request, response


def _frame_messages(direction: str) -> tuple[Any, Any]:
    """A step of a camera's frame, FRAME_BYTES in a binary value: ``out`` of a participant
    that sends it (the bridge: a small request, the frame in the response), ``in`` of one that
    receives it (the map: the frame in the request, an empty response)."""
    from coupler.v1 import component_pb2 as pb

    frame = bytes(range(256)) * (FRAME_BYTES // 256)
    request = pb.DoStepRequest(current_time=0.0, step_size=FRAME_STEP, run_id="bench")
    response = pb.DoStepResponse()
    if direction == "out":
        response.outputs.add(channel="front", binary=frame)
    else:
        request.inputs.add(channel="camera", binary=frame)
    return request, response


def _messages(kind: str) -> tuple[Any, Any]:
    """A step's request and response: the gain participant's sizes (``kind`` empty), a camera
    frame's (``out``, ``in``: ``_frame_messages``) or ``minimal`` (empty messages)."""
    if kind == "minimal":
        from coupler.v1 import component_pb2 as pb

        return pb.DoStepRequest(), pb.DoStepResponse()
    return _frame_messages(kind) if kind else _raw_messages()


async def raw_server(where: str, frames: str = "") -> None:
    """A trivial GRPCComponentService on a port (``where`` a number) or a unix socket (``where``
    ``unix:PATH``), or one on each of several ports (``where`` comma-separated, one process):
    every step answered with the same outputs (``frames`` ``out``: a camera frame; ``in``:
    nothing, its requests carry one; ``minimal``: an empty response)."""
    if "," in where:
        await asyncio.gather(*(raw_server(w, frames) for w in where.split(",")))
        return
    import grpc

    from coupler.v1 import component_pb2_grpc as rpc

    _, response = _messages(frames)

    class Trivial(rpc.GRPCComponentServiceServicer):  # type: ignore[misc]
        async def DoStep(self, request: Any, context: Any) -> Any:
            return response

        async def StepStream(self, requests: Any, context: Any) -> AsyncIterator[Any]:
            async for _ in requests:
                yield response

    server = grpc.aio.server(options=FRAME_GRPC_OPTIONS)
    rpc.add_GRPCComponentServiceServicer_to_server(Trivial(), server)
    server.add_insecure_port(f"127.0.0.1:{where}" if where.isdigit() else where)
    await server.start()
    await server.wait_for_termination()


async def raw_floor(
    servers: Sequence[int | str], steps: int, *, stream: bool, messages: str = ""
) -> float:
    """Steps/s of bare grpc.aio round trips to every server (a port, or ``unix:PATH``) per
    step (gathered); requests of the kind ``messages`` (``_messages``)."""
    import grpc

    from coupler.v1 import component_pb2_grpc as rpc

    request, _ = _messages(messages)
    targets = [f"127.0.0.1:{s}" if isinstance(s, int) else s for s in servers]
    channels = [grpc.aio.insecure_channel(t) for t in targets]
    try:
        for channel in channels:
            await asyncio.wait_for(channel.channel_ready(), 30)
        stubs = [rpc.GRPCComponentServiceStub(c) for c in channels]
        if stream:
            calls = [stub.StepStream() for stub in stubs]

            async def trip(call: Any) -> Any:
                await call.write(request)
                return await call.read()

            async def once() -> None:
                if len(calls) == 1:
                    await trip(calls[0])
                else:
                    await asyncio.gather(*(trip(c) for c in calls))
        else:

            async def once() -> None:
                if len(stubs) == 1:
                    await stubs[0].DoStep(request)
                else:
                    await asyncio.gather(*(s.DoStep(request) for s in stubs))

        for _ in range(50):
            await once()
        started = time.perf_counter()
        for _ in range(steps):
            await once()
        rate = steps / (time.perf_counter() - started)
        if stream:
            for call in calls:
                await call.done_writing()
        return rate
    finally:
        for channel in channels:
            await channel.close()


# ------------------------------------------------------------------- camera frames, 5 Hz

FRAME_BYTES = 800 * 600 * 3
"""An 800 x 600 RGB frame (the Image message adds a few bytes)."""
FRAME_STEP = 0.2
"""OpenRails' lockstep step: frames at 5 Hz of simulated time."""
FRAME_GRPC_OPTIONS = [("grpc.max_receive_message_length", 8 * 1024 * 1024)]
SENSORS = [{"sensorName": "front", "sensorType": "rgb", "trainName": "PLAYER",
            "width": 800, "height": 600, "fov": 45.0}]  # fmt: skip


async def raw_frames(sender: str, receiver: str, steps: int) -> float:
    """Steps/s of bare grpc.aio bidi streams moving a frame per step as the frames case does:
    one from a sender (its response), one to a receiver (its request), both each step; each
    server at a grpc target (``unix:PATH``)."""
    import grpc

    from coupler.v1 import component_pb2_grpc as rpc

    pairs = [(sender, _frame_messages("out")[0]), (receiver, _frame_messages("in")[0])]
    channels = [
        grpc.aio.insecure_channel(target, options=FRAME_GRPC_OPTIONS) for target, _ in pairs
    ]
    try:
        for channel in channels:
            await asyncio.wait_for(channel.channel_ready(), 30)
        calls = [rpc.GRPCComponentServiceStub(c).StepStream() for c in channels]
        requests = [request for _, request in pairs]

        async def trip(call: Any, request: Any) -> Any:
            await call.write(request)
            return await call.read()

        async def once() -> None:
            await asyncio.gather(*(trip(c, r) for c, r in zip(calls, requests, strict=True)))

        for _ in range(10):
            await once()
        started = time.perf_counter()
        for _ in range(steps):
            await once()
        rate = steps / (time.perf_counter() - started)
        for call in calls:
            await call.done_writing()
        return rate
    finally:
        for channel in channels:
            await channel.close()


def frames_ssd(folder: Path, bridge: int | str, sink: int | str) -> Path:
    """The OpenRails bridge's camera ``front`` into the map server's ``camera`` (each a port
    on loopback or an address, ``address_of``)."""
    image = '<ssc:Binary mime-type="application/x-protobuf; messageType=coupler.v1.Image"/>'
    return _ssd(
        folder / "frames.ssd",
        [
            f'<ssd:Component name="OpenRails" type="application/x-coupler-grpc" '
            f'source="{address_of(bridge)}"><ssd:Connectors>'
            f'<ssd:Connector name="distance" kind="output"><ssc:Real/></ssd:Connector>'
            f'<ssd:Connector name="front" kind="output">{image}</ssd:Connector>'
            f"</ssd:Connectors></ssd:Component>",
            f'<ssd:Component name="Map" type="application/x-coupler-grpc" '
            f'source="{address_of(sink)}"><ssd:Connectors>'
            f'<ssd:Connector name="camera" kind="input">{image}</ssd:Connector>'
            f"</ssd:Connectors></ssd:Component>",
        ],
        [
            '<ssd:Connection startElement="OpenRails" startConnector="front" '
            'endElement="Map" endConnector="camera"/>'
        ],
    )


async def coupler_frames(ssd: Path, steps: int, out: Path) -> float:
    """Steps/s of `coupler run` moving the camera frames (recording the distance only)."""
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.runner import run_scenario

    clock = _Clock(time.perf_counter())
    options = RunOptions(
        stop_time=steps * FRAME_STEP,
        step_size=FRAME_STEP,
        run_id=f"bench-{time.time_ns()}",
        output_variables=("OpenRails.distance",),
    )
    outcome = await run_scenario(  # runs repeat into one folder: each replaces the last
        ssd, options, out_dir=out, replace=True, observers=[clock.observer]
    )
    if outcome.end.status != "completed":
        raise RuntimeError(f"{ssd.name}: {outcome.end.status}: {outcome.end.reason}")
    return clock.rate


def frame_services(work: Path, mock: int, bridge: Path, sink: Path) -> list[list[str]]:
    """The mock with one 800 x 600 camera (a standing train: the frame is rendered once and
    served from its cache, so the figure is the frames' transport) on a port, the bridge and
    the map on unix sockets (``--socket``, as ``coupler fleet`` serves them)."""
    sensors = work / "sensors.json"
    sensors.write_text(json.dumps(SENSORS))
    return [
        [sys.executable, "-m", "openrails_mock", "--port", str(mock), "--sensors", str(sensors),
         "--loading-delay-s", "0"],
        [sys.executable, "-m", "openrails_bridge", "--socket", str(bridge), "--openrails-url",
         f"http://127.0.0.1:{mock}", "--sensors", str(sensors)],
        [sys.executable, "-m", "mapserver", "--socket", str(sink), "--http-port", "0"],
    ]  # fmt: skip


# -------------------------------------------------------------------------------- mosaik


def mosaik_rate(steps: int) -> float | None:
    """Steps/s of mosaik 3: a local source -> the gain simulator (its own process, TCP) -> a
    local sink, time-based, one step per time unit."""
    try:
        import mosaik  # noqa: F401  (installed? the bench group brings it)
        from loguru import logger
    except ImportError:
        return None
    logger.remove()
    script = Path(__file__).with_name("mosaik_gain.py")
    sys.path.insert(0, str(script.parent))
    config = {
        "Local": {"python": "mosaik_gain:Simulator"},
        "Local2": {"python": "mosaik_gain:Simulator"},
        "Remote": {"cmd": f"{sys.executable} {script} %(addr)s"},
    }
    with _quiet():  # mosaik's banner and its simulators' log lines
        return _mosaik_world(config, steps)


def _mosaik_world(config: dict[str, Any], steps: int) -> float:
    import mosaik

    world = mosaik.World(config, debug=False)
    source = world.start("Local").Source()
    gain = world.start("Remote").Gain()
    sink = world.start("Local2").Sink()
    world.connect(source, gain, ("value", "u"))
    world.connect(gain, sink, "y")
    started = time.perf_counter()
    world.run(until=steps, print_progress=False)
    return steps / (time.perf_counter() - started)


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """stdout and stderr of this process and its children to /dev/null (file descriptors)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


# -------------------------------------------------------------------------------- memory


async def rss_probe(port: int, steps: int, sample_at: int) -> dict[str, float]:
    """In this process (the orchestrator's): remote x1 for ``steps`` steps; RSS at
    ``sample_at`` steps and at the end."""
    from coupler_orchestrator.observer import Observer
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.runner import run_scenario

    samples: dict[str, float] = {}

    class Sample(Observer):
        count = 0

        def stepped(self, time_s: float, row: Sequence[Any]) -> None:
            self.count += 1
            if self.count in (sample_at, steps):
                samples[str(self.count)] = rss_mb(os.getpid())

    with tempfile.TemporaryDirectory() as folder:
        ssd = ring_ssd(Path(folder), [port])
        options = RunOptions(stop_time=(steps - 1) * STEP, step_size=STEP)
        await run_scenario(ssd, options, out_dir=Path(folder) / "out", observers=[Sample()])
    return samples


def replay_probe(recording: Path, steps: int) -> dict[str, float]:
    """In this process: RSS after the imports, then the peak RSS once ``steps`` steps of the
    recording were replayed (the way a run's replay reads it)."""
    from coupler.channels import RunSetup
    from coupler_orchestrator.pipeline.replay import ReplayParticipant

    before = rss_mb(os.getpid())

    async def replay() -> None:
        participant = ReplayParticipant(recording)
        await participant.open()
        try:
            grid = participant.recording.grid
            h = grid.component_step
            await participant.initialize(
                RunSetup(run_id="bench", start_time=grid.start_time, step_size=h)
            )
            for k in range(steps):
                await participant.do_step(grid.start_time + k * h, h, {})
        finally:
            await participant.close()

    asyncio.run(replay())
    peak = rss_mb(os.getpid(), "VmHWM")
    return {"before_mb": before, "peak_mb": peak}


def big_recording(path: Path, megabytes: int) -> Path:
    """A recording of one Binary output, 6 kB a point, ``megabytes`` MB in all."""
    from coupler.channels import Causality, Channel, Description, ValueType
    from coupler_orchestrator.observer import Column, RunEnd, RunInfo
    from coupler_orchestrator.recording import Recorder

    blob = os.urandom(6000)
    points = megabytes * 1_000_000 // len(blob)
    channel = Channel(name="b", causality=Causality.OUTPUT, type=ValueType.BINARY)
    recorder = Recorder(
        path, Description(name="Big", channels=(channel,)), component="Big", multiple=1, step=STEP
    )
    recorder.started(
        RunInfo(
            run_id="bench", algorithm="jacobi", members=("Big",), multiples=(1,),
            columns=(Column(name="Big.b", unit="", type="Binary"),), start_time=0.0,
            stop_time=points * STEP, step_size=STEP, steps=points,
        )
    )  # fmt: skip
    for k in range(points + 1):
        recorder.stepped(k * STEP, [blob])
    recorder.finished(RunEnd(status="completed", reason="", steps=points, end_time=0, wall_time=0))
    return path


# ---------------------------------------------------------------------------------- suite


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


QUICK = Sizes(
    chain_steps=20000,
    remote_steps=3000,
    repeats=3,
    scale_steps=100,
    rss_steps=100_000,
    render_positions=20,
    frame_steps=150,
    perception_stop_s=120.0,
)
FULL = Sizes(chain_steps=60000, remote_steps=10000, repeats=5, scale_steps=1000,
             rss_steps=100_000, render_positions=100, frame_steps=500,
             perception_stop_s=300.0)  # fmt: skip
SMOKE = Sizes(chain_steps=200, remote_steps=50, repeats=1, scale_steps=5, rss_steps=11_000,
              render_positions=2, frame_steps=10, perception_stop_s=2.0)  # fmt: skip
"""Every section once with the fewest steps it needs (the RSS probe samples at 1e4): a check
that `make bench` runs (tests/bench), never a figure."""


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


async def suite(
    sizes: Sizes, log: Callable[[str], None], only: Sequence[str] = ()
) -> tuple[list[Row], dict[str, Any]]:
    rows: list[Row] = []
    extra: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="coupler-bench-") as folder:
        for section in SECTIONS:
            if not only or section.__name__ in only:
                await section(sizes, log, Path(folder), rows, extra)
    return rows, extra


async def cli_start(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log("coupler --help: the command line's start (a command imports what it needs when it runs)")
    command = [str(Path(sys.executable).with_name("coupler")), "--help"]
    seconds = []
    for _ in range(5):
        started = time.perf_counter()
        await asyncio.to_thread(subprocess.run, command, capture_output=True, check=True)
        seconds.append(time.perf_counter() - started)
    extra["cli_help_s"] = round(median_of(seconds), 3)
    rows.append(
        Row("coupler --help", median_of(seconds), note="seconds, not steps/s; target: < 0.3 s")
    )


async def watched_run(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    steps = 100_000
    log(f"coupler run, watched (as a user runs it) and not watched: Source2, {steps:.0e} steps")
    arguments = [
        "run", str(FMUS / "Source2.fmu"), "--stop-time", str(steps * STEP), "--step", str(STEP),
        "--no-progress", "--out", str(work / "watched"), "--force",
    ]  # fmt: skip
    watched = [str(Path(sys.executable).with_name("coupler")), *arguments]
    direct = "import sys; from coupler_orchestrator.cli.main import main; sys.exit(main())"
    unwatched = [sys.executable, "-c", direct, *arguments]

    def timed(command: list[str]) -> Callable[[], Awaitable[float]]:
        async def run() -> float:
            started = time.perf_counter()
            done = await asyncio.to_thread(subprocess.run, command, capture_output=True, text=True)
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(command)} failed ({done.returncode}): {done.stderr}")
            return steps / (time.perf_counter() - started)

        return run

    rate, reference = await interleaved(sizes.repeats, timed(watched), timed(unwatched))
    assert rate is not None and reference is not None
    rows.append(
        Row(
            "coupler run, watched",
            rate,
            "the same, not watched",
            reference,
            target=0.95,
            note="whole command, start-up included",
        )
    )


async def chains(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    for n in (2, 10):
        log(f"in-process FMU chain x{n}")
        ssd = chain_ssd(work, n)
        steps = sizes.chain_steps if n == 2 else sizes.chain_steps // 2

        async def coupler_chain(ssd: Path = ssd, steps: int = steps) -> float:
            return (await coupler_run(ssd, steps, work / "out")).rate

        async def fmpy_chain(n: int = n, steps: int = steps) -> float:
            return fmpy_loop(n, steps)

        async def cosim_chain(n: int = n, steps: int = steps) -> float | None:
            return libcosim_loop(n, steps * 5)

        coupler, fmpy, cosim = await interleaved(
            sizes.repeats, coupler_chain, fmpy_chain, cosim_chain
        )
        assert coupler is not None and fmpy is not None
        rows.append(Row(f"in-process FMU chain x{n}", coupler, "FMPy loop", fmpy, 1.0))
        if cosim is not None:
            rows.append(Row(f"in-process FMU chain x{n}", coupler, "libcosim (C++)", cosim, 0.5,
                            note="stretch target"))  # fmt: skip


async def tight_loop(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The chains against their physical limit: a bare C loop (cloop.py) making the same FMI
    calls and writing the same results.csv text with the same formatter; both files compared
    byte for byte. Ten times the chains' steps: the loop takes well under a second."""
    import cloop

    why = cloop.missing()
    if why:
        log(f"tight C-loop rows skipped: {why}")
        extra.setdefault("skipped", []).append(f"chain x2 and x10 vs a bare C loop: {why}")
        return
    binary = cloop.build(work)
    for n in (2, 10):
        log(f"in-process FMU chain x{n} against a bare C loop")
        ssd = chain_ssd(work, n)
        steps = 10 * (sizes.chain_steps if n == 2 else sizes.chain_steps // 2)
        ours, theirs = work / f"tight-coupler{n}", work / f"tight-c{n}.csv"

        async def coupler_chain(ssd: Path = ssd, steps: int = steps, out: Path = ours) -> float:
            return (await coupler_run(ssd, steps, out)).rate

        async def c_chain(n: int = n, steps: int = steps, out: Path = theirs) -> float:
            return await asyncio.to_thread(cloop.rate, binary, FMUS, n, steps, round(1 / STEP), out)

        coupler, reference = await interleaved(sizes.repeats, coupler_chain, c_chain)
        assert coupler is not None and reference is not None
        same = (ours / "results.csv").read_bytes() == theirs.read_bytes()
        rows.append(
            Row(f"in-process FMU chain x{n}", coupler, "bare C loop", reference, 0.5,
                note="same calls; results.csv byte-identical" if same
                else "RESULTS DIFFER from the C loop's",
                equal=same)
        )  # fmt: skip


async def openmcx(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The FMU chains against OpenMCx (the binary ``$OPENMCX``) on the same SSD, and a check
    that both computed the same results."""
    binary = os.environ.get("OPENMCX", "")
    why = openmcx_missing(binary)
    if why:
        log(f"OpenMCx rows skipped: {why}")
        extra.setdefault("skipped", []).append(f"chain x2 and x10 vs OpenMCx: skipped, {why}")
        return
    for n in (2, 10):
        log(f"in-process FMU chain x{n} against OpenMCx ({binary})")
        steps = min(sizes.chain_steps, OPENMCX_STEPS) // (1 if n == 2 else 2)
        ssd = openmcx_chain_ssd(work, n, steps)
        out = work / f"openmcx-coupler{n}"

        async def coupler_chain(ssd: Path = ssd, steps: int = steps, out: Path = out) -> float:
            return (await coupler_run(ssd, steps, out)).rate

        async def openmcx_chain(ssd: Path = ssd, steps: int = steps) -> float:
            return await asyncio.to_thread(openmcx_rate, binary, ssd, steps)

        coupler, reference = await interleaved(sizes.repeats, coupler_chain, openmcx_chain)
        assert coupler is not None and reference is not None
        problems, worst = openmcx_differences(ssd.parent / "results", out / "results.csv")
        rows.append(
            Row(
                f"in-process FMU chain x{n}",
                coupler,
                "OpenMCx (C)",
                reference,
                3.0,  # the core held at 3x OpenMCx (docs/performance.md)
                note=(
                    f"results equal, worst {worst:.1e} of the column's scale"
                    if not problems
                    else f"RESULTS DIFFER: {'; '.join(problems[:3])}"
                ),
                equal=not problems,
            )
        )


async def remotes(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    for n, target in ((1, 0.8), (3, 0.9), (10, 0.8)):
        log(f"remote x{n}")
        gain_ports, raw_ports = free_ports(n), free_ports(n)
        raw = [[sys.executable, __file__, "--raw-server", str(p)] for p in raw_ports]
        with processes(gains(gain_ports) + raw):
            await serving(gain_ports)  # the raw servers: channel_ready in raw_floor
            ssd = ring_ssd(work, gain_ports)
            steps = sizes.remote_steps if n < 10 else sizes.remote_steps // 2

            async def coupler_remote(ssd: Path = ssd, steps: int = steps) -> float:
                return (await coupler_run(ssd, steps, work / "out")).rate

            async def stream(ports: list[int] = raw_ports, steps: int = steps) -> float:
                return await raw_floor(ports, steps, stream=True)

            async def unary(ports: list[int] = raw_ports, steps: int = steps) -> float:
                return await raw_floor(ports, steps, stream=False)

            coupler, floor, unary_floor = await interleaved(
                sizes.repeats, coupler_remote, stream, unary
            )
        assert coupler is not None and floor is not None and unary_floor is not None
        rows.append(Row(f"remote x{n}", coupler, f"raw grpc.aio stream x{n}", floor, target))
        rows.append(Row(f"remote x{n}", coupler, f"raw grpc.aio unary x{n}", unary_floor))
        if n == 1:
            log("mosaik 3, one remote simulator")

            async def mosaik_once() -> float | None:
                return await asyncio.to_thread(mosaik_rate, sizes.remote_steps)

            [mosaik_figure] = await interleaved(sizes.repeats, mosaik_once)
            if mosaik_figure is not None:
                rows.append(Row("remote x1", coupler, "mosaik 3 (TCP)", mosaik_figure, 1.25))


async def sockets(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """remote x1 with the gain participant on a unix socket (as ``coupler fleet`` serves local
    participants; stepped over its step socket) against the same on TCP, against the same over
    its StepStream on the socket (``--no-step-socket``), and against a bare grpc.aio stream over
    a socket."""
    log(
        "remote x1 over a unix socket (its step socket, and its StepStream), over TCP, and a raw "
        "grpc.aio stream over a unix socket"
    )
    folder = Path(tempfile.mkdtemp(prefix="cb-", dir="/tmp"))  # a socket path has 107 bytes
    gain_socket, raw_socket = folder / "gain.sock", folder / "raw.sock"
    [port] = free_ports(1)
    on_socket = [sys.executable, "-m", "coupler.examples", "gain", "--socket", str(gain_socket)]
    raw = [sys.executable, __file__, "--raw-server", f"unix:{raw_socket}"]
    with processes([*gains([port]), on_socket, raw]):
        await serving([port, f"unix://{gain_socket}"])
        tcp_ssd = ring_ssd(work, [port])
        unix_ssd = ring_ssd(work, [f"unix://{gain_socket}"], name="ring-unix")
        steps = sizes.remote_steps

        async def over_unix() -> float:
            return (await coupler_run(unix_ssd, steps, work / "out")).rate

        async def over_unix_stream() -> float:
            clock = await coupler_run(unix_ssd, steps, work / "out", step_socket=False)
            return clock.rate

        async def over_tcp() -> float:
            return (await coupler_run(tcp_ssd, steps, work / "out")).rate

        async def stream() -> float:
            return await raw_floor([f"unix:{raw_socket}"], steps, stream=True)

        unix, unix_stream, tcp, floor = await interleaved(
            sizes.repeats, over_unix, over_unix_stream, over_tcp, stream
        )
    assert unix is not None and unix_stream is not None and tcp is not None and floor is not None
    rows.append(Row("remote x1 over UDS", unix, "remote x1 over TCP", tcp, 1.2))
    rows.append(Row("remote x1 over UDS, gRPC stream", unix_stream, "remote x1 over TCP", tcp))
    rows.append(Row("remote x1 over UDS", unix, "raw grpc.aio stream x1 UDS", floor, 0.8))
    await asyncio.to_thread(shutil.rmtree, folder, True)  # the raw server leaves its socket


async def proxy_fmu(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log("the exported proxy FMU (coupler export-fmu) vs coupler run driving the participant")
    [port] = free_ports(1)
    with processes(gains([port])):
        await serving([port])
        fmu = await asyncio.to_thread(export_gain, work, port)
        if fmu is None:
            log("  skipped: coupler-native (the proxy FMU's binaries) is not installed")
        else:
            direct_ssd, through_ssd = ring_ssd(work, [port]), proxy_ssd(work, fmu)
            steps = sizes.remote_steps

            async def direct(ssd: Path = direct_ssd, steps: int = steps) -> float:
                return (await coupler_run(ssd, steps, work / "out")).rate

            async def proxied(ssd: Path = through_ssd, steps: int = steps) -> float:
                return (await coupler_run(ssd, steps, work / "out")).rate

            async def fmpy_proxied(fmu: Path = fmu, steps: int = steps) -> float:
                return await asyncio.to_thread(fmpy_proxy_loop, fmu, steps)

            coupler_direct, through, by_fmpy = await interleaved(
                sizes.repeats, direct, proxied, fmpy_proxied
            )
            assert coupler_direct and through and by_fmpy
            per_step = {name: round(1e6 / rate, 1) for name, rate in (
                ("coupler_direct", coupler_direct), ("coupler_proxy_fmu", through),
                ("fmpy_proxy_fmu", by_fmpy))}  # fmt: skip
            extra["proxy_fmu_us_per_step"] = per_step
            rows.append(Row("proxy FMU in Coupler (x1)", through, "coupler run, direct x1",
                            coupler_direct,
                            note=f"{per_step['coupler_proxy_fmu']:.0f} vs "
                                 f"{per_step['coupler_direct']:.0f} us/step"))  # fmt: skip
            rows.append(Row("proxy FMU under FMPy loop (x1)", by_fmpy, "coupler run, direct x1",
                            coupler_direct,
                            note=f"{per_step['fmpy_proxy_fmu']:.0f} us/step"))  # fmt: skip


async def scale(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log("scale: 1, 10, 100 participants (time to the first step; 100 in one run)")
    first_step: dict[str, float] = {}
    for n in (1, 10, 100):
        ports = free_ports(n)
        launched = time.perf_counter()
        with processes(gains(ports)) as started:
            await serving(ports)
            up = time.perf_counter() - launched
            clock = await coupler_run(ring_ssd(work, ports), sizes.scale_steps, work / "out")
            first_step[str(n)] = round(clock.first - clock.begun, 3) if clock.first else -1
            if n == 100:
                rss = [rss_mb(p.pid) for p in started]
                extra["scale_100"] = {
                    "steps_per_s": round(clock.rate, 1),
                    "participants_up_s": round(up, 1),
                    "participant_rss_mb_median": round(median_of(rss), 1),
                    "participant_rss_mb_max": round(max(rss), 1),
                }
                rows.append(
                    Row("remote x100 (completes)", clock.rate, note=f"{n} processes, "
                        f"{median_of(rss):.0f} MB RSS each (median)")
                )  # fmt: skip
    extra["time_to_first_step_s"] = first_step


async def frames(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log("camera frames through the bridge at 5 Hz simulated vs raw grpc.aio streams (UDS)")
    [mock] = free_ports(1)
    folder = Path(tempfile.mkdtemp(prefix="cb-", dir="/tmp"))  # a socket path has 107 bytes
    bridge, sink = folder / "bridge.sock", folder / "map.sock"
    raw_out, raw_in = f"unix:{folder / 'raw-out.sock'}", f"unix:{folder / 'raw-in.sock'}"
    raw = [[sys.executable, __file__, "--raw-server", raw_out, "--frames", "out"],
           [sys.executable, __file__, "--raw-server", raw_in, "--frames", "in"]]  # fmt: skip
    names = ("OpenRails mock", "bridge", "map server", "orchestrator")
    cpu = dict.fromkeys(names, 0.0)  # CPU seconds of each process during the Coupler runs
    with processes(frame_services(work, mock, bridge, sink) + raw) as started:
        await serving([f"unix://{bridge}", f"unix://{sink}"])
        ssd = frames_ssd(work, f"unix://{bridge}", f"unix://{sink}")

        def spent() -> list[float]:
            return [*(cpu_s(p.pid) for p in started[:3]), time.process_time()]

        async def through_bridge() -> float:
            before = spent()
            rate = await coupler_frames(ssd, sizes.frame_steps, work / "out")
            for name, was, now in zip(names, before, spent(), strict=True):
                cpu[name] += now - was
            return rate

        async def frames_floor() -> float:
            return await raw_frames(raw_out, raw_in, sizes.frame_steps)

        coupler_fps, floor_fps = await interleaved(sizes.repeats, through_bridge, frames_floor)
    await asyncio.to_thread(shutil.rmtree, folder, True)  # the raw servers leave their sockets
    assert coupler_fps is not None and floor_fps is not None
    megabytes = 2 * FRAME_BYTES / 1e6  # into the orchestrator and out again, each step
    extra["frames_mb_per_s"] = {
        "coupler": round(coupler_fps * megabytes, 1),
        "raw_grpc": round(floor_fps * megabytes, 1),
    }
    per_step = {n: round(1000 * s / (sizes.repeats * sizes.frame_steps), 2) for n, s in cpu.items()}
    extra["frames_cpu_ms_per_step"] = per_step
    log("  CPU per step [ms]: " + ", ".join(f"{n} {ms:.2f}" for n, ms in per_step.items()))
    rows.append(
        Row("camera frames x1 (1.44 MB, 5 Hz)", coupler_fps, "raw grpc.aio streams (UDS)",
            floor_fps, 0.8,
            note=f"{coupler_fps * megabytes:.0f} vs {floor_fps * megabytes:.0f} MB/s, the same "
                 f"bytes; the coupler figure includes the bridge's HTTP hops to OpenRails")
    )  # fmt: skip


async def memory(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log(f"memory: orchestrator RSS at 1e4 and {sizes.rss_steps:.0e} steps (remote x1)")
    [port] = free_ports(1)
    with processes(gains([port])):
        await serving([port])
        probe = await asyncio.to_thread(
            subprocess.run,
            [sys.executable, __file__, "--rss-probe", str(port), str(sizes.rss_steps)],
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
        )
    samples = json.loads(probe.stdout.strip().splitlines()[-1])
    early, late = samples["10000"], samples[str(sizes.rss_steps)]
    extra["orchestrator_rss_mb"] = samples
    rows.append(
        Row(
            "orchestrator RSS 1e4 -> 1e5 steps",
            late,
            "RSS at 1e4 steps",
            early,
            note="MB, not steps/s; target: within 5 %",
        )
    )
    log("memory: peak RSS replaying 10 steps of a 160 MB recording")
    recording = await asyncio.to_thread(big_recording, work / "Big.crec", 160)
    size_mb = recording.stat().st_size / 1e6
    probe = await asyncio.to_thread(
        subprocess.run,
        [sys.executable, __file__, "--replay-probe", str(recording), "10"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    replay = json.loads(probe.stdout.strip().splitlines()[-1])
    extra["replay_rss_mb"] = replay | {"recording_mb": round(size_mb, 1)}
    rows.append(
        Row(
            "replay RSS, 160 MB recording",
            replay["peak_mb"],
            "RSS before opening it",
            replay["before_mb"],
            note=f"MB, not steps/s; target: < 32 MB more (the file: {size_mb:.0f} MB)",
        )
    )


RAILML = ROOT / "scenarios" / "railway" / "data" / "annaberg-schwarzenberg.railml"
OPENRAILS_STEP_S = 0.2
"""OpenRails' lockstep step: the time a frame pair may take."""


# ----------------------------------- the participant side; many participants (#31 targets 3, 4)


async def participant_side(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """remote x1 against a bare grpc.aio bidi stream of empty messages: what the participant
    runtime's own per-step work (decoding, the adapter, encoding) costs."""
    log("remote x1 against a bare grpc.aio stream of empty messages")
    port, raw_port = free_ports(2)
    raw = [sys.executable, __file__, "--raw-server", str(raw_port), "--frames", "minimal"]
    with processes([*gains([port]), raw]):
        await serving([port])  # the raw server: channel_ready in raw_floor
        ssd = ring_ssd(work, [port])
        steps = sizes.remote_steps

        async def coupler_remote() -> float:
            return (await coupler_run(ssd, steps, work / "out")).rate

        async def bare() -> float:
            return await raw_floor([raw_port], steps, stream=True, messages="minimal")

        coupler, floor = await interleaved(sizes.repeats, coupler_remote, bare)
    assert coupler is not None and floor is not None
    rows.append(Row("remote x1", coupler, "bare grpc.aio stream, empty", floor, 0.85))


MANY = 100
"""Participants of the ``many`` section."""
PER_HOST = 25
"""Participants one process of the ``many`` section serves."""
MANY_UP_TARGET = 10.0
"""All of ``MANY`` participants up (launched, serving, the run at its first step) within [s]."""


def gain_host(ports: Sequence[int]) -> None:
    """Gain participants on ``ports``, in this one process, each its own server: the example
    program's participant (``coupler.examples.gain``) in the participant runtime
    (``coupler.server.ParticipantServer``, on uvloop as ``serve`` runs it); prints ``ready``
    once all serve, stops on SIGTERM."""
    import signal

    from coupler.examples.gain import GainParticipant
    from coupler.server import ParticipantServer, run

    async def host() -> None:
        servers = [ParticipantServer(GainParticipant(f"Gain{p}"), port=p) for p in ports]
        stop = asyncio.Event()
        asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
        await asyncio.gather(*(server.start() for server in servers))
        print("ready", flush=True)
        await stop.wait()
        await asyncio.gather(*(server.stop(0) for server in servers))

    run(host())


async def many(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """MANY gain participants, PER_HOST to a process, stepped in lockstep by one run, against
    MANY bare grpc.aio streams to trivial servers grouped the same way; and the time from
    launching the participants' processes to the run's first communication point."""
    log(f"{MANY} participants, {PER_HOST} to a process, against {MANY} bare grpc.aio streams")
    ports, raw_ports = free_ports(MANY), free_ports(MANY)

    def hosts(option: str, group: Sequence[int]) -> list[str]:
        return [sys.executable, __file__, option, ",".join(str(p) for p in group)]

    groups = [range(k, min(k + PER_HOST, MANY)) for k in range(0, MANY, PER_HOST)]
    gain_hosts = [hosts("--gain-host", [ports[k] for k in g]) for g in groups]
    raw_hosts = [hosts("--raw-server", [raw_ports[k] for k in g]) for g in groups]
    launched = time.perf_counter()
    started = _start_hosts(gain_hosts, work)
    with contextlib.ExitStack() as stack:
        for process in started:
            stack.callback(_end, process)
        for k, process in enumerate(started):
            assert process.stdout is not None
            line = await asyncio.to_thread(process.stdout.readline)
            if line.strip() != b"ready":
                why = (work / f"host-{k}.err").read_text()[-2000:]
                raise RuntimeError(f"a participant host did not start: {process.args}: {why}")
        log(f"  {MANY} participants serving after {time.perf_counter() - launched:.1f} s")
        await serving(ports)  # every one answers its health check: SERVING
        serving_s = time.perf_counter() - launched
        log(f"  ... and answering health checks after {serving_s:.1f} s")
        ssd = ring_ssd(work, ports, name="many")
        steps = max(300, sizes.scale_steps)
        first = await coupler_run(ssd, steps, work / "out")
        assert first.first is not None
        up_s = serving_s + (first.first - first.begun)
        stack.enter_context(processes(raw_hosts))  # started once the participants are up

        async def coupler_many() -> float:
            return (await coupler_run(ssd, steps, work / "out")).rate

        async def bare() -> float:
            return await raw_floor(raw_ports, steps, stream=True)

        coupler, floor = await interleaved(sizes.repeats, coupler_many, bare)
    assert coupler is not None and floor is not None
    rows.append(
        Row(f"remote x{MANY}", coupler, f"raw grpc.aio stream x{MANY}", floor, 0.8,
            note=f"{PER_HOST} participants to a process")
    )  # fmt: skip
    extra["many"] = {
        "participants": MANY,
        "per_process": PER_HOST,
        "serving_s": round(serving_s, 2),
        "up_s": round(up_s, 2),
        "target_s": MANY_UP_TARGET,
        "verdict": "PASS" if up_s < MANY_UP_TARGET else "FAIL",
    }


def _start_hosts(commands: Sequence[Sequence[str]], work: Path) -> list[subprocess.Popen[bytes]]:
    """Processes whose stdout is read (a line when ready), stderr in ``work/host-K.err``."""
    started = []
    for k, command in enumerate(commands):
        with (work / f"host-{k}.err").open("wb") as errors:
            started.append(
                subprocess.Popen(command, stdout=subprocess.PIPE, stderr=errors, cwd=ROOT)
            )
    return started


def _end(process: subprocess.Popen[bytes]) -> None:
    process.terminate()
    try:
        process.wait(10)
    except subprocess.TimeoutExpired:
        process.kill()


def many_line(figures: dict[str, Any]) -> str:
    """The ``many`` section's start-up figure, its target and verdict."""
    return (
        f"{figures['participants']} participants ({figures['per_process']} to a process) up in "
        f"{figures['up_s']:.1f} s (launched -> all serving {figures['serving_s']:.1f} s -> the "
        f"run's first step), target < {figures['target_s']:g} s: {figures['verdict']}"
    )


async def render(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The OpenRails mock's renderer on one core (this process's CPU time): an 800 x 600 frame
    in the clear scene and with every condition on against the targets of issue 44 (25 and
    40 ms median), every condition against one OpenRails step (issue 38: 200 ms, worst
    frame), what each condition costs alone, and a frame pair with depth as the mock serves
    them."""
    log("render: the mock's 800 x 600 frames, clear and with every condition, one core")
    times = render_times(
        sizes.render_positions, {"clear": {}, "every": EVERY_CONDITION, **CONDITIONS_ALONE}
    )
    clear, everything = times["clear"], times["every"]
    costs = {  # the median of the differences at the same places, rendered in turns
        name: round(median_of([a - b for a, b in zip(times[name], clear, strict=True)]), 1)
        for name in CONDITIONS_ALONE
    }
    extra["render_ms"] = {
        "clear": {"median": round(median_of(clear), 1), "max": round(max(clear), 1)},
        "every condition": {"median": round(median_of(everything), 1),
                            "max": round(max(everything), 1)},
        "cost of each condition alone": costs,
    }  # fmt: skip
    log("  cost of each condition alone [ms over clear]: "
        + ", ".join(f"{n} {ms:+.1f}" for n, ms in costs.items()))  # fmt: skip
    rows.append(
        Row("render 800x600 rgb, clear", 1000 / median_of(clear), "the 25 ms target", 40.0, 1.0,
            note=f"frames/s; {median_of(clear):.1f} ms median, {max(clear):.0f} ms worst")
    )  # fmt: skip
    rows.append(
        Row("render 800x600 rgb, every condition", 1000 / median_of(everything),
            "the 40 ms target", 25.0, 1.0,
            note=f"frames/s; {median_of(everything):.1f} ms median, {max(everything):.0f} ms "
                 "worst: sun and shadows, trees, roofs, snow, rain, fog, dirt, leaves, noise, "
                 "motion blur, auto-exposure, JPEG")
    )  # fmt: skip
    rows.append(
        Row("render every condition, worst frame", 1000 / max(everything),
            "one OpenRails step (200 ms)", 1.0 / OPENRAILS_STEP_S, 1.0,
            note="frames/s of the slowest frame")
    )  # fmt: skip
    pairs, typical, worst = render_rate(sizes.render_positions)
    extra["render_pair_ms"] = {"median": round(typical, 1), "max": round(worst, 1)}
    rows.append(
        Row("render 800x600 rgb + 200x150 depth", pairs, "one OpenRails step (200 ms)",
            1.0 / OPENRAILS_STEP_S, 1.0,
            note=f"frame pairs/s; {typical:.0f} ms median, {worst:.0f} ms worst, one core")
    )  # fmt: skip


async def perception(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The railway perception run end to end, unpaced, as ``coupler fleet`` runs it
    (perception_run.py), in clear weather and under every condition: its speed against real
    time (targets 10x and 5x), and against its floor, the same frames rendered alone on one
    core (target 0.8); the time around the run (services up, route loaded, stopped)."""
    import perception_run

    cases = {"clear": ({}, {}), "every condition": (
        perception_run.EVERY_CONDITION_PARAMETERS, EVERY_CONDITION)}  # fmt: skip
    if sizes.repeats == 1:  # the smoke run: that it runs
        cases = {"clear": cases["clear"]}
    figures: dict[str, Any] = {}
    for name, (parameters, conditions) in cases.items():
        log(f"perception run, {name}: {sizes.perception_stop_s:g} s of the line")
        ran = await asyncio.to_thread(
            perception_run.run, work, sizes.perception_stop_s, parameters, free_ports(7)
        )
        floor_s = await asyncio.to_thread(
            perception_run.render_floor_s, ran.steps, conditions, sizes.render_positions
        )
        floor = ran.stop_s / floor_s
        figures[name] = {"frames": ran.steps, "stepping_s": round(ran.stepping_s, 2),
                         "render_alone_s": round(floor_s, 2),
                         "around_the_run_s": round(ran.overhead_s, 1)}  # fmt: skip
        target = 10.0 if name == "clear" else 5.0
        rows.append(
            Row(f"perception run, {name}", ran.speed, "real time", 1.0, target,
                note=f"x real time: {sizes.perception_stop_s:g} s of the line, {ran.steps} "
                     f"frames in {ran.stepping_s:.1f} s; {ran.overhead_s:.0f} s around the run")
        )  # fmt: skip
        rows.append(
            Row(f"perception run, {name}", ran.speed, "its frames rendered alone", floor, 0.8,
                note=f"the renderer alone on one core: {floor_s:.1f} s, {floor:.1f}x real time")
        )  # fmt: skip
    extra["perception_run"] = figures


async def perception_campaign(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """A campaign of short perception runs on a local Dask cluster of two workers, services
    kept between a worker's runs: the time a run costs around its stepping (target 3 s)."""
    import perception_run

    runs = 2 if sizes.repeats == 1 else 12
    log(f"perception campaign: {runs} runs of 4 s of the line, 2 Dask workers")
    done = await asyncio.to_thread(perception_run.campaign, work, runs, 4.0)
    extra["perception_campaign"] = {"runs": done.runs, "wall_s": round(done.wall_s, 1),
                                    "stepping_s": round(done.stepping_s, 1),
                                    "around_a_run_s": round(done.around_a_run_s, 2)}  # fmt: skip
    rows.append(
        Row("perception campaign, time around a run", 1.0 / done.around_a_run_s,
            "the 3 s target", 1.0 / 3.0, 1.0,
            note=f"runs/s of it: {done.around_a_run_s:.1f} s a run besides its stepping; "
                 f"{done.runs} runs in {done.wall_s:.0f} s, cluster start included")
    )  # fmt: skip


EVERY_CONDITION: dict[str, Any] = {
    "light": "sun", "season": "winter", "weather": "snow", "rain_mm_per_h": 2.0,
    "visibility_m": 300.0, "dirt": 0.5, "leaves_per_m2": 0.3, "trees_per_km": 40.0,
    "platform_roofs": True, "noise": True, "motion_blur": True, "jpeg_quality": 80,
}  # fmt: skip
"""Every condition of the mock's renderer at once (issue 38's budget row)."""
CONDITIONS_ALONE: dict[str, dict[str, Any]] = {
    "sun, shadows, headlights, auto-exposure": {"light": "sun"},
    "trees (40/km) and platform roofs": {"trees_per_km": 40.0, "platform_roofs": True},
    "fog (300 m)": {"visibility_m": 300.0},
    "rain (4 mm/h)": {"weather": "rain"},
    "snowfall and snow cover": {"season": "winter", "weather": "snow"},
    "dirt and leaves": {"dirt": 0.5, "leaves_per_m2": 0.3},
    "sensor noise": {"noise": True},
    "motion blur": {"motion_blur": True, "exposure_ms": 4.0, "gain": 0.25},
    "JPEG (quality 80)": {"jpeg_quality": 80},
}
"""What each condition costs, alone."""


def render_times(positions: int, cases: dict[str, dict[str, Any]]) -> dict[str, list[float]]:
    """Milliseconds of this process's CPU time per 800 x 600 colour frame under each case's
    conditions at ``positions`` places 250 m apart on the Annaberg-Schwarzenberg line (at
    16 m/s, 15:00), the cases rendered in turns at each place (a busy moment hits them
    alike)."""
    from coupler_railway import load_infrastructure
    from openrails_mock.conditions import Conditions
    from openrails_mock.renderer import CameraModel, Renderer, View
    from openrails_mock.scene import Scene

    scene = Scene.of_infrastructure(load_infrastructure(RAILML))
    renderers = {
        name: Renderer(scene, conditions=Conditions(**conditions))
        for name, conditions in cases.items()
    }
    rgb = CameraModel(width=800, height=600, fov_deg=45.0)
    for renderer in renderers.values():  # compile or load the kernels
        renderer.render(rgb, 100.0, View(speed_mps=16.0))
    took: dict[str, list[float]] = {name: [] for name in cases}
    for k in range(positions):
        view = View(elapsed_s=10.0 * k, clock_s=15 * 3600.0 + 10.0 * k, speed_mps=16.0)
        for name, renderer in renderers.items():
            begun = time.process_time()
            renderer.render(rgb, 60.0 + 250.0 * k, view).pixels.tobytes()
            took[name].append(1000 * (time.process_time() - begun))
    return took


from frameworks import frameworks  # noqa: E402  (benchmarks/frameworks.py)

SECTIONS = (
    cli_start,
    watched_run,
    chains,
    tight_loop,
    openmcx,
    remotes,
    sockets,
    participant_side,
    proxy_fmu,
    scale,
    many,
    frames,
    render,
    perception,
    frameworks,
    perception_campaign,
    memory,
)
"""The suite's sections, in the order they run (``--sections`` picks some)."""


def render_rate(positions: int) -> tuple[float, float, float]:
    """Frame pairs per second of one core (800 x 600 RGB + 200 x 150 depth, as the mock serves
    them) over ``positions`` places 250 m apart, and the median and worst milliseconds of a
    pair: this process's CPU time, so that other work on a busy machine does not count."""
    from coupler_railway import load_infrastructure
    from openrails_mock.renderer import CameraModel, Renderer
    from openrails_mock.scene import Scene

    renderer = Renderer(Scene.of_infrastructure(load_infrastructure(RAILML)))
    rgb = CameraModel(width=800, height=600, fov_deg=45.0)
    depth = CameraModel(width=200, height=150, fov_deg=45.0)
    renderer.rgb(rgb, 100.0), renderer.depth(depth, 100.0, 200.0)  # warm the caches
    took = []
    for k in range(positions):
        at = 60.0 + 250.0 * k
        begun = time.process_time()
        renderer.rgb(rgb, at).tobytes()
        renderer.depth(depth, at, 200.0).astype("<u2").tobytes()
        took.append(time.process_time() - begun)
    return 1.0 / median_of(took), 1000 * median_of(took), 1000 * max(took)


async def only(case: str, steps: int) -> float:
    with tempfile.TemporaryDirectory(prefix="coupler-bench-") as folder:
        work = Path(folder)
        n = int(case.removeprefix("chain").removeprefix("remote"))
        if case.startswith("chain"):
            return (await coupler_run(chain_ssd(work, n), steps, work / "out")).rate
        ports = free_ports(n)
        with processes(gains(ports)):
            await serving(ports)
            return (await coupler_run(ring_ssd(work, ports), steps, work / "out")).rate


def rss_verdict(row: Row) -> str:
    assert row.reference_rate
    if row.case.startswith("replay RSS"):
        return "PASS" if row.coupler - row.reference_rate < 32 else "FAIL"
    return "PASS" if abs(row.coupler / row.reference_rate - 1) <= 0.05 else "FAIL"


def _memory_row(row: Row) -> bool:
    return row.case.startswith(("orchestrator RSS", "replay RSS"))


def table(rows: Sequence[Row]) -> str:
    lines = [
        f"{'case':<34} {'Coupler':>10} {'reference':<26} {'reference':>10} {'ratio':>7} "
        f"{'target':>7}  verdict",
        "-" * 110,
    ]
    for row in rows:
        ratio = f"{row.ratio:.2f}" if row.ratio is not None else ""
        target = f">={row.target:g}" if row.target is not None else ""
        verdict = rss_verdict(row) if _memory_row(row) else row.verdict
        if row.case.startswith("orchestrator RSS"):
            target = "1+-0.05"
        elif row.case.startswith("replay RSS"):
            target = "+32 MB"
        reference = f"{row.reference_rate:,.0f}" if row.reference_rate else ""
        figure = f"{row.coupler:.3f}" if row.case == "coupler --help" else f"{row.coupler:,.1f}"
        lines.append(
            f"{row.case:<34} {figure:>10} {row.reference:<26} {reference:>10} "
            f"{ratio:>7} {target:>7}  {verdict}{'  (' + row.note + ')' if row.note else ''}"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="more steps and repetitions")
    parser.add_argument(
        "--smoke",
        action="store_true",
        help="every section with the fewest steps: checks that the suite runs, measures nothing",
    )
    parser.add_argument("--out", type=Path, default=OUT, help=f"JSON (default {OUT})")
    parser.add_argument(
        "--only",
        metavar="CASE",
        help="run one Coupler case alone and print its steps/s (for a profiler): chainN, "
        "remoteN or render, e.g. py-spy record -o chain10.txt --format raw -- .venv/bin/python "
        "benchmarks/suite.py --only chain10",
    )
    parser.add_argument("--steps", type=int, default=20000, help="steps of --only")
    parser.add_argument(
        "--sections",
        type=lambda text: [t.strip() for t in text.split(",") if t.strip()],
        default=[],
        help="run only these sections, comma-separated: " + ", ".join(s.__name__ for s in SECTIONS),
    )
    parser.add_argument("--raw-server", help=argparse.SUPPRESS)
    parser.add_argument(
        "--frames", choices=["in", "out", "minimal"], default="", help=argparse.SUPPRESS
    )
    parser.add_argument("--gain-host", help=argparse.SUPPRESS)
    parser.add_argument("--rss-probe", nargs=2, type=int, help=argparse.SUPPRESS)
    parser.add_argument("--replay-probe", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    from coupler.logs import configure_logging

    configure_logging("ERROR")
    if args.raw_server:
        asyncio.run(raw_server(args.raw_server, args.frames))
        return 0
    if args.gain_host:
        gain_host([int(p) for p in args.gain_host.split(",")])
        return 0
    unknown = sorted(set(args.sections) - {s.__name__ for s in SECTIONS})
    if unknown:
        parser.error(f"--sections: no section {', '.join(unknown)}")
    if args.rss_probe:
        port, steps = args.rss_probe
        print(json.dumps(asyncio.run(rss_probe(port, steps, 10_000))))
        return 0
    if args.only == "render":
        pairs, typical, worst = render_rate(args.steps if args.steps != 20000 else 20)
        print(f"render: {pairs:.1f} frame pairs/s, {typical:.0f} ms median, {worst:.0f} ms worst")
    if args.replay_probe:
        recording, steps = args.replay_probe
        print(json.dumps(replay_probe(Path(recording), int(steps))))
        return 0
    if args.only:
        print(f"{args.only}: {asyncio.run(only(args.only, args.steps)):,.0f} steps/s")
        return 0
    if not (FMUS / "Feedthrough2.fmu").exists():
        print("error: build/fmus is empty: run make setup (make bench does)", file=sys.stderr)
        return 1
    sizes = SMOKE if args.smoke else FULL if args.full else QUICK
    kind = "smoke: not a measurement" if args.smoke else "full" if args.full else "quick"
    started = time.perf_counter()

    def log(text: str) -> None:
        print(f"[{time.perf_counter() - started:6.1f} s] {text}", file=sys.stderr, flush=True)

    from coupler_orchestrator.master import native_fmu_step as kernel
    from coupler_orchestrator.master import native_step_channel as steps

    channel = "native step channel" if steps.enabled() else "grpc.aio"
    fmu_steps = "in C" if steps.wanted() and kernel.library() is not None else "through Python"
    rows, extra = asyncio.run(suite(sizes, log, args.sections))
    extra["remote_steps"] = channel
    extra["fmu_steps"] = fmu_steps
    print()
    print(
        f"Coupler benchmark ({kind}; steps/s, median of "
        f"{sizes.repeats}, Coupler and reference interleaved in this run; {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; remote steps over the {channel}, in-process FMUs "
        f"stepped {fmu_steps})"
    )
    print(table(rows))
    for sentence in extra.get("skipped", []):
        print(sentence)
    if "many" in extra:
        print(many_line(extra["many"]))
    if "time_to_first_step_s" in extra:
        print(f"time from run start to first step [s]: {extra['time_to_first_step_s']}")
        print(f"100 participants: {extra['scale_100']}")
    print(f"took {time.perf_counter() - started:.0f} s")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "mode": "full" if args.full else "quick",
                "rows": [asdict(r) | {"ratio": r.ratio, "verdict": r.verdict} for r in rows],
                **extra,
            },
            indent=2,
        )
    )
    print(f"written: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
