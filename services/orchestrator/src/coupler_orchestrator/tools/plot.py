"""``coupler plot``: time series of chosen channels of one or more runs, as PNG or HTML.

A run is a results directory (``results.csv`` and, when present, ``summary.json`` for units and
types) or a ``results.csv``. Channels are named or globbed (``Gain.*``); several runs are
overlaid, e.g. the variants of a campaign: a run with a ``variant.json`` beside its results (a
campaign's) is labelled by the parameters that differ between the runs (``Gain.gain=2``),
another by its folder's name. Channels are grouped by unit, one chart per unit with the unit
on its axis.

- PNG: matplotlib (the ``plot`` extra of coupler-orchestrator; ``make setup`` installs it).
- HTML: one self-contained file, the chart library (uPlot, from npm) inlined, so it opens
  offline anywhere: zoom by dragging, double-click to reset, click a legend entry to hide it.
"""

from __future__ import annotations

import csv
import fnmatch
import html
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coupler.errors import CouplerError
from coupler_orchestrator.assets import SETUP_HINT, UPLOT_FILES, VENDOR
from coupler_tools import vendor as vendor_files

NUMERIC_TYPES = {"Real", "Integer", "Boolean", "Enumeration", "Float64", "Float32", "Int32"}
PALETTE = (
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
    "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
)  # fmt: skip


class PlotError(CouplerError):
    """Results that cannot be plotted as asked (missing file, unknown channel, bad output)."""


@dataclass(frozen=True, kw_only=True)
class Series:
    """One channel of one run."""

    run: str
    """The run's label: its varied parameters (campaigns), else its directory's name (its path
    when names repeat)."""
    channel: str
    """``Component.connector``."""
    unit: str
    times: tuple[float, ...]
    values: tuple[float, ...]
    """NaN where the run recorded no number."""

    def label(self, several_runs: bool) -> str:
        return f"{self.run}: {self.channel}" if several_runs else self.channel


@dataclass(frozen=True, kw_only=True)
class Run:
    """One run's results as read from disk."""

    label: str
    csv: Path
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    units: dict[str, str]
    types: dict[str, str]
    variant: Mapping[str, Any] | None = None
    """The parameters of a campaign's run (``variant.json`` beside its results), else None."""


def read_run(path: Path) -> Run:
    """``path`` is a results directory or a results.csv; summary.json beside it is optional."""
    csv_path = path / "results.csv" if path.is_dir() else path
    if not csv_path.is_file():
        raise PlotError(
            f"{path}: no results here; give a results directory (with results.csv) or a "
            f"results.csv file"
        )
    try:
        with csv_path.open(newline="", encoding="utf-8") as file:
            table = list(csv.reader(file))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise PlotError(f"cannot read {csv_path}: {exc}") from exc
    if not table or not table[0] or table[0][0] != "time":
        raise PlotError(f"{csv_path}: not a Coupler results.csv (its first column is not 'time')")
    units: dict[str, str] = {}
    types: dict[str, str] = {}
    summary = csv_path.parent / "summary.json"
    if summary.is_file():
        try:
            for column in json.loads(summary.read_text(encoding="utf-8")).get("columns", []):
                units[column["name"]] = column.get("unit", "")
                types[column["name"]] = column.get("type", "")
        except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
            raise PlotError(
                f"{summary}: unreadable ({exc}); move it away to plot without units"
            ) from exc
    return Run(
        label=csv_path.parent.name or str(csv_path.parent),
        csv=csv_path,
        header=tuple(table[0]),
        rows=tuple(tuple(row) for row in table[1:]),
        units=units,
        types=types,
        variant=_variant(csv_path.parent / "variant.json"),
    )


def _variant(path: Path) -> Mapping[str, Any] | None:
    try:
        found = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return found if isinstance(found, dict) else None


def select(runs: Sequence[Run], patterns: Sequence[str]) -> list[Series]:
    """The series of every run for the channels ``patterns`` name (names or globs; default:
    every numeric channel). Every pattern must match a numeric channel of some run."""
    series: list[Series] = []
    matched: set[str] = set()
    labels = _labels(runs)
    for run, label in zip(runs, labels, strict=True):
        for index, name in enumerate(run.header[1:], start=1):
            hit = [p for p in patterns if fnmatch.fnmatchcase(name, p)] if patterns else ["*"]
            if not hit or not _numeric(run, name, index):
                continue
            matched.update(hit)
            series.append(_series(run, label, name, index))
    for pattern in patterns:
        if pattern not in matched:
            raise PlotError(_no_match(runs, pattern))
    if not series:
        raise PlotError(f"no numeric channel in {', '.join(str(r.csv) for r in runs)}")
    return series


