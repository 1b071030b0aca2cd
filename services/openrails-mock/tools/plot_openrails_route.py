"""Draw docs/img/openrails-route.png: the exported OpenRails track over the railML track.

Panels: the whole line (railML B-spline, exported section starts), a close-up where the
sections are shortest, the distance of the exported track from the B-spline along the line
(as OpenRails lays the sections, read back with the mock's route loader), and each balise's
passage distance on the mock's track database minus the TrackBalises FMU's distance.
Lives beside the mock it reads the route with (the railway package imports no service).
Needs the dev workspace (the mock, matplotlib) and `make setup` (route, FMU).
Run: .venv/bin/python services/openrails-mock/tools/plot_openrails_route.py
"""

from __future__ import annotations

import csv
import io
import math
import zipfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler_railway import load_infrastructure
from openrails_mock.routefolder import load_route
from openrails_mock.tdb import TrackNetwork

ROOT = Path(__file__).resolve().parents[3]
RAILML = ROOT / "scenarios/railway/data/annaberg-schwarzenberg.railml"
ROUTE = ROOT / "build/routes/annaberg-schwarzenberg"
FMU = ROOT / "build/fmus/TrackBalises.fmu"
OUT = ROOT / "docs/img/openrails-route.png"


def main() -> None:
    infra = load_infrastructure(RAILML)
    model = infra.model
    route = load_route(ROUTE)
    network = TrackNetwork(route)
    node = route.nodes[1]
    x0 = route.start[0] * 2048.0 + route.start[2]
    z0 = route.start[1] * 2048.0 + route.start[3]

    # the exported track, as OpenRails lays it, every 1 m, against the B-spline
    distances = np.arange(0.0, node.length, 1.0)
    points = []
    for d in distances:
        place = network.place(1, float(d))
        points.append((place.tile_x * 2048.0 + place.x - x0, place.tile_z * 2048.0 + place.z - z0))
    exported = np.array(points)
    spline = model.local_xy(np.minimum(distances, model.length))
    headings = model.headings(np.minimum(distances, model.length))
    normal = np.column_stack([np.cos(headings), -np.sin(headings)])
    lateral = np.sum((exported - spline) * normal, axis=1) * 1000.0
    starts = np.cumsum([0.0] + [s.shape.length for s in node.sections[:-1]])
    section_xy = model.local_xy(starts)

    with zipfile.ZipFile(FMU) as fmu:
        rows = csv.DictReader(io.StringIO(fmu.read("resources/balises.csv").decode("ascii")))
        fmu_distance = {int(r["balise_id"]): float(r["distance_m"]) for r in rows}
    passages = sorted(
        (fmu_distance[int(item.number)], (item.offset - fmu_distance[int(item.number)]) * 1000.0)
        for item in route.items.values()
        if item.kind == "SpeedPostItem" and item.number is not None
    )

    figure = plt.figure(figsize=(12, 9), constrained_layout=True)
    grid = figure.add_gridspec(3, 2, height_ratios=[2.2, 1, 1])
    whole = figure.add_subplot(grid[0, 0])
    whole.plot(spline[:, 0] / 1000, spline[:, 1] / 1000, color="0.6", lw=4, label="railML B-spline")
    whole.plot(
        exported[:, 0] / 1000,
        exported[:, 1] / 1000,
        color="tab:blue",
        lw=1,
        label="exported sections (OpenRails)",
    )
    whole.set(
        xlabel="east [km]",
        ylabel="north [km]",
        aspect="equal",
        title=f"{route.name}: {len(node.sections)} sections over {node.length / 1000:.1f} km",
    )
    whole.legend(loc="lower left")
    # a close-up of 120 m around the tightest curve
    k = int(np.argmax([abs(s.shape.angle) / s.shape.length for s in node.sections]))
    centre = starts[k]
    near = (distances > centre - 60) & (distances < centre + 60)
    close = figure.add_subplot(grid[0, 1])
    close.plot(spline[near, 0], spline[near, 1], color="0.6", lw=6, label="railML B-spline")
    close.plot(exported[near, 0], exported[near, 1], color="tab:blue", lw=1.2, label="exported")
    inside = (starts > centre - 60) & (starts < centre + 60)
    close.plot(section_xy[inside, 0], section_xy[inside, 1], "k|", ms=12, label="section starts")
    close.set(
        xlabel="east [m]",
        ylabel="north [m]",
        aspect="equal",
        title=f"close-up at {centre:.0f} m: radius {node.sections[k].shape.radius:.0f} m, "
        f"{model.gradient(centre):+.1f} ‰ grade",
    )
    close.legend(loc="best")
    across = figure.add_subplot(grid[1, :])
    across.plot(distances / 1000, lateral, lw=0.6)
    across.axhline(10, color="tab:red", lw=0.8, ls="--")
    across.axhline(-10, color="tab:red", lw=0.8, ls="--", label="±10 mm target")
    across.set(
        xlabel="distance along the line [km]",
        ylabel="across the track [mm]",
        title=f"exported track minus railML B-spline, across the track: max "
        f"{np.max(np.abs(lateral)):.2f} mm",
    )
    across.legend(loc="upper right")
    balise = figure.add_subplot(grid[2, :])
    balise.plot([p[0] / 1000 for p in passages], [p[1] for p in passages], "o", ms=3)
    worst = max(abs(p[1]) for p in passages)
    balise.axhline(0, color="0.6", lw=0.8)
    balise.set(
        xlabel="distance along the line [km]",
        ylabel="difference [mm]",
        ylim=(-3, 3),
        title=f"{len(passages)} balises: passage on the mock's track database minus the "
        f"TrackBalises FMU's B-spline distance (max {worst:.2f} mm; target 50 mm)",
    )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(OUT, dpi=110)
    print(
        f"wrote {OUT}: max across {np.max(np.abs(lateral)):.2f} mm, balises {worst:.2f} mm, "
        f"{math.fsum(s.shape.length for s in node.sections) - model.length:+.6f} m length"
    )


if __name__ == "__main__":
    main()
