"""The ``coupler`` command: run, validate, describe, fleet, campaign, plot, replay, export-fmu.

Exit codes: 0 the run completed (or a participant ended it early: ``terminated``; or Ctrl-C
stopped a fleet's services after its run completed), 1 any problem (bad input, a participant
failing: ``failed``), 2 a wrong command line, 130 interrupted (Ctrl-C or SIGTERM during a run:
``aborted``, the rows so far kept).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

from coupler import durations
from coupler.channels import Description
from coupler.client import RemoteParticipant
from coupler.errors import CouplerError
from coupler.fmu import FmuParticipant
from coupler.logs import configure_logging
from coupler.participant import Participant
from coupler.security import ClientSecurity
from coupler.server import ParticipantServer
from coupler.settings import SecuritySettings, add_security_arguments
from coupler_orchestrator.campaign import (
    CampaignError,
    CampaignProgress,
    CampaignSpec,
    format_table,
    run_campaign,
)
from coupler_orchestrator.export import export_fmu
from coupler_orchestrator.fleet import Fleet, FleetSpec
from coupler_orchestrator.monitor import MonitorServer
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo
from coupler_orchestrator.options import MIN_REALTIME_FACTOR, Algorithm, RunOptions
from coupler_orchestrator.plot import plot
from coupler_orchestrator.progress import ProgressBar, ProgressLines
from coupler_orchestrator.replay import ReplayParticipant
from coupler_orchestrator.runner import run_scenario, validate_scenario
from coupler_orchestrator.watchdog import active as active_watchdog

EXIT_OK, EXIT_ERROR, EXIT_INTERRUPTED = 0, 1, 130
MAX_LEASE, MAX_TIMEOUT = durations.MAX_LEASE, durations.MAX_TIMEOUT
seconds = durations.argument


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="coupler", description="Co-simulation of FMUs and gRPC participants from an SSP file."
    )
    top.add_argument("--log-level", default="WARNING", help="DEBUG, INFO, WARNING (default)")
    top.add_argument(
        "--log-format",
        choices=["auto", "console", "json"],
        default="auto",
        help="log lines for people (console) or machines (json); default: console on a "
        "terminal, else json",
    )
    commands = top.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="run a scenario and record results")
    run.add_argument(
        "ssp", type=Path, help=".ssp archive, unpacked SSP folder, .ssd file or a single .fmu"
    )
    _run_options(run)
    run.add_argument(
        "--output-interval",
        type=float,
        metavar="S",
        help="record every communication point that is a multiple of S past the start "
        "(default: every one)",
    )
    run.add_argument(
        "--output-variables",
        nargs="+",
        default=[],
        metavar="NAME",
        help="record only these outputs: Component.output names or globs (Gain.*)",
    )
    run.add_argument(
        "--parquet",
        action="store_true",
        help="also write results.parquet, typed columns (needs the pyarrow package)",
    )
    run.add_argument(
        "--out",
        type=Path,
        help="results directory (default: the SSD's OpenMCx outputDirectory, else ./results)",
    )
    _record_options(run)
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
        type=seconds(MAX_TIMEOUT, zero=True),
        default=0.0,
        metavar="S",
        help="keep the monitor page up S seconds after the run ends (default 0)",
    )

    validate = commands.add_parser("validate", help="check a scenario and its participants")
    validate.add_argument(
        "ssp", type=Path, help=".ssp archive, unpacked SSP folder, .ssd file or a single .fmu"
    )
    _run_options(validate)
    _replay_option(validate)

    fleet = commands.add_parser(
        "fleet", help="start a scenario's services as local processes, run it, keep them up"
    )
    fleet.add_argument(
        "fleet", type=Path, help="fleet file (TOML), e.g. scenarios/railway/fleet.toml"
    )
    fleet.add_argument("--exit", action="store_true", help="stop the services when the run ends")
    fleet.add_argument("--out", type=Path, help="results directory (default from the fleet file)")
    fleet.add_argument(
        "--realtime-factor",
        type=realtime_factor,
        help="override the fleet file's pacing; 0 = unpaced",
    )
    fleet.add_argument(
        "--health-timeout", type=seconds(MAX_TIMEOUT), default=60.0, help="[s] per service"
    )
    _record_options(fleet)

    campaign = commands.add_parser(
        "campaign",
        help="run a scenario under many variants, in parallel, into one table",
        description="Runs every variant of a campaign file (docs/campaigns.md): here, --jobs at "
        "once, or as tasks of a Dask cluster (--scheduler). Runs that completed before are "
        "skipped unless --force.",
    )
    campaign.add_argument("campaign", type=Path, help="campaign file (TOML)")
    campaign.add_argument("--jobs", type=int, help="runs at once (default: one per core)")
    campaign.add_argument(
        "--scheduler",
        help="tcp://HOST:8786 (a Dask scheduler) or local (a Dask LocalCluster); default: "
        "runs as local processes",
    )
    campaign.add_argument("--force", action="store_true", help="run completed variants again")
    campaign.add_argument("--out", type=Path, help="campaign folder (default: [scenario] out)")

    plot = commands.add_parser(
        "plot",
        help="draw channels of one or more runs into a PNG or a self-contained HTML page",
        description="RESULTS are results directories or results.csv files (several are "
        "overlaid); CHANNELS are names or globs (default: every numeric channel).",
    )
    plot.add_argument("inputs", nargs="+", metavar="RESULTS|CHANNEL", help="runs, then channels")
    plot.add_argument("-o", "--output", type=Path, required=True, help="FILE.png or FILE.html")
    plot.add_argument("--title", default="", help="default: the runs' directories")

    replay = commands.add_parser(
        "replay", help="serve a recording (coupler run --record) as a gRPC participant"
    )
    replay.add_argument("recording", type=Path, help="a .crec file or a results directory")
    replay.add_argument(
        "--component", help="the recorded component (default: the file's; needed for a directory)"
    )
    replay.add_argument("--host", default="127.0.0.1", help="bind address (default: 127.0.0.1)")
    replay.add_argument("--port", type=int, default=0, help="gRPC port (default: any free one)")
    add_security_arguments(replay)

    export = commands.add_parser(
        "export-fmu",
        help="write an FMU (FMI 2.0/3.0 co-simulation) that drives a running participant, for "
        "any FMI tool (docs/export-fmu.md)",
    )
    export.add_argument("address", help="the participant: grpc://HOST:PORT or grpcs://HOST:PORT")
    export.add_argument("--out", type=Path, required=True, help="NAME.fmu to write")
    export.add_argument(
        "--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2)"
    )
    export.add_argument(
        "--call-timeout",
        type=seconds(MAX_TIMEOUT),
        default=30.0,
        help="[s] deadline of every call the FMU makes to the participant (default 30)",
    )
    export.add_argument(
        "--timeout", type=seconds(MAX_TIMEOUT), default=10.0, help="connect timeout [s]"
    )
    _security_options(export)

    describe = commands.add_parser("describe", help="print a participant's channels")
    describe.add_argument("target", help="grpc://HOST:PORT, grpcs://HOST:PORT or an .fmu file")
    describe.add_argument(
        "--timeout", type=seconds(MAX_TIMEOUT), default=10.0, help="connect timeout [s]"
    )
    _security_options(describe)
    return top


def _run_options(command: argparse.ArgumentParser) -> None:
    command.add_argument("--start-time", type=float, help="start time [s]")
    command.add_argument("--stop-time", type=float, help="stop time [s]")
    command.add_argument("--step", type=float, help="base communication step [s]")
    command.add_argument(
        "--algorithm",
        choices=[a.value for a in Algorithm],
        help="master algorithm (default: the SSD's OpenMCx stepType, sequential = "
        "gauss-seidel, else jacobi)",
    )
    command.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="COMPONENT.NAME=VALUE",
        help="override a parameter or input start value (repeatable; a single FMU's "
        "parameters may be given as NAME=VALUE)",
    )
    command.add_argument("--run-id", help="run id sent to participants (default: a random UUID)")
    command.add_argument(
        "--lease",
        type=seconds(MAX_LEASE),
        help="[s] a participant ends the run after this long without a call (default: the "
        "larger of 60 s and 4 call deadlines; at most 86400 = 24 h)",
    )
    command.add_argument(
        "--connect-timeout",
        type=seconds(MAX_TIMEOUT),
        default=10.0,
        help="[s] how long a participant may take to report SERVING (default 10)",
    )
    command.add_argument(
        "--call-timeout",
        type=seconds(MAX_TIMEOUT),
        default=30.0,
        help="[s] deadline of every call to a participant (default 30; at most 86400 = 24 h)",
    )
    command.add_argument(
        "--unpack-limit",
        type=int,
        default=2048,
        metavar="MB",
        help="what an .ssp and the FMUs it runs may unpack to, together (default 2048 MB)",
    )
    command.add_argument(
        "--isolate-fmus",
        action="store_true",
        help="run every FMU in a child process: a crash or hang of an FMU fails the run "
        "cleanly instead of the orchestrator (per component: SSD annotation "
        "org.coupler.component isolate)",
    )
    command.add_argument(
        "--no-native-steps",
        dest="native_steps",
        action="store_false",
        help="step everything through Python: remote participants over grpc.aio instead of the "
        "native step channel (used when the C++ gRPC tool chain is installed), in-process FMUs "
        "one ctypes call at a time instead of the native FMU step (C, built with gcc); the "
        "same results either way (also COUPLER_NATIVE_STEPS=0)",
    )
    _security_options(command)


def realtime_factor(text: str) -> float:
    """An argparse type: 0 (as fast as possible) or at least MIN_REALTIME_FACTOR, finite."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    if value != 0 and not value >= MIN_REALTIME_FACTOR:
        raise argparse.ArgumentTypeError(
            f"must be 0 (as fast as possible) or at least {MIN_REALTIME_FACTOR:g} (one "
            f"simulated second per {1 / MIN_REALTIME_FACTOR:g} s), got {text}"
        )
    return value


