"""A perception participant's balise detections scored against the TrackBalises ground truth.

Input: a run's ``results.csv`` with

- ``<balises>.passed_in_step`` (the TrackBalises FMU: every balise its antenna crossed in the
  step, ``id:group:distance;...``) -- the ground truth: which balise, where, passed when;
- ``<perception>.detections`` (a ``coupler.v1.BaliseDetections`` per step, as the JSON text
  results.csv writes for registered messages, or hex) -- what the system under test saw.

Each detection is matched to the balise passed in the run whose distance along the line is
nearest to the detection's estimated track position, when that is within ``gate_m`` (default
1.5 m, half the 3 m spacing of the balises of a group) and the detection came at or before
the balise was passed; every other detection is false. Per balise passed: whether it was
detected before being passed, when first, how far ahead (estimated and true), the position
error of the first and of all its detections. Overall: recall (balises detected before being
passed / balises passed), precision (matched detections / all detections), false detections,
the error's mean, maximum and 95th percentile.

``python -m coupler_railway.scoring RESULTS_DIR`` writes ``perception-report.json`` (summary
and per balise) and ``perception-report.csv`` (one row per balise passed) into the folder and
prints the summary. ``coupler run`` does the same at the end of every run that records a
``BaliseDetections`` channel and a ``passed_in_step`` column (``run_report``, the entry point
``coupler.reports: perception``), and puts the summary into summary.json.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from coupler.messages import decode_message

REPORT_JSON = "perception-report.json"
REPORT_CSV = "perception-report.csv"
GATE_M = 1.5
"""A detection within this distance of a balise's position is that balise."""


@dataclass(frozen=True)
class Pass:
    """A balise the ground truth saw passed."""

    balise_id: int
    group_id: int
    distance_m: float
    time_s: float


@dataclass(frozen=True)
class Sighting:
    """One detection of one frame."""

    time_s: float
    track_position_m: float
    distance_ahead_m: float
    confidence: float


@dataclass
class BaliseScore:
    """How the perception did on one balise passed."""

    balise_id: int
    group_id: int
    distance_m: float
    passed_at_s: float
    detected: bool = False
    """Detected at or before it was passed."""
    detections: int = 0
    first_detected_at_s: float | None = None
    first_distance_ahead_m: float | None = None
    """Estimated distance ahead at the first detection."""
    first_true_distance_ahead_m: float | None = None
    """The balise's true distance from the camera at the first detection (the camera's
    position taken from the detection: its track position minus its distance ahead)."""
    first_error_m: float | None = None
    """Estimated minus true track position at the first detection."""
    mean_abs_error_m: float | None = None
    max_abs_error_m: float | None = None


@dataclass
class Report:
    """The whole run's score."""

    balises_passed: int
    balises_detected: int
    recall: float
    detections: int
    true_detections: int
    false_detections: int
    precision: float
    mean_abs_error_m: float
    p95_abs_error_m: float
    max_abs_error_m: float
    first_detection_mean_distance_m: float
    gate_m: float
    balises: list[BaliseScore] = field(default_factory=list)
    false: list[dict[str, float]] = field(default_factory=list)
    """Every false detection: time, estimated track position, distance ahead, confidence."""

    def summary(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if k not in ("balises", "false")}


class ScoringError(ValueError):
    """The results lack what the scoring needs (a column, a readable value)."""


def parse_passes(rows: Iterable[tuple[float, str]]) -> list[Pass]:
    """Passes from (time, ``passed_in_step`` text) rows, in order."""
    passes: list[Pass] = []
    for time_s, text in rows:
        for item in filter(None, (text or "").split(";")):
            balise, group, distance = item.split(":")
            passes.append(Pass(int(balise), int(group), float(distance), time_s))
    return passes


