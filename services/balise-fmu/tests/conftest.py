"""Shared fixtures: the TrackBalises FMUs (FMI 2.0 and 3.0) built for the railway test line,
and a driver that runs one through FMPy's low-level API with a given position per step."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import fmpy
import pytest

from balise_fmu.build import build_track_balises
from coupler_railway import Balise, Infrastructure, load_infrastructure

TEST_LINE = Path(__file__).resolve().parents[3] / "packages/railway/tests/data/test-line.railml"
OUTPUTS = (
    "last_balise_id",
    "last_group_id",
    "last_balise_distance",
    "balises_passed",
    "latitude",
    "longitude",
    "passed_in_step",
)

Row = dict[str, Any]
Drive = Callable[..., list[Row]]

requires_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")


@pytest.fixture(scope="session")
def infrastructure() -> Infrastructure:
    return load_infrastructure(TEST_LINE)


@pytest.fixture(scope="session")
def balises(infrastructure: Infrastructure) -> list[Balise]:
    """coupler_railway's balise table, in distance order: the reference for every test."""
    return sorted(infrastructure.balises, key=lambda b: b.distance_m)


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """TrackBalises.fmu (FMI 2.0) and TrackBalises3.fmu (FMI 3.0) for the test line."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    out = tmp_path_factory.mktemp("fmus")
    return {
        2: build_track_balises(TEST_LINE, out / "TrackBalises.fmu", fmi_version=2),
        3: build_track_balises(TEST_LINE, out / "TrackBalises3.fmu", fmi_version=3),
    }


def _drive(
    fmu: Path, positions: Sequence[float], *, antenna_offset: float = 0.0, step: float = 1.0
) -> list[Row]:
    """Instantiate with position = positions[0], then doStep(t_k, step) after setting
    position = positions[k] for k >= 1. Row 0: outputs after initialization; row k: after
    step k (the outputs at t_k = k*step for the position set before that step)."""
    md = fmpy.read_model_description(str(fmu))
    unzipdir = fmpy.extract(str(fmu))
    refs = {v.name: v.valueReference for v in md.modelVariables}
    v3 = md.fmiVersion == "3.0"
    slave: Any = fmpy.instantiate_fmu(unzipdir, md, fmi_type="CoSimulation")
    try:
        set_real = slave.setFloat64 if v3 else slave.setReal
        get_real = slave.getFloat64 if v3 else slave.getReal
        get_int = slave.getInt32 if v3 else slave.getInteger

        def read() -> Row:
            ints = get_int([refs[n] for n in ("last_balise_id", "last_group_id", "balises_passed")])
            reals = get_real(
                [refs[n] for n in ("last_balise_distance", "latitude", "longitude", "position")]
            )
            (text,) = slave.getString([refs["passed_in_step"]])
            return {
                "last_balise_id": ints[0],
                "last_group_id": ints[1],
                "balises_passed": ints[2],
                "last_balise_distance": reals[0],
                "latitude": reals[1],
                "longitude": reals[2],
                "position": reals[3],
                "passed_in_step": text.decode() if isinstance(text, bytes) else text,
            }

        if v3:
            set_real([refs["antenna_offset"], refs["position"]], [antenna_offset, positions[0]])
            slave.enterInitializationMode(startTime=0.0)
        else:
            slave.setupExperiment(startTime=0.0)
            set_real([refs["antenna_offset"], refs["position"]], [antenna_offset, positions[0]])
            slave.enterInitializationMode()
        slave.exitInitializationMode()
        rows = [read()]
        for k, position in enumerate(positions[1:]):
            set_real([refs["position"]], [position])
            slave.doStep(currentCommunicationPoint=k * step, communicationStepSize=step)
            rows.append(read())
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(unzipdir, ignore_errors=True)
    return rows


@pytest.fixture(scope="session")
def drive() -> Drive:
    return _drive


def readings(rows: Sequence[Row]) -> list[tuple[int, int, float]]:
    """Every (id, group, distance) of passed_in_step over the run, in order."""
    out: list[tuple[int, int, float]] = []
    for row in rows:
        for entry in filter(None, row["passed_in_step"].split(";")):
            balise_id, group_id, distance = entry.split(":")
            out.append((int(balise_id), int(group_id), float(distance)))
    return out


@pytest.fixture(scope="session")
def parse_readings() -> Callable[[Sequence[Row]], list[tuple[int, int, float]]]:
    return readings
