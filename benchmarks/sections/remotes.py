"""Remote participants:

- remote xN: N example gain participants, each its own process, chained y -> u in a ring,
  Jacobi, over the native step channel when it is built (COUPLER_NATIVE_STEPS=0 measures the
  grpc.aio path instead); against raw grpc.aio round trips to N trivial servers and, for
  N = 1, mosaik 3 with one remote simulator over its TCP API (a local source and sink around
  it);
- remote x1 over UDS (section sockets): the gain participant on a unix socket (``--socket``,
  as ``coupler fleet`` serves local participants) against the same over TCP, and against a
  raw grpc.aio StepStream to a trivial server on a unix socket;
- remote x1 against a bare stream (section participant_side): a bare grpc.aio StepStream of
  empty messages to a trivial server (the participant runtime's own work).
"""

from __future__ import annotations

import asyncio
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import (
    SUITE,
    Row,
    Sizes,
    coupler_run,
    free_ports,
    gains,
    interleaved,
    processes,
    ring_ssd,
    serving,
)
from sections.peers import mosaik_rate
from sections.raw import raw_floor


async def remotes(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    for n, target in ((1, 0.8), (3, 0.9), (10, 0.8)):
        log(f"remote x{n}")
        gain_ports, raw_ports = free_ports(n), free_ports(n)
        raw = [[sys.executable, SUITE, "--raw-server", str(p)] for p in raw_ports]
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
    raw = [sys.executable, SUITE, "--raw-server", f"unix:{raw_socket}"]
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


async def participant_side(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """remote x1 against a bare grpc.aio bidi stream of empty messages: what the participant
    runtime's own per-step work (decoding, the adapter, encoding) costs."""
    log("remote x1 against a bare grpc.aio stream of empty messages")
    port, raw_port = free_ports(2)
    raw = [sys.executable, SUITE, "--raw-server", str(raw_port), "--frames", "minimal"]
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
