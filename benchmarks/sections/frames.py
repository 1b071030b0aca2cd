"""Camera frames x1: an 800 x 600 RGB frame (1.44 MB) per 0.2 s step from the OpenRails mock
(a standing train) through the bridge (HTTP GET, its sensor channel) and the orchestrator into
the map server, `coupler run` at 5 Hz simulated, unpaced; against two bare grpc.aio bidi
streams moving the same bytes per step (one frame out of a server, one into another). The
bridge and the map serve gRPC on unix sockets, as `coupler fleet` serves local participants,
and so do the two raw servers (the mock stays on HTTP over TCP, as OpenRails).
"""

from __future__ import annotations

import asyncio
import json
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import (
    SUITE,
    Clock,
    Row,
    Sizes,
    address_of,
    cpu_s,
    free_ports,
    interleaved,
    processes,
    serving,
    write_ssd,
)
from sections.raw import FRAME_BYTES, FRAME_STEP, raw_frames

SENSORS = [{"sensorName": "front", "sensorType": "rgb", "trainName": "PLAYER",
            "width": 800, "height": 600, "fov": 45.0}]  # fmt: skip


def frames_ssd(folder: Path, bridge: int | str, sink: int | str) -> Path:
    """The OpenRails bridge's camera ``front`` into the map server's ``camera`` (each a port
    on loopback or an address, ``address_of``)."""
    image = '<ssc:Binary mime-type="application/x-protobuf; messageType=coupler.v1.Image"/>'
    return write_ssd(
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

    clock = Clock(time.perf_counter())
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


async def frames(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log("camera frames through the bridge at 5 Hz simulated vs raw grpc.aio streams (UDS)")
    [mock] = free_ports(1)
    folder = Path(tempfile.mkdtemp(prefix="cb-", dir="/tmp"))  # a socket path has 107 bytes
    bridge, sink = folder / "bridge.sock", folder / "map.sock"
    raw_out, raw_in = f"unix:{folder / 'raw-out.sock'}", f"unix:{folder / 'raw-in.sock'}"
    raw = [[sys.executable, SUITE, "--raw-server", raw_out, "--frames", "out"],
           [sys.executable, SUITE, "--raw-server", raw_in, "--frames", "in"]]  # fmt: skip
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
