"""``coupler export-fmu``: an FMU (FMI 2.0/3.0 co-simulation) that drives a running participant,
for any FMI tool (docs/export-fmu.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TextIO

from coupler import durations
from coupler_orchestrator.cli.exits import EXIT_OK
from coupler_orchestrator.cli.parser import security_of, security_options
from coupler_orchestrator.cli.session import Session, shown

HELP = (
    "write an FMU (FMI 2.0/3.0 co-simulation) that drives a running participant, for any FMI "
    "tool (docs/export-fmu.md)"
)


def arguments(export: argparse.ArgumentParser) -> None:
    export.add_argument("address", help="the participant: grpc://HOST:PORT or grpcs://HOST:PORT")
    export.add_argument("--out", type=Path, required=True, help="NAME.fmu to write")
    export.add_argument(
        "--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2)"
    )
    export.add_argument(
        "--call-timeout",
        type=durations.argument(durations.MAX_TIMEOUT),
        default=30.0,
        help="[s] deadline of every call the FMU makes to the participant (default 30)",
    )
    export.add_argument(
        "--timeout",
        type=durations.argument(durations.MAX_TIMEOUT),
        default=10.0,
        help="connect timeout [s]",
    )
    security_options(export)


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    from coupler_orchestrator.tools.export_fmu import export_fmu

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
        f"exported {shown(exported.path)}: FMI {exported.fmi_version}.0 co-simulation, "
        f"{exported.variables} variables, driving the participant at {args.address}",
        file=out,
    )
    return EXIT_OK