def _record_options(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--record",
        action="append",
        default=[],
        metavar="COMPONENT[,...]",
        help="record every output of these components at each of their communication points "
        "into OUT/recordings/COMPONENT.crec, for replay (docs/replay.md)",
    )
    _replay_option(command)


def _replay_option(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--replay",
        action="append",
        default=[],
        metavar="COMPONENT=RECORDING",
        help="serve COMPONENT from a recording (a .crec file or a results directory) instead "
        "of its participant (repeatable)",
    )


def _security_options(command: argparse.ArgumentParser) -> None:
    group = command.add_argument_group(
        "security of grpcs:// participants (default: COUPLER_TLS_CA, COUPLER_TLS_CERT, "
        "COUPLER_TLS_KEY, COUPLER_TOKEN_FILE; docs/security.md)"
    )
    group.add_argument("--tls-ca", type=Path, help="CA bundle (PEM) trusted for participants")
    group.add_argument("--tls-cert", type=Path, help="client certificate (PEM), mutual TLS")
    group.add_argument("--tls-key", type=Path, help="its private key (PEM)")
    group.add_argument("--token-file", type=Path, help="bearer token sent with every call")


def security_of(args: argparse.Namespace) -> ClientSecurity:
    """The environment's client security with the command line's options on top."""
    return ClientSecurity.from_environment().override(
        ClientSecurity(
            ca=args.tls_ca, cert=args.tls_cert, key=args.tls_key, token_file=args.token_file
        )
    )


