"""Property-based tests: whatever a route folder's track database or path holds, the mock
loads it or refuses it with a RouteError (file and line), never another exception."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openrails_mock.paths import load_path
from openrails_mock.routefolder import load_route
from openrails_mock.stf import RouteError
from openrails_mock.tdb import TrackNetwork

from .support import ARC_END, ROUTE_FILE, SECTIONS, pat, tdb, utf16

FUZZ = settings(
    max_examples=int(os.environ.get("COUPLER_FUZZ_EXAMPLES", "120")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
TOKENS = [b"(", b")", b'"', b"0", b"-1", b"nan", b"1e39", b"TrPin", b"", b"\xff", b"\x00", b"x"]


def mutated(text: str, data: st.DataObject) -> bytes:
    raw = bytearray(text.encode("utf-8"))
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(raw) - 1))
        raw[at : at + data.draw(st.integers(0, 12))] = data.draw(st.sampled_from(TOKENS))
    return bytes(raw)


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    (tmp_path / "PATHS").mkdir(exist_ok=True)
    (tmp_path / "hand.trk").write_bytes(utf16(ROUTE_FILE))
    (tmp_path / "tsection.dat").write_text(SECTIONS, encoding="utf-8")
    return tmp_path


def loads_or_refuses(folder: Path) -> None:
    with contextlib.suppress(RouteError):
        route = load_route(folder)
        load_path(TrackNetwork(route), folder / "PATHS" / "p.pat")


@FUZZ
@given(data=st.data())
def test_mutated_track_database(folder: Path, data: st.DataObject) -> None:
    (folder / "hand.tdb").write_bytes(mutated(tdb(), data))
    (folder / "PATHS" / "p.pat").write_bytes(
        utf16(pat("p", [(0.0, 0.0, "1 1"), (200.0, 0.0, "2 0"), (*ARC_END, "1 1")]))
    )
    loads_or_refuses(folder)


@FUZZ
@given(data=st.data())
def test_mutated_path(folder: Path, data: st.DataObject) -> None:
    (folder / "hand.tdb").write_bytes(utf16(tdb()))
    points = [(0.0, 0.0, "1 1"), (200.0, 0.0, "2 0"), (500.0, 0.0, "1 1")]
    (folder / "PATHS" / "p.pat").write_bytes(mutated(pat("p", points), data))
    loads_or_refuses(folder)


@FUZZ
@given(content=st.binary(max_size=2000))
def test_any_bytes_as_track_database(folder: Path, content: bytes) -> None:
    (folder / "hand.tdb").write_bytes(content)
    (folder / "PATHS" / "p.pat").write_bytes(utf16(pat("p", [(0.0, 0.0, "1 1")] * 2)))
    loads_or_refuses(folder)
