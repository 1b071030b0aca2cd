"""The native FMU step's row log: several base steps in one call into C (``ck_steps``,
csrc/fmu_steps.c) log each step's row, and what Python reads of it (``RowLog``, csrc/rows.c)
and the results.csv lines made of it (``RowFormat.lines``) are what one step per call gives:
the row ``RowRead`` reads after the step, and ``RowFormat.line`` of that row.

    ck_steps --> member.DoStep (a callback writing the drawn row into the slots)
             --> ck_log: time, every slot's value (strings copied), timing
             --> RowLog.row(j) == RowRead.row() then;  RowFormat.lines == RowFormat.line per row

The member is a ctypes callback in place of an FMU's fmi2DoStep, so that any value of every C
type the log reads can be drawn; runs of real FMUs are compared in test_native_kernel.py.
"""

from __future__ import annotations

import ctypes
import math
import struct
from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coupler_orchestrator.master import native_fmu_step as kernel
from coupler_orchestrator.model import TimeGrid
from coupler_orchestrator.observer import Column
from coupler_orchestrator.outputs.csv import native_row_format

from ..support import require_native

SLOTS = {
    "d": ctypes.c_double,
    "i": ctypes.c_int,
    "q": ctypes.c_int64,
    "b": ctypes.c_int,
    "?": ctypes.c_bool,
    "s": ctypes.c_char_p,
}
"""Each C type the log reads (``ck_cell.code``), as a slot."""
TYPES = {"d": "Real", "i": "Integer", "q": "Integer", "b": "Boolean", "?": "Boolean", "s": "String"}
INT32 = st.integers(-(2**31), 2**31 - 1)
VALUES = {
    "d": st.floats(allow_nan=True, allow_infinity=True, width=64),
    "i": INT32,
    "q": st.integers(-(2**63), 2**63 - 1),
    "b": INT32,
    "?": st.booleans(),
    # NUL ends a C string; commas, quotes, newlines, non-ASCII and invalid UTF-8 are drawn
    "s": st.none() | st.binary(max_size=12).map(lambda b: b.replace(b"\0", b"")),
}
FMI2_DO_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                                ctypes.c_int)  # fmt: skip


@st.composite
def logs(draw: st.DrawFn) -> tuple[str, list[list[Any]]]:
    """Column codes and the rows a member's steps leave in their slots."""
    codes = "".join(draw(st.lists(st.sampled_from(sorted(SLOTS)), min_size=1, max_size=8)))
    steps = draw(st.integers(1, 12))
    # a value that stays the same from row to row is drawn often (the log reuses its text)
    rows = draw(
        st.lists(st.tuples(*(VALUES[c] for c in codes)).map(list), min_size=steps, max_size=steps)
    )
    return codes, rows


def key(value: Any) -> Any:
    """A value compared by type and bits (nan equals nan, -0.0 is not 0.0)."""
    if isinstance(value, float):
        return float, struct.pack("<d", value)
    return type(value), value


def arrays() -> tuple[Any, Any, Any]:
    """The arrays a step writes: each member's timing, the watchdog's (nothing under way) and
    the stop's."""
    return (ctypes.c_double * 1)(), (ctypes.c_double * 3)(-1.0, 0, 0), (ctypes.c_int * 3)()


class Member:
    """One member of the step: its fmi2DoStep writes the next drawn row into the slots."""

    def __init__(self, codes: str, rows: list[list[Any]], fail_at: int | None) -> None:
        self.codes = codes
        self.slots = [SLOTS[c]() for c in codes]
        self.rows = rows
        self.fail_at = fail_at
        self.stepped = 0
        self.times: list[float] = []
        self.function = FMI2_DO_STEP(self.do_step)

    def write(self, row: Sequence[Any]) -> None:
        for slot, value in zip(self.slots, row, strict=True):
            slot.value = value

    def do_step(self, instance: Any, time: float, step: float, last: int) -> int:
        j, self.stepped = self.stepped, self.stepped + 1
        self.times.append(time)
        if j == self.fail_at:
            return 3  # fmi2Error
        self.write(self.rows[j])
        return 0


