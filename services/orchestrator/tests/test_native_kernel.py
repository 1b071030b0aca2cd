"""The native FMU step (coupler_orchestrator.master.native_fmu_step): chosen for runs of
in-process FMUs, the same bytes in results.csv as the step in Python, and left alone where it
would not mean the same (a string connection).

    Source (FMI 2 or 3) --ramp, counter--> Feed1 --real, int, bool--> Feed2 --real--> Feed3
                                           (Feedthrough2, FMI 2)

The step in C is also run by test_fmu_termination.py (an FMU asking to end the run, FMI 2
and 3) and test_faults.py (an FMU hanging in-process, an interrupt while it hangs, an
interrupt of a fast run), each over both paths (the ``fmu_path`` fixture).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from coupler.testing import Annotation, Connection, Connector, SystemStructure, fmu
from coupler_orchestrator import native
from coupler_orchestrator.master import native_fmu_step as kernel
from coupler_orchestrator.model import Plan

from .conftest import Coupler, require_native

ROUTES = [
    ("Source", "ramp", "Feed1", "real_in"),
    ("Source", "counter", "Feed1", "int_in"),
    ("Feed1", "real_out", "Feed2", "real_in"),
    ("Feed1", "int_out", "Feed2", "int_in"),
    ("Feed1", "bool_out", "Feed2", "bool_in"),
    ("Feed2", "real_out", "Feed3", "real_in"),
    ("Feed3", "bool_out", "Feed1", "bool_in"),  # a loop: Jacobi and Gauss-Seidel differ
]
DECOUPLED = Annotation("org.coupler.connection", "Connection", {"decoupled": "true"})
"""The loop's last connection: Gauss-Seidel reads it from the previous step."""
STRING = ("Feed1", "string_out", "Feed2", "string_in")


TYPES = {"ramp": "Real", "sine": "Real", "counter": "Integer", "real": "Real", "int": "Integer",
         "bool": "Boolean", "string": "String"}  # fmt: skip


def connectors(outputs: list[str], inputs: list[str]) -> list[Connector]:
    """Connectors of every output and of the connected inputs."""
    return [
        Connector(name, kind, TYPES[name.split("_")[0]])
        for names, kind in ((outputs, "output"), (inputs, "input"))
        for name in names
    ]


def chain(
    folder: Path, fmus: Mapping[str, Path], source: str, routes: list[tuple[str, ...]]
) -> Path:
    def inputs(element: str) -> list[str]:
        return [d for _, _, c, d in routes if c == element]

    components = [fmu("Source", fmus[source], *connectors(["ramp", "sine", "counter"], []))] + [
        fmu(
            f"Feed{k}",
            fmus["Feedthrough2"],
            *connectors(["real_out", "int_out", "bool_out", "string_out"], inputs(f"Feed{k}")),
        )
        for k in (1, 2, 3)
    ]
    connections = [
        Connection(f"{a}.{b}", f"{c}.{d}", [DECOUPLED] if (a, c) == ("Feed3", "Feed1") else [])
        for a, b, c, d in routes
    ]
    return SystemStructure("Chain", components, connections, stop_time=2).write(
        folder / "chain.ssd"
    )


@pytest.fixture
def prepared(monkeypatch: pytest.MonkeyPatch) -> list[kernel.Kernel | None]:
    """What ``kernel.prepare`` gave each run of the test (None: the run stepped in Python)."""
    require_native(kernel.library)
    made: list[kernel.Kernel | None] = []
    real = kernel.prepare

    def spy(plan: Plan) -> tuple[kernel.Kernel | None, str]:
        chosen = real(plan)
        made.append(chosen[0])
        return chosen

    monkeypatch.setattr(kernel, "prepare", spy)
    return made


PARAMS = ("--param", "Feed2.gain=-1.5", "--param", "Feed1.int_offset=3", "--step", "0.01")


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
@pytest.mark.parametrize("source", ["Source2", "Source3"])
def test_fmus_step_in_c_with_the_same_bytes_as_in_python(
    coupler: Coupler,
    fmus: Mapping[str, Path],
    tmp_path: Path,
    prepared: list[kernel.Kernel | None],
    algorithm: str,
    source: str,
) -> None:
    ssd = chain(tmp_path, fmus, source, ROUTES)
    recorded = {}
    stepped = {
        "C": {"path": "native FMU step", "reason": kernel.USED},
        "Python": {"path": "Python", "reason": f"in-process; not in C: {kernel.OFF}"},
    }
    for path, flag in (("C", ()), ("Python", ("--no-native-steps",))):
        out = tmp_path / path
        outcome = coupler("run", ssd, "--out", out, "--algorithm", algorithm, *PARAMS, *flag)
        assert outcome.code == 0, outcome.err
        recorded[path] = (out / "results.csv").read_bytes()
        summary = coupler.summary(out)
        for name in ("Source", "Feed1", "Feed2", "Feed3"):
            assert summary["participants"][name]["steps"] == 200
            assert 0 < summary["participants"][name]["do_step_latency_ms"]["p50"] < 1000
            assert summary["participants"][name]["step_path"] == stepped[path]
    assert [made is not None for made in prepared] == [True, False]
    assert recorded["C"] == recorded["Python"]
    lines = recorded["C"].decode().splitlines()
    assert len(lines) == 202  # header and t = 0 .. 2 s
    header = lines[0].split(",")
    last = dict(zip(header, lines[-1].split(","), strict=True))
    # the ramp went through gains 1, -1.5, 1 (one step late per member under Jacobi)
    assert float(last["Feed3.real_out"]) != 0.0
    assert int(last["Feed1.int_out"]) >= 3


