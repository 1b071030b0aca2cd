"""``coupler-helics FILE.toml``: serve a HELICS value federate as a Coupler participant over gRPC
(prints "serving NAME at ADDRESS" once it serves)."""

from __future__ import annotations

import argparse

from coupler.arguments import add_security_arguments, add_socket_argument


def main() -> None:
    parser = argparse.ArgumentParser(prog="coupler-helics", description=__doc__.splitlines()[0])
    parser.add_argument("config", help="the participant's TOML file (docs/frameworks.md)")
    parser.add_argument("--host", help="bind address (default: 127.0.0.1)")
    parser.add_argument("--port", type=int, help="gRPC port, 0 = any free one (default 50051)")
    parser.add_argument("--log-level", dest="log_level")
    add_socket_argument(parser)
    add_security_arguments(parser)
    args = parser.parse_args()

    from coupler.errors import CouplerError
    from coupler.logs import configure_logging
    from coupler.server import ParticipantServer
    from coupler.settings import ParticipantSettings
    from coupler_helics.participant import HelicsParticipant

    given = {k: v for k, v in vars(args).items() if v is not None and k != "config"}
    settings = ParticipantSettings(**given)
    configure_logging(settings.log_level, json=settings.log_json)
    try:
        served = HelicsParticipant.from_file(args.config)
    except CouplerError as exc:
        raise SystemExit(f"coupler-helics: {exc}") from None

    def announce(server: ParticipantServer) -> None:
        print(f"serving {served.config.name} at {server.address}", flush=True)

    settings.serve(served, program="coupler-helics", on_started=announce)


if __name__ == "__main__":
    main()