@settings(max_examples=150, deadline=None)
@given(
    drawn=logs(),
    capacity=st.integers(1, 16),
    fail_at=st.none() | st.integers(0, 12),
    start=st.sampled_from([0.0, -1.5, 0.1, 1e3]),
    step=st.sampled_from([0.01, 0.1, 1e-3, 0.25, 7e-3]),
    k0=st.integers(0, 10**6),
    picks=st.data(),
)
def test_the_log_holds_what_one_step_per_call_reads(
    drawn: tuple[str, list[list[Any]]],
    capacity: int,
    fail_at: int | None,
    start: float,
    step: float,
    k0: int,
    picks: st.DataObject,
) -> None:
    """Each logged row is the row RowRead reads after that step (values, types, strings
    decoded as it decodes them), its time the grid's t_{k+1}, its lines RowFormat.line's of
    that row (any picked columns, every n-th row from any first); a member that fails a step
    stops the call there, the steps before it logged, the failure told as ck_step tells it."""
    native = kernel.library()
    rows_module = kernel.rows()
    if native is None or rows_module is None:
        require_native(kernel.library)
        require_native(kernel.rows)
    codes, rows = drawn
    member = Member(codes, rows, fail_at)
    addresses = [ctypes.addressof(slot) for slot in member.slots]
    log = native.Log(list(zip(addresses, codes, strict=True)), 1, capacity)
    read = rows_module.RowLog(log.address, log)
    kept = _, watch, stop = arrays()
    function = ctypes.cast(member.function, ctypes.c_void_p).value or 0
    members = native.Members(
        [(0, function, step, 2, 0, [], [], [])], *map(ctypes.addressof, kept), True
    )
    grid = TimeGrid(start=start, step=step, steps=k0 + len(rows))
    exact = grid.in_doubles()
    assert exact is not None

    index = members.steps(*exact, k0, len(rows), 60.0, log)

    done = min(len(rows), capacity, len(rows) if fail_at is None else fail_at)
    if fail_at is not None and fail_at < min(len(rows), capacity):
        assert index == 0 and list(stop) == [native.CK_CALL_STEP, 0, 3]
    else:
        assert index == native.CK_DONE
    assert len(read) == done
    assert member.times == [grid.time(k0 + j) for j in range(member.stepped)]
    assert read.times() == [grid.time(k0 + j + 1) for j in range(done)]
    assert watch[0] == -1.0
    assert len(read.samples(0)) == done and all(s >= 0 for s in read.samples(0))

    columns = [Column(name=f"c{i}", unit="", type=TYPES[c]) for i, c in enumerate(codes)]
    picked = picks.draw(st.lists(st.integers(0, len(codes) - 1), max_size=10), label="picked")
    first = picks.draw(st.integers(0, 4), label="first")
    every = picks.draw(st.integers(1, 4), label="every")
    one_by_one, together = native_row_format(columns, picked), native_row_format(columns, picked)
    row_read = rows_module.RowRead(addresses, codes)
    expected = []
    for j in range(done):
        member.write(rows[j])
        row = row_read.row()
        assert [key(v) for v in read.row(j)] == [key(v) for v in row]
        assert read.seconds(j) == [read.samples(0)[j]]
        if j >= first and (j - first) % every == 0:
            expected.append(one_by_one.line(grid.time(k0 + j + 1), row))
    assert together.lines(read, first, every) == "".join(expected)


def test_lines_are_none_where_a_column_is_not_made_in_c() -> None:
    """A cell C does not make from the log (a Binary column's formatter, a Real column read
    from an int) leaves the rows to Python: ``lines`` answers None."""
    native, rows_module = kernel.library(), kernel.rows()
    if native is None or rows_module is None:
        require_native(kernel.library)
        require_native(kernel.rows)
    slot = ctypes.c_int(7)
    log = native.Log([(ctypes.addressof(slot), "i")], 0, 4)
    read = rows_module.RowLog(log.address, log)
    kept = arrays()
    members = native.Members([], *map(ctypes.addressof, kept), True)  # no member at all
    assert members.steps(0.0, 1.0, 10.0, 0, 3, 60.0, log) == native.CK_DONE
    assert len(read) == 3 and read.row(-1) == [7] and read.times() == [0.1, 0.2, 0.3]
    for kind in ("Real", "Binary"):
        made = native_row_format([Column(name="c", unit="", type=kind)], [0])
        assert made.lines(read, 0, 1) is None
    made = native_row_format([Column(name="c", unit="", type="Integer")], [0])
    assert made.lines(read, 1, 1) == "0.2,7\n0.3,7\n"
    with pytest.raises(IndexError):
        read.row(3)


@given(
    start=st.decimals(-1e6, 1e6, places=6).map(float),
    step=st.decimals("1e-6", 100, places=6).map(float).filter(lambda h: h > 0),
    steps=st.integers(1, 10**9),
    k=st.data(),
)
def test_times_computed_in_doubles_are_the_grids(
    start: float, step: float, steps: int, k: st.DataObject
) -> None:
    """Where ``TimeGrid.in_doubles`` gives the grid's integers as doubles, the quotient the
    log's times are computed by is ``time(k)`` at every k; a grid whose numerators a double
    cannot hold (a step of 1/3: 16 digits, or 96.440699 s x 93,396,246 steps: past 2**53)
    gives None, and steps one call at a time."""
    grid = TimeGrid(start=start, step=step, steps=steps)
    exact = grid.in_doubles()
    written = Fraction(repr(start)), Fraction(repr(step))  # the decimals drawn
    denominator = math.lcm(*(part.denominator for part in written))
    last = (abs(written[0]) + (steps + 1) * written[1]) * denominator
    if last >= 2**53:  # the last point's numerator is no double: stepped one call at a time
        assert exact is None
        return
    assert exact is not None
    origin, stride, scale = exact
    for point in (0, steps, k.draw(st.integers(0, steps), label="k")):
        assert (origin + float(point) * stride) / scale == grid.time(point)
    assert TimeGrid(start=0.0, step=1 / 3, steps=10).in_doubles() is None
