"""`coupler run` scores a perception run itself: the `coupler.reports` entry point of this
package writes perception-report.json/.csv into the run's folder and its summary goes into
summary.json (`reports.perception`).

    Perception (detections: BaliseDetections)   TrackBalises (passed_in_step: String)
              \\                                      /
               `coupler run` (a process) -- results.csv -- the report

Both participants play test_scoring's table (ROWS) over gRPC, one value per second.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

import pytest

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.participant import Participant, Values
from coupler.testing import SystemStructure, remote, served_in_thread
from coupler_railway.messages import BALISE_DETECTIONS

from .test_scoring import ROWS, detections

LOOPBACK = "grpc://127.0.0.1:{}"


def scored(*, perception: int | None, balises: int) -> SystemStructure:
    """Perception (when served) and TrackBalises, each alone, 0 .. 60 s."""
    components = [
        remote("Perception", LOOPBACK.format(perception), outputs=["detections"]),
        remote("TrackBalises", LOOPBACK.format(balises), outputs=["passed_in_step"]),
    ]
    return SystemStructure("Scored", components[perception is None :], stop_time=60)


class Table(Participant):
    """One output channel playing a column of ROWS: its value at t, or ``empty``."""

    def __init__(self, name: str, channel: Channel, column: int, empty: Value) -> None:
        self.name, self.output, self.empty = name, channel, empty
        self.values = {round(row[0]): row[column] for row in ROWS}

    async def describe(self) -> Description:
        return Description(name=self.name, channels=(self.output,), implementation="tests.Table")

    async def initialize(self, setup: RunSetup) -> Values:
        return {self.output.name: self.values.get(0, self.empty)}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return {self.output.name: self.values.get(round(time + step), self.empty)}

    async def terminate(self, reason: str = "") -> None:
        pass


def test_coupler_run_writes_the_perception_report(tmp_path: Path) -> None:
    perception = Table(
        "Perception",
        Channel(
            name="detections",
            causality=Causality.OUTPUT,
            type=ValueType.BINARY,
            message_type=BALISE_DETECTIONS,
        ),
        1,
        detections(0.0),
    )
    balises = Table(
        "TrackBalises",
        Channel(name="passed_in_step", causality=Causality.OUTPUT, type=ValueType.STRING),
        2,
        "",
    )
    out = tmp_path / "run"
    with served_in_thread(perception) as one, served_in_thread(balises) as two:
        ssd = scored(perception=one.port, balises=two.port).write(tmp_path / "scored.ssd")
        coupler = Path(sys.executable).with_name("coupler")
        done = subprocess.run(
            [str(coupler), "run", str(ssd), "--step", "1", "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    report = summary["reports"]["perception"]
    assert (report["perception"], report["ground_truth"]) == ("Perception", "TrackBalises")
    assert (report["balises_passed"], report["balises_detected"]) == (3, 2)
    assert report["recall"] == pytest.approx(2 / 3, abs=1e-4)
    assert report["precision"] == pytest.approx(0.6)
    assert report["missed"] == [3]
    assert report["files"] == ["perception-report.json", "perception-report.csv"]
    written = json.loads((out / "perception-report.json").read_text())
    assert written["recall"] == report["recall"] and len(written["balises"]) == 3
    assert (out / "perception-report.csv").read_text().count("\n") == 4  # header + 3 balises


def test_a_run_without_detections_has_no_report(tmp_path: Path) -> None:
    balises = Table(
        "TrackBalises",
        Channel(name="passed_in_step", causality=Causality.OUTPUT, type=ValueType.STRING),
        2,
        "",
    )
    out = tmp_path / "run"
    with served_in_thread(balises) as server:
        ssd = scored(perception=None, balises=server.port).write(tmp_path / "plain.ssd")
        coupler = Path(sys.executable).with_name("coupler")
        done = subprocess.run(
            [str(coupler), "run", str(ssd), "--step", "1", "--stop-time", "3", "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    assert done.returncode == 0, done.stderr
    assert "reports" not in json.loads((out / "summary.json").read_text())
    assert not (out / "perception-report.json").exists()
