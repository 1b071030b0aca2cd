"""Run an example participant: ``python -m coupler.examples gain --port 50051``."""

from __future__ import annotations

import argparse

from coupler.examples.gain import GainParticipant
from coupler.logs import configure_logging
from coupler.server import ParticipantServer
from coupler.settings import ParticipantSettings, add_security_arguments, add_socket_argument


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m coupler.examples", description=__doc__)
    parser.add_argument("example", choices=["gain"], help="which example participant")
    parser.add_argument("--name", default="Gain", help="participant name (default: Gain)")
    parser.add_argument("--host", help="bind address (default: 127.0.0.1)")
    parser.add_argument("--port", type=int, help="gRPC port, 0 = any free one (default 50051)")
    add_socket_argument(parser)
    parser.add_argument("--log-level", dest="log_level")
    add_security_arguments(parser)
    args = parser.parse_args()
    given = {k: v for k, v in vars(args).items() if v is not None and k not in ("example", "name")}
    settings = ParticipantSettings(**given)
    configure_logging(settings.log_level, json=settings.log_json)

    def announce(server: ParticipantServer) -> None:
        print(f"serving {args.name} at {server.address}", flush=True)

    settings.serve(GainParticipant(args.name), program="coupler.examples", on_started=announce)


if __name__ == "__main__":
    main()
