"""``coupler`` / ``python -m coupler_orchestrator``: parse the command line, run the command,
and decide how the process ends (exit codes: ``exits``; Ctrl-C: ``interrupts``)."""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from typing import TextIO

from coupler_orchestrator.cli.exits import EXIT_ERROR
from coupler_orchestrator.cli.parser import parser


def main(
    argv: Sequence[str] | None = None, *, stdout: TextIO | None = None, supervise: bool = False
) -> int:
    """Run one command. ``supervise`` (the ``coupler`` command itself, not a caller in
    Python): a command that runs a scenario in this process runs in a child process this one
    watches, so a crash inside it still ends with a sentence and a summary (``supervisor``)."""
    out = stdout or sys.stdout
    args = parser().parse_args(argv)
    if supervise:
        from coupler_orchestrator.cli.supervisor import SUPERVISED, supervised

        if args.command in SUPERVISED and (code := supervised()) is not None:
            # The watching parent ran nothing of the command: no finalising of its own to wait for.
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)

    import asyncio

    from coupler.errors import CouplerError
    from coupler.logs import configure_logging
    from coupler_orchestrator.cli.interrupts import Interrupted, interruptible
    from coupler_orchestrator.cli.session import Session, start_hint

    configure_logging(
        args.log_level, json={"auto": None, "console": False, "json": True}[args.log_format]
    )
    session = Session()
    try:
        return asyncio.run(interruptible(args.execute(args, out, session)))
    except (KeyboardInterrupt, Interrupted):
        code, sentence = session.interrupted(args)
        print(sentence, file=sys.stderr)
        return code
    except CouplerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        if session.waited_for:
            print(f"hint: {start_hint(args)}", file=sys.stderr)
        return EXIT_ERROR
