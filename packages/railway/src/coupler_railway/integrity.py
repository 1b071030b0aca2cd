"""A localisation's estimate scored for integrity against the truth: was the true front end
always inside the confidence interval, how far off was the estimate, how wide the interval
grew with the distance since the last balise group, and did the linking errors it raised match
the balise faults injected.

Input: a run's ``results.csv`` with

- ``<localisation>.estimated_front``, ``.min_safe_front``, ``.max_safe_front`` (and, when
  recorded, ``.distance_since_group``, ``.linking_errors``, ``.missed_group_id``): the system
  under test (services/localisation's channel names);
- the truth: ``OpenRails.distance`` (the simulator's distance travelled) plus ``front_offset``
  (41.7 m in the railway scenario: the front end's place along the line when the train has
  travelled 0 m); without that column, a ``*.true_front`` column as it is;
- ``<balises>.passed_in_step`` (TrackBalises): which groups the train passed, when;
- ``<transmission>.faults`` (the balise transmission, ``kind:balise:group;...``): the faults
  injected.

Integrity: every row whose true front end is outside [min, max] is a violation; consecutive
ones are one episode, reported with its start, end, side (``ahead``: the truth beyond the max
safe front end, the estimate under-read; ``behind``: below the min) and size (the furthest the
truth was outside). Error: estimate minus truth, its mean, mean of magnitudes, 95th percentile
and maximum of magnitudes. Width: max - min, by bins of ``bin_m`` of distance since the last
group. Linking: a group whose every balise passed was lost or corrupted was not read: a linking
error naming it is a detection, none a miss; a linking error naming a group without any fault is
a false alarm; late groups are counted with whether a linking error named them.

``python -m coupler_railway.integrity RESULTS_DIR`` writes ``localisation-report.json`` (summary,
violations, bins, groups) and ``localisation-report.csv`` (one row per step: time, truth,
estimate, interval, error, inside) into the folder and prints the summary. ``coupler run`` does
the same at the end of every run that records a min/max safe front end (``run_report``, the
entry point ``coupler.reports: localisation``) and puts the summary into summary.json.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

REPORT_JSON = "localisation-report.json"
REPORT_CSV = "localisation-report.csv"
FRONT_OFFSET_M = 41.7
"""The railway scenario's front end along the line when the train has travelled 0 m."""
TRUTH = "OpenRails.distance"
BIN_M = 500.0
MAX_LISTED = 50
"""Violations (and linking events) listed in summary.json; the report file has them all."""


class IntegrityError(ValueError):
    """The results lack what the scoring needs (a column, a readable value)."""


@dataclass
class Violation:
    """One stretch of time the true front end was outside the interval."""

    start_s: float
    end_s: float
    side: str
    """``ahead``: the truth beyond the max safe front end; ``behind``: below the min."""
    size_m: float
    """The furthest the truth was outside the interval."""
    steps: int


@dataclass
class WidthBin:
    """The interval's width over the steps whose distance since the last group is in
    [from_m, from_m + bin)."""

    from_m: float
    steps: int
    width_mean_m: float
    width_max_m: float
    error_abs_max_m: float


@dataclass
class GroupOutcome:
    """A balise group the train passed, what was injected and what the localisation said."""

    group_id: int
    passed_at_s: float
    balises: int
    lost: int = 0
    corrupt: int = 0
    late: int = 0
    not_read: bool = False
    """Every balise passed was lost or corrupted."""
    linking_error_at_s: float | None = None


@dataclass
class Report:
    """The whole run's score."""

    steps: int
    integrity: bool
    violations: int
    violation_steps: int
    worst_violation_m: float
    error_mean_m: float
    error_abs_mean_m: float
    error_p95_m: float
    error_max_m: float
    width_mean_m: float
    width_max_m: float
    max_distance_since_group_m: float
    groups_passed: int
    groups_not_read: int
    groups_late: int
    linking_errors: int
    detected: int
    missed: int
    false_alarms: int
    late_raised: int
    front_offset_m: float
    violation_list: list[Violation] = field(default_factory=list)
    width_bins: list[WidthBin] = field(default_factory=list)
    groups: list[GroupOutcome] = field(default_factory=list)
    linking_events: list[dict[str, float | int]] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        listed = ("violation_list", "width_bins", "groups", "linking_events")
        return {k: v for k, v in asdict(self).items() if k not in listed}


