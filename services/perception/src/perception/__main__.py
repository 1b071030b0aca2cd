"""``python -m perception``: serve the balise perception participant.

Options override the ``PERCEPTION_*`` environment variables (see ``config.py``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from coupler.logs import configure_logging
from coupler.server import ParticipantServer
from coupler.settings import add_security_arguments, add_socket_argument

from .config import PerceptionSettings
from .participant import PerceptionParticipant


def _parse(argv: list[str] | None) -> PerceptionSettings:
    parser = argparse.ArgumentParser(prog="perception", description=__doc__)
    parser.add_argument("--host", help="gRPC bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="gRPC port, 0 = any free one (default 50063)")
    add_socket_argument(parser)
    parser.add_argument("--model", type=Path,
                        help="the learned detector's model file (default "
                             "build/models/balise-pixels.json: make detector-model)")  # fmt: skip
    parser.add_argument("--log-level", dest="log_level")
    add_security_arguments(parser)
    given = {k: v for k, v in vars(parser.parse_args(argv)).items() if v is not None}
    return PerceptionSettings(**given)


def main(argv: list[str] | None = None) -> None:
    settings = _parse(argv)
    configure_logging(settings.log_level, json=settings.log_json)

    def announce(server: ParticipantServer) -> None:
        print(f"perception listening at {server.address}", flush=True)

    settings.serve(
        PerceptionParticipant(model=settings.model), program="perception", on_started=announce
    )


if __name__ == "__main__":
    main()
