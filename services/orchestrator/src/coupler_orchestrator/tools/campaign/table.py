"""The campaign table: one row per run (its variant, status, reason, wall time, the [outputs],
derived and [checks] columns), written as campaign.csv (and campaign.parquet with pyarrow) and
shown on the terminal."""

from __future__ import annotations

import contextlib
import csv
import io
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from coupler_orchestrator.outputs.parquet import parquet_available
from coupler_orchestrator.tools.campaign.checks import evaluate_checks
from coupler_orchestrator.tools.campaign.model import CampaignSpec, RunReport


def run_directory(spec: CampaignSpec, report: RunReport) -> Path:
    return spec.out / "runs" / f"{report.index:03d}-{report.key}"


def table_rows(
    spec: CampaignSpec, reports: Iterable[RunReport]
) -> tuple[list[str], list[dict[str, Any]]]:
    """The campaign table: header and one row per run."""
    parameters = spec.variants.names()
    values = [o.name for o in spec.outputs]
    rows = []
    for report in reports:
        found = dict(report.values)
        row: dict[str, Any] = {"run": report.index, "key": report.key}
        row |= {p: report.variant.get(p) for p in parameters}
        row |= {"status": report.status, "reason": report.reason}
        if spec.timings:
            row |= {"wall_time_s": report.wall_time_s, "realtime_factor": report.realtime_factor}
        row |= {name: found.pop(name, None) for name in values}
        row |= found  # derived columns
        names = {**{k: v for k, v in report.variant.items() if k.isidentifier()}, **row}
        row |= evaluate_checks(spec.checks, names)
        row["directory"] = str(run_directory(spec, report).relative_to(spec.out))
        rows.append(row)
    timings = ["wall_time_s", "realtime_factor"] if spec.timings else []
    header = list(dict.fromkeys(k for row in rows for k in row)) if rows else [
        "run", "key", *parameters, "status", "reason", *timings, *values,
    ]  # fmt: skip
    return header, rows


def write_table(spec: CampaignSpec, reports: Sequence[RunReport]) -> tuple[Path, Path | None]:
    """campaign.csv (and campaign.parquet with pyarrow) in the campaign's folder."""
    header, rows = table_rows(spec, reports)
    text = io.StringIO()
    writer = csv.DictWriter(text, header, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _cell(v) for k, v in row.items()})
    table_csv = spec.out / "campaign.csv"
    partial = table_csv.with_name(".campaign.csv.partial")
    partial.write_text(text.getvalue(), encoding="utf-8")
    os.replace(partial, table_csv)
    if not parquet_available():
        return table_csv, None
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = {name: [row.get(name) for row in rows] for name in header}
    arrays = {}
    for name, cells in columns.items():
        try:
            arrays[name] = pa.array(cells)
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed kinds: keep them as text
            arrays[name] = pa.array([None if c is None else str(c) for c in cells])
    table_parquet = spec.out / "campaign.parquet"
    pq.write_table(pa.table(arrays), table_parquet)
    return table_csv, table_parquet


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def format_table(spec: CampaignSpec, reports: Sequence[RunReport], limit: int = 40) -> str:
    """The campaign table for a terminal (the first ``limit`` rows)."""
    header, rows = table_rows(spec, reports)
    header = [h for h in header if h not in ("key", "reason", "directory")]
    cells = [[_short(_cell(row.get(h))) for h in header] for row in rows[:limit]]
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in cells]
    if len(rows) > limit:
        lines.append(f"... {len(rows) - limit} more rows in campaign.csv")
    return "\n".join(lines)


def _short(text: str) -> str:
    with contextlib.suppress(ValueError):
        number = float(text)
        if "." in text or "e" in text:
            return f"{number:.6g}"
    return text if len(text) <= 24 else text[:21] + "..."
