"""The localisation's integrity scoring on results.csv files written here: violations with time
and size, error figures, width by distance since the last group, linking errors against the
faults injected, the report hook and the command line."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from coupler_railway.integrity import (
    REPORT_CSV,
    REPORT_JSON,
    IntegrityError,
    campaign_columns,
    run_report,
    score_results,
)

HEADER = [
    "time", "OpenRails.distance", "Localisation.estimated_front", "Localisation.min_safe_front",
    "Localisation.max_safe_front", "Localisation.distance_since_group",
    "Localisation.linking_errors", "Localisation.missed_group_id", "TrackBalises.passed_in_step",
    "BaliseTransmission.faults",
]  # fmt: skip


def write(folder: Path, rows: list[list[object]]) -> Path:
    with (folder / "results.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(HEADER)
        writer.writerows(rows)
    return folder


def row(
    t: float,
    travelled: float,
    estimate: float,
    half: float,
    since: float = 0.0,
    errors: int = 0,
    missed: int = 0,
    passed: str = "",
    faults: str = "",
) -> list[object]:
    return [t, travelled, estimate, estimate - half, estimate + half, since, errors, missed,
            passed, faults]  # fmt: skip


def run_with_two_violations(folder: Path) -> Path:
    # truth = travelled + 41.7
    return write(
        folder,
        [
            row(0, 0.0, 41.7, 7.0),
            row(1, 10.0, 52.0, 7.0, 10.0, passed="1000:100:120;1001:100:123"),
            row(2, 20.0, 70.0, 7.0, 20.0),  # truth 61.7, min 63: behind by 1.3
            row(3, 30.0, 81.0, 7.0, 30.0),  # truth 71.7, min 74: behind by 2.3
            row(4, 40.0, 82.0, 7.0, 40.0),  # inside
            row(5, 50.0, 80.0, 7.0, 50.0),  # truth 91.7, max 87: ahead by 4.7
            row(6, 60.0, 101.7, 7.0, 60.0),
        ],
    )


def test_violations_have_time_side_and_size(tmp_path: Path) -> None:
    report, _ = score_results(run_with_two_violations(tmp_path))
    assert not report.integrity and report.violations == 2 and report.violation_steps == 3
    first, second = report.violation_list
    assert (first.start_s, first.end_s, first.side, first.size_m) == (2, 3, "behind", 2.3)
    assert (second.start_s, second.end_s, second.side, second.size_m) == (5, 5, "ahead", 4.7)
    assert report.worst_violation_m == 4.7
    assert report.error_max_m == pytest.approx(11.7)
    assert report.width_max_m == 14.0


def test_integrity_holds_when_the_truth_stays_inside(tmp_path: Path) -> None:
    rows = [row(t, 10.0 * t, 41.7 + 10.0 * t + 0.5, 6.0 + t, 10.0 * t) for t in range(20)]
    report, _ = score_results(write(tmp_path, rows), bin_m=50.0)
    assert report.integrity and report.violation_list == []
    assert report.error_mean_m == pytest.approx(0.5)
    assert [b.from_m for b in report.width_bins] == [0.0, 50.0, 100.0, 150.0]
    assert report.width_bins[0].width_max_m == pytest.approx(2 * (6.0 + 4))
    assert report.width_bins[-1].steps == 5


def test_linking_errors_against_injected_faults(tmp_path: Path) -> None:
    rows = [
        row(0, 0, 41.7, 7),
        row(1, 100, 141.7, 7, passed="1000:100:120;1001:100:123",
            faults="lost:1000:100;lost:1001:100"),  # group 100: not read
        row(2, 300, 341.7, 7, passed="1010:101:320;1011:101:323",
            faults="lost:1010:101"),  # group 101: one of two lost, read
        row(3, 400, 441.7, 7, errors=1, missed=100),  # detected
        row(4, 1000, 1041.7, 7, errors=2, missed=102, passed="1020:102:1000.8"),  # false alarm
        row(5, 1600, 1641.7, 7, errors=2, missed=102, passed="1030:103:1681.7",
            faults="corrupt:1030:103"),  # group 103: not read, never raised: missed
        row(6, 2000, 2041.7, 7, errors=2, missed=102, passed="1040:104:1900",
            faults="late:1040:104"),
    ]  # fmt: skip
    report, _ = score_results(write(tmp_path, rows))
    assert (report.groups_passed, report.groups_not_read, report.groups_late) == (5, 2, 1)
    assert (report.linking_errors, report.detected, report.missed) == (2, 1, 1)
    assert (report.false_alarms, report.late_raised) == (1, 0)
    assert report.linking_events == [
        {"time_s": 3.0, "group_id": 100, "count": 1},
        {"time_s": 4.0, "group_id": 102, "count": 1},
    ]


def test_report_hook_writes_files_and_summary(tmp_path: Path) -> None:
    folder = run_with_two_violations(tmp_path)
    columns = {name: "" for name in HEADER[1:]}
    summary = run_report(folder, columns)
    assert summary is not None
    assert summary["localisation"] == "Localisation" and summary["truth"] == (
        "OpenRails.distance + 41.7 m"
    )
    assert summary["integrity"] is False and summary["violations"] == 2
    assert summary["violation_list"][1] == {
        "start_s": 5.0, "end_s": 5.0, "side": "ahead", "size_m": 4.7, "steps": 1
    }  # fmt: skip
    assert summary["files"] == [REPORT_JSON, REPORT_CSV]
    assert json.loads((folder / REPORT_JSON).read_text())["violations"] == 2
    lines = (folder / REPORT_CSV).read_text().splitlines()
    assert lines[0].startswith("time,true_front_m,estimated_front_m") and len(lines) == 8
    assert lines[3].endswith(",False")
    # not a localisation run: no interval recorded
    assert run_report(folder, {"OpenRails.distance": ""}) is None


def test_campaign_columns_read_the_runs_report(tmp_path: Path) -> None:
    class Finished:
        directory = tmp_path

    (tmp_path / "summary.json").write_text(
        json.dumps({"reports": {"localisation": {"integrity": True, "width_max_m": 80.0}}})
    )
    assert campaign_columns(Finished()) == {"loc_integrity": True, "loc_width_max_m": 80.0}
    (tmp_path / "summary.json").write_text(json.dumps({"reports": {}}))
    assert campaign_columns(Finished()) == {}


def test_missing_column_is_named_with_the_fix(tmp_path: Path) -> None:
    (tmp_path / "results.csv").write_text("time,OpenRails.distance\n0,0\n")
    with pytest.raises(IntegrityError, match=r"no column 'Localisation\.estimated_front'.*record"):
        score_results(tmp_path)
    done = subprocess.run(
        [sys.executable, "-m", "coupler_railway.integrity", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith("coupler_railway.integrity: ")


def test_command_line_prints_the_summary(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "coupler_railway.integrity", str(run_with_two_violations(tmp_path))],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert '"integrity": false' in done.stdout
    assert "violation 5-5 s: truth ahead by 4.7 m" in done.stdout
