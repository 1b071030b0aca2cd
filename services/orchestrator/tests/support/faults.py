"""The fault tests' scenario and its participant process (test_faults.py, and the tests that
reuse them: master/test_native_steps.py, test_temp_folders.py).

    Source (FMI 2) --ramp--> Gain (gRPC: faulty_participant.py, a process) --y--> Integ (FMI 2)

0 .. 20 s in steps of 0.1 s.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from coupler.testing import SystemStructure, end_group, fmu, free_port, remote

HERE = Path(__file__).parent
SSD = SystemStructure(
    "Faults",
    components=[
        fmu("Source", "${COUPLER_FMU_DIR}/Source2.fmu", outputs=["ramp"]),
        remote("Gain", "grpc://127.0.0.1:${GAIN_PORT}", inputs=["u"], outputs=["y"]),
        fmu("Integ", "${COUPLER_FMU_DIR}/Integrator2.fmu", inputs=["u"]),
    ],
    connections=[("Source.ramp", "Gain.u"), ("Gain.y", "Integ.u")],
    stop_time=20,
)
RUN = ("--step", "0.1")


class Gain:
    """A participant process (faulty_participant.py) on a port of its own."""

    def __init__(self, port: int, *flags: str) -> None:
        self.port = port
        self.log = Path(os.environ.get("TMPDIR", "/tmp")) / f"gain-{port}-{time.time_ns()}.log"
        with self.log.open("wb") as err:
            self.process = subprocess.Popen(
                [sys.executable, str(HERE / "faulty_participant.py"), "--port", str(port), *flags],
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
                start_new_session=True,  # ``stop`` ends whatever it started too
            )
        assert self.process.stdout is not None
        line = self.process.stdout.readline()
        assert line.startswith("serving Gain at"), (line, self.log.read_text())

    def signal(self, sig: int) -> None:
        self.process.send_signal(sig)

    def stop(self) -> None:
        end_group(self.process, grace=1)
        self.log.unlink(missing_ok=True)


@contextmanager
def gain(monkeypatch: pytest.MonkeyPatch, *flags: str, port: int = 0) -> Iterator[Gain]:
    port = port or free_port()
    monkeypatch.setenv("GAIN_PORT", str(port))
    process = Gain(port, *flags)
    try:
        yield process
    finally:
        process.stop()


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as file:
        return list(csv.DictReader(file))


def summary(out: Path) -> dict[str, Any]:
    return json.loads((out / "summary.json").read_text())  # type: ignore[no-any-return]


def assert_rows_kept(out: Path) -> list[dict[str, str]]:
    """Every recorded row is whole and the summary counts them."""
    recorded = rows(out)
    assert recorded, "no row was kept"
    width = len(recorded[0])
    for row in recorded:  # a cut row would have missing (None) or surplus cells
        assert len(row) == width and None not in row.values() and None not in row, row
        float(row["time"])
    assert len(recorded) == summary(out)["steps"] + 1
    return recorded


FAULTY_SSD = SystemStructure(
    "FaultyFmu",
    components=[
        fmu("Source", "${COUPLER_FMU_DIR}/Source2.fmu", outputs=["ramp"]),
        fmu("Faulty", "${FAULTY_FMU_DIR}/Faulty2.fmu", inputs=["u"]),
    ],
    connections=[("Source.ramp", "Faulty.u")],
    stop_time=10,
)
