"""Memory: the orchestrator's RSS after 1e4 and after 1e5 steps of remote x1 (its own process,
``suite.py --rss-probe``); the peak RSS of replaying 10 steps of a 160 MB recording (its own
process, ``suite.py --replay-probe``) against its RSS before it opened the recording (a replay
holds one block, not the file).
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sections.common import (
    ROOT,
    STEP,
    SUITE,
    Row,
    Sizes,
    free_ports,
    gains,
    processes,
    ring_ssd,
    rss_mb,
    serving,
)


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


async def memory(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    log(f"memory: orchestrator RSS at 1e4 and {sizes.rss_steps:.0e} steps (remote x1)")
    [port] = free_ports(1)
    with processes(gains([port])):
        await serving([port])
        probe = await asyncio.to_thread(
            subprocess.run,
            [sys.executable, SUITE, "--rss-probe", str(port), str(sizes.rss_steps)],
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
        [sys.executable, SUITE, "--replay-probe", str(recording), "10"],
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
