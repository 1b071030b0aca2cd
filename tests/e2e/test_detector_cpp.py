"""A balise detector in C++, written from the .proto files alone (examples/detector-cpp), in the
railway scenario's perception fleet end to end, scored as the Python detector is.

    Driver (FMU) == throttle, brake ==> OpenRails bridge ==HTTP==> OpenRails mock (camera)
    OpenRails bridge == front (800 x 600 Image), train_state ==> balise-detector (C++)
    balise-detector == detections ==> Map;  OpenRails == distance ==> TrackBalises

The fleet file is scenarios/railway/perception-cpp-fleet.toml, its run stopped at 40 s (the
first two balise groups). The detector is built with Debian's C++ gRPC (`make detector-cpp`;
built here when missing); without that tool chain the test is skipped, saying what to install.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from coupler.testing import free_ports

ROOT = Path(__file__).resolve().parents[2]
FLEET = ROOT / "scenarios" / "railway" / "perception-cpp-fleet.toml"
DETECTOR = ROOT / "build" / "detector-cpp" / "balise-detector"
PORTS = ("MOCK_PORT", "BRIDGE_PORT", "BALISE_PORT", "PERCEPTION_PORT", "MAP_PORT",
         "MAP_HTTP_PORT", "MONITOR_PORT")  # fmt: skip
TOOLS = ("cmake", "protoc", "grpc_cpp_plugin", "pkg-config")

pytestmark = pytest.mark.timeout(900)


def detector() -> Path:
    """The built detector; built here when missing (skipped without the tool chain)."""
    if DETECTOR.exists():
        return DETECTOR
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    found = subprocess.run(["pkg-config", "--exists", "grpc++", "protobuf"], check=False)
    if missing or found.returncode != 0:
        pytest.skip(
            f"the C++ detector needs {', '.join(missing) or 'libgrpc++-dev'}: "
            "scripts/install-grpc-dev.sh (make grpc-dev) installs Debian's C++ gRPC"
        )
    built = subprocess.run(["make", "detector-cpp"], cwd=ROOT, capture_output=True, text=True)
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    return DETECTOR


@pytest.mark.slow
def test_the_cpp_detector_runs_in_the_perception_fleet_and_is_scored(tmp_path: Path) -> None:
    detector()
    out = tmp_path / "run"
    text = FLEET.read_text()
    services = text[text.index("[[service]]") :]
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(
        f'[scenario]\nssp = "scenarios/railway/Perception.ssd"\nout = "{out}"\n'
        f'args = ["--stop-time", "40"]\n\n{services}'
    )
    ports = {name: str(port) for name, port in zip(PORTS, free_ports(len(PORTS)), strict=True)}
    done = subprocess.run(
        [str(Path(sys.executable).with_name("coupler")), "fleet", str(fleet), "--exit",
         "--realtime-factor", "0"],
        cwd=ROOT, env={**os.environ, **ports}, capture_output=True, text=True, timeout=600,
        stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    summary = json.loads((out / "latest" / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["implementations"]["Perception"].startswith("examples/detector-cpp (C++")
    report = summary["reports"]["perception"]
    assert (report["balises_passed"], report["recall"], report["precision"]) == (5, 1.0, 1.0)
    assert report["max_abs_error_m"] < 1.0
    assert (out / "latest" / "perception-detections.csv").is_file()
