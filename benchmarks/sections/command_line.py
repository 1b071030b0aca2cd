"""The command line: ``coupler --help``'s start (median of five [s]), and the watched run:
`coupler run` of Source2 alone (1e5 steps, its own process, as a user runs it: a parent
watching the run's process for a crash) against the same command run unwatched
(`cli.main.main()` called directly), wall time as steps/s, the median of three times the
suite's repetitions.
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from sections.common import FMUS, STEP, Row, Sizes, interleaved, median_of


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

    # The command is mostly its start (0.65 of its 0.75 s), whose noise is tens of ms: three
    # times the suite's repetitions, so that the median holds still.
    rate, reference = await interleaved(3 * sizes.repeats, timed(watched), timed(unwatched))
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