def options_of(args: argparse.Namespace) -> RunOptions:
    parameters = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise CouplerError(f"--param {item!r}: write COMPONENT.NAME=VALUE")
        parameters[key] = value
    return RunOptions(
        start_time=args.start_time,
        stop_time=args.stop_time,
        step_size=args.step,
        algorithm=Algorithm(args.algorithm) if args.algorithm else None,
        realtime_factor=getattr(args, "realtime_factor", None) or None,
        parameters=parameters,
        connect_timeout=args.connect_timeout,
        call_timeout=args.call_timeout,
        isolate_fmus=args.isolate_fmus,
        native_steps=args.native_steps,
        unpack_limit=args.unpack_limit * 1024 * 1024,
        lease=args.lease,
        security=security_of(args),
        exit_when_stuck=True,  # a hung in-process FMU cannot be left any other way
        output_interval=getattr(args, "output_interval", None),
        output_variables=tuple(getattr(args, "output_variables", ())),
        parquet=getattr(args, "parquet", False),
        record=tuple(
            name.strip()
            for item in getattr(args, "record", ())
            for name in item.split(",")
            if name.strip()
        ),
        replays=_replays_of(getattr(args, "replay", ())),
        **({"run_id": args.run_id} if args.run_id else {}),
    )


def _replays_of(items: Sequence[str]) -> dict[str, Path]:
    replays = {}
    for item in items:
        component, sep, path = item.partition("=")
        if not sep or not component or not path:
            raise CouplerError(f"--replay {item!r}: write COMPONENT=RECORDING")
        replays[component] = Path(path)
    return replays


