"""``coupler describe``: a participant's channels (a running one, or an FMU file)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from coupler import durations
from coupler_orchestrator.cli.exits import EXIT_OK
from coupler_orchestrator.cli.parser import security_of, security_options
from coupler_orchestrator.cli.session import Session

if TYPE_CHECKING:
    from coupler.channels import Description

HELP = "print a participant's channels"


def arguments(describe: argparse.ArgumentParser) -> None:
    describe.add_argument(
        "target",
        help="a running participant: grpc://HOST:PORT, grpcs://HOST:PORT or unix:///PATH (its "
        "unix socket, as coupler fleet serves it); or an .fmu file",
    )
    describe.add_argument(
        "--timeout",
        type=durations.argument(durations.MAX_TIMEOUT),
        default=10.0,
        help="connect timeout [s]",
    )
    security_options(describe)


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    from coupler.client import RemoteParticipant
    from coupler.fmu import FmuParticipant
    from coupler.participant import Participant

    target, security = args.target, security_of(args)
    participant: Participant
    if target.startswith(("grpc://", "grpcs://")) or not target.endswith(".fmu"):
        participant = RemoteParticipant(
            target,
            connect_timeout=args.timeout,
            security=security,
            on_waiting=lambda reason: print(
                f"waiting up to {args.timeout:g} s for a participant at {target} ({reason})",
                file=sys.stderr,
                flush=True,
            ),
        )
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
            (f"{c.type}({c.message_type})" if c.message_type else str(c.type))
            + (f" max {c.max_bytes} B" if c.sized and c.max_bytes else ""),
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
        )
        + (
            f", step_socket={description.capabilities.step_socket}"
            if description.capabilities.step_socket
            else ""
        ),
        "",
    ]
    for row in [header, *rows]:
        lines.append("  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)).rstrip())
    return "\n".join(lines)
