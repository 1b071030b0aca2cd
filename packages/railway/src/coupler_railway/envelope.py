"""A perception campaign's operating envelope: where the detector's recall holds and where it
falls, over the conditions the campaign varied.

    coupler-railway envelope CAMPAIGN_FOLDER [-o envelope.html] [--axes A B]

reads every completed run of the campaign (``runs/*/variant.json`` and the run's
``summary.json`` ``reports.perception``: recall, precision, position errors; the perception
participant that ran, when the variants name one) and writes

- ``envelope.html``: one self-contained page (inline SVG, no script, no network): recall and
  the largest position error against each varied parameter (the mean over the runs sharing
  that value, each run a dot), and a map of recall over two of them; the boundaries where
  recall falls below 0.9 and 0.5 are marked (dashed lines on the charts, thick edges between
  the map's cells); the runs with the lowest recall, each with links to its frames around
  misses and false detections (``perception-frames/``, drawn by the scorer);
- ``envelope.png`` beside it (matplotlib, the ``plot`` extra of coupler-orchestrator), the
  same charts;
- ``envelope.csv``: the table the charts are drawn from (one row per run).

Runs whose variant differs only in ``detector`` (a campaign comparing detectors) are drawn as
one series per detector. Boundaries are drawn between the values the campaign ran: a finer
grid draws them finer.
"""

from __future__ import annotations

import html
import itertools
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

THRESHOLDS = (0.9, 0.5)
"""Recall below which the envelope marks a boundary."""
WORST = 5
"""Runs listed with their frames."""
DETECTOR = "detector"
"""A variant key (or a component's parameter, ``Perception.detector``) naming the detector;
runs are split into series by it, runs naming none are the participant's default."""
COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


class EnvelopeError(ValueError):
    """A folder that holds no campaign, or no run with a perception report."""


@dataclass(frozen=True)
class Run:
    """One run of the campaign, as the envelope sees it."""

    folder: Path
    variant: Mapping[str, Any]
    recall: float
    precision: float
    max_abs_error_m: float
    mean_abs_error_m: float
    frames: tuple[str, ...] = ()
    """Its drawn frames, relative to the campaign folder."""

    @property
    def detector(self) -> str:
        """The detector its variant names (``detector`` or ``Component.detector``); empty: the
        participant's default."""
        for key, value in self.variant.items():
            if _is_detector(key):
                return str(value)
        return str(self.variant.get("perception", ""))


@dataclass
class Envelope:
    """Every scored run and the parameters the campaign varied."""

    runs: list[Run]
    axes: list[str]
    """Varied parameters (numbers), in the campaign's order."""
    detectors: list[str] = field(default_factory=list)