def main(argv: Sequence[str] | None = None, *, stdout: TextIO | None = None) -> int:
    out = stdout or sys.stdout
    args = parser().parse_args(argv)
    configure_logging(
        args.log_level, json={"auto": None, "console": False, "json": True}[args.log_format]
    )
    session = _Session()
    try:
        return asyncio.run(_interruptible(_dispatch(args, out, session)))
    except (KeyboardInterrupt, _Interrupted):
        code, sentence = session.interrupted(args)
        print(sentence, file=sys.stderr)
        return code
    except CouplerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        if session.waited_for:
            print(f"hint: {start_hint(args)}", file=sys.stderr)
        return EXIT_ERROR


class _Session(Observer):
    """What one command has seen, for its last words: the participants it waited for (printed
    at once, one line each), the run's progress and end, where the results go."""

    def __init__(self) -> None:
        self.waited_for: list[str] = []
        self.info: RunInfo | None = None
        self.time: float | None = None
        self.end: RunEnd | None = None
        self.out_dir: Path | None = None
        self.campaign: Path | None = None
        self.monitor: MonitorServer | None = None

    def waiting(self, name: str, address: str, reason: str) -> None:
        self.waited_for.append(name)
        if self.monitor is not None:
            self.monitor.state.waiting(name, address, reason)
        print(f"waiting for {name} at {address} ({reason})", file=sys.stderr, flush=True)

    def started(self, info: RunInfo) -> None:
        self.info, self.end = info, None

    def stepped(self, time: float, row: Sequence[Any]) -> None:
        self.time = time

    def finished(self, end: RunEnd) -> None:
        self.end = end

    def interrupted(self, args: argparse.Namespace) -> tuple[int, str]:
        """The exit code and the one sentence Ctrl-C (or SIGTERM) ends a command with."""
        if self.campaign is not None:
            return EXIT_INTERRUPTED, (
                f"interrupted the campaign; the runs that ended are in "
                f"{_shown(self.campaign / 'campaign.csv')} (the same command again runs the rest)"
            )
        if args.command == "replay":
            return EXIT_OK, "stopped serving the recording"
        where = _shown(self.out_dir) if self.out_dir else "./results (or the SSD's outputDirectory)"
        end = self.end
        if end is not None and end.status != "aborted":
            return EXIT_OK, (
                f"stopped the services; the run had ended {end.status} at t={end.end_time:g} s, "
                f"results in {where}"
            )
        if self.info is None:
            return EXIT_INTERRUPTED, "interrupted before the run started; nothing was recorded"
        reached = end.end_time if end is not None else self.time
        at = f"t={reached:g} s" if reached is not None else "the start"
        return EXIT_INTERRUPTED, (
            f"interrupted at {at} of {self.info.stop_time:g} s; the results so far are in "
            f"{where} (summary.json: status aborted)"
        )


