"""Property-based tests: whatever bytes an SSP file holds, loading gives a scenario or the
project's own error (ScenarioError), never another exception.

Inputs are arbitrary bytes, and mutations of real files (the reference SSD, its .ssv/.ssm/.ssb),
which reach far deeper into the loader than random bytes do.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import zipfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coupler.errors import ScenarioError
from coupler_orchestrator.ssp import load_ssp

DATA = Path(__file__).parent / "data"
FILES = ("scenario.ssd", "params.ssv", "mapping.ssm", "signals.ssb")
FUZZ = settings(
    max_examples=int(os.environ.get("COUPLER_FUZZ_EXAMPLES", "120")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@st.composite
def mutated(draw: st.DrawFn, original: bytes) -> bytes:
    """``original`` with a few bytes deleted, inserted or replaced, or a slice duplicated."""
    data = bytearray(original)
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, max(len(data) - 1, 0)))
        action = draw(st.sampled_from(["delete", "insert", "replace", "duplicate"]))
        size = draw(st.integers(1, 40))
        if action == "delete":
            del data[at : at + size]
        elif action == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=size))
        elif action == "replace":
            data[at : at + size] = draw(
                st.sampled_from([b'"', b"<", b">", b"/", b"&", b"]]>", b"\x00", b"\xff", b"1e999"])
            )
        else:
            data[at:at] = data[at : at + size]
    return bytes(data)


def tree(tmp_path: Path, name: str, content: bytes) -> Path:
    """The reference scenario's files in a fresh folder, ``name`` replaced by ``content``."""
    folder = tmp_path / "case"
    shutil.rmtree(folder, ignore_errors=True)
    (folder / "resources").mkdir(parents=True)
    for item in FILES:
        (folder / item).write_bytes((DATA / item).read_bytes())
    shutil.copy(DATA / "resources" / "gain.fmu", folder / "resources")
    (folder / name).write_bytes(content)
    return folder / "scenario.ssd"


def loads_or_refuses(path: Path, **kwargs: object) -> None:
    with contextlib.suppress(ScenarioError):
        load_ssp(path, env={"SCALE_HOST": "h"}, **kwargs)  # type: ignore[arg-type]


@FUZZ
@given(content=st.binary(max_size=2000))
def test_any_bytes_as_an_ssd(tmp_path: Path, content: bytes) -> None:
    loads_or_refuses(tree(tmp_path, "scenario.ssd", content))


@FUZZ
@given(data=st.data(), name=st.sampled_from(FILES))
def test_mutated_ssd_ssv_ssm_ssb(tmp_path: Path, data: st.DataObject, name: str) -> None:
    content = data.draw(mutated((DATA / name).read_bytes()))
    loads_or_refuses(tree(tmp_path, name, content))


@FUZZ
@given(data=st.data())
def test_mutated_ssp_archives(tmp_path: Path, data: st.DataObject) -> None:
    """A valid archive with its bytes mutated: zip structure, compression and the SSD inside."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.write(DATA / "scenario.ssd", "SystemStructure.ssd")
        for item in FILES[1:]:
            zf.write(DATA / item, item)
    archive = tmp_path / "fuzz.ssp"
    archive.write_bytes(data.draw(mutated(buffer.getvalue())))
    work = tmp_path / "work"
    shutil.rmtree(work, ignore_errors=True)
    loads_or_refuses(archive, workdir=work, max_archive_bytes=1_000_000)
