"""The gallery of docs/railway-perception.md: one place on the Annaberg-Schwarzenberg line
under each condition, rendered by the OpenRails mock's renderer (800 x 600, as the perception
fleet's camera), written as PNG files into docs/img/conditions/.

    .venv/bin/python scripts/conditions-gallery.py [--out docs/img/conditions]

The place: 21.7 m before balise 1050 at Annaberg-Buchholz Süd (the platform on the left, the
exit signal ahead), the train at 15 m/s; each frame is what the mock serves for that state.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from PIL import Image

from coupler_railway import load_infrastructure
from openrails_mock.conditions import Conditions
from openrails_mock.renderer import CameraModel, Renderer, View
from openrails_mock.scene import Scene

ROOT = Path(__file__).resolve().parents[1]
RAILML = ROOT / "scenarios" / "railway" / "data" / "annaberg-schwarzenberg.railml"
FRONT_M = 2100.0
CASES: dict[str, tuple[str, dict[str, Any], float]] = {
    "clear": ("the default: the clear-noon look", {}, 12.0),
    "noon": ("12:00 in summer, the sun of the place, trees and a platform roof",
             {"light": "sun", "trees_per_km": 30.0, "platform_roofs": True}, 12.0),
    "dusk": ("20:30 in summer (the sun 3 degrees below the horizon), auto-exposure and noise",
             {"light": "sun", "noise": True}, 20.5),
    "night": ("23:00, the headlights on", {"light": "sun", "noise": True}, 23.0),
    "night-dark": ("23:00, the headlights off", {"light": "sun", "headlights": False,
                                                  "noise": True}, 23.0),
    "fog": ("fog, visibility 50 m", {"visibility_m": 50.0}, 12.0),
    "rain": ("rain, 4 mm/h at noon", {"light": "sun", "weather": "rain"}, 12.0),
    "snow": ("winter snow at noon: snowfall 1 mm/h, 60 % of each balise under snow",
             {"light": "sun", "season": "winter", "weather": "snow"}, 12.0),
    "autumn": ("autumn leaves and a dirty balise (dirt 0.6)",
               {"season": "autumn", "dirt": 0.6}, 12.0),
}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "conditions")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    scene = Scene.of_infrastructure(load_infrastructure(RAILML))
    camera = CameraModel(width=800, height=600, fov_deg=45.0)
    for name, (what, conditions, hour) in CASES.items():
        renderer = Renderer(scene, conditions=Conditions(**conditions))
        view = View(elapsed_s=1.0, clock_s=hour * 3600.0, speed_mps=15.0)
        frame = renderer.render(camera, FRONT_M, view)
        Image.fromarray(frame.pixels).save(args.out / f"{name}.png", optimize=True)
        balise = next((x for x in frame.labels if (x.kind, x.id) == ("balise", 1050)), None)
        seen = f"{balise.visible_fraction:.2f}" if balise else "-"
        print(f"{name}.png: {what}; balise 1050 visible fraction {seen}, exposure "
              f"{frame.exposure_ms:.2f} ms, gain {frame.gain:.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