def _shown(path: Path) -> str:
    """``path`` relative to the working directory when it is below it."""
    try:
        return str(path.resolve().relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def start_hint(args: argparse.Namespace) -> str:
    """How to start the scenario's services: its fleet file (and the make target running it)
    when there is one beside the SSD."""
    ssp = getattr(args, "ssp", None)
    fleet = ssp.resolve().parent / "fleet.toml" if ssp is not None else None
    if fleet is None or not fleet.exists():
        return "start the participants first (see the scenario's README), then run again"
    shown = _shown(fleet)
    command = f"`.venv/bin/coupler fleet {shown}`"
    makefile = Path("Makefile")
    if makefile.exists():
        target = re.search(
            rf"^([\w-]+):[^\n]*\n(?:\t[^\n]*\n)*?\t[^\n]*coupler fleet {re.escape(shown)}\b",
            makefile.read_text(encoding="utf-8", errors="replace"),
            re.MULTILINE,
        )
        if target:
            command += f" or `make {target.group(1)}`"
    return (
        f"start the scenario's services with {command} (it starts them and runs the scenario), "
        f"or start each one yourself"
    )


class _Interrupted(Exception):
    """SIGINT or SIGTERM ended the command."""


async def _interruptible(command: Coroutine[Any, Any, int]) -> int:
    """Run ``command``; the first SIGINT/SIGTERM cancels it, so the run ends as ``aborted`` with
    its summary written and every service stopped; further signals during that clean-up (a
    terminal and ``uv run`` may both deliver Ctrl-C) are ignored.

    Signals are heard by a thread (through the signal wakeup pipe), not by the event loop's
    thread: when that thread is blocked in a participant computing in-process (an FMU hanging
    in doStep), the watchdog ends the run from there instead, within a second.
    """
    loop = asyncio.get_running_loop()
    task = asyncio.ensure_future(command)
    interrupted = asyncio.Event()

    def interrupt() -> None:
        if not interrupted.is_set():
            interrupted.set()
            task.cancel()

    with _Signals(loop, interrupt):
        try:
            return await task
        except asyncio.CancelledError:
            if interrupted.is_set():
                raise _Interrupted from None
            raise


class _Signals:
    """SIGINT and SIGTERM, heard by a thread of their own through the signal wakeup pipe."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, loop: asyncio.AbstractEventLoop, interrupt: Callable[[], None]) -> None:
        self.loop = loop
        self.interrupt = interrupt
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)
        self._previous: dict[int, Any] = {}
        self._previous_fd = -1

    def __enter__(self) -> _Signals:
        self._previous_fd = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        for sig in self.SIGNALS:  # the handler only has to exist; the thread acts
            self._previous[sig] = signal.signal(sig, lambda number, frame: None)
        threading.Thread(target=self._listen, name="coupler-signals", daemon=True).start()
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(self._previous_fd)
        os.close(self._write)  # ends the listening thread

    def _listen(self) -> None:
        while True:
            try:
                if not os.read(self._read, 64):
                    break
            except OSError:
                break
            with contextlib.suppress(RuntimeError):  # the loop has closed: nothing to tell
                self.loop.call_soon_threadsafe(self.interrupt)
            watchdog = active_watchdog()
            if watchdog is not None:
                time.sleep(0.5)  # a loop that is not blocked has begun ending the run by now
                if watchdog.blocked_for() > 0.5:
                    watchdog.end("aborted", "interrupted by the user")
        os.close(self._read)


async def _dispatch(args: argparse.Namespace, out: TextIO, session: _Session) -> int:
    if args.command == "describe":
        return await _describe(args.target, args.timeout, security_of(args), out=out)
    if args.command == "export-fmu":
        return await _export_fmu(args, out)
    if args.command == "fleet":
        return await _fleet(args, out, session)
    if args.command == "plot":
        return _plot(args, out)
    if args.command == "replay":
        return await _replay(args, out)
    if args.command == "campaign":
        return await _campaign(args, out, session)
    options = replace(options_of(args), on_waiting=session.waiting)
    if args.command == "validate":
        validation = await validate_scenario(args.ssp, options)
        for warning in validation.warnings:
            print(f"warning: {warning}", file=out)
        scenario = validation.scenario
        print(
            f"{args.ssp}: valid ({len(scenario.components)} components, "
            f"{len(scenario.connections)} connections)",
            file=out,
        )
        return EXIT_OK
    return await _run(args, options, out, session)


async def _run(
    args: argparse.Namespace, options: RunOptions, out: TextIO, session: _Session
) -> int:
    session.out_dir = args.out
    observers: list[Observer] = [session]
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
        outcome = await run_scenario(args.ssp, options, out_dir=args.out, observers=observers)
    end = outcome.end
    print(
        f"{end.status}: {end.steps} steps to t={end.end_time:g} s in {end.wall_time:.3g} s",
        file=out,
    )
    print(f"results: {outcome.results_csv}", file=out)
    print(f"summary: {outcome.summary_json}", file=out)
    for recording in outcome.recordings:
        print(f"recording: {recording}", file=out)
    if end.status == "terminated":
        print(f"terminated early: {end.reason}", file=out)
        return EXIT_OK
    if end.status != "completed":
        print(f"error: run {end.status}: {end.reason}", file=sys.stderr)
        return EXIT_ERROR
    return EXIT_OK


async def _linger(monitor: MonitorServer, seconds: float, out: TextIO) -> None:
    if seconds > 0:
        print(f"monitor: {monitor.url} stays up {seconds:g} s", file=out, flush=True)
        await asyncio.sleep(seconds)


async def _fleet(args: argparse.Namespace, out: TextIO, session: _Session) -> int:
    spec = FleetSpec.load(args.fleet)
    run_argv = ["run", str(spec.ssp), "--out", str(args.out or spec.out), *spec.run_args]
    run_argv += [f"--record={item}" for item in args.record]
    run_argv += [f"--replay={item}" for item in args.replay]
    if args.realtime_factor is not None:
        run_argv += ["--realtime-factor", str(args.realtime_factor)]
    run_args = parser().parse_args(run_argv)
    async with contextlib.AsyncExitStack() as stack:
        if run_args.monitor is not None:  # up as long as the fleet, from before its services
            session.monitor = await stack.enter_async_context(MonitorServer(run_args.monitor))
        return await _fleet_run(args, spec, run_args, out, session)


async def _fleet_run(
    args: argparse.Namespace,
    spec: FleetSpec,
    run_args: argparse.Namespace,
    out: TextIO,
    session: _Session,
) -> int:
    async with Fleet(spec, health_timeout=args.health_timeout) as fleet:
        print(
            f"fleet: {len(spec.services)} services healthy (logs in {_shown(fleet.logs)})",
            file=out,
        )
        for name, url in spec.urls.items():
            print(f"{name}: {url}", file=out)
        if session.monitor is not None:
            print(f"monitor: {session.monitor.url}", file=out)
        out.flush()
        options = replace(options_of(run_args), on_waiting=session.waiting)
        code = await _run(run_args, options, out, session)
        if code == EXIT_OK and not args.exit:
            print("services stay up; Ctrl-C stops them", file=out, flush=True)
            await asyncio.Event().wait()
    return code


async def _replay(args: argparse.Namespace, out: TextIO) -> int:
    """Serve a recording until Ctrl-C or SIGTERM (``_interruptible`` cancels the wait)."""
    participant = ReplayParticipant(args.recording, args.component)
    given = {k: getattr(args, k) for k in ReplaySettings.model_fields if getattr(args, k, None)}
    security = ReplaySettings(**given).security()
    server = ParticipantServer(
        participant,
        host=args.host,
        port=args.port,
        security=security,
        reflection=bool(given.get("reflection")),
    )
    try:
        await server.start()
        recording = participant.recording
        print(recording.summary(), file=out)
        print(f"serving {recording.component} at {server.address}", file=out, flush=True)
        await asyncio.Event().wait()
    finally:
        await server.stop()
    return EXIT_OK


class ReplaySettings(SecuritySettings):
    """``coupler replay``'s server security: its options over ``COUPLER_REPLAY_*`` variables
    (``COUPLER_REPLAY_TLS_CERT``, ...; docs/security.md)."""

    model_config = SecuritySettings.model_config | {"env_prefix": "COUPLER_REPLAY_"}


async def _campaign(args: argparse.Namespace, out: TextIO, session: _Session) -> int:
    spec = CampaignSpec.load(args.campaign)
    if args.out is not None:
        spec = replace(spec, out=args.out)
    if args.jobs is not None and args.jobs < 1:
        raise CampaignError(f"--jobs {args.jobs}: give at least 1")
    session.campaign = spec.out
    print(
        f"campaign: {len(spec.variants)} runs of {_shown(spec.scenario.ssp)} into "
        f"{_shown(spec.out)}",
        file=out,
        flush=True,
    )
    result = await run_campaign(
        spec,
        jobs=args.jobs,
        scheduler=args.scheduler,
        force=args.force,
        progress=CampaignProgress(sys.stderr),
    )
    print(format_table(spec, result.reports), file=out)
    print(f"table: {_shown(result.table_csv)}", file=out)
    if result.table_parquet is not None:
        print(f"table: {_shown(result.table_parquet)}", file=out)
    if result.failed:
        print(
            f"error: {len(result.failed)} of {len(result.reports)} runs did not complete "
            f"(status and reason in the table; run.log in each run's folder)",
            file=sys.stderr,
        )
        return EXIT_ERROR
    return EXIT_OK


def _plot(args: argparse.Namespace, out: TextIO) -> int:
    """The leading arguments that exist on disk are runs, the rest channels."""
    count = next((i for i, a in enumerate(args.inputs) if not Path(a).exists()), len(args.inputs))
    runs, channels = [Path(a) for a in args.inputs[:count]], args.inputs[count:]
    looks_like_path = [c for c in channels if "/" in c or c.endswith(".csv")]
    if not runs or looks_like_path:
        missing = looks_like_path[0] if looks_like_path else args.inputs[0]
        raise CouplerError(
            f"coupler plot: {missing}: no such results directory or results.csv (give the runs "
            f"first, then channel names or globs)"
        )
    written = plot(runs, channels, args.output, title=args.title)
    print(f"plot: {written}", file=out)
    return EXIT_OK


async def _export_fmu(args: argparse.Namespace, out: TextIO) -> int:
    exported = await export_fmu(
        args.address,
        args.out,
        fmi_version=args.fmi,
        call_timeout=args.call_timeout,
        connect_timeout=args.timeout,
        security=security_of(args),
    )
    for warning in exported.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print(
        f"exported {_shown(exported.path)}: FMI {exported.fmi_version}.0 co-simulation, "
        f"{exported.variables} variables, driving the participant at {args.address}",
        file=out,
    )
    return EXIT_OK


async def _describe(
    target: str, connect_timeout: float, security: ClientSecurity, *, out: TextIO
) -> int:
    participant: Participant
    if target.startswith(("grpc://", "grpcs://")) or not target.endswith(".fmu"):
        participant = RemoteParticipant(target, connect_timeout=connect_timeout, security=security)
    else:
        participant = FmuParticipant(Path(target))
    try:
        description = await participant.describe()
    finally:
        await participant.close()
    print(format_description(description), file=out)
    return EXIT_OK


def format_description(description: Description) -> str:
    """The channels as an aligned table."""
    header = ("CHANNEL", "CAUSALITY", "TYPE", "UNIT", "START", "DESCRIPTION")
    rows = [
        (
            c.name,
            str(c.causality),
            f"{c.type}({c.message_type})" if c.message_type else str(c.type),
            c.unit or "-",
            "-" if c.start is None else repr(c.start),
            c.description,
        )
        for c in description.channels
    ]
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = [
        f"{description.name}  ({description.implementation or 'unknown implementation'})",
        f"capabilities: streaming={description.capabilities.streaming}, "
        f"variable_step_size={description.capabilities.variable_step_size}"
        + (
            f", fixed_step_size={description.capabilities.fixed_step_size:g}"
            if description.capabilities.fixed_step_size
            else ""
        ),
        "",
    ]
    for row in [header, *rows]:
        lines.append("  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)).rstrip())
    return "\n".join(lines)