def _labels(runs: Sequence[Run]) -> list[str]:
    """Each run's label: the parameters that differ between the runs (all of them campaign
    runs), else the folder's name; its path where labels would repeat."""
    varied = varied_parameters(runs)
    if varied:
        labels = [", ".join(f"{k}={_shown(r.variant, k)}" for k in varied) for r in runs]
    else:
        labels = [r.label for r in runs]
    return [
        label if labels.count(label) == 1 else f"{label} ({r.csv.parent})"
        for label, r in zip(labels, runs, strict=True)
    ]


def varied_parameters(runs: Sequence[Run]) -> list[str]:
    """The parameters whose values differ between ``runs``, when every run has a variant
    (in first-seen order); [] otherwise."""
    if len(runs) < 2 or any(r.variant is None for r in runs):
        return []
    keys = list(dict.fromkeys(k for r in runs for k in r.variant or {}))
    return [k for k in keys if len({_shown(r.variant, k) for r in runs}) > 1]


def _shown(variant: Mapping[str, Any] | None, key: str) -> str:
    """A variant's value as its campaign file would write it (2.0 -> 2, True -> true)."""
    value = (variant or {}).get(key, "-")
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def default_title(runs: Sequence[Run]) -> str:
    """One run: its folder. Several: the folder they share and how many they are (and over
    which parameters, for a campaign's runs) — never every path joined."""
    folders = [r.csv.parent.resolve() for r in runs]
    if len(runs) == 1:
        return _relative(folders[0])
    common = Path(os.path.commonpath(folders))
    varied = varied_parameters(runs)
    if varied and common.name == "runs":  # a campaign's out/runs/<n>-<key>/
        common = common.parent
    over = f" over {', '.join(varied)}" if varied else ""
    return f"{_relative(common)}: {len(runs)} runs{over}"


def _relative(path: Path) -> str:
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _numeric(run: Run, name: str, index: int) -> bool:
    declared = run.types.get(name)
    if declared:
        return declared in NUMERIC_TYPES
    for row in run.rows:  # no summary.json: numeric when every non-empty cell is a number
        cell = row[index] if index < len(row) else ""
        if cell and _number(cell) is None:
            return False
    return True


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _series(run: Run, label: str, name: str, index: int) -> Series:
    times, values = [], []
    for row in run.rows:
        if not row or index >= len(row):
            continue
        time = _number(row[0])
        if time is None:
            continue
        value = _number(row[index]) if row[index] else None
        times.append(time)
        values.append(math.nan if value is None else value)
    return Series(
        run=label, channel=name, unit=run.units.get(name, ""), times=tuple(times),
        values=tuple(values),
    )  # fmt: skip


def _no_match(runs: Sequence[Run], pattern: str) -> str:
    names = sorted({n for r in runs for n in r.header[1:]})
    kinds = {n: t for r in runs for n, t in r.types.items()}
    hits = [n for n in names if fnmatch.fnmatchcase(n, pattern)]
    if hits:
        found = ", ".join(f"{n}: {kinds.get(n, 'text')}" for n in hits)
        return (
            f"channel {pattern!r} is not numeric ({found}); only Real, Integer, Boolean and "
            f"Enumeration channels plot"
        )
    shown = ", ".join(names[:40]) + (", ..." if len(names) > 40 else "")
    return f"no channel matches {pattern!r}; the results have: {shown}"


def groups(series: Sequence[Series]) -> list[tuple[str, list[Series]]]:
    """Series by unit, in first-seen order: one chart each."""
    by_unit: dict[str, list[Series]] = {}
    for s in series:
        by_unit.setdefault(s.unit, []).append(s)
    return list(by_unit.items())


def axis_label(unit: str) -> str:
    return f"[{unit}]" if unit else "(no unit)"


def plot(paths: Sequence[Path], channels: Sequence[str], out: Path, *, title: str = "") -> Path:
    """Read the runs, select the channels and write ``out`` (.png or .html)."""
    suffix = out.suffix.lower()
    if suffix not in {".png", ".html", ".htm"}:
        raise PlotError(f"-o {out}: write FILE.png (a picture) or FILE.html (interactive)")
    runs = [read_run(p) for p in paths]
    series = select(runs, channels)
    title = title or default_title(runs)
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        write_png(series, out, title=title, several_runs=len(runs) > 1)
    else:
        write_html(series, out, title=title, several_runs=len(runs) > 1)
    return out