def parse_detections(rows: Iterable[tuple[float, str]], message_type: str) -> list[Sighting]:
    """Detections from (time, results.csv cell) rows: JSON text of BaliseDetections, or hex."""
    found: list[Sighting] = []
    for _, text in rows:
        if not text:
            continue
        if text.lstrip().startswith("{"):
            message = json.loads(text)
        else:
            message = decode_message(message_type, bytes.fromhex(text))
        for d in message.get("detections", ()):
            found.append(
                Sighting(
                    time_s=float(d.get("time_s", message.get("time_s", 0.0))),
                    track_position_m=float(d.get("track_position_m", 0.0)),
                    distance_ahead_m=float(d.get("distance_ahead_m", 0.0)),
                    confidence=float(d.get("confidence", 0.0)),
                )
            )
    return found


def score(passes: Sequence[Pass], sightings: Sequence[Sighting], gate_m: float = GATE_M) -> Report:
    """Match detections to balises passed and score them (module docstring)."""
    first_pass: dict[int, Pass] = {}
    for p in passes:
        first_pass.setdefault(p.balise_id, p)
    truth = sorted(first_pass.values(), key=lambda p: p.distance_m)
    scores = {
        p.balise_id: BaliseScore(p.balise_id, p.group_id, p.distance_m, p.time_s) for p in truth
    }
    errors: dict[int, list[float]] = {p.balise_id: [] for p in truth}
    all_errors: list[float] = []
    false: list[dict[str, float]] = []
    positions = [p.distance_m for p in truth]
    for seen in sorted(sightings, key=lambda s: s.time_s):
        nearest = _nearest(positions, seen.track_position_m)
        balise = truth[nearest] if nearest is not None else None
        error = seen.track_position_m - balise.distance_m if balise else math.inf
        if balise is None or abs(error) > gate_m or seen.time_s > balise.time_s:
            false.append(
                {
                    "time_s": seen.time_s,
                    "track_position_m": seen.track_position_m,
                    "distance_ahead_m": seen.distance_ahead_m,
                    "confidence": seen.confidence,
                }
            )
            continue
        entry = scores[balise.balise_id]
        entry.detections += 1
        errors[balise.balise_id].append(error)
        all_errors.append(abs(error))
        if not entry.detected:
            entry.detected = True
            entry.first_detected_at_s = seen.time_s
            entry.first_distance_ahead_m = seen.distance_ahead_m
            camera = seen.track_position_m - seen.distance_ahead_m
            entry.first_true_distance_ahead_m = round(balise.distance_m - camera, 3)
            entry.first_error_m = round(error, 3)
    for balise_id, found in errors.items():
        if found:
            scores[balise_id].mean_abs_error_m = round(sum(map(abs, found)) / len(found), 3)
            scores[balise_id].max_abs_error_m = round(max(map(abs, found)), 3)
    detected = [s for s in scores.values() if s.detected]
    total = len(all_errors) + len(false)
    firsts = [s.first_true_distance_ahead_m for s in detected if s.first_true_distance_ahead_m]
    return Report(
        balises_passed=len(truth),
        balises_detected=len(detected),
        recall=round(len(detected) / len(truth), 4) if truth else 0.0,
        detections=total,
        true_detections=len(all_errors),
        false_detections=len(false),
        precision=round(len(all_errors) / total, 4) if total else 0.0,
        mean_abs_error_m=round(sum(all_errors) / len(all_errors), 3) if all_errors else 0.0,
        p95_abs_error_m=round(_percentile(all_errors, 0.95), 3),
        max_abs_error_m=round(max(all_errors, default=0.0), 3),
        first_detection_mean_distance_m=round(sum(firsts) / len(firsts), 2) if firsts else 0.0,
        gate_m=gate_m,
        balises=list(scores.values()),
        false=false,
    )


