"""The FMUs of fmus/faulty misbehave as designed; ``coupler describe`` never shows a traceback.

    FMPy in a child process (never in the test process) simulates, 0 .. 1 s, h = 0.25 s:
      Faulty2 crash_at = 0.5          -> killed by SIGSEGV in the doStep from t = 0.5
      Faulty2 hang_at = 0.5           -> still running, blocked in that doStep, until killed
      CrashOnInstantiate2             -> killed by SIGSEGV in fmi2Instantiate
      Faulty2 (no fault)              -> exit 0, y = u

The child prints every communication point it completes, so the tests see where it stopped.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

from .support import Coupler

CHILD = """
import json, sys
import fmpy

def finished(time, recorder):
    print(time, flush=True)
    return True

result = fmpy.simulate_fmu(
    sys.argv[1], stop_time=1.0, output_interval=0.25, start_values=json.loads(sys.argv[2]),
    step_finished=finished,
)
print("y", *result["y"], flush=True)
"""


def _simulate(fmu: Path, start_values: Mapping[str, float], scratch: Path) -> subprocess.Popen[str]:
    """FMPy unpacks into ``scratch``: a crashed or killed child cannot remove what it unpacked."""
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, str(fmu), json.dumps(start_values)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "TMPDIR": str(scratch)},
    )


def _finish(child: subprocess.Popen[str]) -> tuple[int, list[str]]:
    try:
        out, _ = child.communicate(timeout=60)
    finally:
        child.kill()
    return child.returncode, out.split("\n")[:-1]


def test_no_fault(faulty_fmus: Mapping[str, Path], tmp_path: Path) -> None:
    code, lines = _finish(_simulate(faulty_fmus["Faulty2"], {"u": 1.5}, tmp_path))
    assert code == 0
    assert lines == ["0.25", "0.5", "0.75", "1.0", "y 1.5 1.5 1.5 1.5 1.5"]


def test_crash_at_segfaults_in_do_step(faulty_fmus: Mapping[str, Path], tmp_path: Path) -> None:
    code, lines = _finish(_simulate(faulty_fmus["Faulty2"], {"crash_at": 0.5}, tmp_path))
    assert code == -signal.SIGSEGV
    assert lines == ["0.25", "0.5"]


def test_crash_in_instantiate(faulty_fmus: Mapping[str, Path], tmp_path: Path) -> None:
    code, lines = _finish(_simulate(faulty_fmus["CrashOnInstantiate2"], {}, tmp_path))
    assert code == -signal.SIGSEGV
    assert lines == []


def test_hang_at_blocks_in_do_step(faulty_fmus: Mapping[str, Path], tmp_path: Path) -> None:
    child = _simulate(faulty_fmus["Faulty2"], {"hang_at": 0.5}, tmp_path)
    try:
        assert child.stdout is not None
        assert [child.stdout.readline(), child.stdout.readline()] == ["0.25\n", "0.5\n"]
        time.sleep(1.0)
        assert child.poll() is None, "the FMU should still be blocked in doStep"
    finally:
        child.kill()
        child.communicate(timeout=60)
    assert child.returncode == -signal.SIGKILL


REFUSED = {"Clocks3", "Scheduled3"}


def test_describe_never_shows_a_traceback(
    fmus: Mapping[str, Path], faulty_fmus: Mapping[str, Path], coupler: Coupler
) -> None:
    """Every FMU the project builds: described (faults are in steps or instantiation, which
    describe does not reach), or refused with a one-line error."""
    for name, path in {**fmus, **faulty_fmus}.items():
        outcome = coupler("describe", path)
        assert "Traceback" not in outcome.err, name
        if name in REFUSED:
            assert outcome.code == 1, name
            assert outcome.err.startswith(f"error: {path}: FMU "), name
        else:
            assert outcome.code == 0, (name, outcome.err)
            assert "CHANNEL" in outcome.out
