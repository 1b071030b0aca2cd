"""``coupler run``: run a scenario and record results."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import functools
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from coupler import durations
from coupler_orchestrator.cli.exits import EXIT_ERROR, EXIT_OK
from coupler_orchestrator.cli.parser import (
    MIN_REALTIME_FACTOR,
    options_of,
    out_options,
    realtime_factor,
    record_options,
    run_options,
    scenario_argument,
)
from coupler_orchestrator.cli.session import Session

if TYPE_CHECKING:
    from coupler_orchestrator.cli.supervisor import Beacon
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.outputs.monitor import MonitorServer
    from coupler_orchestrator.runner import RunOutcome

HELP = "run a scenario and record results"


def arguments(run: argparse.ArgumentParser) -> None:
    scenario_argument(run)
    run_options(run)
    run.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="also print how each participant stepped (native FMU step, native step channel "
        "or Python) and why; summary.json records it either way",
    )
    run.add_argument(
        "--output-interval",
        type=float,
        metavar="S",
        help="record every communication point that is a multiple of S past the start "
        "(default: every one)",
    )
    run.add_argument(
        "--output-variables",
        action="append",
        default=[],
        metavar="NAME[,NAME...]",
        help="record only these outputs: Component.output names or globs, comma-separated "
        "(--output-variables 'Gain.*,Integrator.x'; repeatable)",
    )
    run.add_argument(
        "--parquet",
        action="store_true",
        help="also write results.parquet, typed columns (needs the pyarrow package)",
    )
    run.add_argument(
        "--openmcx-results",
        action="store_true",
        help="also write OpenMCx's result files, <Component>_res.csv and <Component>_in.csv "
        "(implies --openmcx)",
    )
    out_options(run)
    record_options(run)
    run.add_argument(
        "--realtime-factor",
        type=realtime_factor,
        help="pace at X times real time (0: as fast as possible; at least "
        f"{MIN_REALTIME_FACTOR:g})",
    )
    run.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress (default: a bar on a terminal, else a line every 10 s on stderr)",
    )
    run.add_argument(
        "--monitor",
        metavar="[HOST:]PORT",
        help="serve a live page of the run (status, real-time factor, step latency, channel "
        "charts) on HOST:PORT (default host 127.0.0.1; port 0: any free port)",
    )
    run.add_argument(
        "--monitor-linger",
        type=durations.argument(durations.MAX_TIMEOUT, zero=True),
        default=0.0,
        metavar="S",
        help="keep the monitor page up S seconds after the run ends (default 0)",
    )


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    return await run(args, replace(options_of(args), on_waiting=session.waiting), out, session)


def _results_in(session: Session, watched: Beacon | None, directory: Path) -> None:
    """Where the run writes: the session (its messages) and a watching parent (a crash's
    summary) are told before any participant starts."""
    session.results_in(directory)
    if watched is not None:
        watched.results(directory)


async def run(args: argparse.Namespace, options: RunOptions, out: TextIO, session: Session) -> int:
    """Run with a progress display and, when asked, the monitor page; say how it ended."""
    from coupler_orchestrator.cli.supervisor import beacon
    from coupler_orchestrator.observer import Observer
    from coupler_orchestrator.outputs.monitor import MonitorServer
    from coupler_orchestrator.outputs.progress import ProgressBar, ProgressLines
    from coupler_orchestrator.runner import run_scenario

    observers: list[Observer] = [session]
    watched = beacon()
    if watched is not None:  # the parent process says what a crash of this one left
        observers.append(watched)
        options = dataclasses.replace(options, progress=watched.progress)
    if not args.no_progress:
        observers.append(ProgressBar() if sys.stderr.isatty() else ProgressLines())
    async with contextlib.AsyncExitStack() as stack:
        if args.monitor is not None and session.monitor is None:
            monitor = await stack.enter_async_context(MonitorServer(args.monitor))
            print(f"monitor: {monitor.url}", file=out, flush=True)
            stack.push_async_callback(_linger, monitor, args.monitor_linger, out)
            session.monitor = monitor
        if session.monitor is not None:
            observers.append(session.monitor.state)
        outcome = await run_scenario(
            args.ssp,
            options,
            out_dir=args.out,
            base=getattr(args, "results_base", None),
            replace=args.force,
            observers=observers,
            on_results=functools.partial(_results_in, session, watched),
        )
        return _said(outcome, args, out)  # when the run ends: before the monitor lingers


def _said(outcome: RunOutcome, args: argparse.Namespace, out: TextIO) -> int:
    """How the run ended and where its results are; the exit code."""
    end = outcome.end
    print(
        f"{end.status}: {end.steps} steps to t={end.end_time:g} s in {end.wall_time:.3g} s",
        file=out,
    )
    print(f"results: {outcome.results_csv}", file=out)
    print(f"summary: {outcome.summary_json}", file=out)
    if getattr(args, "verbose", False):
        for name, stepped in end.step_paths.items():
            print(f"stepped: {name}: {stepped.path} ({stepped.reason})", file=out)
        print(f"results.csv rows made {outcome.summary.get('results_rows')}", file=out)
    for recording in outcome.recordings:
        print(f"recording: {recording}", file=out)
    if outcome.openmcx_files:
        names = ", ".join(p.name for p in outcome.openmcx_files)
        print(f"openmcx results: {names} in {outcome.openmcx_files[0].parent}", file=out)
    if end.status == "terminated":
        print(f"terminated early: {end.reason}", file=out, flush=True)
        return EXIT_OK
    if end.status != "completed":
        print(f"error: run {end.status}: {end.reason}", file=sys.stderr, flush=True)
        return EXIT_ERROR
    out.flush()
    return EXIT_OK


async def _linger(monitor: MonitorServer, seconds: float, out: TextIO) -> None:
    import asyncio

    if seconds > 0:
        print(f"monitor: {monitor.url} stays up {seconds:g} s", file=out, flush=True)
        await asyncio.sleep(seconds)
