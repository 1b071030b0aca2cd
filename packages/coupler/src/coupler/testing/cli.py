"""The ``coupler`` command as a user runs it, from tests of packages that must not import the
orchestrator (the adapters to other frameworks): a process of its own, and what it recorded."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any


def run_coupler(
    *argv: str | Path, timeout: float = 120, env: Mapping[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """``coupler ARGV...`` (the console script beside this Python, else ``python -m
    coupler_orchestrator``) as a process of its own; its exit code, stdout and stderr."""
    script = Path(sys.executable).with_name("coupler")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "coupler_orchestrator"]
    return subprocess.run(
        [*command, *(str(a) for a in argv)],
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
        env=None if env is None else {**os.environ, **env},
    )


def recorded(out_dir: Path) -> list[dict[str, str]]:
    """A run's results.csv, one dict per row (header -> cell text)."""
    with (out_dir / "results.csv").open(newline="") as file:
        return list(csv.DictReader(file))


def summary(out_dir: Path) -> dict[str, Any]:
    """A run's summary.json."""
    return json.loads((out_dir / "summary.json").read_text())
