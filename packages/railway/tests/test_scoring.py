"""Scoring balise detections against the TrackBalises ground truth, on a results.csv written
here the way `coupler run` writes one (JSON text of registered messages, or hex).

Ground truth: balises 1 (100 m) and 2 (103 m) passed at 10 s, balise 3 (600 m) at 50 s.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from coupler.messages import encode_message, message_json
from coupler_railway.messages import BALISE_DETECTIONS
from coupler_railway.scoring import ScoringError, score_results


def detections(time_s: float, *positions: float, ahead: float = 20.0) -> bytes:
    return encode_message(
        BALISE_DETECTIONS,
        {
            "time_s": time_s,
            "sensor": "front",
            "detections": [
                {"time_s": time_s, "track_position_m": p, "distance_ahead_m": ahead,
                 "confidence": 0.9}
                for p in positions
            ],
        },
    )  # fmt: skip


def write(folder: Path, rows: list[tuple[float, bytes, str]], *, as_hex: bool = False) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "results.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", "Perception.detections", "TrackBalises.passed_in_step"])
        for time_s, found, passed in rows:
            cell = found.hex() if as_hex else message_json(BALISE_DETECTIONS, found)
            writer.writerow([time_s, cell, passed])
    return folder


ROWS = [
    (0.0, detections(0.0), ""),
    (5.0, detections(5.0, 100.4, 102.7), ""),  # both of the group, 0.4 and 0.3 m off
    (6.0, detections(6.0, 100.1), ""),
    (10.0, detections(10.0), "1:1:100;2:1:103"),
    (20.0, detections(20.0, 350.0), ""),  # nothing there: false
    (50.0, detections(50.0), "3:2:600"),  # never seen: missed
    (55.0, detections(55.0, 600.2), ""),  # after it was passed: false
]


@pytest.mark.parametrize("as_hex", [False, True])
def test_recall_precision_and_errors(tmp_path: Path, as_hex: bool) -> None:
    report = score_results(write(tmp_path, ROWS, as_hex=as_hex))
    assert (report.balises_passed, report.balises_detected) == (3, 2)
    assert report.recall == pytest.approx(2 / 3, abs=1e-4)
    assert (report.detections, report.true_detections, report.false_detections) == (5, 3, 2)
    assert report.precision == pytest.approx(0.6)
    assert report.max_abs_error_m == pytest.approx(0.4)
    first, second, third = report.balises
    assert (first.balise_id, first.detections, first.first_detected_at_s) == (1, 2, 5.0)
    assert first.first_error_m == pytest.approx(0.4)
    assert first.first_true_distance_ahead_m == pytest.approx(19.6)
    assert second.detected and second.first_error_m == pytest.approx(-0.3)
    assert not third.detected and third.passed_at_s == 50.0
    assert [f["track_position_m"] for f in report.false] == [350.0, 600.2]


def test_the_command_writes_the_report_and_names_a_missing_column(tmp_path: Path) -> None:
    folder = write(tmp_path / "run", ROWS)
    done = subprocess.run(
        [sys.executable, "-m", "coupler_railway.scoring", str(folder)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads((folder / "perception-report.json").read_text())
    assert report["recall"] == pytest.approx(0.6667)
    with (folder / "perception-report.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [r["balise_id"] for r in rows] == ["1", "2", "3"]
    assert rows[2]["detected"] == "False" and rows[2]["first_detected_at_s"] == ""
    with pytest.raises(ScoringError, match=r"has no column 'Camera\.detections'"):
        score_results(folder, perception="Camera")
    done = subprocess.run(
        [sys.executable, "-m", "coupler_railway.scoring", str(tmp_path / "nowhere")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1 and "cannot read" in done.stderr and "Traceback" not in done.stderr
