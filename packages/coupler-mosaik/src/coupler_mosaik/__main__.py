"""``coupler-mosaik``: Coupler and mosaik, both ways.

coupler-mosaik simulator HOST:PORT       a Coupler participant as a mosaik simulator: what
                                         mosaik's "cmd" starter runs (%(addr)s)
coupler-mosaik participant FILE.toml     a mosaik simulator as a Coupler participant,
    [--port N] [--host H] [--socket P]   served over gRPC (prints "serving NAME at ADDRESS")
"""

from __future__ import annotations

import argparse
import sys

from coupler.errors import CouplerError


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "simulator":
        simulator(sys.argv[2:])
        return
    parser = argparse.ArgumentParser(prog="coupler-mosaik", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("simulator", help="a Coupler participant as a mosaik simulator (HOST:PORT)")
    serve = commands.add_parser("participant", help="a mosaik simulator as a Coupler participant")
    serve.add_argument("config", help="the participant's TOML file (docs/frameworks.md)")
    serve.add_argument("--host", help="bind address (default: 127.0.0.1)")
    serve.add_argument("--port", type=int, help="gRPC port, 0 = any free one (default 50051)")
    serve.add_argument("--log-level", dest="log_level")
    from coupler.arguments import add_security_arguments, add_socket_argument

    add_socket_argument(serve)
    add_security_arguments(serve)
    args = parser.parse_args()
    participant(args)


def simulator(arguments: list[str]) -> None:
    """mosaik's command line (``HOST:PORT``, ``--remote``, ...) for ``CouplerSimulator``."""
    import mosaik_api_v3

    from coupler_mosaik.simulator import CouplerSimulator

    sys.argv = ["coupler-mosaik simulator", *arguments]
    code = mosaik_api_v3.start_simulation(
        CouplerSimulator(), "A Coupler participant as a mosaik simulator.", configure_logging=False
    )
    raise SystemExit(code)


def participant(args: argparse.Namespace) -> None:
    from coupler.logs import configure_logging
    from coupler.server import ParticipantServer
    from coupler.settings import ParticipantSettings
    from coupler_mosaik.participant import MosaikParticipant

    given = {
        k: v for k, v in vars(args).items() if v is not None and k not in ("command", "config")
    }
    settings = ParticipantSettings(**given)
    configure_logging(settings.log_level, json=settings.log_json)
    try:
        served = MosaikParticipant.from_file(args.config)
    except CouplerError as exc:
        raise SystemExit(f"coupler-mosaik: {exc}") from None

    def announce(server: ParticipantServer) -> None:
        print(f"serving {served.config.name} at {server.address}", flush=True)

    settings.serve(served, program="coupler-mosaik", on_started=announce)


if __name__ == "__main__":
    main()
