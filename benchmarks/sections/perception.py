"""The railway perception run end to end, as a user runs it: ``coupler fleet
scenarios/railway/perception-fleet.toml --exit --realtime-factor 0`` (the OpenRails mock with its
front camera, the bridge, TrackBalises, perception, the map and the orchestrator, each its own
process), timed by its summary.json; and its floor, the same frames (its results.csv's places
and times) rendered alone by the mock's renderer on one core under the same conditions."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sections.common import ROOT, Row, Sizes, free_ports
from sections.render import EVERY_CONDITION

FLEET = ROOT / "scenarios" / "railway" / "perception-fleet.toml"
MOCK_START_CLOCK_S = 8 * 3600.0
"""The mock's time of day at start when the run sets none (its ``start_time_s``)."""
CAMERA_PERIOD_S = 0.4
"""Perception.ssd's step: one camera frame a step."""

EVERY_CONDITION_PARAMETERS = {
    "OpenRails.time_of_day": "43200",
    "OpenRails.season": "winter",
    "OpenRails.weather": "snow",
    "OpenRails.light": "sun",
    "OpenRails.visibility": "300",
    "OpenRails.rain_rate": "2",
    "OpenRails.dirt": "0.5",
    "OpenRails.leaves": "0.3",
    "OpenRails.conditions": json.dumps(
        {"trees_per_km": 40.0, "platform_roofs": True, "noise": True, "motion_blur": True,
         "jpeg_quality": 80}
    ),
}  # fmt: skip
"""The heaviest condition set (the render rows' every condition), as the run's parameters."""


@dataclass(frozen=True)
class Run:
    stop_s: float
    steps: int
    stepping_s: float
    """summary.json's wall time: Initialize to Terminate (about 0.17 s of a 300-step run's
    4.9 s here is the two of them)."""
    total_s: float
    """The command's whole time: services started, route loaded, run, services stopped."""
    results: Path
    """Its results.csv."""

    @property
    def speed(self) -> float:
        """Simulated seconds per wall second of stepping."""
        return self.stop_s / self.stepping_s

    @property
    def overhead_s(self) -> float:
        return self.total_s - self.stepping_s


def run(work: Path, stop_s: float, parameters: dict[str, str], ports: list[int]) -> Run:
    """One unpaced perception run of ``stop_s`` simulated seconds on free ``ports`` (seven)."""
    names = ("MOCK_PORT", "BRIDGE_PORT", "BALISE_PORT", "PERCEPTION_PORT", "MAP_PORT",
             "MAP_HTTP_PORT", "MONITOR_PORT")  # fmt: skip
    environment = {**os.environ, **{n: str(p) for n, p in zip(names, ports, strict=True)}}
    out = work / "perception-run"
    command = [sys.executable, "-m", "coupler_orchestrator", "fleet", str(FLEET), "--exit",
               "--realtime-factor", "0", "--stop-time", f"{stop_s:g}", "--out", str(out),
               "--force"]  # fmt: skip
    for name, value in parameters.items():
        command += ["--param", f"{name}={value}"]
    begun = time.perf_counter()
    ran = subprocess.run(command, cwd=ROOT, env=environment, capture_output=True, text=True)
    total = time.perf_counter() - begun
    summary: dict[str, Any] = {}
    if (out / "summary.json").exists():
        summary = json.loads((out / "summary.json").read_text())
    if ran.returncode != 0 or summary.get("status") != "completed":
        raise RuntimeError(
            f"perception run: exit {ran.returncode}, {summary.get('status')}: "
            f"{summary.get('reason') or ran.stderr[-2000:]}"
        )
    return Run(stop_s, int(summary["steps"]), float(summary["wall_time_s"]), total,
               out / "results.csv")  # fmt: skip


def render_floor_s(results: Path, conditions: dict[str, Any], start_clock_s: float) -> float:
    """Seconds of one core to render, alone, the frames a run's camera took: each row of its
    ``results`` (results.csv: time, distance and speed) rendered 800 x 600 in colour under
    ``conditions`` by the mock's renderer on one thread from a run that started at
    ``start_clock_s`` (time of day), the CPU time of every frame summed."""
    import csv

    from coupler_railway import load_infrastructure
    from openrails_mock.conditions import Conditions
    from openrails_mock.physics import PRESETS
    from openrails_mock.renderer import CameraModel, Renderer, View
    from openrails_mock.scene import Scene

    railml = ROOT / "scenarios" / "railway" / "data" / "annaberg-schwarzenberg.railml"
    renderer = Renderer(Scene.of_infrastructure(load_infrastructure(railml)),
                        conditions=Conditions(**conditions), threads=1)  # fmt: skip
    rgb = CameraModel(width=800, height=600, fov_deg=45.0)
    renderer.render(rgb, 100.0, View(speed_mps=16.0))  # compile or load the kernels
    front_at_start_m = PRESETS["br642"].length_m  # the mock's train starts with its rear at 0
    took = 0.0
    with results.open(encoding="utf-8", newline="") as file:
        for row in csv.DictReader(file):
            t = float(row["time"])
            view = View(elapsed_s=t, clock_s=start_clock_s + t,
                        speed_mps=abs(float(row["OpenRails.speed"])))  # fmt: skip
            begun = time.process_time()
            renderer.render(rgb, front_at_start_m + float(row["OpenRails.distance"]), view)
            took += time.process_time() - begun
    return took


