"""A gain participant process that misbehaves on request, for the fault tests.

    python faulty_participant.py [--port P] [--hang-at T] [--block-at T] [--slow S] [--lease-log]

--hang-at T   every DoStep from t >= T awaits forever (the event loop stays free)
--block-at T  every DoStep from t >= T blocks the whole process (time.sleep in the loop)
--slow S      every DoStep takes S seconds
--token-file  require this bearer token
Prints ``serving NAME at ADDRESS`` when ready; logs run starts and ends on stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from collections.abc import Mapping
from pathlib import Path

from coupler.channels import Value
from coupler.examples.gain import GainParticipant
from coupler.logs import configure_logging
from coupler.participant import Values
from coupler.security import ServerSecurity
from coupler.server import ParticipantServer, serve


class Faulty(GainParticipant):
    def __init__(self, hang_at: float | None, block_at: float | None, slow: float) -> None:
        super().__init__("Gain")
        self.hang_at, self.block_at, self.slow = hang_at, block_at, slow

    async def do_step(self, time_s: float, step: float, inputs: Mapping[str, Value]) -> Values:
        if self.hang_at is not None and time_s >= self.hang_at - 1e-9:
            await asyncio.Event().wait()
        if self.block_at is not None and time_s >= self.block_at - 1e-9:
            time.sleep(3600)  # noqa: ASYNC251 - blocking the loop is the fault under test
        if self.slow:
            await asyncio.sleep(self.slow)
        return await super().do_step(time_s, step, inputs)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--hang-at", type=float)
    parser.add_argument("--block-at", type=float)
    parser.add_argument("--slow", type=float, default=0.0)
    parser.add_argument("--token-file", type=Path)
    args = parser.parse_args()
    configure_logging("INFO", json=True)

    def announce(server: ParticipantServer) -> None:
        print(f"serving Gain at {server.address}", flush=True)

    participant = Faulty(args.hang_at, args.block_at, args.slow)
    security = ServerSecurity(token_file=args.token_file)
    asyncio.run(serve(participant, port=args.port, security=security, on_started=announce))


if __name__ == "__main__":
    main()
