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
from coupler_railway.scoring import Grid, ScoringError, score_results

from .support import ROWS


def write(folder: Path, rows: list[tuple[float, bytes, str]], *, as_hex: bool = False) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "results.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", "Perception.detections", "TrackBalises.passed_in_step"])
        for time_s, found, passed in rows:
            cell = found.hex() if as_hex else message_json(BALISE_DETECTIONS, found)
            writer.writerow([time_s, cell, passed])
    return folder


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


def train_run(folder: Path) -> Path:
    """A run on the grid 0, 1, ... 21 s as `coupler run` writes it: the train at 10 m/s (the
    camera 0 m along the line at 0 m travelled), balise 1 at 100 m passed at 10 s, balise 2 at
    200 m at 20 s; each row's detections are of the previous point's frame, whose time the
    participant computed with a float sum (9.200000000000001-like); balise 1 seen at 30 and
    20 m ahead, once at 20 m with an error of 0.4 m; balise 2 never; one false detection."""
    seen = {7: [(100.2, 30.0)], 8: [(100.4, 20.0)], 13: [(150.0, 20.0)]}
    drift = 1e-15
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "results.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", "Perception.detections", "TrackBalises.passed_in_step",
                         "OpenRails.train_state"])  # fmt: skip
        for t in range(22):
            frame = t - 1 + drift * t  # the frame's time, slightly off the grid
            found = b"" if t == 0 else encode_message(BALISE_DETECTIONS, {
                "time_s": frame, "sensor": "front",
                "detections": [
                    {"time_s": frame, "track_position_m": p, "distance_ahead_m": a,
                     "confidence": 0.9, "box": {"left": 1, "top": 2, "right": 3, "bottom": 4}}
                    for p, a in seen.get(t - 1, ())
                ],
            })  # fmt: skip
            passed = {10: "1:1:100", 20: "2:2:200"}.get(t, "")
            state = json.dumps({"time_s": t, "distance_m": 10.0 * t})
            cell = message_json(BALISE_DETECTIONS, found) if found else ""
            writer.writerow([float(t), cell, passed, state])
    summary = {
        "start_time": 0.0,
        "step_size": 1.0,
        "parameters": {"Perception.track_offset": 0.0, "OpenRails.fog_m": 200.0,
                       "TrackBalises.antenna_offset": 0.0},
        "columns": [{"name": "OpenRails.train_state", "message_type": "coupler.v1.TrainState"}],
    }  # fmt: skip
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def test_by_distance_recall_is_per_band_of_true_distance_and_errors_per_estimated_band(
    tmp_path: Path,
) -> None:
    report = score_results(train_run(tmp_path))
    assert (report.recall, report.false_detections) == (0.5, 1)
    bins = {(b.from_m, b.to_m): b for b in report.by_distance}
    assert list(bins) == [(0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0)]
    # frames showed both balises at 10, 20 and 30 m ahead (40 m is past the last band)
    assert [(b.balises, b.detected, b.recall) for b in bins.values()] == [
        (0, 0, None), (2, 0, 0.0), (2, 1, 0.5), (2, 1, 0.5)
    ]  # fmt: skip
    twenty = bins[(20.0, 30.0)]  # the detector's estimate of 20 m: one true, one false
    assert (twenty.detections, twenty.true_detections, twenty.precision) == (2, 1, 0.5)
    assert (twenty.bias_m, twenty.std_m, twenty.max_abs_error_m) == (0.4, 0.0, 0.4)
    assert bins[(30.0, 40.0)].bias_m == 0.2
    # the conditions: the run's parameters but the participant's and the ground truth's
    assert report.conditions == {"OpenRails.fog_m": 200.0}
    assert report.summary()["by_condition"][0]["OpenRails.fog_m"] == 200.0


def test_times_are_on_the_grid_and_every_detection_has_a_row(tmp_path: Path) -> None:
    folder = train_run(tmp_path)
    done = subprocess.run(
        [sys.executable, "-m", "coupler_railway.scoring", str(folder)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    with (folder / "perception-detections.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [r["time_s"] for r in rows] == ["7.0", "8.0", "13.0"]  # not 7.000000000000008
    first = rows[0]
    assert (first["outcome"], first["balise_id"], first["true_distance_ahead_m"]) == (
        "true", "1", "30.0"
    )  # fmt: skip
    assert (first["left"], first["bottom"], first["error_m"]) == ("1", "4", "0.2")
    assert (rows[2]["outcome"], rows[2]["balise_id"], rows[2]["error_m"]) == ("false", "", "")
    report = json.loads((folder / "perception-report.json").read_text())
    assert report["false"][0]["time_s"] == 13.0
    with (folder / "perception-by-distance.csv").open() as handle:
        assert next(csv.DictReader(handle))["from_m"] == "0.0"
    markdown = subprocess.run(
        [sys.executable, "-m", "coupler_railway.scoring", str(folder), "--markdown"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "| 20-30 m | 2 | 0.50 | 2 | 0.50 | +0.40 m | 0.00 m | 0.40 m |" in markdown.stdout


def test_the_grid_prints_times_as_written() -> None:
    grid = Grid(0.0, 0.4)
    assert [grid(t) for t in (9.200000000000001, 26.799999999999997, 0.4 * 3)] == [9.2, 26.8, 1.2]
    assert Grid(0.05, 0.01)(0.05 + 0.01 * 7) == 0.12