def test_a_string_connection_steps_in_python(
    coupler: Coupler, fmus: Mapping[str, Path], tmp_path: Path, prepared: list[kernel.Kernel | None]
) -> None:
    """A string lives in its FMU's memory only until that FMU's next call: the step in C
    would copy a pointer that the source's own step invalidates, so the run steps in
    Python (and the string arrives); `coupler run -v` and summary.json say so, and why."""
    ssd = chain(tmp_path, fmus, "Source2", [*ROUTES, STRING])
    out = tmp_path / "out"
    outcome = coupler("run", ssd, "--out", out, "-v", *PARAMS)
    assert outcome.code == 0, outcome.err
    assert prepared == [None]
    why = "in-process; not in C: Feed2.string_in (String) is fed a String by Feed1.string_out"
    for name in ("Source", "Feed1", "Feed2", "Feed3"):
        assert f"stepped: {name}: Python ({why})" in outcome.out, outcome.out
        stepped = coupler.summary(out)["participants"][name]["step_path"]
        assert stepped == {"path": "Python", "reason": why}
    rows = coupler.results(out)
    assert rows[-1]["Feed2.string_out"] == rows[-1]["Feed1.string_out"]


def test_what_is_recorded_is_picked_from_the_same_row(
    coupler: Coupler, fmus: Mapping[str, Path], tmp_path: Path, prepared: list[kernel.Kernel | None]
) -> None:
    """--output-variables and --output-interval pick from the row the native step reads."""
    ssd = chain(tmp_path, fmus, "Source2", ROUTES)
    picked = ("--output-variables", "Feed2.*,Source.counter", "--output-interval", "0.05")
    recorded = {}
    for path, flag in (("C", ()), ("Python", ("--no-native-steps",))):
        out = tmp_path / path
        outcome = coupler("run", ssd, "--out", out, *PARAMS, *picked, *flag)
        assert outcome.code == 0, outcome.err
        recorded[path] = (out / "results.csv").read_bytes()
    assert [made is not None for made in prepared] == [True, False]
    assert recorded["C"] == recorded["Python"]
    lines = recorded["C"].decode().splitlines()
    assert lines[0] == (
        "time,Source.counter,Feed2.real_out,Feed2.int_out,Feed2.bool_out,Feed2.string_out"
    )
    assert len(lines) == 42  # header and t = 0, 0.05 .. 2 s


@pytest.mark.usefixtures("without_coupler_native")
def test_without_coupler_native_fmus_step_in_python_and_say_why(
    coupler: Coupler, fmus: Mapping[str, Path], tmp_path: Path
) -> None:
    """Where coupler-native is not installed (no wheel for the platform) nothing is built or
    loaded from elsewhere: the run steps through Python and summary.json says why."""
    out = tmp_path / "out"
    outcome = coupler("run", chain(tmp_path, fmus, "Source2", ROUTES), "--out", out, *PARAMS)
    assert outcome.code == 0, outcome.err
    assert outcome.err == ""  # not installed is no warning: the Python path is a normal one
    for stepped in coupler.summary(out)["participants"].values():
        assert stepped["step_path"] == {
            "path": "Python",
            "reason": f"in-process; not in C: {native.MISSING}",
        }


def test_the_row_read_in_c_is_the_row_sliced_in_python(
    coupler: Coupler,
    fmus: Mapping[str, Path],
    tmp_path: Path,
    prepared: list[kernel.Kernel | None],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """At every communication point, the row RowRead reads from the arrays in C is the list of
    values the slices of the arrays make in Python (FMI 2 and 3: Reals, Integers, Booleans
    and Strings)."""
    require_native(kernel.rows)
    compared = []
    read = kernel.Kernel.row

    def both(self: kernel.Kernel) -> list[Any]:
        row = read(self)
        sliced = self.sliced_row()
        assert [(type(v), v) for v in row] == [(type(v), v) for v in sliced]
        compared.append(row)
        return row

    monkeypatch.setattr(kernel.Kernel, "row", both)
    for source in ("Source2", "Source3"):
        (tmp_path / source).mkdir()
        ssd = chain(tmp_path / source, fmus, source, ROUTES)
        outcome = coupler("run", ssd, "--out", tmp_path / source / "out", *PARAMS)
        assert outcome.code == 0, outcome.err
    assert all(made is not None and made._read is not None for made in prepared)
    assert len(compared) == 2 * 201  # t = 0 .. 2 s, twice
    assert {type(v) for v in compared[-1]} == {float, int, bool, str}
