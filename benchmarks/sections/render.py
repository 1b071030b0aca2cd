"""Render: the OpenRails mock's camera frames on the Annaberg-Schwarzenberg line (one core, this
process's CPU time): an 800 x 600 RGB frame in the clear scene against 25 ms and with every
condition on against 40 ms (issue 44's targets), every condition's worst frame against the
200 ms of one OpenRails lockstep step (issue 38), what each condition costs alone, and an
800 x 600 RGB with a 200 x 150 depth frame per position against the 200 ms step.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import ROOT, Row, Sizes, median_of

RAILML = ROOT / "scenarios" / "railway" / "data" / "annaberg-schwarzenberg.railml"


OPENRAILS_STEP_S = 0.2
"""OpenRails' lockstep step: the time a frame pair may take."""


async def render(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The OpenRails mock's renderer on one core (this process's CPU time): an 800 x 600 frame
    in the clear scene and with every condition on against the targets of issue 44 (25 and
    40 ms median), every condition against one OpenRails step (issue 38: 200 ms, worst
    frame), what each condition costs alone, and a frame pair with depth as the mock serves
    them."""
    log("render: the mock's 800 x 600 frames, clear and with every condition, one core")
    times = render_times(
        sizes.render_positions, {"clear": {}, "every": EVERY_CONDITION, **CONDITIONS_ALONE}
    )
    clear, everything = times["clear"], times["every"]
    costs = {  # the median of the differences at the same places, rendered in turns
        name: round(median_of([a - b for a, b in zip(times[name], clear, strict=True)]), 1)
        for name in CONDITIONS_ALONE
    }
    extra["render_ms"] = {
        "clear": {"median": round(median_of(clear), 1), "max": round(max(clear), 1)},
        "every condition": {"median": round(median_of(everything), 1),
                            "max": round(max(everything), 1)},
        "cost of each condition alone": costs,
    }  # fmt: skip
    log("  cost of each condition alone [ms over clear]: "
        + ", ".join(f"{n} {ms:+.1f}" for n, ms in costs.items()))  # fmt: skip
    rows.append(
        Row("render 800x600 rgb, clear", 1000 / median_of(clear), "the 25 ms target", 40.0, 1.0,
            note=f"frames/s; {median_of(clear):.1f} ms median, {max(clear):.0f} ms worst")
    )  # fmt: skip
    rows.append(
        Row("render 800x600 rgb, every condition", 1000 / median_of(everything),
            "the 40 ms target", 25.0, 1.0,
            note=f"frames/s; {median_of(everything):.1f} ms median, {max(everything):.0f} ms "
                 "worst: sun and shadows, trees, roofs, snow, rain, fog, dirt, leaves, noise, "
                 "motion blur, auto-exposure, JPEG")
    )  # fmt: skip
    rows.append(
        Row("render every condition, worst frame", 1000 / max(everything),
            "one OpenRails step (200 ms)", 1.0 / OPENRAILS_STEP_S, 1.0,
            note="frames/s of the slowest frame")
    )  # fmt: skip
    pairs, typical, worst = render_rate(sizes.render_positions)
    extra["render_pair_ms"] = {"median": round(typical, 1), "max": round(worst, 1)}
    rows.append(
        Row("render 800x600 rgb + 200x150 depth", pairs, "one OpenRails step (200 ms)",
            1.0 / OPENRAILS_STEP_S, 1.0,
            note=f"frame pairs/s; {typical:.0f} ms median, {worst:.0f} ms worst, one core")
    )  # fmt: skip


EVERY_CONDITION: dict[str, Any] = {
    "light": "sun", "season": "winter", "weather": "snow", "rain_mm_per_h": 2.0,
    "visibility_m": 300.0, "dirt": 0.5, "leaves_per_m2": 0.3, "trees_per_km": 40.0,
    "platform_roofs": True, "noise": True, "motion_blur": True, "jpeg_quality": 80,
}  # fmt: skip
"""Every condition of the mock's renderer at once (issue 38's budget row)."""


CONDITIONS_ALONE: dict[str, dict[str, Any]] = {
    "sun, shadows, headlights, auto-exposure": {"light": "sun"},
    "trees (40/km) and platform roofs": {"trees_per_km": 40.0, "platform_roofs": True},
    "fog (300 m)": {"visibility_m": 300.0},
    "rain (4 mm/h)": {"weather": "rain"},
    "snowfall and snow cover": {"season": "winter", "weather": "snow"},
    "dirt and leaves": {"dirt": 0.5, "leaves_per_m2": 0.3},
    "sensor noise": {"noise": True},
    "motion blur": {"motion_blur": True, "exposure_ms": 4.0, "gain": 0.25},
    "JPEG (quality 80)": {"jpeg_quality": 80},
}
"""What each condition costs, alone."""


def render_times(positions: int, cases: dict[str, dict[str, Any]]) -> dict[str, list[float]]:
    """Milliseconds of this process's CPU time per 800 x 600 colour frame under each case's
    conditions at ``positions`` places 250 m apart on the Annaberg-Schwarzenberg line (at
    16 m/s, 15:00), the cases rendered in turns at each place (a busy moment hits them
    alike)."""
    from coupler_railway import load_infrastructure
    from openrails_mock.conditions import Conditions
    from openrails_mock.renderer import CameraModel, Renderer, View
    from openrails_mock.scene import Scene

    scene = Scene.of_infrastructure(load_infrastructure(RAILML))
    renderers = {
        name: Renderer(scene, conditions=Conditions(**conditions))
        for name, conditions in cases.items()
    }
    rgb = CameraModel(width=800, height=600, fov_deg=45.0)
    for renderer in renderers.values():  # compile or load the kernels
        renderer.render(rgb, 100.0, View(speed_mps=16.0))
    took: dict[str, list[float]] = {name: [] for name in cases}
    for k in range(positions):
        view = View(elapsed_s=10.0 * k, clock_s=15 * 3600.0 + 10.0 * k, speed_mps=16.0)
        for name, renderer in renderers.items():
            begun = time.process_time()
            renderer.render(rgb, 60.0 + 250.0 * k, view).pixels.tobytes()
            took[name].append(1000 * (time.process_time() - begun))
    return took


def render_rate(positions: int) -> tuple[float, float, float]:
    """Frame pairs per second of one core (800 x 600 RGB + 200 x 150 depth, as the mock serves
    them) over ``positions`` places 250 m apart, and the median and worst milliseconds of a
    pair: this process's CPU time, so that other work on a busy machine does not count."""
    from coupler_railway import load_infrastructure
    from openrails_mock.renderer import CameraModel, Renderer
    from openrails_mock.scene import Scene

    renderer = Renderer(Scene.of_infrastructure(load_infrastructure(RAILML)))
    rgb = CameraModel(width=800, height=600, fov_deg=45.0)
    depth = CameraModel(width=200, height=150, fov_deg=45.0)
    renderer.rgb(rgb, 100.0), renderer.depth(depth, 100.0, 200.0)  # warm the caches
    took = []
    for k in range(positions):
        at = 60.0 + 250.0 * k
        begun = time.process_time()
        renderer.rgb(rgb, at).tobytes()
        renderer.depth(depth, at, 200.0).astype("<u2").tobytes()
        took.append(time.process_time() - begun)
    return 1.0 / median_of(took), 1000 * median_of(took), 1000 * max(took)
