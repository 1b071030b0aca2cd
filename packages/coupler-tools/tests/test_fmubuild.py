"""Build the example FMUs of fmus/ with gcc and run them with FMPy against hand-computed values."""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2Discard, fmi2LastSuccessfulTime, fmi2Terminated
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from coupler_tools.fmubuild import FmuBuildError, build_all, build_fmu, find_model_folders, main

FMUS = Path(__file__).resolve().parents[3] / "fmus"
EXAMPLES = [folder.name for folder in find_model_folders(FMUS)]

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")


@pytest.fixture(scope="session")
def built(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("fmus")
    return {path.stem: path for path in build_all(FMUS, out)}


@contextlib.contextmanager
def _instance(
    slave_class: type[FMU2Slave] | type[FMU3Slave], path: Path, tmp_path: Path
) -> Iterator[tuple[Any, dict[str, int]]]:
    """The FMU instantiated by FMPy's low-level class, with its value references by name."""
    md = fmpy.read_model_description(str(path))
    fmu = slave_class(
        guid=md.guid,
        unzipDirectory=fmpy.extract(str(path), str(tmp_path / "unzip")),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName=path.stem,
    )
    fmu.instantiate()
    try:
        yield fmu, {v.name: v.valueReference for v in md.modelVariables}
    finally:
        fmu.freeInstance()


@pytest.mark.slow
def test_every_example_is_built(built: dict[str, Path]) -> None:
    for name in ("Source", "Feedthrough", "Integrator"):
        assert f"{name}2" in built
        assert f"{name}3" in built
    assert sorted(built) == sorted(EXAMPLES)


@pytest.mark.parametrize("name", EXAMPLES)
def test_model_description_is_valid(built: dict[str, Path], name: str) -> None:
    assert validate_fmu(str(built[name])) == []
    md = fmpy.read_model_description(str(built[name]), validate=True)
    assert md.coSimulation is not None
    assert md.coSimulation.modelIdentifier == name


@pytest.mark.parametrize("name", [n for n in EXAMPLES if n.startswith("Source")])
def test_source_ramp_sine_counter(built: dict[str, Path], name: str) -> None:
    result = fmpy.simulate_fmu(
        str(built[name]),
        stop_time=1.0,
        output_interval=0.25,
        start_values={"slope": 2.0, "offset": 1.0, "amplitude": 3.0, "freq": 0.5},
    )
    t = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    assert result["time"] == pytest.approx(t)
    assert result["ramp"] == pytest.approx(2.0 * t + 1.0)
    assert result["sine"] == pytest.approx(3.0 * np.sin(2 * math.pi * 0.5 * t), abs=1e-12)
    assert list(result["counter"]) == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("name", [n for n in EXAMPLES if n.startswith("Feedthrough")])
def test_feedthrough_in_simulation(built: dict[str, Path], name: str) -> None:
    result = fmpy.simulate_fmu(
        str(built[name]),
        stop_time=0.3,
        output_interval=0.1,
        start_values={
            "gain": 3.0,
            "int_offset": 10,
            "real_in": 1.5,
            "int_in": 4,
            "bool_in": True,
            "string_in": "hello",
        },
    )
    assert len(result) == 4
    assert result["real_out"] == pytest.approx([4.5] * 4)
    assert list(result["int_out"]) == [14] * 4
    assert not result["bool_out"].any()


def test_feedthrough2_all_types_and_errors(built: dict[str, Path], tmp_path: Path) -> None:
    with _instance(FMU2Slave, built["Feedthrough2"], tmp_path) as (fmu, vr):
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        # Defaults: gain 2, int_offset 0, inputs at their start values.
        assert fmu.getReal([vr["real_out"]]) == [0.0]
        assert fmu.getBoolean([vr["bool_out"]]) == [True]
        fmu.exitInitializationMode()
        # Direct feedthrough: outputs follow the inputs before any step.
        fmu.setReal([vr["real_in"]], [1.25])
        fmu.setInteger([vr["int_in"]], [-7])
        fmu.setBoolean([vr["bool_in"]], [True])
        fmu.setString([vr["string_in"]], ["grüß dich"])
        assert fmu.getReal([vr["real_out"]]) == [2.5]
        assert fmu.getInteger([vr["int_out"]]) == [-7]
        assert fmu.getBoolean([vr["bool_out"]]) == [False]
        assert fmu.getString([vr["string_out"]]) == [b"gr\xc3\xbc\xc3\x9f dich"]
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        assert fmu.getReal([vr["time"], vr["real_out"]]) == [0.1, 2.5]
        with pytest.raises(FMICallException):
            fmu.getReal([99])  # unknown value reference
        with pytest.raises(FMICallException):
            fmu.getReal([vr["int_out"]])  # wrong type
        with pytest.raises(FMICallException):
            fmu.setReal([vr["real_out"]], [1.0])  # outputs cannot be set
        with pytest.raises(FMICallException):
            fmu.setReal([vr["gain"]], [1.0])  # fixed parameter after initialization
        fmu.terminate()


def test_feedthrough3_all_types_and_binary(built: dict[str, Path], tmp_path: Path) -> None:
    with _instance(FMU3Slave, built["Feedthrough3"], tmp_path) as (fmu, vr):
        fmu.setFloat64([vr["gain"]], [0.5])
        fmu.setInt32([vr["int_offset"]], [100])
        fmu.enterInitializationMode(startTime=1.0)
        fmu.exitInitializationMode()
        fmu.setFloat64([vr["real_in"]], [8.0])
        fmu.setInt32([vr["int_in"]], [1])
        fmu.setString([vr["string_in"]], ["balise 17"])
        fmu.setBinary([vr["binary_in"]], [b"\x00\x01\xfe"])
        assert fmu.getFloat64([vr["real_out"]]) == [4.0]
        assert fmu.getInt32([vr["int_out"]]) == [101]
        assert fmu.getBoolean([vr["bool_out"]]) == [True]
        assert fmu.getString([vr["string_out"]]) == ["balise 17"]
        assert fmu.getBinary([vr["binary_out"]]) == [b"\x00\x01\xfe"]
        fmu.doStep(currentCommunicationPoint=1.0, communicationStepSize=0.5)
        assert fmu.getFloat64([vr["time"]]) == [1.5]
        with pytest.raises(FMICallException):
            fmu.getFloat64([99])
        with pytest.raises(FMICallException):
            fmu.getFloat32([vr["real_out"]])
        fmu.terminate()


@pytest.mark.parametrize("name", [n for n in EXAMPLES if n.startswith("Integrator")])
def test_integrator_explicit_euler(built: dict[str, Path], name: str) -> None:
    h, x0 = 0.1, 0.5
    u = [1.0, 2.0, -1.0, 0.5, 3.0, 0.0]
    signal = np.array(
        [(k * h, value) for k, value in enumerate(u)], dtype=[("time", float), ("u", float)]
    )
    result = fmpy.simulate_fmu(
        str(built[name]),
        stop_time=0.5,
        output_interval=h,
        start_values={"x0": x0},
        input=signal,
    )
    # x_k = x0 + h * (u_0 + ... + u_{k-1}): each doStep adds u*h with u as set before it.
    expected = [x0 + h * sum(u[:k]) for k in range(6)]
    assert result["x"] == pytest.approx(expected, abs=1e-12)


def test_rebuild_is_skipped_when_up_to_date(tmp_path: Path) -> None:
    src = tmp_path / "src"
    shutil.copytree(FMUS / "Integrator2", src / "Integrator2")
    shutil.copytree(FMUS / "common", src / "common")
    out = tmp_path / "Integrator2.fmu"
    build_fmu(src / "Integrator2", out)
    first = out.stat().st_mtime_ns
    build_fmu(src / "Integrator2", out)
    assert out.stat().st_mtime_ns == first
    # A shared header included by relative path is an input too.
    header = src / "common" / "integrator.h"
    later = first / 1e9 + 10
    os.utime(header, (later, later))
    build_fmu(src / "Integrator2", out)
    assert out.stat().st_mtime_ns != first


def test_resources_are_packed(tmp_path: Path) -> None:
    src = tmp_path / "src"
    shutil.copytree(FMUS / "Source2", src / "Source2")
    shutil.copytree(FMUS / "common", src / "common")
    resources = tmp_path / "res"
    (resources / "sub").mkdir(parents=True)
    (resources / "sub" / "track.xml").write_text("<track/>")
    out = build_fmu(src / "Source2", tmp_path / "Source2.fmu", resources=resources)
    with zipfile.ZipFile(out) as fmu:
        names = set(fmu.namelist())
    assert names == {
        "modelDescription.xml",
        "binaries/linux64/Source2.so",
        "resources/sub/track.xml",
    }


def test_compile_error_shows_gcc_output(tmp_path: Path) -> None:
    src = tmp_path / "Broken2"
    shutil.copytree(FMUS / "Source2", src)
    shutil.copytree(FMUS / "common", tmp_path / "common")
    (src / "extra.c").write_text("int broken(void) { return no_such_symbol; }\n")
    with pytest.raises(FmuBuildError) as info:
        build_fmu(src, tmp_path / "Broken2.fmu")
    message = str(info.value)
    assert "gcc failed" in message
    assert "no_such_symbol" in message
    assert "extra.c" in message
    assert not (tmp_path / "Broken2.fmu").exists()


def test_not_a_model_folder(tmp_path: Path) -> None:
    with pytest.raises(FmuBuildError, match=r"no modelDescription\.xml"):
        build_fmu(tmp_path, tmp_path / "x.fmu")


def test_main_builds_everything(
    built: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = next(iter(built.values())).parent  # already built there: nothing is recompiled
    assert main([str(FMUS), str(out_dir)]) == 0
    printed = capsys.readouterr().out.split()
    assert sorted(Path(p).name for p in printed) == sorted(f"{n}.fmu" for n in EXAMPLES)
    assert main([str(tmp_path), str(tmp_path / "out")]) == 1
    assert "no model folders" in capsys.readouterr().err


def test_faulty_fmus_are_a_set_of_their_own(tmp_path: Path) -> None:
    """fmus/faulty is not an example folder; built on its own, scheduled execution included."""
    assert not any("faulty" in folder.parts for folder in find_model_folders(FMUS))
    faulty = {folder.name for folder in find_model_folders(FMUS / "faulty")}
    assert faulty == {"Faulty2", "CrashOnInstantiate2", "Clocks3", "Scheduled3"}
    out = build_fmu(FMUS / "faulty" / "Scheduled3", tmp_path / "Scheduled3.fmu")
    with zipfile.ZipFile(out) as fmu:
        assert "binaries/x86_64-linux/Scheduled3.so" in fmu.namelist()


def test_stair2_asks_to_terminate(built: dict[str, Path], tmp_path: Path) -> None:
    """fmi2DoStep ending at terminate_at returns fmi2Discard; the status functions say why."""
    with _instance(FMU2Slave, built["Stair2"], tmp_path) as (fmu, vr):
        fmu.setReal([vr["terminate_at"]], [2.5])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=2.0)
        assert fmu.getInteger([vr["counter"]]) == [3]
        with pytest.raises(FMICallException) as discarded:
            fmu.doStep(currentCommunicationPoint=2.0, communicationStepSize=2.0)
        assert discarded.value.status == fmi2Discard
        assert fmu.getBooleanStatus(fmi2Terminated)
        assert fmu.getRealStatus(fmi2LastSuccessfulTime) == 2.5
        assert fmu.getReal([vr["time"]]) == [2.5]
        assert fmu.getInteger([vr["counter"]]) == [3]
        with pytest.raises(FMICallException):
            fmu.doStep(currentCommunicationPoint=2.5, communicationStepSize=1.0)
        fmu.terminate()


def test_statespace3_arrays_row_major(built: dict[str, Path], tmp_path: Path) -> None:
    with _instance(FMU3Slave, built["StateSpace3"], tmp_path) as (fmu, vr):
        assert fmu.getUInt64([vr["nx"], vr["nu"]]) == [2, 3]
        assert fmu.getFloat64([vr["B"]], 6) == [1.0, 0.0, 0.0, 0.0, 1.0, 0.5]
        fmu.setFloat64([vr["x0"], vr["u"]], [2.0, -1.0, 1.0, 2.0, 4.0])
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        # y = C x + D u: C = [[1, 0], [0.5, 1]], D[2,3] = 1
        assert fmu.getFloat64([vr["y"], vr["x"]], 4) == [2.0, 4.0, 2.0, -1.0]
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.5)
        # x += h (A x + B u): A = [[0, 1], [-2, -0.5]], B = [[1, 0, 0], [0, 1, 0.5]]
        # dx = (-1 + 1, -4 + 0.5 + 2 + 2) = (0, 0.5)
        assert fmu.getFloat64([vr["x"]], 2) == [2.0, -0.75]
        with pytest.raises(FMICallException):
            fmu.getFloat64([vr["y"]], 3)  # y has 2 elements
        with pytest.raises(FMICallException):
            fmu.setFloat64([vr["u"]], [1.0, 2.0])  # u has 3
        fmu.terminate()
