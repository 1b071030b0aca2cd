"""The OpenRails bridge exported as an FMU and driven by FMPy against the mock, 60 s of
simulated time: the train's distance equals the same run under ``coupler run``.

    FMPy --FMI 2--> OpenRails.fmu (proxy) --gRPC--> python -m openrails_bridge --HTTP--> mock
    coupler run --------------------------gRPC--> python -m openrails_bridge --HTTP--> mock

Each run gets a fresh mock and bridge (the mock, like OpenRails, cannot be reset).
"""

from __future__ import annotations

import asyncio
import csv
import importlib.util
import json
import os
import subprocess
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from coupler.testing import Connector, SystemStructure, free_port, remote
from coupler_orchestrator.tools import export_fmu as export
from coupler_orchestrator.tools.fleet import Fleet, FleetSpec

ROOT = Path(__file__).resolve().parents[2]
FLEET = ROOT / "scenarios" / "railway" / "fleet.toml"
DRIVER = ROOT / "services" / "orchestrator" / "tests" / "tools" / "fmpy_driver.py"
STARTS = {"throttle": 0.8, "brake": 0.0, "direction": 1}
STOP, STEP = 60.0, 1.0  # whole multiples of the lockstep 0.2 s, exact in binary

BRIDGE_CONNECTORS = [
    Connector("throttle", "input", "Real"),
    Connector("brake", "input", "Real"),
    Connector("direction", "input", "Integer"),
    Connector("distance", "output", "Real", "m"),
    Connector("speed", "output", "Real", "m/s"),
]


def bridge_ssd(address: str) -> SystemStructure:
    """The OpenRails bridge alone at ``address`` (a gRPC address or an exported FMU)."""
    bridge = remote("OpenRails", address, *BRIDGE_CONNECTORS)
    units = {"m": {"m": 1}, "m/s": {"m": 1, "s": -1}}
    return SystemStructure("Bridge", [bridge], start_time=0.0, stop_time=STOP, units=units)


pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def proxy_binaries() -> Path:
    """The proxy FMU's binaries of the installed coupler-native (skipped only without it)."""
    try:
        return export.proxy_binaries()
    except export.ProxyMissing as exc:
        if importlib.util.find_spec("coupler_native") is None:
            pytest.skip(str(exc))
        raise


@asynccontextmanager
async def openrails(tmp_path: Path) -> AsyncIterator[str]:
    """A fresh mock and bridge as the railway fleet (`make demo`) starts them, on free ports;
    the bridge's address."""
    ports = {"MOCK_PORT": str(free_port()), "BRIDGE_PORT": str(free_port())}
    railway = FleetSpec.load(FLEET, root=ROOT, env={**os.environ, **ports})
    spec = replace(
        railway,
        out=tmp_path / "fleet",
        services=tuple(s for s in railway.services if s.name.startswith("openrails-")),
    )
    assert len(spec.services) == 2, spec.services
    async with Fleet(spec, health_timeout=60):
        yield f"grpc://127.0.0.1:{ports['BRIDGE_PORT']}"


async def command(argv: list[str], **options: Any) -> subprocess.CompletedProcess[str]:
    """``subprocess.run`` off the event loop (the fleet's services stay watched)."""
    return await asyncio.to_thread(
        subprocess.run, argv, capture_output=True, text=True, check=False, **options
    )


@pytest.mark.slow
async def test_bridge_exported_under_fmpy_drives_the_train_as_coupler_run_does(
    tmp_path: Path, proxy_binaries: Path
) -> None:
    fmu = tmp_path / "OpenRails.fmu"
    async with openrails(tmp_path) as bridge:
        exported = await command(
            [sys.executable, "-m", "coupler_orchestrator", "export-fmu", bridge, "--out", str(fmu)],
            timeout=120,
        )
        assert exported.returncode == 0, exported.stderr
        spec = tmp_path / "spec.json"
        spec.write_text(
            json.dumps(
                {
                    "runs": [
                        {
                            "fmu": str(fmu),
                            "stop": STOP,
                            "step": STEP,
                            "start_values": STARTS,
                            "outputs": ["distance", "speed"],
                        }
                    ]
                }
            )
        )
        driven = await command(
            [sys.executable, str(DRIVER), str(spec)],
            timeout=180,
            env=dict(os.environ),
        )
    answer = json.loads(driven.stdout.strip().splitlines()[-1])
    assert "results" in answer, driven.stdout + driven.stderr
    fmpy = answer["results"][0]

    async with openrails(tmp_path) as bridge:
        ssd = bridge_ssd(bridge).write(tmp_path / "bridge.ssd")
        params = [f"--param=OpenRails.{k}={v}" for k, v in STARTS.items()]
        run = await command(
            [
                sys.executable,
                "-m",
                "coupler_orchestrator",
                "run",
                str(ssd),
                "--step",
                str(STEP),
                "--out",
                str(tmp_path / "direct"),
                *params,
            ],
            timeout=180,
        )
        assert run.returncode == 0, run.stderr
    with (tmp_path / "direct" / "results.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    distance = [float(r["OpenRails.distance"]) for r in rows]
    print(
        f"distance after {STOP:g} s: FMPy via the FMU {fmpy['distance'][-1]:.3f} m, "
        f"coupler run {distance[-1]:.3f} m"
    )
    assert distance[-1] > 50  # the train did move
    assert fmpy["time"] == [float(r["time"]) for r in rows]
    assert fmpy["distance"] == distance
    assert fmpy["speed"] == [float(r["OpenRails.speed"]) for r in rows]