def score_results(
    results: Path,
    *,
    perception: str = "Perception",
    balises: str = "TrackBalises",
    gate_m: float = GATE_M,
) -> Report:
    """Score a run's results.csv (or its folder)."""
    from coupler_railway.messages import BALISE_DETECTIONS

    path = results / "results.csv" if results.is_dir() else results
    detections, passed = f"{perception}.detections", f"{balises}.passed_in_step"
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            missing = [
                c for c in ("time", detections, passed) if c not in (reader.fieldnames or ())
            ]
            if missing:
                raise ScoringError(
                    f"{path} has no column {missing[0]!r}: record it (coupler run "
                    f"--output-variables '{perception}.*,{balises}.*')"
                )
            rows = [(float(r["time"]), r[detections], r[passed]) for r in reader]
    except OSError as exc:
        raise ScoringError(f"cannot read {path}: {exc.strerror or exc}") from exc
    return score(
        parse_passes((t, p) for t, _, p in rows),
        parse_detections(((t, d) for t, d, _ in rows), BALISE_DETECTIONS),
        gate_m,
    )


def run_report(folder: Path, columns: Mapping[str, str]) -> dict[str, Any] | None:
    """The perception report of the run whose results are in ``folder``, written there, for
    summary.json (the orchestrator's ``coupler.reports`` hook); None when the run recorded no
    ``BaliseDetections`` channel or no ``passed_in_step`` column: it is not a perception run."""
    from coupler_railway.messages import BALISE_DETECTIONS

    detections = [n for n, message in columns.items() if message == BALISE_DETECTIONS]
    passes = [n for n in columns if n.endswith(".passed_in_step")]
    if len(detections) != 1 or len(passes) != 1:
        return None
    perception, balises = detections[0].rpartition(".")[0], passes[0].rpartition(".")[0]
    if detections[0] != f"{perception}.detections":
        return None
    report = score_results(folder, perception=perception, balises=balises)
    as_json, as_csv = write_report(report, folder)
    return {
        "perception": perception,
        "ground_truth": balises,
        **report.summary(),
        "missed": [b.balise_id for b in report.balises if not b.detected],
        "files": [as_json.name, as_csv.name],
    }


def write_report(report: Report, folder: Path) -> tuple[Path, Path]:
    """``perception-report.json`` and ``perception-report.csv`` in ``folder``."""
    as_json = folder / REPORT_JSON
    as_json.write_text(json.dumps(asdict(report), indent=2) + "\n", encoding="utf-8")
    as_csv = folder / REPORT_CSV
    columns = [f.name for f in BaliseScore.__dataclass_fields__.values()]
    with as_csv.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        for entry in report.balises:
            writer.writerow({k: "" if v is None else v for k, v in asdict(entry).items()})
    return as_json, as_csv


def _nearest(positions: Sequence[float], x: float) -> int | None:
    if not positions:
        return None
    return min(range(len(positions)), key=lambda i: abs(positions[i] - x))


def _percentile(values: Sequence[float], q: float) -> float:
    if not values:
        return 0.0
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, math.ceil(q * len(ordered)) - 1)]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m coupler_railway.scoring",
        description="Score a run's balise detections against the TrackBalises ground truth.",
    )
    parser.add_argument("results", type=Path, help="the run's folder (or its results.csv)")
    parser.add_argument("--perception", default="Perception", help="the perception component")
    parser.add_argument("--balises", default="TrackBalises", help="the TrackBalises component")
    parser.add_argument("--gate", type=float, default=GATE_M, help="match distance [m]")
    args = parser.parse_args(argv)
    try:
        report = score_results(
            args.results, perception=args.perception, balises=args.balises, gate_m=args.gate
        )
    except (ScoringError, ValueError) as exc:
        print(f"coupler_railway.scoring: {exc}", file=sys.stderr)
        return 1
    folder = args.results if args.results.is_dir() else args.results.parent
    as_json, as_csv = write_report(report, folder)
    summary: Mapping[str, Any] = report.summary()
    print(json.dumps(summary, indent=2))
    missed = [s.balise_id for s in report.balises if not s.detected]
    print(f"missed: {missed or 'none'}; written: {as_json}, {as_csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
