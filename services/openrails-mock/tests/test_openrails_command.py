"""The mock started the way OpenRails' simulation client starts OpenRails.

    the client's command line (its get_synced_command's form) --sh--> launcher/RunActivity.exe
        --> openrails-mock: GET /API/READY, /API/TIME, /API/ENVIRONMENT, /API/CAMERASENSOR/cam

The command is written here from the client's format (DLR-SE/openrails-for-simulation,
``Dlr/simulation_client/openrails_interface/open_rails_server_interface.py``:
``-start -syncsimulation "<route>\\PATHS\\<n>.pat" "<consist>" HH:MM <season> <weather>
<step_ms> <trains json> <sensors json> port=<port>``), with the route path joined by a
backslash as the client joins it, and run by a shell as one string (the client hands
``subprocess.Popen`` one string, which a shell splits on Linux).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from coupler.testing import end_group, free_port, wait_until
from coupler_railway.openrails.export import export_route

ROOT = Path(__file__).resolve().parents[3]
LAUNCHER = ROOT / "services" / "openrails-mock" / "launcher" / "RunActivity.exe"
TEST_LINE = ROOT / "packages" / "railway" / "tests" / "data" / "test-line.railml"


def get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=10) as answer:
        data: bytes = answer.read()
        return data


def synced_command(
    exe: Path, route: Path, path: str, consist: str, hh_mm: str, season: int, weather: int,
    step_ms: int, trains: Path, sensors: Path, port: int,
) -> str:  # fmt: skip
    ego_route = str(route) + "\\PATHS\\" + path + ".pat"
    return (
        f'{exe} -start -syncsimulation "{ego_route}" "{consist}" {hh_mm} {season} {weather} '
        f"{step_ms} {trains} {sensors} port={port}"
    )


@pytest.mark.slow
def test_the_clients_launch_command_starts_the_mock_with_its_world(tmp_path: Path) -> None:
    route = tmp_path / "routes" / "test-line"
    export_route(TEST_LINE, route)
    trains = tmp_path / "trains.json"
    trains.write_text("[]")
    sensors = tmp_path / "sensors.json"
    sensors.write_text(json.dumps([{"sensorName": "cam", "sensorType": "rgb",
                                    "trainName": "PLAYER", "width": 80, "height": 60,
                                    "fov": 45.0}]))  # fmt: skip
    port = free_port()
    command = synced_command(
        LAUNCHER, route, "ocpW-ocpN", "Dlr\\BR642", "23:30", 3, 1, 250, trains, sensors, port
    )
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    mock = subprocess.Popen(
        command, shell=True, env=env, cwd=tmp_path, start_new_session=True,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    base = f"http://127.0.0.1:{port}/API"
    try:

        def ready() -> bool:
            assert mock.poll() is None, mock.communicate()[0]
            try:
                get(f"{base}/READY")
            except OSError:
                return False
            return True

        wait_until(ready, 60, what="the mock's READY")
        assert json.loads(get(f"{base}/TIME")) == 23.5 * 3600  # 23:30, as passed
        world = json.loads(get(f"{base}/ENVIRONMENT"))["conditions"]
        assert (world["season"], world["weather"], world["light"]) == ("winter", "snow", "sun")
        frame = np.frombuffer(get(f"{base}/CAMERASENSOR/cam"), np.uint8).reshape(60, 80, 3)
        assert frame[:20].mean() < 10  # a night sky: the time took effect on the frame too
        step = urllib.request.Request(
            f"{base}/CABCONTROLS",
            data=json.dumps({"Controls": [], "Commands": [], "SwitchCommands": {}}).encode(),
            method="POST",
        )
        with urllib.request.urlopen(step, timeout=10) as answer:
            reply = json.loads(answer.read())
        assert set(reply["CameraSensors"]) == {"cam"}  # the sensors it passed
        assert json.loads(get(f"{base}/TIME")) == pytest.approx(23.5 * 3600 + 0.25)  # 250 ms
    finally:
        end_group(mock)


def test_a_route_that_does_not_exist_here_is_one_clear_error(tmp_path: Path) -> None:
    command = [sys.executable, "-m", "openrails_mock", "-start", "-explore",
               "C:\\OR\\ROUTES\\Nowhere\\PATHS\\1.pat", "BR642", "12:00", "0", "0",
               "port=0"]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    assert "the route folder 'C:/OR/ROUTES/Nowhere'" in done.stderr
    assert "does not exist here" in done.stderr
