"""Each module of coupler-native and its Python twin, behind one interface
(``coupler_orchestrator.native``), give the same results on the same inputs: one test runs both
of every pair.

    pair       interface     native               Python twin                  compared
    rows       RowLines      _rows.RowFormat      outputs.csv.RowTemplate      the lines' bytes
    row read   RowReader     _rows.RowRead        native_fmu_step.SlicedRow    values and types
    latencies  BucketCount   _rows.log_buckets    outputs.latency.log_buckets  total, max, buckets
    answers    AnswerReader  _answers.AnswerRead  native_step_channel.         outputs (types,
                                                  ProtobufAnswers              bits), the cost

The two whole-run pairs are compared by the bytes of results.csv, stepped both ways: the native
FMU step and the master's steppers in master/test_native_kernel.py, the native step channel and
grpc.aio (both a ``coupler.client.StepTransport``) in master/test_native_steps.py.
"""

from __future__ import annotations

import ctypes
import math
import struct
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coupler import wire
from coupler.channels import Causality, Channel, Description, ValueType
from coupler.costs import StepMeter
from coupler_orchestrator.master import native_fmu_step as kernel
from coupler_orchestrator.master import native_step_channel as steps
from coupler_orchestrator.native import AnswerReader, BucketCount, RowLines, RowReader
from coupler_orchestrator.observer import Column
from coupler_orchestrator.outputs import csv as csv_output
from coupler_orchestrator.outputs import latency

from .support import require_native

CELLS = {
    "Real": st.floats(width=64),
    "Integer": st.integers(-(2**70), 2**70),
    "Enumeration": st.integers(-(2**31), 2**31 - 1),
    "UInt64": st.integers(0, 2**64 - 1),
    "Boolean": st.booleans() | st.integers(-2, 2),
    "String": st.text(max_size=8),
    "Binary": st.binary(max_size=8),
}
"""Per column type, the values a row may hold."""


def key(values: Any) -> list[tuple[type, Any]]:
    """Values compared by type and bits (nan equals nan, -0.0 is not 0.0)."""
    return [(type(v), struct.pack("<d", v) if isinstance(v, float) else v) for v in values]


def row_lines(data: st.DataObject) -> tuple[list[Any], list[Any]]:
    """Each way's line of one drawn row, as bytes."""
    kinds = data.draw(st.lists(st.sampled_from(sorted(CELLS)), min_size=1, max_size=8))
    columns = [Column(name=f"C.v{i}", unit="", type=kind) for i, kind in enumerate(kinds)]
    picked = data.draw(st.lists(st.integers(0, len(kinds) - 1), max_size=10))
    row = [data.draw(CELLS[kind]) for kind in kinds]
    time = data.draw(st.floats(allow_nan=False))
    made: list[list[Any]] = []
    for lines in (
        csv_output.native_row_format(columns, picked),
        csv_output.RowTemplate(columns, picked),
    ):
        way: RowLines = lines
        made.append([way.line(time, row).encode()])
    return made[0], made[1]


PLANES = {  # an output's C type in the FMU step's arrays, and its FMI type
    "d": (ctypes.c_double, "Real", st.floats(width=64)),
    "i": (ctypes.c_int, "Integer", st.integers(-(2**31), 2**31 - 1)),
    "q": (ctypes.c_int64, "Integer", st.integers(-(2**63), 2**63 - 1)),
    "b": (ctypes.c_int, "Boolean", st.integers(-2, 2)),
    "?": (ctypes.c_bool, "Boolean", st.booleans()),
    "s": (ctypes.c_char_p, "String", st.text(max_size=8).map(str.encode)),
}


class _Kind:
    def __init__(self, kind: str) -> None:
        self.kind = kind


