"""A perception participant's balise detections scored against the TrackBalises ground truth.

Input: a run's ``results.csv`` with

- ``<balises>.passed_in_step`` (the TrackBalises FMU: every balise its antenna crossed in the
  step, ``id:group:distance;...``) -- the ground truth: which balise, where, passed when;
- ``<perception>.detections`` (a ``coupler.v1.BaliseDetections`` per step, as the JSON text
  results.csv writes for registered messages, or hex) -- what the system under test saw;
- optionally a ``coupler.v1.TrainState`` column (the train's distance travelled at each frame)
  and the run's summary.json (its grid, its parameters: the camera's ``track_offset`` and
  mounting, the conditions) -- for where the camera was at every frame.

Each detection is matched to the balise passed in the run whose distance along the line is
nearest to the detection's estimated track position, when that is within ``gate_m`` (default
1.5 m, half the 3 m spacing of the balises of a group) and the detection came at or before
the balise was passed; every other detection is false. Per balise passed: whether it was
detected before being passed, when first, how far ahead (estimated and true), the position
error of the first and of all its detections. Overall: recall (balises detected before being
passed / balises passed), precision (matched detections / all detections), false detections,
the error's mean, maximum and 95th percentile.

**Per detection** (``perception-detections.csv``, and ``.parquet`` with pyarrow): the frame's
time, the box, the estimated and the true distance ahead, the balise it belongs to (empty:
false), the error (estimated minus true track position), and the drawn frame of a false one.

**By distance ahead** (``BIN_M`` = 10 m bins up to the participant's ``max_range``): a
balise's *recall* in a bin is the probability that it was detected in at least one of the
frames that showed it at that true distance before its pass (a balise is "shown" when its
box, projected by ``camera.Camera``, is in the frame -- without a kept frame to take the
intrinsics from: when it is ahead); the detections' figures (count, precision, bias, standard
deviation and maximum of the error) are binned by the distance the detector estimated.

**Conditions**: the run's parameters (summary.json ``parameters``) other than the perception
participant's and the ground truth's -- the world the camera saw (time of day, fog, ... as the
simulator's run parameters) -- written with the figures as the ``by_condition`` row, which a
campaign's rows put side by side.

**Frames** around every miss and every false detection (``frames``): drawn from the frames
the run kept, linked from the rows.

Times are printed on the run's grid (start time + k x step, as the user wrote them: 9.2, never
9.200000000000001).

``python -m coupler_railway.scoring RESULTS_DIR`` writes ``perception-report.json`` (summary,
per balise, per bin, false detections), ``perception-report.csv`` (one row per balise
passed), ``perception-detections.csv`` and ``perception-by-distance.csv`` into the folder and
prints the summary; ``--markdown`` prints the tables of docs/railway-perception.md instead.
``coupler run`` does the same at the end of every run that records a ``BaliseDetections``
channel and a ``passed_in_step`` column (``run_report``, the entry point ``coupler.reports:
perception``), and puts the summary into summary.json.
"""

from __future__ import annotations

import argparse
import bisect
import contextlib
import csv
import json
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from decimal import Decimal
from pathlib import Path
from typing import Any

from coupler.messages import decode_message
from coupler_railway import frames as kept
from coupler_railway.camera import Camera

REPORT_JSON = "perception-report.json"
REPORT_CSV = "perception-report.csv"
DETECTIONS_CSV = "perception-detections.csv"
DETECTIONS_PARQUET = "perception-detections.parquet"
BY_DISTANCE_CSV = "perception-by-distance.csv"
GATE_M = 1.5
"""A detection within this distance of a balise's position is that balise."""
BIN_M = 10.0
"""Width of the distance bins [m]."""
RANGE_M = 40.0
"""The bins' end when the run does not say the participant's ``max_range``."""


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
    box: tuple[int, int, int, int] | None = None
    """left, top, right, bottom (inclusive)."""
    sensor: str = ""


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
    frames: str = ""
    """A miss: its drawn frames (``perception-frames/...``), space-separated."""


