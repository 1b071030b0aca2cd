"""results.csv's rows made in C (the native CSV row, ``coupler_native._rows``) are the bytes
Python's %-format makes (``outputs.csv.row_formatter``): awkward values, any mix of column
types, and a whole run with and without coupler-native."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given

from coupler_orchestrator import native
from coupler_orchestrator.observer import Column
from coupler_orchestrator.outputs import csv as csv_output
from coupler_orchestrator.outputs.csv import native_row_formatter, row_formatter

from ..support import Coupler, require_native
from ..support.chains import PARAMS, ROUTES, chain
from ..support.rows import RESULT_ROWS

AWKWARD = {
    "Real": [-0.0, 0.0, math.inf, -math.inf, math.nan, 1e-300, 5e-324, -5e-324, 1e16, 1e15,
             123456789012345678.0, 0.1 + 0.2, 1 / 3, 2.0**-1074, 1.7976931348623157e308, 3,
             -(2**80), True],
    "Integer": [0, -1, 2**63 - 1, -(2**63), 2**63, -(2**64) - 1, 10**40, True, False],
    "Enumeration": [0, 7, -3],
    "UInt64": [0, 2**64 - 1, 2**63],
    "Boolean": [True, False, 0, 1, 2, -1],
    "String": ["", "plain", "a,b", 'say "hi"', "two\nlines", "cr\ronly", "é ∑ 🚂"],
    "Binary": [b"", b"\x00\xff", b"a,b"],
}  # fmt: skip
"""Per column type, values whose text is easy to get wrong."""


@pytest.fixture(autouse=True)
def _native_rows() -> None:
    require_native(csv_output.native_rows)


def both(columns: list[Column], picked: list[int], time: float, row: Any) -> tuple[str, str]:
    """The line made in C and the one made by Python's %-format."""
    made = native_row_formatter(columns, picked)
    assert made is not None
    return made(time, row), row_formatter(columns, picked)(time, row)


@pytest.mark.parametrize("kind", sorted(AWKWARD))
def test_awkward_values_are_the_same_text(kind: str) -> None:
    values = AWKWARD[kind]
    columns = [Column(name=f"C.v{i}", unit="", type=kind) for i in range(len(values))]
    picked = list(range(len(values)))
    for time in (0.0, -0.0, 0.1 + 0.2, 1e16, 5e-324, 200.00000000000003):
        native_line, python_line = both(columns, picked, time, values)
        assert native_line == python_line
        assert native_line.endswith("\n")
    line, _ = both(columns, picked, 0.0, tuple(values))  # a tuple as a row
    assert line.split(",")[0] == "0.0"


def test_reals_are_their_repr() -> None:
    """The shortest text that reads back to the same double: CPython's repr."""
    values = [-0.0, math.inf, math.nan, 1e-300, 5e-324, 1e16, 0.1 + 0.2, 2.5]
    columns = [Column(name=f"C.r{i}", unit="", type="Real") for i in range(len(values))]
    line, _ = both(columns, list(range(len(values))), 0.5, values)
    assert line == "0.5,-0.0,inf,nan,1e-300,5e-324,1e+16,0.30000000000000004,2.5\n"


@given(RESULT_ROWS)
def test_any_row_is_the_same_text(case: Any) -> None:
    """Any mix of column types, any selection (none too)."""
    types, row, chosen, time = case
    columns = [Column(name=f"C.v{i}", unit="", type=t) for i, t in enumerate(types)]
    native_line, python_line = both(columns, sorted(chosen), time, list(row))
    assert native_line == python_line


def test_a_cell_repeated_from_the_row_before_is_its_own_text() -> None:
    """C reuses a Real's or an Integer's text when the row before had the same value (the
    same bits): 0.0 after -0.0, True after 1 or 1 after 1.0 are not the same."""
    sequences = {
        "Real": [0.0, 0.0, -0.0, -0.0, 0.0, math.nan, math.nan, 1.0, 1, 1.0, True, 1e16, 1e16],
        "Integer": [1, 1, True, 1, -1, -1, 2**63, 2**63, 2**63 - 1, 0, False, 0],
    }
    for kind, values in sequences.items():
        columns = [Column(name="C.v", unit="", type=kind), Column(name="C.w", unit="", type=kind)]
        made = native_row_formatter(columns, [0, 1])
        assert made is not None
        python = row_formatter(columns, [0, 1])
        for value, other in zip(values, reversed(values), strict=True):
            assert made(0.5, [value, other]) == python(0.5, [value, other])


def test_a_cell_that_cannot_be_written_raises_as_in_python() -> None:
    """An int past Python's limit for str (4300 digits) and a row too short raise the
    same errors in C as in Python: no crash, no half line."""
    columns = [Column(name="C.i", unit="", type="Integer")]
    made = native_row_formatter(columns, [0])
    assert made is not None
    for row, error in (([10**5000], ValueError), ([], IndexError)):
        with pytest.raises(error):
            row_formatter(columns, [0])(0.0, row)
        with pytest.raises(error):
            made(0.0, row)


def test_a_run_records_the_same_bytes_with_and_without_coupler_native(
    coupler: Coupler,
    fmus: Mapping[str, Path],
    tmp_path: Path,
    request: pytest.FixtureRequest,
) -> None:
    """A chain of FMUs (Reals, Integers, Booleans and Strings recorded): results.csv's bytes
    are the same whether its rows are made in C or, without coupler-native, in Python; `-v`
    and summary.json say which."""
    ssd = chain(tmp_path, fmus, "Source2", ROUTES)
    recorded = {}
    for way in ("C", "Python"):
        if way == "Python":
            request.getfixturevalue("without_coupler_native")
        out = tmp_path / way
        outcome = coupler("run", ssd, "--out", out, "-v", *PARAMS, "--stop-time", "3")
        assert outcome.code == 0, outcome.err
        recorded[way] = (out / "results.csv").read_bytes()
        said = "in C (the native CSV row)" if way == "C" else f"in Python: {native.MISSING}"
        assert f"results.csv rows made {said}" in outcome.out
        assert coupler.summary(out)["results_rows"] == said
    assert recorded["C"] == recorded["Python"]
    lines = recorded["C"].decode().splitlines()
    assert len(lines) == 302  # the header and t = 0 .. 3 s
    assert "string_out" in lines[0] and "bool_out" in lines[0]
