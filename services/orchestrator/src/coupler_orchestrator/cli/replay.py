"""``coupler replay``: serve a recording as a gRPC participant until Ctrl-C or SIGTERM."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TextIO

from coupler.arguments import add_security_arguments, add_socket_argument
from coupler_orchestrator.cli.exits import EXIT_OK
from coupler_orchestrator.cli.session import Session

HELP = "serve a recording (coupler run --record) as a gRPC participant"


def arguments(replay: argparse.ArgumentParser) -> None:
    replay.add_argument("recording", type=Path, help="a .crec file or a results directory")
    replay.add_argument(
        "--component", help="the recorded component (default: the file's; needed for a directory)"
    )
    replay.add_argument("--host", default="127.0.0.1", help="bind address (default: 127.0.0.1)")
    replay.add_argument("--port", type=int, default=0, help="gRPC port (default: any free one)")
    add_socket_argument(replay)
    add_security_arguments(replay)


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    """Serve until cancelled (``interrupts.interruptible`` cancels the wait)."""
    from coupler_orchestrator.tools.replay import ReplaySettings, serve_recording

    given = {k: getattr(args, k) for k in ReplaySettings.model_fields if getattr(args, k, None)}
    await serve_recording(
        args.recording,
        args.component,
        host=args.host,
        port=args.port,
        unix_socket=args.socket,
        given=given,
        out=out,
    )
    return EXIT_OK
