"""Proxy FMU x1: the gain participant exported by `coupler export-fmu` (FMI 2, its C++ binary
calling the participant over its StepStream) run in-process by Coupler and by a hand-written
FMPy loop, against `coupler run` driving the same participant directly (its stream).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import (
    GAIN_FMI2,
    STEP,
    Row,
    Sizes,
    coupler_run,
    free_ports,
    gains,
    interleaved,
    processes,
    ring_ssd,
    serving,
    write_ssd,
)
from sections.peers import fmpy_slave, free_slave


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
    return write_ssd(folder / "proxy1.ssd", [element], [connection])


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