@dataclass
class DetectionRow:
    """One detection, judged (``perception-detections.csv``)."""

    time_s: float
    sensor: str
    left: int | None
    top: int | None
    right: int | None
    bottom: int | None
    confidence: float
    distance_ahead_m: float
    """Estimated by the detector."""
    true_distance_ahead_m: float | None
    """Of the balise it belongs to (empty: false)."""
    track_position_m: float
    balise_id: int | None
    group_id: int | None
    outcome: str
    """``true`` or ``false``."""
    error_m: float | None
    """Estimated minus true track position."""
    frame: str = ""
    """A false detection: its drawn frame."""


@dataclass
class DistanceBin:
    """The figures of one band of distance ahead."""

    from_m: float
    to_m: float
    balises: int
    """Balises shown at a true distance in this band before their pass."""
    detected: int
    """... and detected in one of those frames."""
    recall: float | None
    frames: int
    """(frame, balise) pairs in this band."""
    detections: int
    """Detections the detector placed in this band (estimated distance)."""
    true_detections: int
    precision: float | None
    bias_m: float | None
    """Mean error (estimated minus true track position) of its true detections."""
    std_m: float | None
    max_abs_error_m: float | None


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
    false: list[dict[str, Any]] = field(default_factory=list)
    """Every false detection: time, estimated track position, distance ahead, confidence."""
    rows: list[DetectionRow] = field(default_factory=list)
    by_distance: list[DistanceBin] = field(default_factory=list)
    conditions: dict[str, Any] = field(default_factory=dict)
    """The run's parameters of the world the camera saw (module docstring)."""
    frames_drawn: int = 0
    """Frames drawn around misses and false detections (``perception-frames/``)."""

    def summary(self) -> dict[str, Any]:
        """What summary.json's ``reports.perception`` holds: the figures, the bins, the
        conditions and the row of figures by condition; no per-balise or per-detection rows."""
        left_out = ("balises", "false", "rows")
        made = {k: v for k, v in asdict(self).items() if k not in left_out}
        figures = ("recall", "precision", "mean_abs_error_m", "max_abs_error_m")
        made["by_condition"] = [{**self.conditions, **{k: made[k] for k in figures}}]
        return made


class ScoringError(ValueError):
    """The results lack what the scoring needs (a column, a readable value)."""


@dataclass(frozen=True)
class Grid:
    """The run's communication points: ``start + k * step``, printed as the user wrote them."""

    start: float
    step: float

    @property
    def decimals(self) -> int:
        exponents = [Decimal(repr(x)).as_tuple().exponent for x in (self.start, self.step)]
        return max(0, *(-e for e in exponents if isinstance(e, int)))

    def __call__(self, time: float) -> float:
        """``time`` on the grid (the nearest point, as its decimal text reads)."""
        if self.step <= 0 or not math.isfinite(time):
            return time
        k = round((time - self.start) / self.step)
        return round(self.start + k * self.step, self.decimals)

    @classmethod
    def of(cls, summary: Mapping[str, Any], times: Sequence[float]) -> Grid:
        """From summary.json's start time and step, else the results' first two times."""
        start, step = summary.get("start_time"), summary.get("step_size")
        if isinstance(start, int | float) and isinstance(step, int | float) and step > 0:
            return cls(float(start), float(step))
        if len(times) >= 2:
            return cls(times[0], float(repr(round(times[1] - times[0], 12))))
        return cls(times[0] if times else 0.0, 0.0)


def parse_passes(rows: Iterable[tuple[float, str]]) -> list[Pass]:
    """Passes from (time, ``passed_in_step`` text) rows, in order."""
    passes: list[Pass] = []
    for time_s, text in rows:
        for item in filter(None, (text or "").split(";")):
            balise, group, distance = item.split(":")
            passes.append(Pass(int(balise), int(group), float(distance), time_s))
    return passes


