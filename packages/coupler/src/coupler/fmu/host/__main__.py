"""The generic FMU host as a child process of the orchestrator:
``python -m coupler.fmu.host FMU --socket PATH --token-file FILE [--name NAME] [--unpacked DIR]``.

Serves one FMU (``coupler.fmu.FmuParticipant``) on a unix socket, requiring the token; exits
on SIGTERM/SIGINT and when its parent process is gone. The orchestrator unpacks the FMU itself
(``--unpacked``: within the run's budget, in a folder it removes however the host ends).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
from pathlib import Path

from coupler.errors import CouplerError
from coupler.fmu import FmuParticipant
from coupler.fmu.host import parent_alive
from coupler.lifetimes import die_with_parent
from coupler.logs import configure_logging
from coupler.security import ServerSecurity
from coupler.server import ParticipantServer


async def host(
    fmu: Path, name: str | None, socket: Path, token_file: Path, unpacked: Path | None = None
) -> None:
    parent = os.getppid()
    if not die_with_parent(parent):  # also while stuck in the FMU, where nothing polls
        return
    server = ParticipantServer(
        FmuParticipant(fmu, name=name, unpacked=unpacked),
        unix_socket=socket,
        security=ServerSecurity(token_file=token_file),
    )
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    try:
        await server.start()
        while not stop.is_set() and parent_alive(parent):
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 0.5)
    finally:
        await server.stop(grace=0.5)


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m coupler.fmu.host", description=__doc__)
    parser.add_argument("fmu", type=Path, help="the FMU to serve")
    parser.add_argument("--name", help="participant name (default: the FMU's model name)")
    parser.add_argument(
        "--unpacked", type=Path, help="the FMU already unpacked there (default: unpack it)"
    )
    parser.add_argument("--socket", type=Path, required=True, help="unix socket to serve on")
    parser.add_argument("--token-file", type=Path, required=True, help="bearer token required")
    parser.add_argument("--log-level", default="WARNING")
    args = parser.parse_args()
    configure_logging(args.log_level)
    try:
        asyncio.run(host(args.fmu, args.name, args.socket, args.token_file, args.unpacked))
    except CouplerError as exc:
        raise SystemExit(f"coupler.fmu.host: {exc}") from exc


if __name__ == "__main__":
    main()
