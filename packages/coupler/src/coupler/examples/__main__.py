"""Run an example participant: ``python -m coupler.examples gain --port 50051``."""

from __future__ import annotations

import argparse
import asyncio

from coupler.examples.gain import GainParticipant
from coupler.logs import configure_logging
from coupler.server import ParticipantServer, serve


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m coupler.examples", description=__doc__)
    parser.add_argument("example", choices=["gain"], help="which example participant")
    parser.add_argument("--name", default="Gain", help="participant name (default: Gain)")
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default: 127.0.0.1)")
    parser.add_argument("--port", type=int, default=50051, help="gRPC port, 0 = any free one")
    parser.add_argument("--log-level", default="INFO")
    args = parser.parse_args()
    configure_logging(args.log_level)

    def announce(server: ParticipantServer) -> None:
        print(f"serving {args.name} at {server.address}", flush=True)

    asyncio.run(
        serve(GainParticipant(args.name), host=args.host, port=args.port, on_started=announce)
    )


if __name__ == "__main__":
    main()
