"""``python -m balise_fmu``: serve an FMU (TrackBalises.fmu by default) as a participant.

Options override the ``BALISE_FMU_*`` environment variables (see ``config.py``). Channels,
types, units and start values come from the FMU's modelDescription.xml; parameters and start
values arrive with Initialize (``coupler.fmu.FmuParticipant`` is the host).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import structlog

from coupler.fmu import FmuParticipant
from coupler.logs import configure_logging
from coupler.server import ParticipantServer
from coupler.settings import add_security_arguments, add_socket_argument
from coupler_railway import RailMLError
from coupler_tools.fmubuild import FmuBuildError

from .build import DEFAULT_FMU, DEFAULT_RAILML, build_track_balises
from .config import BaliseFmuSettings

log = structlog.get_logger("balise_fmu")


def _parse(argv: list[str] | None) -> BaliseFmuSettings:
    parser = argparse.ArgumentParser(prog="balise-fmu", description=__doc__.split("\n")[0])
    parser.add_argument("--fmu", type=Path, help=f"FMU to serve (default {DEFAULT_FMU})")
    parser.add_argument("--name", help="participant name (default: the FMU's model name)")
    parser.add_argument(
        "--railml", type=Path, help="railML the default FMU is built from when missing"
    )
    parser.add_argument("--host", help="gRPC bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="gRPC port, 0 = any free one (default 50062)")
    add_socket_argument(parser)
    parser.add_argument("--log-level", dest="log_level")
    add_security_arguments(parser)
    given = {k: v for k, v in vars(parser.parse_args(argv)).items() if v is not None}
    return BaliseFmuSettings(**given)


def resolve_fmu(settings: BaliseFmuSettings) -> Path:
    """The FMU to serve: as configured (it must exist), else the default TrackBalises.fmu,
    built from the railML file when it is missing."""
    if settings.fmu is not None:
        if not settings.fmu.is_file():
            raise FileNotFoundError(
                f"FMU not found: {settings.fmu} (give an existing .fmu with --fmu or "
                f"BALISE_FMU_FMU; omit it to serve the TrackBalises FMU)"
            )
        return settings.fmu
    if DEFAULT_FMU.is_file():
        return DEFAULT_FMU
    railml = settings.railml or DEFAULT_RAILML
    log.info("building_default_fmu", fmu=str(DEFAULT_FMU), railml=str(railml))
    return build_track_balises(railml, DEFAULT_FMU)


def main(argv: list[str] | None = None) -> None:
    settings = _parse(argv)
    configure_logging(settings.log_level, json=settings.log_json)
    try:
        path = resolve_fmu(settings)
    except (FileNotFoundError, FmuBuildError, RailMLError) as exc:
        sys.exit(
            f"balise-fmu: {exc}\n(build the TrackBalises FMU with "
            f"'.venv/bin/python -m balise_fmu.build --railml FILE --out {DEFAULT_FMU}')"
        )
    participant = FmuParticipant(path, name=settings.name)

    def announce(server: ParticipantServer) -> None:
        print(f"balise-fmu serving {path} at {server.address}", flush=True)

    settings.serve(participant, program="balise-fmu", on_started=announce)


if __name__ == "__main__":
    main()
