"""Build the TrackBalises FMU: railML -> track and balise tables -> C FMU with them as resources.

``coupler_railway`` reads the railML file and writes ``track.csv`` and ``balises.csv`` (the
FMU's ``resources/``); ``coupler_tools.fmubuild`` compiles the C model in ``fmu/TrackBalises`` (FMI
2.0) or ``fmu/TrackBalises3`` (FMI 3.0, same model source) with gcc and zips the FMU.

Command line::

    python -m balise_fmu.build [--railml FILE] [--out FMU] [--fmi-version 2|3] [--spacing M]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

from coupler_railway import RailMLError, load_infrastructure, write_fmu_resources
from coupler_tools.fmubuild import FmuBuildError, build_fmu

__all__ = [
    "DEFAULT_FMU",
    "DEFAULT_RAILML",
    "FMU_SOURCES",
    "REPOSITORY",
    "build_track_balises",
    "main",
]

SERVICE = Path(__file__).resolve().parents[2]
"""services/balise-fmu."""
REPOSITORY = SERVICE.parents[1]
FMU_SOURCES = SERVICE / "fmu"
"""Model folders TrackBalises (FMI 2.0) and TrackBalises3 (FMI 3.0), and the model in model/."""
DEFAULT_RAILML = REPOSITORY / "scenarios/railway/data/annaberg-schwarzenberg.railml"
DEFAULT_FMU = REPOSITORY / "build/fmus/TrackBalises.fmu"
_FOLDERS = {2: "TrackBalises", 3: "TrackBalises3"}


def build_track_balises(
    railml: str | Path = DEFAULT_RAILML,
    out: str | Path = DEFAULT_FMU,
    *,
    fmi_version: int = 2,
    spacing_m: float = 5.0,
) -> Path:
    """Build the TrackBalises FMU for the line in ``railml`` into ``out``; returns ``out``.

    Raises RailMLError for a bad railML file and FmuBuildError when the FMU cannot be built.
    """
    if fmi_version not in _FOLDERS:
        raise FmuBuildError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    infrastructure = load_infrastructure(Path(railml))
    with tempfile.TemporaryDirectory(prefix="trackbalises-") as tmp:
        write_fmu_resources(infrastructure, tmp, spacing_m=spacing_m)
        return build_fmu(FMU_SOURCES / _FOLDERS[fmi_version], Path(out), resources=Path(tmp))


def main(argv: Sequence[str] | None = None) -> int:
    """Build the FMU, print its path; exit status 1 with a message on failure."""
    parser = argparse.ArgumentParser(
        prog="python -m balise_fmu.build", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--railml", type=Path, default=DEFAULT_RAILML, help="railML 2.x file")
    parser.add_argument("--out", type=Path, default=None, help="FMU to write")
    parser.add_argument("--fmi-version", type=int, choices=sorted(_FOLDERS), default=2)
    parser.add_argument(
        "--spacing", type=float, default=5.0, help="track sample spacing in track.csv [m]"
    )
    args = parser.parse_args(argv)
    out = args.out
    if out is None:
        out = DEFAULT_FMU.with_name(f"{_FOLDERS[args.fmi_version]}.fmu")
    try:
        path = build_track_balises(
            args.railml, out, fmi_version=args.fmi_version, spacing_m=args.spacing
        )
    except (FmuBuildError, RailMLError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
