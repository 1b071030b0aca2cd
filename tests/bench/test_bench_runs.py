"""`make bench` must not rot: its scenarios load and run, in-process and remote, with a few
steps (no figure is checked: speed is the benchmark's business, never a test's)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


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