@dataclass(frozen=True)
class Columns:
    """Which results.csv columns the scoring reads."""

    localisation: str = "Localisation"
    truth: str = TRUTH
    front_offset_m: float = FRONT_OFFSET_M
    balises: str | None = "TrackBalises"
    transmission: str | None = "BaliseTransmission"


@dataclass
class Row:
    """One step of the run, as the scoring reads it."""

    time: float
    truth: float
    estimate: float
    low: float
    high: float
    since: float | None
    errors: int | None
    missed: int | None
    passed: str
    faults: str


def score(rows: Sequence[Row], *, front_offset_m: float, bin_m: float = BIN_M) -> Report:
    """Score rows of a run (module docstring)."""
    errors = [r.estimate - r.truth for r in rows]
    magnitudes = sorted(abs(e) for e in errors)
    widths = [r.high - r.low for r in rows]
    violations = _violations(rows)
    groups, events = _linking(rows)
    faulted = {g.group_id for g in groups if g.not_read}
    late = {g.group_id for g in groups if g.late and not g.not_read}
    clean = {g.group_id for g in groups if not (g.lost or g.corrupt or g.late)}
    named = {int(e["group_id"]) for e in events}
    n = len(rows) or 1
    return Report(
        steps=len(rows),
        integrity=not violations,
        violations=len(violations),
        violation_steps=sum(v.steps for v in violations),
        worst_violation_m=_r(max((v.size_m for v in violations), default=0.0)),
        error_mean_m=_r(sum(errors) / n),
        error_abs_mean_m=_r(sum(magnitudes) / n),
        error_p95_m=_r(_percentile(magnitudes, 0.95)),
        error_max_m=_r(magnitudes[-1] if magnitudes else 0.0),
        width_mean_m=_r(sum(widths) / n),
        width_max_m=_r(max(widths, default=0.0)),
        max_distance_since_group_m=_r(max((r.since or 0.0 for r in rows), default=0.0)),
        groups_passed=len(groups),
        groups_not_read=len(faulted),
        groups_late=len(late),
        linking_errors=len(events),
        detected=len(faulted & named),
        missed=len(faulted - named),
        false_alarms=sum(1 for e in events if int(e["group_id"]) in clean or e["group_id"] == 0),
        late_raised=len(late & named),
        front_offset_m=front_offset_m,
        violation_list=violations,
        width_bins=_bins(rows, errors, bin_m),
        groups=groups,
        linking_events=events,
    )


def _violations(rows: Sequence[Row]) -> list[Violation]:
    found: list[Violation] = []
    current: Violation | None = None
    for r in rows:
        side = "ahead" if r.truth > r.high else "behind" if r.truth < r.low else ""
        if not side:
            current = None
            continue
        size = r.truth - r.high if side == "ahead" else r.low - r.truth
        if current is None or current.side != side:
            current = Violation(r.time, r.time, side, _r(size), 0)
            found.append(current)
        current.end_s = r.time
        current.size_m = max(current.size_m, _r(size))
        current.steps += 1
    return found