def parse_messages(rows: Iterable[tuple[float, str]], message_type: str) -> list[dict[str, Any]]:
    """The messages of (time, results.csv cell) rows: JSON text, or hex; empty cells skipped."""
    found = []
    for _, text in rows:
        if not text:
            continue
        if text.lstrip().startswith("{"):
            found.append(json.loads(text))
        else:
            found.append(decode_message(message_type, bytes.fromhex(text)))
    return found


def parse_detections(rows: Iterable[tuple[float, str]], message_type: str) -> list[Sighting]:
    """Detections from (time, results.csv cell) rows: JSON text of BaliseDetections, or hex."""
    return [s for m in parse_messages(rows, message_type) for s in _sightings(m)]


def _sightings(message: Mapping[str, Any]) -> list[Sighting]:
    found = []
    for d in message.get("detections", ()):
        box = d.get("box")
        found.append(
            Sighting(
                time_s=float(d.get("time_s", message.get("time_s", 0.0))),
                track_position_m=float(d.get("track_position_m", 0.0)),
                distance_ahead_m=float(d.get("distance_ahead_m", 0.0)),
                confidence=float(d.get("confidence", 0.0)),
                box=(
                    tuple(int(box.get(k, 0)) for k in ("left", "top", "right", "bottom"))  # type: ignore[arg-type]
                    if isinstance(box, dict)
                    else None
                ),
                sensor=str(message.get("sensor", "")),
            )
        )
    return found


def score(
    passes: Sequence[Pass],
    sightings: Sequence[Sighting],
    gate_m: float = GATE_M,
    cameras: Mapping[float, float] | None = None,
) -> Report:
    """Match detections to balises passed and score them (module docstring). ``cameras``:
    the camera's true track position at each frame's time, where known; elsewhere it is
    taken from the detection (its track position minus its distance ahead)."""
    first_pass: dict[int, Pass] = {}
    for p in passes:
        first_pass.setdefault(p.balise_id, p)
    truth = sorted(first_pass.values(), key=lambda p: p.distance_m)
    scores = {
        p.balise_id: BaliseScore(p.balise_id, p.group_id, p.distance_m, p.time_s) for p in truth
    }
    errors: dict[int, list[float]] = {p.balise_id: [] for p in truth}
    all_errors: list[float] = []
    false: list[dict[str, Any]] = []
    rows: list[DetectionRow] = []
    positions = [p.distance_m for p in truth]
    for seen in sorted(sightings, key=lambda s: s.time_s):
        nearest = _nearest(positions, seen.track_position_m)
        balise = truth[nearest] if nearest is not None else None
        error = seen.track_position_m - balise.distance_m if balise else math.inf
        row = _row(seen)
        rows.append(row)
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
        camera = (cameras or {}).get(seen.time_s, seen.track_position_m - seen.distance_ahead_m)
        row.outcome, row.balise_id, row.group_id = "true", balise.balise_id, balise.group_id
        row.error_m = round(error, 3)
        row.true_distance_ahead_m = round(balise.distance_m - camera, 3)
        entry = scores[balise.balise_id]
        entry.detections += 1
        errors[balise.balise_id].append(error)
        all_errors.append(abs(error))
        if not entry.detected:
            entry.detected = True
            entry.first_detected_at_s = seen.time_s
            entry.first_distance_ahead_m = seen.distance_ahead_m
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
        rows=rows,
    )


def _row(seen: Sighting) -> DetectionRow:
    left, top, right, bottom = seen.box if seen.box else (None, None, None, None)
    return DetectionRow(
        time_s=seen.time_s,
        sensor=seen.sensor,
        left=left,
        top=top,
        right=right,
        bottom=bottom,
        confidence=seen.confidence,
        distance_ahead_m=seen.distance_ahead_m,
        true_distance_ahead_m=None,
        track_position_m=seen.track_position_m,
        balise_id=None,
        group_id=None,
        outcome="false",
        error_m=None,
    )


