"""No failing FMU run leaves its unpacked FMU behind: crash, hang and SIGTERM during a hang, in
the orchestrator's process and isolated (``--isolate-fmus``), from a bare SSD and from an .ssp
archive. Each run is ``coupler run`` as a subprocess with a temporary folder of its own (TMPDIR)
that must be empty once it has ended.

    Source (FMI 2) --ramp--> Faulty (FMI 2: crash_at / hang_at)
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from coupler.testing import wait_until

from .support.faults import FAULTY_SSD, RUN, assert_rows_kept, summary

pytestmark = pytest.mark.usefixtures("fmus")


@pytest.fixture
def tmpdir_of_run() -> Iterator[Path]:
    """An empty folder for the run's TMPDIR; short (a unix socket's path must fit 107 bytes)."""
    folder = Path(tempfile.mkdtemp(prefix="c-", dir="/tmp"))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def faulty_ssd(
    tmp_path: Path, faulty_fmus: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> Path:
    monkeypatch.setenv("FAULTY_FMU_DIR", str(faulty_fmus["Faulty2"].parent))
    return FAULTY_SSD.write(tmp_path / "faulty.ssd")


@pytest.fixture
def archive(tmp_path: Path, fmus: dict[str, Path], faulty_fmus: dict[str, Path]) -> Path:
    """The faulty scenario as an .ssp holding both FMUs."""
    path = tmp_path / "faulty.ssp"
    ssd = (
        FAULTY_SSD.xml()
        .replace("${COUPLER_FMU_DIR}", "resources")
        .replace("${FAULTY_FMU_DIR}", "resources")
    )
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", ssd)
        zf.write(fmus["Source2"], "resources/Source2.fmu")
        zf.write(faulty_fmus["Faulty2"], "resources/Faulty2.fmu")
    return path


def start(scenario: Path, out: Path, tmpdir: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "coupler_orchestrator", "run", str(scenario), "--out", str(out),
         "--no-progress", *RUN, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "TMPDIR": str(tmpdir)},
    )  # fmt: skip


def left_in(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def assert_nothing_left(folder: Path) -> None:
    """The run's temporary folder is empty (an isolated host is given a moment to be reaped)."""
    wait_until(lambda: not left_in(folder), 5, what=f"nothing left in {folder}")


FAULTS = {
    "crash": ("--param", "Faulty.crash_at=1"),
    "hang": ("--param", "Faulty.hang_at=1", "--call-timeout", "1"),
}


@pytest.mark.slow
@pytest.mark.parametrize("isolated", [False, True], ids=["in-process", "isolated"])
@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("form", ["ssd", "ssp"])
def test_a_failing_fmu_run_leaves_no_temporary_folder(
    faulty_ssd: Path,
    archive: Path,
    tmp_path: Path,
    tmpdir_of_run: Path,
    fault: str,
    isolated: bool,
    form: str,
) -> None:
    scenario = faulty_ssd if form == "ssd" else archive
    flags = FAULTS[fault] + (("--isolate-fmus",) if isolated else ())
    run = start(scenario, tmp_path / "o", tmpdir_of_run, *flags)
    _, err = run.communicate(timeout=60)
    assert run.returncode != 0, err
    assert summary(tmp_path / "o")["status"] in ("failed", "crashed"), err
    assert_nothing_left(tmpdir_of_run)


@pytest.mark.slow
@pytest.mark.parametrize("isolated", [False, True], ids=["in-process", "isolated"])
def test_sigterm_during_a_hang_leaves_no_temporary_folder(
    faulty_ssd: Path, tmp_path: Path, tmpdir_of_run: Path, isolated: bool
) -> None:
    out = tmp_path / "o"
    flags = ("--param", "Faulty.hang_at=1", "--call-timeout", "600")
    run = start(faulty_ssd, out, tmpdir_of_run, *flags, *(("--isolate-fmus",) if isolated else ()))
    wait_until(lambda: (out / "summary.json").exists(), 30, what="the run to start")
    time.sleep(2.0)  # blocked in doStep at t = 1
    assert run.poll() is None
    run.send_signal(signal.SIGTERM)
    _, err = run.communicate(timeout=30)
    assert run.returncode == 130, err
    assert summary(out)["status"] == "aborted"
    assert_rows_kept(out)
    assert_nothing_left(tmpdir_of_run)
