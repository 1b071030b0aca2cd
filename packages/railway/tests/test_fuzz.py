"""Property-based tests: whatever bytes a railML file holds, reading it gives an
infrastructure (or a network) or a RailMLError, never another exception."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coupler_railway import RailMLError, load_infrastructure, load_network

LINE = Path(__file__).parent / "data" / "test-line.railml"
JUNCTION = Path(__file__).parent / "data" / "junction.railml"
FUZZ = settings(
    max_examples=int(os.environ.get("COUPLER_FUZZ_EXAMPLES", "120")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def reads_or_refuses(path: Path, content: bytes) -> None:
    path.write_bytes(content)
    with contextlib.suppress(RailMLError):
        load_infrastructure(path)


@FUZZ
@given(content=st.binary(max_size=2000))
def test_any_bytes(tmp_path: Path, content: bytes) -> None:
    reads_or_refuses(tmp_path / "line.railml", content)


@FUZZ
@given(data=st.data())
def test_mutated_railml(tmp_path: Path, data: st.DataObject) -> None:
    original = bytearray(LINE.read_bytes())
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(original) - 1))
        token = data.draw(
            st.sampled_from([b'"', b"<", b">", b"-", b"0", b"nan", b"1e308", b"", b"\xff", b"'"])
        )
        original[at : at + data.draw(st.integers(0, 12))] = token
    reads_or_refuses(tmp_path / "line.railml", bytes(original))


@FUZZ
@given(data=st.data())
def test_mutated_network(tmp_path: Path, data: st.DataObject) -> None:
    original = bytearray(JUNCTION.read_bytes())
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(original) - 1))
        token = data.draw(
            st.sampled_from([b'"', b"<", b">", b"-", b"0", b"nan", b"sw1c", b"b1c", b"", b"'"])
        )
        original[at : at + data.draw(st.integers(0, 12))] = token
    path = tmp_path / "junction.railml"
    path.write_bytes(bytes(original))
    with contextlib.suppress(RailMLError):
        load_network(path)
