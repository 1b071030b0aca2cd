"""``coupler-railway``: the railway library's command line.

    coupler-railway export-openrails FILE.railml --out ROUTES/NAME [--name NAME] [--tolerance-m M]
    coupler-railway envelope CAMPAIGN_FOLDER [-o FILE.html] [--axes A B]

``export-openrails`` writes the OpenRails route folder of a railML file
(docs/openrails-route.md) and prints what it wrote and how closely the written track follows
the railML track. A bad input file ends with one line ``error: FILE:LINE: ...`` naming the
place and the fix, and exit status 1.

``envelope`` writes a perception campaign's operating envelope (``envelope``: HTML, PNG, CSV).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _export_openrails(args: argparse.Namespace) -> int:
    from coupler_railway.errors import RailMLError
    from coupler_railway.openrails.export import ExportError, export_route

    try:
        report = export_route(args.railml, args.out, name=args.name, tolerance_m=args.tolerance_m)
    except (RailMLError, ExportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"error: {exc.filename or args.railml}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # e.g. a degenerate track the model cannot be built from
        print(f"error: {args.railml}: {exc}", file=sys.stderr)
        return 1
    origin = report.origin
    print(f"OpenRails route {report.name!r} written to {report.folder}")
    print(
        f"  track nodes: {report.vector_nodes} vector, {report.junction_nodes} junction, "
        f"{report.end_nodes} end; {report.sections} sections; {report.items} track items"
    )
    print(
        f"  origin (RouteStart): tile {origin.tile_x} {origin.tile_z}, "
        f"x {origin.x:.3f} z {origin.z:.3f}"
    )
    print(
        f"  largest distance from the railML track: {report.fit.max_lateral_m * 1000:.2f} mm "
        f"across, {report.fit.max_along_m * 1000:.2f} mm at equal distance; slope "
        f"foreshortening up to {report.slope_offset_m * 1000:.2f} mm"
    )
    altitude = (
        f"{report.altitude_m:.3f} m (railML)"
        if report.altitude_m is not None
        else "0 (railML gives no altitude)"
    )
    print(f"  height at RouteStart: {altitude}; terrain: {report.terrain_tiles} tiles")
    for path in report.paths:
        print(f"  path: {path}")
    print(f"  consist: {report.consist} (placeholder stock)")
    return 0


def _envelope(args: argparse.Namespace) -> int:
    from coupler_railway.envelope import EnvelopeError, write_envelope

    try:
        written = write_envelope(args.campaign, args.output, args.axes or ())
    except EnvelopeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"error: {exc.filename or args.campaign}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    for path in written:
        print(f"envelope: {path}")
    return 0


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="coupler-railway", description="Coupler's railway domain tools."
    )
    commands = parser.add_subparsers(dest="command", required=True)
    export = commands.add_parser(
        "export-openrails",
        help="write the OpenRails route folder of a railML file",
        description="Write the OpenRails route folder (route, track database, track "
        "sections, paths, world files) of a railML 2.x file.",
    )
    export.add_argument("railml", type=Path, metavar="FILE.railml")
    export.add_argument(
        "--out", type=Path, required=True, metavar="ROUTES/NAME", help="the route folder"
    )
    export.add_argument("--name", help="route name and file stem (default: the folder's name)")
    export.add_argument(
        "--tolerance-m",
        type=float,
        default=0.01,
        help="largest horizontal distance of the written track from the railML track "
        "(default 0.01 m)",
    )
    envelope = commands.add_parser(
        "envelope",
        help="a perception campaign's operating envelope (HTML, PNG, CSV)",
        description="Recall and position error of every scored run of a perception campaign "
        "against each parameter it varied, a map over two of them, the boundaries at recall "
        "0.9 and 0.5, and the worst runs with links to their frames.",
    )
    envelope.add_argument("campaign", type=Path, metavar="CAMPAIGN_FOLDER", help="its out folder")
    envelope.add_argument(
        "-o", "--output", type=Path, help="FILE.html (default CAMPAIGN_FOLDER/envelope.html)"
    )
    envelope.add_argument(
        "--axes",
        nargs=2,
        metavar=("X", "Y"),
        help="the map's two parameters (default: the first two)",
    )
    args = parser.parse_args(argv)
    command = _envelope if args.command == "envelope" else _export_openrails
    sys.exit(command(args))


if __name__ == "__main__":
    main()
