"""The native FMU step (coupler_orchestrator.master.native_fmu_step): chosen for runs of
in-process FMUs, the same bytes in results.csv as the step in Python, and left alone where it
would not mean the same (a string connection).

    Source (FMI 2 or 3) --ramp, counter--> Feed1 --real, int, bool--> Feed2 --real--> Feed3
                                           (Feedthrough2, FMI 2)

The step in C is also run by test_fmu_termination.py (an FMU asking to end the run, FMI 2
and 3) and test_faults.py (an FMU hanging in-process, an interrupt while it hangs, an
interrupt of a fast run), each over both paths (the ``fmu_path`` fixture). Several base steps
per call into C (``Kernel.steps``, its row log) give what one step per call gives: the same
results.csv, rows, latencies counted and live history (test_row_log.py tests the log itself).
"""

from __future__ import annotations

import asyncio
import csv
import io
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coupler_orchestrator import native
from coupler_orchestrator.master import loop
from coupler_orchestrator.master import native_fmu_step as kernel
from coupler_orchestrator.model import Algorithm, Plan
from coupler_orchestrator.observer import Observer, Steps
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.outputs.monitor import MonitorState
from coupler_orchestrator.runner import run_scenario

from ..support import Coupler, require_native
from ..support.chains import PARAMS, ROUTES, STRING, chain


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
        sliced = self.sliced.row()
        assert [(type(v), v) for v in row] == [(type(v), v) for v in sliced]
        compared.append(row)
        return row

    monkeypatch.setattr(kernel.Kernel, "row", both)
    monkeypatch.setattr(kernel.Kernel, "logs", property(lambda self: False))  # one step a call
    for source in ("Source2", "Source3"):
        (tmp_path / source).mkdir()
        ssd = chain(tmp_path / source, fmus, source, ROUTES)
        outcome = coupler("run", ssd, "--out", tmp_path / source / "out", *PARAMS)
        assert outcome.code == 0, outcome.err
    assert all(made is not None and made.reader is not made.sliced for made in prepared)
    assert len(compared) == 2 * 201  # t = 0 .. 2 s, twice
    assert {type(v) for v in compared[-1]} == {float, int, bool, str}


class Seen(Observer):
    """Every point a run told, as ``stepped`` and ``timed`` were called (the default
    ``stepped_batch`` calls them for each point of a batch), and how many batches."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, list[tuple[type, Any]]]] = []
        self.timed_for: list[list[bool]] = []
        self.batches = 0

    def stepped(self, time: float, row: Sequence[Any]) -> None:
        self.rows.append((time, [(type(v), v) for v in row]))

    def timed(self, seconds: Sequence[float | None]) -> None:
        self.timed_for.append([s is not None for s in seconds])

    def stepped_batch(self, steps: Steps) -> None:
        self.batches += 1
        super().stepped_batch(steps)


PARAMETERS = {
    "Feed2.gain": "-1.5",
    "Feed1.int_offset": "3",
    "Feed1.string_in": 'a, "b"',  # quoted in results.csv
    "Feed2.string_in": "\u00fcber\nall",  # not ASCII, quoted
}


def run_chain(ssd: Path, out: Path, *, every: int, algorithm: str) -> tuple[Seen, MonitorState]:
    seen, monitor = Seen(), MonitorState(points=16)
    options = RunOptions(
        stop_time=1.37,
        step_size=0.01,
        algorithm=Algorithm(algorithm),
        output_interval=every * 0.01,
        parameters=PARAMETERS,
    )
    outcome = asyncio.run(run_scenario(ssd, options, out_dir=out, observers=[seen, monitor]))
    assert outcome.end.status == "completed", outcome.end.reason
    return seen, monitor


@settings(
    max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    capacity=st.integers(1, 200),
    budget=st.sampled_from([0.0, 1e-4, loop.YIELD_EVERY]),
    every=st.integers(1, 7),
    algorithm=st.sampled_from(["jacobi", "gauss-seidel"]),
    source=st.sampled_from(["Source2", "Source3"]),
)
def test_several_steps_per_call_are_told_as_one_step_per_call_tells_them(
    fmus: Mapping[str, Path],
    prepared: list[kernel.Kernel | None],
    capacity: int,
    budget: float,
    every: int,
    algorithm: str,
    source: str,
) -> None:
    """However many steps a call into C takes (the log's capacity, the time a batch may last),
    results.csv has the same bytes, every observer sees the same rows with the same types,
    each step's latencies are told, summary.json counts them, the monitor keeps the same
    history: as when every base step is one call."""
    require_native(kernel.rows)
    with tempfile.TemporaryDirectory() as folder, pytest.MonkeyPatch.context() as patch:
        work = Path(folder)
        ssd = chain(work, fmus, source, ROUTES)
        patch.setattr(kernel, "BATCH", capacity)
        patch.setattr(loop, "YIELD_EVERY", budget)
        batched = run_chain(ssd, work / "batched", every=every, algorithm=algorithm)
        patch.setattr(kernel.Kernel, "logs", property(lambda self: False))
        single = run_chain(ssd, work / "single", every=every, algorithm=algorithm)
        recorded = [(work / d / "results.csv").read_bytes() for d in ("batched", "single")]
        summaries = [Coupler.summary(work / d)["participants"] for d in ("batched", "single")]
    assert batched[0].batches >= 137 // capacity and single[0].batches == 0
    assert recorded[0] == recorded[1]
    assert len(list(csv.reader(io.StringIO(recorded[0].decode())))) == 2 + 137 // every
    assert batched[0].rows == single[0].rows
    assert len(batched[0].rows) == 138
    assert batched[0].timed_for == single[0].timed_for
    for name, member in summaries[0].items():
        assert member["steps"] == summaries[1][name]["steps"] == 137
    for a, b in (
        (batched[1].values, single[1].values),
        (batched[1].latencies, single[1].latencies),
    ):
        assert a.times == b.times and a.stride == b.stride
    assert batched[1].values.rows == single[1].values.rows
    assert batched[1].row == single[1].row and batched[1].time == single[1].time
