"""The railway scenario's localisation variant end to end: `coupler fleet` with the variant's
services as real local processes (the OpenRails mock, the bridge, the TrackBalises FMU host,
the map, and services/localisation three times), the map in Chromium, the run scored.

    Driver (FMU) == throttle, brake ==> OpenRails bridge ==HTTP==> OpenRails mock
    OpenRails == distance ==> TrackBalises == passed_in_step ==> BaliseTransmission
    OpenRails == distance, speed, acceleration, wheelslip, wheelskid ==> Odometer
    Odometer, BaliseTransmission ==> Localisation == estimate, interval ==> Map

The fleet file is the scenario's own (scenarios/railway/localisation-fleet.toml): its services,
commands and health checks, with the run's options replaced. Nominal odometry over the whole
26 km line: the true front end inside the interval at every step, every group read, no
linking error. Every balise of group 104 lost: the linking error raised, naming it.
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from coupler.testing import free_ports
from coupler_dev.browser import CHROMIUM, chromium

ROOT = Path(__file__).resolve().parents[2]
FLEET = ROOT / "scenarios" / "railway" / "localisation-fleet.toml"
FMUS = ROOT / "build" / "fmus"
COUPLER = Path(sys.executable).parent / "coupler"
ARTIFACT = ROOT / "test-artifacts" / "railway-localisation-map.png"
PORTS = ("MOCK_PORT", "BRIDGE_PORT", "BALISE_PORT", "MAP_PORT", "MAP_HTTP_PORT",
         "MONITOR_PORT", "LOCALISATION_PORT", "ODOMETER_PORT", "TRANSMISSION_PORT")  # fmt: skip

pytestmark = pytest.mark.timeout(900)

SHOWN = """() => {
  const c = window.coupler;
  const loc = c && c.localisation;
  if (!(loc && loc.interval.length > 1 && c.estimateLatLng() && c.train &&
        loc.max_m - loc.min_m > 60 && document.getElementById('interval-line'))) return null;
  return {loc, panel: !document.getElementById('localisation-panel').hidden,
          inside: document.getElementById('inside').textContent,
          interval: document.getElementById('interval').textContent};
}"""
"""The map once it shows an estimate with an interval over 60 m wide; null until then."""


def fleet(folder: Path, out: Path, args: list[str]) -> Path:
    """The scenario's fleet file with the run's options ``args``, written to ``out``."""
    text = FLEET.read_text()
    services = text[text.index("[[service]]") :]
    path = folder / "fleet.toml"
    path.write_text(
        f'[scenario]\nssp = "scenarios/railway/Localisation.ssd"\nout = "{out}"\n'
        f"args = {json.dumps(args)}\n\n{services}"
    )
    return path


async def watch(url: str, process: subprocess.Popen[str]) -> dict[str, Any]:
    deadline = time.monotonic() + 180
    async with aiohttp.ClientSession() as session:
        while True:
            assert process.poll() is None, "the fleet ended before the map served"
            assert time.monotonic() < deadline, f"the map at {url} did not answer"
            try:
                async with session.get(url + "healthz") as response:
                    if response.status == 200:
                        break
            except aiohttp.ClientError:
                pass
            await asyncio.sleep(0.5)
    async with chromium() as browser:
        page = await browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        await page.goto(url)
        await page.evaluate("() => { document.getElementById('follow').click(); }")
        seen = await (await page.wait_for_function(SHOWN, timeout=300_000)).json_value()
        await page.evaluate("() => window.coupler.map.setZoom(18, {animate: false})")
        await page.wait_for_timeout(500)
        ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=str(ARTIFACT))
        assert errors == []
    return dict(seen)


def run_fleet(
    tmp_path: Path, args: list[str], realtime: str, browser: bool
) -> tuple[Path, dict[str, Any] | None]:
    for fmu in ("Driver2.fmu", "TrackBalises.fmu"):
        if not (FMUS / fmu).exists():
            pytest.fail(f"{FMUS / fmu} is missing: run 'make setup' (make test does)")
    out = tmp_path / "run"
    ports = {name: str(port) for name, port in zip(PORTS, free_ports(len(PORTS)), strict=True)}
    command = [str(COUPLER), "fleet", str(fleet(tmp_path, out, args)), "--exit",
               "--realtime-factor", realtime]  # fmt: skip
    seen = None
    with subprocess.Popen(
        command,
        cwd=ROOT,
        env={**os.environ, **ports},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as process:
        try:
            if browser:
                url = f"http://127.0.0.1:{ports['MAP_HTTP_PORT']}/"
                seen = asyncio.run(watch(url, process))
            output, _ = process.communicate(timeout=800)
        finally:
            if process.poll() is None:
                process.terminate()
    assert process.returncode == 0, output[-3000:]
    return out / "latest", seen


@pytest.mark.slow
def test_nominal_odometry_keeps_the_truth_inside_over_the_whole_line(tmp_path: Path) -> None:
    out, seen = run_fleet(tmp_path, [], "40", CHROMIUM.exists())
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["end_time"] == 1800.0
    report = summary["reports"]["localisation"]
    assert report["integrity"] is True and report["violations"] == 0
    assert report["groups_passed"] == 35 and report["linking_errors"] == 0
    assert report["error_max_m"] < 20.0 and report["width_max_m"] > report["error_max_m"]
    # the train reached Schwarzenberg: the whole line was scored
    assert summary["reports"]["localisation"]["steps"] == 1801
    rows = (out / "localisation-report.csv").read_text().splitlines()
    assert rows[-1].split(",")[1].startswith("2595")  # the true front end at the end [m]
    assert all(line.endswith(",True") for line in rows[1:])
    # the scoring command gives the same figures
    scored = subprocess.run(
        [sys.executable, "-m", "coupler_railway.integrity", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert scored.returncode == 0, scored.stderr
    again = json.loads((out / "localisation-report.json").read_text())
    assert {k: again[k] for k in ("integrity", "error_max_m", "width_max_m")} == {
        k: report[k] for k in ("integrity", "error_max_m", "width_max_m")
    }
    if seen is not None:  # the map showed the estimate and its interval beside the train
        assert seen["panel"] and seen["inside"] == "yes"
        loc = seen["loc"]
        assert seen["interval"].startswith(f"{loc['min_m']:.1f} \u2013 {loc['max_m']:.1f} m")
        assert loc["min_m"] <= loc["estimate_m"] <= loc["max_m"]
        assert loc["min_m"] <= loc["true_m"] <= loc["max_m"]


@pytest.mark.slow
def test_a_whole_group_lost_raises_the_linking_error(tmp_path: Path) -> None:
    args = ["--stop-time", "200", "--param", "BaliseTransmission.lost_groups=104"]
    out, _ = run_fleet(tmp_path, args, "0", browser=False)
    report = json.loads((out / "summary.json").read_text())["reports"]["localisation"]
    assert report["not_read_groups"] == [104]
    assert report["linking_errors"] == 1 and report["detected"] == 1
    assert report["missed"] == 0 and report["false_alarms"] == 0
    assert report["linking_events"][0]["group_id"] == 104
    assert report["integrity"] is True
