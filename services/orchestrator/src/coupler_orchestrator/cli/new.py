"""``coupler new participant NAME``: a folder with a participant that runs as it is."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TextIO

from coupler_orchestrator.cli.exits import EXIT_OK, EXIT_USAGE
from coupler_orchestrator.cli.session import Session
from coupler_orchestrator.tools.scaffold import (
    DEFAULT_PORT,
    DEFAULT_TEMPLATE,
    TEMPLATES,
    name_problem,
)

HELP = "write a new participant: its program, its channels and an SSD that runs it"
DESCRIPTION = (
    "coupler new participant NAME writes the folder NAME (or --dir DIR): participant.py (a "
    "complete participant; it takes every option coupler fleet passes: --port, --socket, ...), "
    "NAME.ssd (a scenario that runs it), fleet.toml (coupler fleet starts the one and runs the "
    "other) and README.md (how, and what to edit). docs/participants.md explains every part."
)


def arguments(new: argparse.ArgumentParser) -> None:
    new.add_argument(
        "kind", choices=["participant"], metavar="participant", help="what to write (the only kind)"
    )
    new.add_argument(
        "name", type=_name, metavar="NAME", help="participant and component name, e.g. Heater"
    )
    new.add_argument(
        "--dir",
        type=Path,
        metavar="DIR",
        help="the folder to write (default: ./NAME); it must not exist",
    )
    new.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        help=f"the participant's port (default {DEFAULT_PORT})",
    )
    new.add_argument(
        "--template",
        choices=list(TEMPLATES),
        default=DEFAULT_TEMPLATE,
        help="; ".join(f"{name}: {t.summary}" for name, t in TEMPLATES.items())
        + f" (default {DEFAULT_TEMPLATE})",
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
        written = write_participant(args.name, folder, port=args.port, template=args.template)
    except ScaffoldError as exc:
        print(f"coupler new participant: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    python = Path(sys.executable)
    print(
        f"wrote {written.folder}/: participant.py, {written.ssd.name}, fleet.toml, README.md\n"
        f"run it:  {_shown(python)} {written.program} --port {args.port} &\n"
        f"         {_shown(python.with_name('coupler'))} run {written.ssd}\n"
        f"         kill %1\n"
        f"or, from {written.folder}: {_shown(python.with_name('coupler'))} fleet fleet.toml --exit",
        file=out,
    )
    return EXIT_OK


def _shown(path: Path) -> str:
    """``path`` relative to the working folder when it is below it (``.venv/bin/python``)."""
    relative = os.path.relpath(path)
    return path.as_posix() if relative.startswith("..") else relative
