"""The TrackBalises FMU standalone through FMPy and through the FMU host service under the
orchestrator give the same outputs.

    Source (FMU, ramp = 7 m/s * t) == ramp ==> TrackBalises (balise-fmu host process)

FMPy applies the input signal position(t_k) = 7 * t_k before each doStep(t_k, h) (sampled at
every communication point, so no interpolation rounds it differently); under
Jacobi the host's FMU steps from t_k on Source.ramp(t_k) = 7 * t_k: the same inputs, so every
output must be equal to the last bit.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import fmpy
import numpy as np
import pytest

from balise_fmu.build import build_track_balises
from coupler.testing import Component, Connector, SystemStructure, free_port, remote
from coupler.testing.ssd import FMU
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.runner import run_scenario
from coupler_orchestrator.tools.fleet import Fleet, FleetSpec, ServiceSpec

ROOT = Path(__file__).resolve().parents[2]
TEST_LINE = ROOT / "packages" / "railway" / "tests" / "data" / "test-line.railml"
SOURCE_FMU = ROOT / "build" / "fmus" / "Source2.fmu"
SLOPE, STEP, STOP = 7.0, 0.5, 260.0
OUTPUTS = (
    "last_balise_id",
    "last_group_id",
    "last_balise_distance",
    "balises_passed",
    "latitude",
    "longitude",
)


def host_check(port: int) -> SystemStructure:
    """Source2 (slope SLOPE, in-process) --ramp--> TrackBalises.position [m], served at ``port``."""
    source = Component(
        "Source",
        "Source2.fmu",
        type=FMU,
        connectors=[Connector("ramp", "output", "Real")],
        parameters={"slope": SLOPE},
    )
    position = Connector("position", "input", "Real", "m")
    balises = remote("TrackBalises", f"grpc://127.0.0.1:{port}", position)
    return SystemStructure(
        "HostCheck",
        [source, balises],
        [("Source.ramp", "TrackBalises.position")],
        stop_time=None,
        units={"m": {"m": 1}},
    )


@pytest.mark.slow
async def test_host_under_coupler_run_equals_fmpy(tmp_path: Path) -> None:
    if not SOURCE_FMU.exists():
        pytest.fail(f"{SOURCE_FMU} is missing: run 'make setup' (make test does)")
    fmu = build_track_balises(TEST_LINE, tmp_path / "TrackBalises.fmu")
    shutil.copy(SOURCE_FMU, tmp_path / "Source2.fmu")
    port = free_port()
    ssd = host_check(port).write(tmp_path / "SystemStructure.ssd")

    # one sample per communication point, each exactly what the Source FMU computes
    times = np.arange(0.0, STOP + STEP, STEP)
    signal = np.array(
        list(zip(times, SLOPE * times, strict=True)),
        dtype=[("time", np.float64), ("position", np.float64)],
    )
    reference = fmpy.simulate_fmu(
        str(fmu), stop_time=STOP, output_interval=STEP, input=signal, output=list(OUTPUTS)
    )

    host = ServiceSpec(
        name="e2e-balise-host",
        command=(
            "python",
            "-m",
            "balise_fmu",
            "--port",
            str(port),
            "--fmu",
            str(fmu),
            "--name",
            "TrackBalises",
        ),
        health=f"grpc://127.0.0.1:{port}",
    )
    async with Fleet(FleetSpec(root=ROOT, ssp=ssd, out=tmp_path, services=(host,))):
        outcome = await run_scenario(
            ssd, RunOptions(stop_time=STOP, step_size=STEP), out_dir=tmp_path / "out"
        )
    assert outcome.end.status == "completed", outcome.end.reason
    with outcome.results_csv.open(newline="") as file:
        rows = list(csv.DictReader(file))

    assert len(rows) == len(reference)
    assert int(rows[-1]["TrackBalises.balises_passed"]) == 7  # every balise of the test line
    for row, expected in zip(rows, reference, strict=True):
        assert float(row["time"]) == expected["time"]
        for name in OUTPUTS:
            assert float(row[f"TrackBalises.{name}"]) == float(expected[name]), (name, row["time"])
