"""``coupler fleet``: start a scenario's services as local processes, run it, keep them up."""

from __future__ import annotations

import argparse
import contextlib
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from coupler import durations
from coupler_orchestrator.cli.exits import EXIT_OK
from coupler_orchestrator.cli.parser import (
    options_of,
    out_options,
    parser,
    realtime_factor,
    record_options,
)
from coupler_orchestrator.cli.session import Session, shown

if TYPE_CHECKING:
    from coupler_orchestrator.tools.fleet import FleetSpec

HELP = "start a scenario's services as local processes, run it, keep them up"


def arguments(fleet: argparse.ArgumentParser) -> None:
    fleet.add_argument(
        "fleet", type=Path, help="fleet file (TOML), e.g. scenarios/railway/fleet.toml"
    )
    fleet.add_argument("--exit", action="store_true", help="stop the services when the run ends")
    fleet.add_argument(
        "--tcp",
        action="store_true",
        help="serve the participants on their TCP ports instead of unix sockets (the default "
        "on one host; the fleet file's unix_sockets = false does the same)",
    )
    out_options(fleet, default="the fleet file's out")
    fleet.add_argument(
        "--realtime-factor",
        type=realtime_factor,
        help="override the fleet file's pacing; 0 = unpaced",
    )
    fleet.add_argument(
        "--health-timeout",
        type=durations.argument(durations.MAX_TIMEOUT),
        default=60.0,
        help="[s] per service",
    )
    record_options(fleet)
    # as `coupler run` takes them, added after the fleet file's run arguments (so they win)
    fleet.add_argument("--stop-time", type=float, help="stop time [s] (instead of the SSD's)")
    fleet.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="COMPONENT.NAME=VALUE",
        help="override a parameter or input start value (repeatable), e.g. "
        "OpenRails.fog_visibility=50",
    )
    fleet.add_argument(
        "--output-variables",
        action="append",
        default=[],
        metavar="NAME[,NAME...]",
        help="record only these outputs (Component.output names or globs, comma-separated; "
        "repeatable); a coupler.v1.Image channel named here is recorded as PNG files",
    )


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    from coupler_orchestrator.outputs.monitor import MonitorServer
    from coupler_orchestrator.tools.fleet import FleetSpec

    spec = FleetSpec.load(args.fleet)
    run_argv = ["run", str(spec.ssp), *spec.run_args]
    if args.out is not None:  # this folder; else a new one per run in the fleet file's out
        spec = replace(spec, out=args.out)
        run_argv += ["--out", str(args.out), *(["--force"] if args.force else [])]
    run_argv += [f"--record={item}" for item in args.record]
    run_argv += [f"--replay={item}" for item in args.replay]
    if args.realtime_factor is not None:
        run_argv += ["--realtime-factor", str(args.realtime_factor)]
    if args.stop_time is not None:
        run_argv += ["--stop-time", repr(args.stop_time)]
    run_argv += [f"--param={item}" for item in args.param]
    run_argv += [f"--output-variables={item}" for item in args.output_variables]
    run_args = parser().parse_args(run_argv)
    if args.out is None:
        run_args.results_base = spec.out
    async with contextlib.AsyncExitStack() as stack:
        if run_args.monitor is not None:  # up as long as the fleet, from before its services
            session.monitor = await stack.enter_async_context(MonitorServer(run_args.monitor))
        return await _fleet_run(args, spec, run_args, out, session)


async def _fleet_run(
    args: argparse.Namespace,
    spec: FleetSpec,
    run_args: argparse.Namespace,
    out: TextIO,
    session: Session,
) -> int:
    import asyncio

    from coupler_orchestrator.cli.run import run
    from coupler_orchestrator.tools.fleet import Fleet

    async with Fleet(spec, health_timeout=args.health_timeout, sockets=not args.tcp) as fleet:
        print(
            f"fleet: {len(spec.services)} services healthy (logs in {shown(fleet.logs)})",
            file=out,
        )
        if fleet.sockets is not None:
            print(
                f"participants on unix sockets in {fleet.sockets} (--tcp: on their TCP ports, "
                "for other runs too)",
                file=out,
            )
        for name, url in spec.urls.items():
            print(f"{name}: {url}", file=out)
        if session.monitor is not None:
            print(f"monitor: {session.monitor.url}", file=out)
        out.flush()
        options = replace(
            options_of(run_args), on_waiting=session.waiting, addresses=dict(fleet.addresses)
        )
        code = await run(run_args, options, out, session)
        if code == EXIT_OK and not args.exit:
            print("services stay up; Ctrl-C stops them", file=out, flush=True)
            await asyncio.Event().wait()
    return code
