"""``coupler new participant NAME``: a folder with a participant that runs as it is."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TextIO

from coupler_orchestrator.cli.exits import EXIT_OK, EXIT_USAGE
from coupler_orchestrator.cli.session import Session
from coupler_orchestrator.tools.scaffold import DEFAULT_PORT, name_problem

HELP = "write a new participant: its program, its channels and an SSD that runs it"
DESCRIPTION = (
    "coupler new participant NAME writes the folder NAME (or --dir DIR): participant.py (a "
    "complete participant served with --port), NAME.ssd (a scenario that runs it) and "
    "README.md (how). docs/participants.md explains every part."
)


def arguments(new: argparse.ArgumentParser) -> None:
    kinds = new.add_subparsers(dest="kind", required=True, metavar="participant")
    participant = kinds.add_parser("participant", help=HELP, description=DESCRIPTION)
    participant.add_argument(
        "name", type=_name, metavar="NAME", help="participant and component name, e.g. Heater"
    )
    participant.add_argument(
        "--dir",
        type=Path,
        metavar="DIR",
        help="the folder to write (default: ./NAME); it must not exist",
    )
    participant.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        help=f"the participant's port (default {DEFAULT_PORT})",
    )


def _name(text: str) -> str:
    """An argparse type: a NAME ``coupler new`` can use (argparse reports the problem)."""
    if why := name_problem(text):
        raise argparse.ArgumentTypeError(why)
    return text


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    from coupler_orchestrator.tools.scaffold import ScaffoldError, write_participant

    folder = args.dir if args.dir is not None else Path(args.name)
    try:
        written = write_participant(args.name, folder, port=args.port)
    except ScaffoldError as exc:
        print(f"coupler new participant: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    python = Path(sys.executable)
    print(
        f"wrote {written.folder}/: participant.py, {written.ssd.name}, README.md\n"
        f"run it:  {_shown(python)} {written.program} --port {args.port} &\n"
        f"         {_shown(python.with_name('coupler'))} run {written.ssd}\n"
        f"         kill %1",
        file=out,
    )
    return EXIT_OK


def _shown(path: Path) -> str:
    """``path`` relative to the working folder when it is below it (``.venv/bin/python``)."""
    relative = os.path.relpath(path)
    return path.as_posix() if relative.startswith("..") else relative