def write_png(series: Sequence[Series], out: Path, *, title: str, several_runs: bool) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib import pyplot
    except ImportError as exc:
        raise PlotError(
            "PNG plots need matplotlib: install coupler-orchestrator[plot] (`make setup` "
            "does), or write FILE.html"
        ) from exc
    grouped = groups(series)
    figure, axes = pyplot.subplots(
        len(grouped), 1, sharex=True, squeeze=False, figsize=(10, 1.2 + 2.8 * len(grouped))
    )
    try:
        colour = 0
        for (unit, members), (ax,) in zip(grouped, axes, strict=True):
            for s in members:
                ax.plot(
                    s.times, s.values, label=s.label(several_runs),
                    color=PALETTE[colour % len(PALETTE)], linewidth=1.4,
                )  # fmt: skip
                colour += 1
            ax.set_ylabel(axis_label(unit))
            ax.grid(True, alpha=0.3)
            ax.legend(loc="best", fontsize="small")
        axes[-1][0].set_xlabel("time [s]")
        figure.suptitle(title, fontsize="medium")
        figure.tight_layout()
        figure.savefig(out, dpi=100)
    finally:
        pyplot.close(figure)


def write_html(series: Sequence[Series], out: Path, *, title: str, several_runs: bool) -> None:
    absent = vendor_files.missing(VENDOR, UPLOT_FILES)
    if absent:
        raise PlotError(f"HTML plots need uPlot ({', '.join(absent)} missing): {SETUP_HINT}")
    script = (VENDOR / "uPlot.iife.min.js").read_text(encoding="utf-8")
    style = (VENDOR / "uPlot.min.css").read_text(encoding="utf-8")
    colour = 0
    charts: list[dict[str, Any]] = []
    for unit, members in groups(series):
        entries = []
        for s in members:
            entries.append(
                {
                    "label": s.label(several_runs),
                    "color": PALETTE[colour % len(PALETTE)],
                    "t": list(s.times),
                    "v": [None if math.isnan(v) else v for v in s.values],
                }
            )
            colour += 1
        charts.append({"axis": axis_label(unit), "series": entries})
    data = json.dumps({"title": title, "charts": charts}, allow_nan=False)
    out.write_text(
        _PAGE.format(
            title=html.escape(title),
            style=style,
            script=_inline(script),
            data=_inline(data),
            app=_APP,
        ),
        encoding="utf-8",
    )


def _inline(text: str) -> str:
    """Text safe inside a <script> element."""
    return text.replace("</", "<\\/")


_PAGE = """<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<link rel="icon" href="data:,">
<style>{style}</style>
<style>
body {{ font: 14px/1.4 system-ui, sans-serif; margin: 16px; color: #1d232b; }}
h1 {{ font-size: 16px; margin: 0 0 12px; }}
.chart {{ margin-bottom: 20px; }}
</style>
</head>
<body>
<h1>{title}</h1>
<p>Drag to zoom, double-click to reset, click a legend entry to hide it.</p>
<div id="charts"></div>
<script>{script}</script>
<script id="plot-data" type="application/json">{data}</script>
<script>{app}</script>
</body>
</html>
"""

_APP = """
"use strict";
(() => {
  const spec = JSON.parse(document.getElementById("plot-data").textContent);
  const view = { charts: [], ready: false };
  window.couplerPlot = view;
  const width = () => Math.max(480, Math.min(1200, window.innerWidth - 40));
  for (const chart of spec.charts) {
    const data = uPlot.join(chart.series.map((s) => [s.t, s.v]));
    const element = document.createElement("div");
    element.className = "chart";
    document.getElementById("charts").appendChild(element);
    view.charts.push(new uPlot({
      width: width(),
      height: 300,
      scales: { x: { time: false } },
      axes: [{ label: "time [s]" }, { label: chart.axis, size: 70 }],
      series: [
        { label: "t [s]" },
        ...chart.series.map((s) => (
          { label: s.label, stroke: s.color, width: 1.5, spanGaps: true })),
      ],
    }, data, element));
  }
  window.addEventListener("resize", () => {
    for (const chart of view.charts) chart.setSize({ width: width(), height: 300 });
  });
  view.ready = true;
})();
"""