def _bins(rows: Sequence[Row], errors: Sequence[float], bin_m: float) -> list[WidthBin]:
    grouped: dict[int, list[tuple[float, float]]] = {}
    for r, e in zip(rows, errors, strict=True):
        if r.since is not None:
            grouped.setdefault(int(max(r.since, 0.0) // bin_m), []).append((r.high - r.low, e))
    return [
        WidthBin(
            from_m=k * bin_m,
            steps=len(items),
            width_mean_m=_r(sum(w for w, _ in items) / len(items)),
            width_max_m=_r(max(w for w, _ in items)),
            error_abs_max_m=_r(max(abs(e) for _, e in items)),
        )
        for k, items in sorted(grouped.items())
    ]


def _linking(rows: Sequence[Row]) -> tuple[list[GroupOutcome], list[dict[str, float | int]]]:
    groups: dict[int, GroupOutcome] = {}
    for r in rows:
        for item in filter(None, r.passed.split(";")):
            passed = int(item.split(":")[1])
            groups.setdefault(passed, GroupOutcome(passed, r.time, 0)).balises += 1
    for r in rows:
        for item in filter(None, r.faults.split(";")):
            kind, _, faulted = item.split(":")
            hit = groups.get(int(faulted))
            if hit is not None and kind in ("lost", "corrupt", "late"):
                setattr(hit, kind, getattr(hit, kind) + 1)
    for g in groups.values():
        g.not_read = g.lost + g.corrupt >= g.balises
    events: list[dict[str, float | int]] = []
    previous = 0
    for r in rows:
        if r.errors is None:
            continue
        if r.errors > previous:
            missed = r.missed or 0
            events.append({"time_s": r.time, "group_id": missed, "count": r.errors - previous})
            if missed in groups and groups[missed].linking_error_at_s is None:
                groups[missed].linking_error_at_s = r.time
        previous = r.errors
    return sorted(groups.values(), key=lambda g: g.passed_at_s), events


def read_rows(path: Path, columns: Columns) -> list[Row]:
    """The rows of a results.csv the scoring needs; IntegrityError naming what is missing."""
    loc = columns.localisation
    needed = [f"{loc}.estimated_front", f"{loc}.min_safe_front", f"{loc}.max_safe_front"]
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            names = set(reader.fieldnames or ())
            missing = [c for c in ("time", columns.truth, *needed) if c not in names]
            if missing:
                raise IntegrityError(
                    f"{path} has no column {missing[0]!r}: record it (coupler run "
                    f"--output-variables '{loc}.*,{columns.truth}')"
                )

            def opt(name: str | None, suffix: str) -> str | None:
                column = f"{name}.{suffix}" if name else None
                return column if column in names else None

            since, count, missed = (
                opt(loc, "distance_since_group"),
                opt(loc, "linking_errors"),
                opt(loc, "missed_group_id"),
            )
            passed = opt(columns.balises, "passed_in_step")
            faults = opt(columns.transmission, "faults")
            rows = []
            for line, r in enumerate(reader, start=2):
                try:
                    rows.append(
                        Row(
                            time=float(r["time"]),
                            truth=float(r[columns.truth]) + columns.front_offset_m,
                            estimate=float(r[needed[0]]),
                            low=float(r[needed[1]]),
                            high=float(r[needed[2]]),
                            since=float(r[since]) if since else None,
                            errors=int(float(r[count])) if count else None,
                            missed=int(float(r[missed])) if missed else None,
                            passed=r[passed] if passed else "",
                            faults=r[faults] if faults else "",
                        )
                    )
                except (TypeError, ValueError) as exc:
                    raise IntegrityError(f"{path} line {line}: {exc}") from exc
    except OSError as exc:
        raise IntegrityError(f"cannot read {path}: {exc.strerror or exc}") from exc
    return rows


def score_results(
    results: Path, columns: Columns = Columns(), *, bin_m: float = BIN_M
) -> tuple[Report, list[Row]]:
    """Score a run's results.csv (or its folder); the report and the rows it was made of."""
    path = results / "results.csv" if results.is_dir() else results
    rows = read_rows(path, columns)
    return score(rows, front_offset_m=columns.front_offset_m, bin_m=bin_m), rows


def run_report(folder: Path, columns: Mapping[str, str]) -> dict[str, Any] | None:
    """The localisation report of the run whose results are in ``folder``, written there, for
    summary.json (the orchestrator's ``coupler.reports`` hook); None when the run recorded no
    ``*.max_safe_front`` column or no truth: it is not a localisation run."""
    ends = [n.rpartition(".")[0] for n in columns if n.endswith(".max_safe_front")]
    if len(ends) != 1:
        return None
    localisation = ends[0]
    if TRUTH in columns:
        truth, offset = TRUTH, FRONT_OFFSET_M
    else:
        fronts = [n for n in columns if n.endswith(".true_front")]
        if len(fronts) != 1:
            return None
        truth, offset = fronts[0], 0.0
    passes = [n.rpartition(".")[0] for n in columns if n.endswith(".passed_in_step")]
    faults = [n.rpartition(".")[0] for n in columns if n.endswith(".faults")]
    chosen = Columns(
        localisation=localisation,
        truth=truth,
        front_offset_m=offset,
        balises=passes[0] if len(passes) == 1 else None,
        transmission=faults[0] if len(faults) == 1 else None,
    )
    report, rows = score_results(folder, chosen)
    as_json, as_csv = write_report(report, rows, folder)
    return {
        "localisation": localisation,
        "truth": f"{truth} + {offset:g} m",
        **report.summary(),
        "violation_list": [asdict(v) for v in report.violation_list[:MAX_LISTED]],
        "linking_events": report.linking_events[:MAX_LISTED],
        "not_read_groups": [g.group_id for g in report.groups if g.not_read],
        "files": [as_json.name, as_csv.name],
    }


def write_report(report: Report, rows: Sequence[Row], folder: Path) -> tuple[Path, Path]:
    """``localisation-report.json`` and ``localisation-report.csv`` (the rows) in ``folder``."""
    as_json = folder / REPORT_JSON
    as_json.write_text(json.dumps(asdict(report), indent=2) + "\n", encoding="utf-8")
    as_csv = folder / REPORT_CSV
    with as_csv.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(
            ["time", "true_front_m", "estimated_front_m", "min_safe_front_m", "max_safe_front_m",
             "error_m", "width_m", "distance_since_group_m", "inside"]
        )  # fmt: skip
        for r in rows:
            writer.writerow(
                [r.time, _r(r.truth), _r(r.estimate), _r(r.low), _r(r.high),
                 _r(r.estimate - r.truth), _r(r.high - r.low),
                 "" if r.since is None else _r(r.since), r.low <= r.truth <= r.high]
            )  # fmt: skip
    return as_json, as_csv


CAMPAIGN_COLUMNS = (
    "integrity",
    "violations",
    "worst_violation_m",
    "error_abs_mean_m",
    "error_p95_m",
    "error_max_m",
    "width_mean_m",
    "width_max_m",
    "max_distance_since_group_m",
    "groups_not_read",
    "linking_errors",
    "detected",
    "missed",
    "false_alarms",
)
"""The report's figures a campaign's table gets (``campaign_columns``)."""


def campaign_columns(run: Any) -> dict[str, float | int | bool | str]:
    """A campaign's ``[[derive]]`` function: the integrity figures of a finished run, from its
    summary.json ``reports.localisation`` (what ``coupler run`` wrote when the run ended), each
    column prefixed ``loc_``; an empty mapping when the run has no such report."""
    try:
        summary = json.loads((Path(run.directory) / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    report = summary.get("reports", {}).get("localisation")
    if not isinstance(report, dict) or "error" in report:
        return {}
    return {f"loc_{k}": report[k] for k in CAMPAIGN_COLUMNS if k in report}


def _r(x: float) -> float:
    return round(x, 3)


def _percentile(ordered: Sequence[float], q: float) -> float:
    if not ordered:
        return 0.0
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m coupler_railway.integrity",
        description="Score a run's localisation for integrity against the truth.",
    )
    parser.add_argument("results", type=Path, help="the run's folder (or its results.csv)")
    parser.add_argument("--localisation", default="Localisation", help="its component")
    parser.add_argument("--truth", default=TRUTH, help="the true distance column")
    parser.add_argument(
        "--front-offset", type=float, default=FRONT_OFFSET_M, help="truth + this = front [m]"
    )
    parser.add_argument("--balises", default="TrackBalises", help="the TrackBalises component")
    parser.add_argument("--transmission", default="BaliseTransmission", help="the fault source")
    parser.add_argument("--bin", type=float, default=BIN_M, help="width bins [m]")
    args = parser.parse_args(argv)
    columns = Columns(
        args.localisation, args.truth, args.front_offset, args.balises, args.transmission
    )
    try:
        report, rows = score_results(args.results, columns, bin_m=args.bin)
    except IntegrityError as exc:
        print(f"coupler_railway.integrity: {exc}", file=sys.stderr)
        return 1
    folder = args.results if args.results.is_dir() else args.results.parent
    as_json, as_csv = write_report(report, rows, folder)
    print(json.dumps(report.summary(), indent=2))
    for v in report.violation_list[:10]:
        print(f"violation {v.start_s:g}-{v.end_s:g} s: truth {v.side} by {v.size_m:g} m")
    print(f"written: {as_json}, {as_csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