def row_reads(data: st.DataObject) -> tuple[list[Any], list[Any]]:
    """Each way's row of drawn arrays (one per C type, as the native FMU step keeps them)."""
    codes = data.draw(st.lists(st.sampled_from(sorted(PLANES)), min_size=1, max_size=6))
    planes, columns = {}, []
    for code in codes:
        element, kind, _ = PLANES[code]
        plane = planes.setdefault(code, kernel._Plane(element, kind))
        columns.append((plane, plane.size, _Kind(kind)))
        plane.size += 1
    start = 0
    for plane in planes.values():
        plane.allocate()
        plane.start, start = start, start + plane.size
    for code, (plane, index, _) in zip(codes, columns, strict=True):
        plane.array[index] = data.draw(PLANES[code][2])
    native = kernel._reader(columns)  # type: ignore[arg-type]
    assert native is not None
    positions = [plane.start + index for plane, index, _ in columns]
    sliced = kernel.SlicedRow(list(planes.values()), kernel._row_getter(positions))
    made: list[list[Any]] = []
    for reader in (native, sliced):
        way: RowReader = reader
        made.append(key(way.row()))
    return made[0], made[1]


def latencies(data: st.DataObject) -> tuple[list[Any], list[Any]]:
    """Each way's count of drawn latencies."""
    samples = data.draw(
        st.lists(st.floats(min_value=0.0, max_value=1e4) | st.just(1e-7), min_size=1)
    )
    native = kernel.rows()
    assert native is not None
    made: list[list[Any]] = []
    for count in (native.log_buckets, latency.log_buckets):
        way: BucketCount = count
        total, maximum, buckets = way(samples, math.log(1e-7), 1 / math.log1p(0.01), 1e-7)
        made.append([total, maximum, dict(buckets)])
    return made[0], made[1]


OUTPUTS = {
    "speed": (ValueType.REAL, st.floats(width=64).filter(math.isfinite)),
    "count": (ValueType.INTEGER, st.integers(-(2**31), 2**31 - 1)),
    "mode": (ValueType.ENUMERATION, st.integers(-(2**31), 2**31 - 1)),
    "on": (ValueType.BOOLEAN, st.booleans()),
    "label": (ValueType.STRING, st.text(max_size=8)),
    "data": (ValueType.BINARY, st.binary(max_size=8) | st.just(bytes(wire.LARGE_BYTES + 3))),
}
CODEC = wire.Codec(
    Description(
        name="Every",
        channels=tuple(
            Channel(name=name, causality=Causality.OUTPUT, type=kind)
            for name, (kind, _) in OUTPUTS.items()
        ),
    )
)


def answers(data: st.DataObject) -> tuple[list[Any], list[Any]]:
    """Each way's reading of a drawn step's answer, as the participant runtime writes it."""
    outputs = {name: data.draw(values) for name, (_, values) in OUTPUTS.items()}
    cost = StepMeter()
    cost.seconds, cost.waited = data.draw(st.floats(0, 10)), data.draw(st.floats(0, 10))
    answer = wire.serialized(wire.StepAnswers(CODEC).answer(outputs, cost))
    native = steps.answers()
    assert native is not None
    made: list[list[Any]] = []
    for reader in (
        native.AnswerRead(CODEC.answer_fields(), CODEC.policy.max_message_bytes),
        steps.ProtobufAnswers(CODEC),
    ):
        way: AnswerReader = reader
        found = way.read(memoryview(answer))
        assert found is not None
        values, seconds, waited = found
        made.append([*key(values.values()), list(values), seconds, waited])
    return made[0], made[1]


PAIRS: dict[str, Callable[[st.DataObject], tuple[list[Any], list[Any]]]] = {
    "rows": row_lines,
    "row read": row_reads,
    "latencies": latencies,
    "answers": answers,
}


@pytest.mark.parametrize("pair", sorted(PAIRS))
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_each_native_module_and_its_python_twin_give_the_same(
    pair: str, data: st.DataObject
) -> None:
    require_native(kernel.rows)
    require_native(steps.answers)
    native, python = PAIRS[pair](data)
    assert native == python
