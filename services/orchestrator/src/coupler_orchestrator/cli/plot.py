"""``coupler plot``: channels of one or more runs drawn into a PNG or a self-contained HTML page."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TextIO

from coupler.errors import CouplerError
from coupler_orchestrator.cli.exits import EXIT_OK
from coupler_orchestrator.cli.session import Session

HELP = "draw channels of one or more runs into a PNG or a self-contained HTML page"
DESCRIPTION = (
    "RESULTS are results directories or results.csv files (several are overlaid); CHANNELS are "
    "names or globs (default: every numeric channel)."
)


def arguments(plot: argparse.ArgumentParser) -> None:
    plot.add_argument("inputs", nargs="+", metavar="RESULTS|CHANNEL", help="runs, then channels")
    plot.add_argument("-o", "--output", type=Path, required=True, help="FILE.png or FILE.html")
    plot.add_argument("--title", default="", help="default: the runs' directories")


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    return _plot(args, out)


def _plot(args: argparse.Namespace, out: TextIO) -> int:
    """The leading arguments that exist on disk are runs, the rest channels."""
    from coupler_orchestrator.tools.plot import plot

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