def read_campaign(folder: Path) -> Envelope:
    """The scored runs of the campaign in ``folder`` (its ``runs/``)."""
    runs_dir = folder / "runs"
    if not runs_dir.is_dir():
        raise EnvelopeError(f"{folder} holds no campaign (no runs/ folder): give the out folder")
    runs: list[Run] = []
    for run in sorted(runs_dir.iterdir()):
        try:
            variant = json.loads((run / "variant.json").read_text(encoding="utf-8"))
            summary = json.loads((run / "summary.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        report = (summary.get("reports") or {}).get("perception")
        if not isinstance(report, dict) or "recall" not in report:
            continue
        frames = sorted(p.relative_to(folder).as_posix() for p in run.glob("perception-frames/*"))
        runs.append(
            Run(
                folder=run,
                variant=variant,
                recall=float(report["recall"]),
                precision=float(report.get("precision", 0.0)),
                max_abs_error_m=float(report.get("max_abs_error_m", 0.0)),
                mean_abs_error_m=float(report.get("mean_abs_error_m", 0.0)),
                frames=tuple(frames),
            )
        )
    if not runs:
        raise EnvelopeError(
            f"{folder}: no completed run with a perception report (summary.json "
            f"reports.perception): is it a perception campaign, and did its runs complete?"
        )
    keys = list(dict.fromkeys(k for r in runs for k in r.variant if not _is_detector(k)))
    axes = [
        k
        for k in keys
        if len({r.variant.get(k) for r in runs}) > 1
        and all(_number(r.variant.get(k)) is not None for r in runs)
    ]
    detectors = sorted(dict.fromkeys(r.detector for r in runs))  # the default ("") first
    return Envelope(runs=runs, axes=axes, detectors=detectors)


def _is_detector(key: str) -> bool:
    return key == DETECTOR or key.endswith("." + DETECTOR)


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def along(envelope: Envelope, axis: str, detector: str, figure: str) -> list[tuple[float, float]]:
    """(value of ``axis``, mean ``figure`` of the runs with that value) for one detector."""
    groups: dict[float, list[float]] = {}
    for run in envelope.runs:
        value = _number(run.variant.get(axis))
        if value is not None and run.detector == detector:
            groups.setdefault(value, []).append(getattr(run, figure))
    return [(x, sum(ys) / len(ys)) for x, ys in sorted(groups.items())]


def boundary(points: Sequence[tuple[float, float]], threshold: float) -> list[float]:
    """Where a line through ``points`` crosses ``threshold`` (linear between values)."""
    crossings = []
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        if (y0 >= threshold) != (y1 >= threshold) and y0 != y1:
            crossings.append(x0 + (threshold - y0) * (x1 - x0) / (y1 - y0))
    return crossings


def grid_of(
    envelope: Envelope, x: str, y: str, detector: str
) -> tuple[list[float], list[float], dict[tuple[float, float], float]]:
    """The mean recall of the runs at each (x, y) pair of values."""
    cells: dict[tuple[float, float], list[float]] = {}
    for run in envelope.runs:
        a, b = _number(run.variant.get(x)), _number(run.variant.get(y))
        if a is not None and b is not None and run.detector == detector:
            cells.setdefault((a, b), []).append(run.recall)
    xs = sorted({a for a, _ in cells})
    ys = sorted({b for _, b in cells})
    return xs, ys, {k: sum(v) / len(v) for k, v in cells.items()}


def _rank(values: Sequence[float], x: float) -> float:
    """Where ``x`` lies among the sorted ``values`` the campaign ran, evenly spaced (a grid of
    12, 25, 50 and 10000 m reads), linear between neighbours (where a boundary crosses)."""
    for i, (a, b) in enumerate(itertools.pairwise(values)):
        if a <= x <= b:
            return i + (x - a) / (b - a)
    return 0.0


def _band(recall: float) -> int:
    return sum(recall < t for t in THRESHOLDS)


def _colour(recall: float) -> str:
    """Green (1) through amber to red (0)."""
    r = round(220 * min(1.0, 2 * (1 - recall)))
    g = round(180 * min(1.0, 2 * recall))
    return f"rgb({r},{g},60)"


# ---- SVG (the HTML page) ------------------------------------------------------------------


def _line_chart(envelope: Envelope, axis: str, figure: str, label: str, thresholds: bool) -> str:
    series = {d: along(envelope, axis, d, figure) for d in envelope.detectors}
    crossings = [
        (i, t, x)
        for i, points in enumerate(series.values())
        for t in (THRESHOLDS if thresholds else ())
        for x in boundary(points, t)
    ]
    # above the chart, a line for each crossing's label (they would cover the lines near 1)
    above = 11 * len(crossings)
    width, height, left, bottom, top, right = 420, 240 + above, 50, 34, 12 + above, 24
    xs = [x for points in series.values() for x, _ in points]
    ys = [y for points in series.values() for _, y in points]
    dots = [(_number(r.variant.get(axis)), getattr(r, figure), r.detector) for r in envelope.runs]
    ys += [y for _, y, _ in dots]
    y0, y1 = (0.0, 1.0) if figure == "recall" else (0.0, max([*ys, 1e-09]) * 1.1)
    values = sorted(set(xs))
    span = max(len(values) - 1, 1)

    def px(x: float) -> float:
        return left + _rank(values, x) / span * (width - left - right)

    def py(y: float) -> float:
        return height - bottom - (y - y0) / (y1 - y0) * (height - top - bottom)

    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'role="img" aria-label="{html.escape(label)} against {html.escape(axis)}">',
        f'<rect x="{left}" y="{top}" width="{width - left - right}" '
        f'height="{height - top - bottom}" fill="#fafafa" stroke="#999"/>',
    ]
    for value in values:
        parts.append(
            f'<text x="{px(value):.1f}" y="{height - bottom + 14}" font-size="10" '
            f'text-anchor="middle">{value:g}</text>'
        )
    for tick in (y0, (y0 + y1) / 2, y1):
        parts.append(
            f'<text x="{left - 4}" y="{py(tick) + 3:.1f}" font-size="10" '
            f'text-anchor="end">{tick:.2g}</text>'
        )
    parts.append(
        f'<text x="{(left + width - right) / 2}" y="{height - 4}" font-size="11" '
        f'text-anchor="middle">{html.escape(axis)}</text>'
    )
    if thresholds:
        for t in THRESHOLDS:
            parts.append(
                f'<line x1="{left}" x2="{width - right}" y1="{py(t):.1f}" y2="{py(t):.1f}" '
                f'stroke="#888" stroke-dasharray="4 3"/>'
                f'<text x="{width - right - 2}" y="{py(t) - 2:.1f}" font-size="9" '
                f'text-anchor="end" fill="#666">recall {t}</text>'
            )
    for i, (detector, points) in enumerate(series.items()):
        colour = COLOURS[i % len(COLOURS)]
        path = " ".join(f"{px(x):.1f},{py(y):.1f}" for x, y in points)
        parts.append(f'<polyline points="{path}" fill="none" stroke="{colour}" stroke-width="2"/>')
        for x, y, d in dots:
            if d == detector and x is not None:
                parts.append(
                    f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" r="2.5" fill="{colour}" '
                    f'opacity="0.5"/>'
                )
    for line, (i, t, crossing) in enumerate(crossings):
        colour, x, y = COLOURS[i % len(COLOURS)], px(crossing), 12 + 11 * line
        text = f"{t} at {float(f'{crossing:.3g}'):g}"  # 62900, not 6.29e+04
        # right of the line, or left of it where the text would leave the chart
        right_of = x + 2 + 5 * len(text) <= width - right
        parts.append(
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{y - 3}" y2="{height - bottom}" '
            f'stroke="{colour}" stroke-dasharray="2 2"/>'
            f'<text x="{x + 2 if right_of else x - 2:.1f}" y="{y + 6}" font-size="9" '
            f'text-anchor="{"start" if right_of else "end"}" fill="{colour}">{text}</text>'
        )
    parts.append("</svg>")
    return "".join(parts)


def _map(envelope: Envelope, x: str, y: str, detector: str) -> str:
    xs, ys, cells = grid_of(envelope, x, y, detector)
    size, left, top = 44, 70, 10
    caption = f"{x} (rows: {y})"
    # as wide as its caption too (a campaign with two values of x draws a narrow map)
    width = max(left + size * len(xs) + 10, 6 * len(caption) + 8)
    height = top + size * len(ys) + 40
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'role="img" aria-label="recall over {html.escape(x)} and {html.escape(y)}">'
    ]
    for j, b in enumerate(reversed(ys)):
        parts.append(
            f'<text x="{left - 4}" y="{top + j * size + size / 2 + 3}" font-size="10" '
            f'text-anchor="end">{b:g}</text>'
        )
        for i, a in enumerate(xs):
            value = cells.get((a, b))
            fill = "#ddd" if value is None else _colour(value)
            text = "" if value is None else f"{value:.2f}"
            parts.append(
                f'<rect x="{left + i * size}" y="{top + j * size}" width="{size}" '
                f'height="{size}" fill="{fill}" stroke="#fff"/>'
                f'<text x="{left + i * size + size / 2}" y="{top + j * size + size / 2 + 3}" '
                f'font-size="10" text-anchor="middle">{text}</text>'
            )
    # boundaries: thick edges between cells on two sides of a threshold
    for j, b in enumerate(reversed(ys)):
        for i, a in enumerate(xs):
            here = cells.get((a, b))
            for di, dj in ((1, 0), (0, 1)):
                if i + di >= len(xs) or j + dj >= len(ys):
                    continue
                there = cells.get((xs[i + di], list(reversed(ys))[j + dj]))
                if here is None or there is None or _band(here) == _band(there):
                    continue
                x0 = left + (i + di) * size
                y0 = top + (j + dj) * size
                x1, y1 = (x0, y0 + size) if di else (x0 + size, y0)
                parts.append(
                    f'<line x1="{x0}" y1="{y0}" x2="{x1}" y2="{y1}" stroke="#000" '
                    f'stroke-width="3"/>'
                )
    for i, a in enumerate(xs):
        parts.append(
            f'<text x="{left + i * size + size / 2}" y="{top + len(ys) * size + 14}" '
            f'font-size="10" text-anchor="middle">{a:g}</text>'
        )
    parts.append(
        f'<text x="{max(left + len(xs) * size / 2, width / 2)}" y="{height - 6}" '
        f'font-size="11" text-anchor="middle">{html.escape(caption)}</text></svg>'
    )
    return "".join(parts)