def by_distance(
    report: Report,
    cameras: Mapping[float, float],
    *,
    end_m: float = RANGE_M,
    width_m: float = BIN_M,
    shown: Camera | None = None,
) -> list[DistanceBin]:
    """The report's figures by distance ahead (module docstring). ``cameras``: the camera's
    true track position at each frame's time (on the grid); ``shown``: the frames' camera,
    whose view decides whether a balise was in the frame."""
    farthest = max((r.distance_ahead_m for r in report.rows), default=0.0)
    count = max(1, math.ceil(max(end_m, farthest) / width_m - 1e-9))
    edges = [i * width_m for i in range(count + 1)]
    truth = sorted(report.balises, key=lambda b: b.distance_m)
    positions = [b.distance_m for b in truth]
    hits = {(r.balise_id, r.time_s) for r in report.rows if r.outcome == "true"}
    opportunities: dict[int, set[int]] = {}
    detected: dict[int, set[int]] = {}
    frames = [0] * count
    for time, camera in cameras.items():
        first = bisect.bisect_right(positions, camera)  # ahead > 0
        last = bisect.bisect_left(positions, camera + edges[-1])  # ahead < the last edge
        for balise in truth[first:last]:
            ahead = balise.distance_m - camera
            if time > balise.passed_at_s or (shown and shown.balise_box(ahead) is None):
                continue
            i = min(int(ahead // width_m), count - 1)
            frames[i] += 1
            opportunities.setdefault(i, set()).add(balise.balise_id)
            if (balise.balise_id, time) in hits:
                detected.setdefault(i, set()).add(balise.balise_id)
    bins = []
    for i in range(count):
        inside = [r for r in report.rows if edges[i] <= r.distance_ahead_m < edges[i + 1]]
        true = [r.error_m for r in inside if r.outcome == "true" and r.error_m is not None]
        balises, found = len(opportunities.get(i, ())), len(detected.get(i, ()))
        mean = sum(true) / len(true) if true else None
        bins.append(
            DistanceBin(
                from_m=edges[i],
                to_m=edges[i + 1],
                balises=balises,
                detected=found,
                recall=round(found / balises, 4) if balises else None,
                frames=frames[i],
                detections=len(inside),
                true_detections=len(true),
                precision=round(len(true) / len(inside), 4) if inside else None,
                bias_m=round(mean, 3) if mean is not None else None,
                std_m=(
                    round(math.sqrt(sum((e - mean) ** 2 for e in true) / len(true)), 3)
                    if mean is not None
                    else None
                ),
                max_abs_error_m=round(max(abs(e) for e in true), 3) if true else None,
            )
        )
    return bins


@dataclass(frozen=True)
class _Run:
    """What the scoring reads of a run."""

    folder: Path
    rows: list[tuple[float, str, str, str]]
    """(time, detections cell, passed_in_step cell, train state cell) per row."""
    summary: Mapping[str, Any]
    perception: str
    balises: str

    @property
    def parameters(self) -> Mapping[str, Any]:
        made = self.summary.get("parameters")
        return made if isinstance(made, dict) else {}


def _read(path: Path, perception: str, balises: str) -> _Run:
    from coupler_railway.messages import TRAIN_STATE

    folder = path.parent
    summary: dict[str, Any] = {}
    with contextlib.suppress(OSError, ValueError):
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    states = [
        c["name"]
        for c in summary.get("columns", ())
        if isinstance(c, dict) and c.get("message_type") == TRAIN_STATE
    ]
    detections, passed = f"{perception}.detections", f"{balises}.passed_in_step"
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            header = reader.fieldnames or ()
            missing = [c for c in ("time", detections, passed) if c not in header]
            if missing:
                raise ScoringError(
                    f"{path} has no column {missing[0]!r}: record it (coupler run "
                    f"--output-variables '{perception}.*,{balises}.*')"
                )
            state = next((s for s in states if s in header), "")
            rows = [
                (float(r["time"]), r[detections], r[passed], r[state] if state else "")
                for r in reader
            ]
    except OSError as exc:
        raise ScoringError(f"cannot read {path}: {exc.strerror or exc}") from exc
    return _Run(folder, rows, summary, perception, balises)


def score_results(
    results: Path,
    *,
    perception: str = "Perception",
    balises: str = "TrackBalises",
    gate_m: float = GATE_M,
) -> Report:
    """Score a run's results.csv (or its folder); the frames it kept are drawn."""
    from coupler_railway.messages import BALISE_DETECTIONS, TRAIN_STATE

    path = results / "results.csv" if results.is_dir() else results
    run = _read(path, perception, balises)
    grid = Grid.of(run.summary, [t for t, *_ in run.rows])
    messages = parse_messages(((t, d) for t, d, _, _ in run.rows), BALISE_DETECTIONS)
    sightings = [_on_grid(s, grid) for m in messages for s in _sightings(m)]
    frame_times = {grid(float(m.get("time_s", 0.0))) for m in messages}
    travelled = {
        grid(t): float(m.get("distance_m", 0.0))
        for t, m in zip(
            [t for t, *_, s in run.rows if s],
            parse_messages(((t, s) for t, *_, s in run.rows), TRAIN_STATE),
            strict=True,
        )
    }
    offset = _camera_offset(run, sightings, travelled)
    cameras = {t: offset + d for t, d in sorted(travelled.items())}
    report = score(parse_passes((t, p) for t, _, p, _ in run.rows), sightings, gate_m, cameras)
    looked_at = {t: cameras[t] for t in sorted(frame_times) if t in cameras}
    for balise in report.balises:
        balise.passed_at_s = grid(balise.passed_at_s)
    frames = kept.kept_frames(run.folder)  # the truth: the mock's mounting, not the detector's
    max_range = run.parameters.get(f"{perception}.max_range", RANGE_M)
    report.by_distance = by_distance(
        report,
        looked_at,
        end_m=float(max_range) if isinstance(max_range, int | float) else RANGE_M,
        shown=frames[0].camera if frames else None,
    )
    report.conditions = {
        name: value
        for name, value in sorted(run.parameters.items())
        if not name.startswith((f"{perception}.", f"{balises}."))
    }
    if frames:
        report.frames_drawn = _draw_frames(report, frames, cameras, grid, run.folder)
    return report


def _on_grid(seen: Sighting, grid: Grid) -> Sighting:
    return Sighting(
        grid(seen.time_s),
        seen.track_position_m,
        seen.distance_ahead_m,
        seen.confidence,
        seen.box,
        seen.sensor,
    )


def _camera_offset(
    run: _Run, sightings: Sequence[Sighting], travelled: Mapping[float, float]
) -> float:
    """Where the camera is along the line when the train has travelled 0 m: the perception
    participant's ``track_offset`` as the run gave it, else what its first detection says."""
    given = run.parameters.get(f"{run.perception}.track_offset")
    if isinstance(given, int | float) and not isinstance(given, bool):
        return float(given)
    for seen in sightings:
        at = travelled.get(seen.time_s)
        if at is not None:
            return seen.track_position_m - seen.distance_ahead_m - at
    return 0.0


def _draw_frames(
    report: Report,
    frames: Sequence[kept.KeptFrame],
    cameras: Mapping[float, float],
    grid: Grid,
    folder: Path,
) -> int:
    """The frames around every miss (those that showed the balise within the bins' range
    before its pass) and of every false detection, drawn once each (``frames``). A run scored
    again keeps the frames its first scoring drew (the kept ones are gone) and links them."""
    fresh = any(f.path.exists() for f in frames)
    target = folder / kept.DRAWN
    if fresh and target.exists():
        import shutil

        shutil.rmtree(target)
    view = _View(report, {grid(f.time): f for f in frames}, cameras)
    why: dict[float, list[str]] = {}
    for balise in report.balises:
        for time in cameras if not balise.detected else ():
            if view.box(balise, time):
                why.setdefault(time, []).append(f"balise {balise.balise_id} missed")
    for row in report.rows:
        if row.outcome == "false" and row.time_s in view.frames:
            why.setdefault(row.time_s, []).append(f"false at {row.distance_ahead_m:.1f} m")
    names = {}
    for time, reasons in sorted(why.items()):
        name = f"{kept.DRAWN}/t{time:0{5 + grid.decimals}.{grid.decimals}f}.png"
        source = view.frames[time].path
        if source.exists():
            title = f"t = {time} s: " + "; ".join(dict.fromkeys(reasons))
            kept.draw(source, folder / name, view.boxes(time), title)
        if (folder / name).exists():
            names[time] = name
    for balise in report.balises:
        if not balise.detected:
            balise.frames = " ".join(names[t] for t in names if view.box(balise, t))
    for row in report.rows:
        if row.outcome == "false":
            row.frame = names.get(row.time_s, "")
    kept.remove_kept(folder)
    return len(names)


class _View:
    """What the kept frames showed: the truth's boxes and the detector's."""

    def __init__(
        self,
        report: Report,
        frames: Mapping[float, kept.KeptFrame],
        cameras: Mapping[float, float],
    ) -> None:
        self.frames, self.cameras = frames, cameras
        self.reach = report.by_distance[-1].to_m if report.by_distance else RANGE_M
        self.truth = sorted(report.balises, key=lambda b: b.distance_m)
        self.rows: dict[float, list[DetectionRow]] = {}
        for row in report.rows:
            self.rows.setdefault(row.time_s, []).append(row)

    def box(self, balise: BaliseScore, time: float) -> tuple[int, int, int, int] | None:
        """The balise's box in the frame of ``time``, when the frame showed it before its
        pass within the bins' range."""
        frame, camera = self.frames.get(time), self.cameras.get(time)
        if frame is None or camera is None or time > balise.passed_at_s:
            return None
        ahead = balise.distance_m - camera
        return frame.camera.balise_box(ahead) if 0 < ahead <= self.reach else None

    def boxes(self, time: float) -> list[kept.Box]:
        made = []
        for r in self.rows.get(time, ()):
            if r.left is not None and r.top is not None and r.right is not None:
                box = (r.left, r.top, r.right, r.bottom if r.bottom is not None else r.top)
                made.append(kept.Box(box, f"{r.distance_ahead_m:.1f} m", r.outcome))
        for balise in self.truth:
            shown = self.box(balise, time)
            if shown is not None:
                ahead = balise.distance_m - self.cameras[time]
                made.append(kept.Box(shown, f"balise {balise.balise_id} at {ahead:.1f} m", "truth"))
        return made


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
    written = write_report(report, folder)
    return {
        "perception": perception,
        "ground_truth": balises,
        **report.summary(),
        "missed": [b.balise_id for b in report.balises if not b.detected],
        "files": [p.name for p in written],
    }


def write_report(report: Report, folder: Path) -> list[Path]:
    """``perception-report.json``, ``perception-report.csv`` (per balise),
    ``perception-detections.csv`` (and ``.parquet`` with pyarrow) and
    ``perception-by-distance.csv`` in ``folder``."""
    as_json = folder / REPORT_JSON
    made = asdict(report)
    made["detections_table"] = made.pop("rows")
    as_json.write_text(json.dumps(made, indent=2) + "\n", encoding="utf-8")
    written = [as_json]
    for name, kind, entries in (
        (REPORT_CSV, BaliseScore, report.balises),
        (DETECTIONS_CSV, DetectionRow, report.rows),
        (BY_DISTANCE_CSV, DistanceBin, report.by_distance),
    ):
        written.append(folder / name)
        _write_csv(folder / name, [f.name for f in fields(kind)], [asdict(e) for e in entries])
    parquet = _write_parquet(folder / DETECTIONS_PARQUET, report.rows)
    return written + ([parquet] if parquet else [])


def _write_csv(path: Path, columns: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if v is None else v for k, v in row.items()})


def _write_parquet(path: Path, rows: Sequence[DetectionRow]) -> Path | None:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    named = fields(DetectionRow)
    columns = [_arrow_column(pa, [getattr(r, f.name) for r in rows], str(f.type)) for f in named]
    pq.write_table(pa.Table.from_arrays(columns, names=[f.name for f in named]), path)
    return path


def _arrow_column(pa: Any, values: list[Any], kind: str) -> Any:
    """One typed column from its buffers. ``pa.array`` of Python values would import pandas
    to ask whether they are pandas' (half a second of every run that writes a report)."""
    import numpy as np

    if kind == "str":
        data = [v.encode() for v in values]
        offsets = np.cumsum([0, *map(len, data)], dtype=np.int32)
        return pa.Array.from_buffers(
            pa.string(), len(data), [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(data))]
        )
    numbers = np.array([0 if v is None else v for v in values],
                       dtype=np.float64 if kind.startswith("float") else np.int64)  # fmt: skip
    valid = np.packbits(np.array([v is not None for v in values], bool), bitorder="little")
    arrow_type = pa.float64() if kind.startswith("float") else pa.int64()
    return pa.Array.from_buffers(
        arrow_type, len(values), [pa.py_buffer(valid), pa.py_buffer(numbers)]
    )