CAMPAIGN = """[scenario]
fleet = "scenarios/railway/perception-fleet.toml"
stop_time = {stop_s}
timeout = 600
keep_services = true
out = "{out}"

[grid]
"OpenRails.visibility" = [{visibilities}]

[outputs]
recall = "reports.perception.recall"
"""


@dataclass(frozen=True)
class Campaign:
    runs: int
    workers: int
    wall_s: float
    """The command's whole time, the Dask cluster's start and end included."""
    stepping_s: float
    """The runs' stepping (their summary.json wall times), summed."""

    @property
    def around_a_run_s(self) -> float:
        """A worker's time per run that is not the run's stepping."""
        return (self.wall_s * self.workers - self.stepping_s) / self.runs


def campaign(work: Path, runs: int, stop_s: float, workers: int = 2) -> Campaign:
    """``coupler campaign --scheduler local`` of ``runs`` perception runs of ``stop_s`` seconds
    (the fog's visibility varied), services kept between a worker's runs."""
    import csv

    out = work / "perception-campaign"
    path = work / "perception-campaign.toml"
    visibilities = ", ".join(f"{50.0 * (k + 1):g}" for k in range(runs))
    path.write_text(CAMPAIGN.format(stop_s=stop_s, out=out, visibilities=visibilities))
    command = [sys.executable, "-m", "coupler_orchestrator", "campaign", str(path), "--force",
               "--scheduler", "local", "--jobs", str(workers)]  # fmt: skip
    begun = time.perf_counter()
    ran = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - begun
    if ran.returncode != 0:
        raise RuntimeError(f"perception campaign: exit {ran.returncode}: {ran.stderr[-2000:]}")
    with (out / "campaign.csv").open(encoding="utf-8", newline="") as file:
        rows = list(csv.DictReader(file))
    return Campaign(len(rows), workers, wall, sum(float(r["wall_time_s"]) for r in rows))


async def perception(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The railway perception run end to end, unpaced, as ``coupler fleet`` runs it
    (py), in clear weather and under every condition: its speed against real
    time (targets 10x and 5x), and against its floor, the same frames rendered alone on one
    core (target 0.8); the time around the run (services up, route loaded, stopped)."""
    cases = {"clear": ({}, {}), "every condition": (
        EVERY_CONDITION_PARAMETERS, EVERY_CONDITION)}  # fmt: skip
    if sizes.repeats == 1:  # the smoke run: that it runs
        cases = {"clear": cases["clear"]}
    figures: dict[str, Any] = {}
    for name, (parameters, conditions) in cases.items():
        log(f"perception run, {name}: {sizes.perception_stop_s:g} s of the line")
        ran = await asyncio.to_thread(run, work, sizes.perception_stop_s, parameters, free_ports(7))
        start_clock_s = float(parameters.get("OpenRails.time_of_day", MOCK_START_CLOCK_S))
        floor_s = await asyncio.to_thread(render_floor_s, ran.results, conditions, start_clock_s)
        floor = ran.stop_s / floor_s
        figures[name] = {"frames": ran.steps, "stepping_s": round(ran.stepping_s, 2),
                         "render_alone_s": round(floor_s, 2),
                         "around_the_run_s": round(ran.overhead_s, 1)}  # fmt: skip
        target = 10.0 if name == "clear" else 5.0
        rows.append(
            Row(f"perception run, {name}", ran.speed, "real time", 1.0, target,
                note=f"x real time: {sizes.perception_stop_s:g} s of the line, {ran.steps} "
                     f"frames in {ran.stepping_s:.1f} s; {ran.overhead_s:.0f} s around the run")
        )  # fmt: skip
        rows.append(
            Row(f"perception run, {name}", ran.speed, "its frames rendered alone", floor, 0.8,
                note=f"the renderer alone on one core: {floor_s:.1f} s, {floor:.1f}x real time")
        )  # fmt: skip
    extra["perception_run"] = figures


async def perception_campaign(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """A campaign of short perception runs on a local Dask cluster of two workers, services
    kept between a worker's runs: the time a run costs around its stepping (target 3 s)."""
    runs = 2 if sizes.repeats == 1 else 12
    log(f"perception campaign: {runs} runs of 4 s of the line, 2 Dask workers")
    done = await asyncio.to_thread(campaign, work, runs, 4.0)
    extra["perception_campaign"] = {"runs": done.runs, "wall_s": round(done.wall_s, 1),
                                    "stepping_s": round(done.stepping_s, 1),
                                    "around_a_run_s": round(done.around_a_run_s, 2)}  # fmt: skip
    rows.append(
        Row("perception campaign, time around a run", 1.0 / done.around_a_run_s,
            "the 3 s target", 1.0 / 3.0, 1.0,
            note=f"runs/s of it: {done.around_a_run_s:.1f} s a run besides its stepping; "
                 f"{done.runs} runs in {done.wall_s:.0f} s, cluster start included")
    )  # fmt: skip
