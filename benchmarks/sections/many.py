"""Many participants:

- scale: 100 gain participants in one run: steps/s, RSS per participant process, time from
  the run's start to its first step for 1, 10 and 100 participants;
- many: 100 gain participants served PER_HOST to a process (``suite.py --gain-host``), one run
  stepping them in lockstep, against 100 bare grpc.aio streams to trivial servers grouped the
  same way; and the time from launching the processes to the run's first step.
"""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sections.common import (
    ROOT,
    SUITE,
    Row,
    Sizes,
    coupler_run,
    free_ports,
    gains,
    interleaved,
    median_of,
    processes,
    ring_ssd,
    rss_mb,
    serving,
)
from sections.raw import raw_floor


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
        return [sys.executable, SUITE, option, ",".join(str(p) for p in group)]

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