def markdown(report: Report) -> str:
    """The tables of docs/railway-perception.md, from the report."""
    false = report.false_detections
    lines = [
        "| figure | value |",
        "|---|---|",
        f"| balises passed (TrackBalises) | {report.balises_passed} |",
        f"| detected before being passed | {report.balises_detected}: "
        f"**recall {report.recall:.2f}** |",
        f"| detections | {report.detections}, {report.true_detections} of a balise: "
        f"**precision {report.precision:.2f}**, {false} false detection{'s' * (false != 1)} |",
        f"| position error, all detections | mean {report.mean_abs_error_m:.2f} m, 95th "
        f"percentile {report.p95_abs_error_m:.2f} m, **max {report.max_abs_error_m:.2f} m** |",
        "",
        "| distance ahead | balises shown | recall | detections | precision | bias "
        "| standard deviation | max abs |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def number(value: float | None, unit: str = "", signed: bool = False) -> str:
        if value is None:
            return "-"
        return f"{value:+.2f}{unit}" if signed else f"{value:.2f}{unit}"

    for b in report.by_distance:
        lines.append(
            f"| {b.from_m:g}-{b.to_m:g} m | {b.balises} | {number(b.recall)} | {b.detections} "
            f"| {number(b.precision)} | {number(b.bias_m, ' m', True)} | {number(b.std_m, ' m')} "
            f"| {number(b.max_abs_error_m, ' m')} |"
        )
    return "\n".join(lines) + "\n"


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
    parser.add_argument(
        "--markdown", action="store_true", help="print the docs' tables instead of the summary"
    )
    args = parser.parse_args(argv)
    try:
        report = score_results(
            args.results, perception=args.perception, balises=args.balises, gate_m=args.gate
        )
    except (ScoringError, ValueError) as exc:
        print(f"coupler_railway.scoring: {exc}", file=sys.stderr)
        return 1
    folder = args.results if args.results.is_dir() else args.results.parent
    written = write_report(report, folder)
    if args.markdown:
        print(markdown(report), end="")
        return 0
    summary: Mapping[str, Any] = report.summary()
    print(json.dumps(summary, indent=2))
    missed = [s.balise_id for s in report.balises if not s.detected]
    print(f"missed: {missed or 'none'}; written: {', '.join(str(p) for p in written)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