def html_page(envelope: Envelope, axes: Sequence[str], target: Path, title: str) -> str:
    """The envelope as one self-contained HTML page; links relative to ``target``'s folder."""
    base = target.parent
    body = [
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{len(envelope.runs)} scored runs; detectors: "
        f"{html.escape(', '.join(d or 'default' for d in envelope.detectors))}. "
        "Dashed lines: recall 0.9 and 0.5, and where each detector's mean recall crosses "
        "them; on the map, thick edges separate recall of 0.9 or more, 0.5 to 0.9 and below "
        "0.5.</p>",
    ]
    legend = "".join(
        f'<span style="color:{COLOURS[i % len(COLOURS)]}">&#9632; '
        f"{html.escape(d or 'default')}</span> "
        for i, d in enumerate(envelope.detectors)
    )
    body.append(f"<p>{legend}</p>")
    for axis in envelope.axes:
        body.append(f"<h2>{html.escape(axis)}</h2><div>")
        body.append(_line_chart(envelope, axis, "recall", "recall", True))
        body.append(_line_chart(envelope, axis, "max_abs_error_m", "max error [m]", False))
        body.append("</div>")
    if len(axes) >= 2:
        for detector in envelope.detectors:
            body.append(
                f"<h2>Recall over {html.escape(axes[0])} and {html.escape(axes[1])}"
                f"{' — ' + html.escape(detector) if detector else ''}</h2>"
            )
            body.append(_map(envelope, axes[0], axes[1], detector))
    body.append("<h2>The runs with the lowest recall</h2><table>")
    body.append(
        "<tr><th>run</th><th>variant</th><th>recall</th><th>precision</th>"
        "<th>max error [m]</th><th>frames (misses, false detections)</th></tr>"
    )
    for run in sorted(envelope.runs, key=lambda r: (r.recall, r.precision))[:WORST]:
        variant = ", ".join(f"{k}={v}" for k, v in run.variant.items())
        campaign = run.folder.parent.parent
        links = " ".join(
            f'<a href="{html.escape(os.path.relpath(campaign / f, base))}">{Path(f).stem}</a>'
            for f in run.frames
        )
        body.append(
            f"<tr><td>{html.escape(run.folder.name)}</td><td>{html.escape(variant)}</td>"
            f"<td>{run.recall:.3f}</td><td>{run.precision:.3f}</td>"
            f"<td>{run.max_abs_error_m:.2f}</td><td>{links or '-'}</td></tr>"
        )
    body.append("</table>")
    style = (
        "body{font-family:sans-serif;margin:1.5em;color:#222}svg{margin:0 1em 1em 0}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 6px;"
        "font-size:13px;text-align:left}"
    )
    return (
        f'<!doctype html><html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{style}</style></head>"
        f"<body>{''.join(body)}</body></html>\n"
    )


