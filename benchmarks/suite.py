"""`make bench`: Coupler against the floors and peers, every figure measured in this one run.

    make bench                  # quick (under 5 min on two cores)
    make bench ARGS=--full      # more steps, 100 participants longer
    suite.py --smoke            # every section with the fewest steps: runs, measures nothing
    suite.py --sections sockets # some sections only

Each section is a module of ``sections/`` whose docstring says what it measures against what
(steps/s, median of the repetitions; Coupler and its reference interleaved); ``SECTIONS`` below
is their order. This driver parses the command line, runs the sections, prints one table with
each ratio, its target and PASS/FAIL, and writes build/bench.json; it also serves the processes
the sections start (``--raw-server``, ``--gain-host``, ``--rss-probe``, ``--replay-probe``).
Not a test: nothing here asserts; the figures go into docs/performance.md.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from sections.chains import chains
from sections.command_line import cli_start, watched_run
from sections.common import (
    FMUS,
    ROOT,
    Row,
    Sizes,
    chain_ssd,
    coupler_run,
    free_ports,
    gains,
    processes,
    ring_ssd,
    serving,
)
from sections.frames import frames
from sections.frameworks import frameworks
from sections.many import gain_host, many, many_line, scale
from sections.memory import memory, replay_probe, rss_probe
from sections.openmcx import openmcx
from sections.perception import perception, perception_campaign
from sections.proxy_fmu import proxy_fmu
from sections.raw import raw_server
from sections.remotes import participant_side, remotes, sockets
from sections.render import render, render_rate
from sections.tight_loop import tight_loop

OUT = ROOT / "build" / "bench.json"


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
    perception_campaign,
    frameworks,
    memory,
)
"""The suite's sections, in the order they run (``--sections`` picks some)."""


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
    from coupler_orchestrator.options import RunOptions

    native = RunOptions().switched().native_steps  # the environment, as a run reads it
    channel = "native step channel" if steps.enabled(native) else "grpc.aio"
    fmu_steps = "in C" if native and kernel.library() is not None else "through Python"
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
