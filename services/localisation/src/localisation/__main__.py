"""``python -m localisation``: serve the localisation (the system under test) or one of the
sensor models that feed it (``--role odometer|transmission``).

Options override the ``LOCALISATION_*`` environment variables (see ``config.py``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from coupler.errors import CouplerError
from coupler.logs import configure_logging
from coupler.participant import Participant
from coupler.server import ParticipantServer
from coupler.settings import add_security_arguments, add_socket_argument
from coupler_railway import RailMLError

from .config import PORTS, LocalisationSettings


def _parse(argv: list[str] | None) -> LocalisationSettings:
    parser = argparse.ArgumentParser(prog="localisation", description=__doc__)
    parser.add_argument("--role", choices=sorted(PORTS), help="default: localisation")
    parser.add_argument("--host", help="gRPC bind address (default 127.0.0.1)")
    parser.add_argument(
        "--port", type=int, help="gRPC port, 0 = any free one (default: 50064, 50065, 50066)"
    )
    add_socket_argument(parser)
    parser.add_argument("--railml", type=Path, help="the line (default: the railway scenario's)")
    parser.add_argument("--channels", type=Path, help="the localisation's channel map (TOML)")
    parser.add_argument("--log-level", dest="log_level")
    add_security_arguments(parser)
    given = {k: v for k, v in vars(parser.parse_args(argv)).items() if v is not None}
    return LocalisationSettings(**given)


def _participant(settings: LocalisationSettings) -> Participant:
    if settings.role == "odometer":
        from .sensors import OdometerParticipant

        return OdometerParticipant()
    if settings.role == "transmission":
        from .sensors import TransmissionParticipant

        return TransmissionParticipant()
    from .unit import participant

    if not settings.railml.is_file():
        raise CouplerError(f"--railml {settings.railml}: no such file (the line to localise on)")
    return participant(settings.railml, settings.channels)


def main(argv: list[str] | None = None) -> None:
    settings = _parse(argv)
    configure_logging(settings.log_level, json=settings.log_json)
    try:
        served = _participant(settings)
    except (CouplerError, RailMLError) as exc:
        print(f"localisation: {exc}", file=sys.stderr)
        sys.exit(1)

    def announce(server: ParticipantServer) -> None:
        print(f"{settings.role} listening at {server.address}", flush=True)

    settings.model_copy(update={"port": settings.role_port()}).serve(
        served, program=f"localisation {settings.role}", on_started=announce
    )


if __name__ == "__main__":
    main()
