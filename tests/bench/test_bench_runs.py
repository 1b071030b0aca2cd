"""`make bench` must not rot: its scenarios load and run, in-process and remote, with a few
steps (no figure is checked: speed is the benchmark's business, never a test's)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.parametrize("case", ["chain2", "remote3"])
def test_a_bench_case_runs(case: str) -> None:
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "suite.py"), "--only", case, "--steps", "300"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert re.search(rf"^{case}: [\d,]+ steps/s$", done.stdout, re.MULTILINE), done.stdout


def test_the_openmcx_rows_say_why_they_are_skipped(tmp_path: Path) -> None:
    """Without ``OPENMCX`` (or with a path that is no program) the rows are skipped, saying so."""
    env = {k: v for k, v in os.environ.items() if k != "OPENMCX"}
    for value, said in [
        (None, "chain x2 and x10 vs OpenMCx: skipped, OPENMCX is not set"),
        (str(tmp_path), f"OPENMCX={tmp_path} is not an executable file"),
    ]:
        done = subprocess.run(
            [sys.executable, str(ROOT / "benchmarks" / "suite.py"), "--sections", "openmcx",
             "--out", str(tmp_path / "bench.json")],
            capture_output=True, text=True, timeout=120, cwd=ROOT,
            env=env if value is None else {**env, "OPENMCX": value},
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-2000:]
        assert said in done.stdout, done.stdout
        assert "OpenMCx (C)" not in done.stdout


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_every_section_runs_with_the_fewest_steps(tmp_path: Path) -> None:
    """`make bench` as a whole, each section once with ``--smoke``: a refused results folder, a
    changed CLI or API breaks this test, not the next person's benchmark run."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "suite.py"), "--smoke",
         "--out", str(tmp_path / "bench.json")],
        capture_output=True, text=True, timeout=1100, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Coupler benchmark (smoke: not a measurement;" in done.stdout, done.stdout
    for row in [
        "coupler --help",
        "coupler run, watched",
        "in-process FMU chain x2",
        "remote x1 over UDS",
        "bare grpc.aio stream, empty",
        "proxy FMU in Coupler (x1)",
        "camera frames x1 (1.44 MB, 5 Hz)",
        "orchestrator RSS 1e4 -> 1e5 steps",
        "replay RSS, 160 MB recording",
        "mosaik World, CouplerSimulator x1 (gRPC)",
        "HELICS federate <-> Coupler run",
        "bare C loop",
        "perception run, clear",
        "perception campaign, time around a run",
    ]:
        assert row in done.stdout, f"no row {row!r}:\n{done.stdout}"