# ---- PNG ---------------------------------------------------------------------------------


def png(envelope: Envelope, axes: Sequence[str], target: Path, title: str) -> None:
    """The same charts with matplotlib (Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(envelope.axes) + (1 if len(axes) >= 2 else 0)
    figure, grid = plt.subplots(rows, 2, figsize=(10, 3.2 * rows), squeeze=False)
    for row, axis in enumerate(envelope.axes):
        for col, (name, label) in enumerate(
            (("recall", "recall"), ("max_abs_error_m", "max error [m]"))
        ):
            chart = grid[row][col]
            ran = sorted({x for d in envelope.detectors
                          for x, _ in along(envelope, axis, d, name)})  # fmt: skip
            for i, detector in enumerate(envelope.detectors):
                points = along(envelope, axis, detector, name)
                colour = COLOURS[i % len(COLOURS)]
                ranks = [_rank(ran, x) for x, _ in points]
                chart.plot(ranks, [y for _, y in points], "-o", color=colour,
                           label=detector or "default")  # fmt: skip
                for t in THRESHOLDS if name == "recall" else ():
                    for crossing in boundary(points, t):
                        chart.axvline(_rank(ran, crossing), color=colour, linestyle=":")
            chart.set_xticks(range(len(ran)), [f"{v:g}" for v in ran])
            if name == "recall":
                for t in THRESHOLDS:
                    chart.axhline(t, color="grey", linestyle="--", linewidth=0.8)
                chart.set_ylim(-0.02, 1.02)
            chart.set_xlabel(axis)
            chart.set_ylabel(label)
            if any(envelope.detectors):
                chart.legend(fontsize=8)
    if len(axes) >= 2:
        for col in range(2):
            chart = grid[rows - 1][col]
            if col >= len(envelope.detectors):
                chart.axis("off")
                continue
            xs, ys, cells = grid_of(envelope, axes[0], axes[1], envelope.detectors[col])
            values = [[cells.get((a, b), math.nan) for a in xs] for b in ys]
            shown = chart.imshow(values, origin="lower", vmin=0, vmax=1, cmap="RdYlGn",
                                 aspect="auto")  # fmt: skip
            chart.contour(values, levels=list(reversed(THRESHOLDS)), colors="black")
            chart.set_xticks(range(len(xs)), [f"{a:g}" for a in xs])
            chart.set_yticks(range(len(ys)), [f"{b:g}" for b in ys])
            chart.set_xlabel(axes[0])
            chart.set_ylabel(axes[1])
            chart.set_title(f"recall {envelope.detectors[col]}".strip(), fontsize=9)
            figure.colorbar(shown, ax=chart)
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(target, dpi=90)
    plt.close(figure)


def write_table(envelope: Envelope, target: Path) -> None:
    import csv

    keys = list(dict.fromkeys(k for r in envelope.runs for k in r.variant))
    with target.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["run", *keys, "recall", "precision", "mean_abs_error_m",
                         "max_abs_error_m", "frames"])  # fmt: skip
        for run in envelope.runs:
            writer.writerow(
                [run.folder.name, *(run.variant.get(k, "") for k in keys), run.recall,
                 run.precision, run.mean_abs_error_m, run.max_abs_error_m, " ".join(run.frames)]
            )  # fmt: skip


def write_envelope(
    folder: Path, output: Path | None = None, axes: Sequence[str] = ()
) -> list[Path]:
    """envelope.html, envelope.png and envelope.csv of the campaign in ``folder``."""
    envelope = read_campaign(folder)
    if not envelope.axes:
        raise EnvelopeError(
            f"{folder}: its runs vary no numeric parameter: an envelope needs at least one axis"
        )
    chosen = list(axes) or envelope.axes[:2]
    unknown = [a for a in chosen if a not in envelope.axes]
    if unknown:
        raise EnvelopeError(
            f"--axes {unknown[0]}: not a parameter the campaign varied (it varied: "
            f"{', '.join(envelope.axes)})"
        )
    target = output or folder / "envelope.html"
    title = f"Operating envelope: {folder.name}"
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(html_page(envelope, chosen, target, title), encoding="utf-8")
    written = [target]
    picture = target.with_suffix(".png")
    try:
        png(envelope, chosen, picture, title)
        written.append(picture)
    except ImportError:
        pass  # matplotlib is the plot extra's: the HTML page is the envelope without it
    table = target.with_suffix(".csv")
    write_table(envelope, table)
    return [*written, table]
