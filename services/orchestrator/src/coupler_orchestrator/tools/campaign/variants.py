"""The sections of a campaign file that make variants — [grid] (every combination), [[variant]]
(explicit), [table] (one per row of a CSV file), [sample] (n drawn with a seed) — and the key
that names a variant's run.

Variants are made as they are asked for (``model.Variants``, a sequence): a grid is its axes, a
sample its laws and seed, so a campaign is counted before any variant is made, and one of more
than ``MAXIMUM`` variants is refused at once.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from coupler_orchestrator.tools.campaign.model import (
    Grid,
    Listed,
    Part,
    Sample,
    Scalar,
    ScenarioSpec,
    Variants,
)

MAXIMUM = 100_000
"""Variants a campaign may have, all sections together."""

TABLE_BYTES = 64 << 20
"""The largest [table] file read."""

RUN_OPTIONS = {"start_time": "--start-time", "stop_time": "--stop-time", "step": "--step"}
"""Variant keys that are options of ``coupler run`` rather than parameters."""

Fail = Callable[[str, str, str], Exception]
"""``fail(section, problem, fix)``: the error naming the campaign file, section and fix."""


def counted(parts: Mapping[str, Part], fail: Fail) -> Variants:
    """The variants of the sections (section name -> part), refused when more than MAXIMUM."""
    sizes = {name: len(part) for name, part in parts.items() if len(part)}
    total = sum(sizes.values())
    if total > MAXIMUM:
        labels = {"variant": "[[variant]]", "sample": "sampled"}
        raise fail(
            ", ".join(sizes),
            f"{total:,} variants "
            f"({', '.join(f'{labels.get(n, n)} {s:,}' for n, s in sizes.items())}) are more "
            f"than the {MAXIMUM:,} a campaign may run",
            "split the campaign into several files, or sample the space ([sample] n = ...)",
        )
    for name, part in parts.items():
        check_run_options(name, part, fail)
    return Variants(list(parts.values()))


def check_run_options(section: str, part: Part, fail: Fail) -> None:
    """Every variant's run options (``stop_time``, ``start_time``, ``step``) are numbers a run
    takes, checked before the campaign's first run (not when that variant's run starts)."""
    keys = [k for k in part.names() if k in RUN_OPTIONS]
    for i in range(len(part) if keys else 0):
        variant = part[i]
        for key in keys:
            if key not in variant:
                continue
            value = variant[key]
            try:
                number = float(value) if not isinstance(value, bool) else math.nan
            except ValueError:
                number = math.nan
            if not math.isfinite(number) or (key != "start_time" and number <= 0):
                raise fail(
                    section,
                    f"variant {i + 1} has {key} = {value!r}, which is not a "
                    f"{'finite number' if key == 'start_time' else 'number of seconds > 0'}",
                    f"give {key} as a number (it becomes coupler run {RUN_OPTIONS[key]})",
                )


def grid(raw: Any, fail: Fail) -> Grid:
    if not isinstance(raw, dict):
        raise fail("grid", "not a table", '"Component.parameter" = [values...]')
    for key, values in raw.items():
        check_key("grid", key, fail)
        if not isinstance(values, list) or not values:
            raise fail("grid", f"'{key}' is not a list of values", f'"{key}" = [1.0, 2.0]')
        for value in values:
            check_scalar("grid", key, value, fail)
    return Grid(tuple((key, tuple(values)) for key, values in raw.items()))


def explicit(raw: Any, fail: Fail) -> Listed:
    if not isinstance(raw, list) or not all(isinstance(v, dict) for v in raw):
        raise fail("variant", "must be [[variant]] tables", "write [[variant]] per variant")
    for variant in raw:
        for key, value in variant.items():
            check_key("variant", key, fail)
            check_scalar("variant", key, value, fail)
    return Listed(tuple(dict(v) for v in raw))


def table(raw: Any, folder: Path, fail: Fail) -> Listed:
    """One variant per row of a CSV file (UTF-8, a byte order mark allowed; a header of keys,
    each once); a cell left empty leaves its key out of that row's variant."""
    if raw is None:
        return Listed(())
    if not isinstance(raw, dict) or "file" not in raw:
        raise fail("table", "no file", 'file = "variants.csv" (a header of parameter names)')
    path = folder / str(raw["file"])
    try:
        with path.open("rb") as file:
            data = file.read(TABLE_BYTES + 1)
    except OSError as exc:
        raise fail("table", f"cannot read {path}: {exc.strerror}", "fix file = ...") from exc
    if len(data) > TABLE_BYTES:
        raise fail("table", f"{path} is larger than {TABLE_BYTES >> 20} MiB", "split it")
    rows = _rows(path, _text(path, data, fail), fail)
    if not rows:
        raise fail("table", f"{path} is empty", "write a header of keys and a row per variant")
    (_, header), body = rows[0], rows[1:]
    for column, key in enumerate(header, start=1):
        if not key.strip():
            raise fail(
                "table",
                f"{path}:1: column {column}: '{key}' is not a key",
                "name every column (Component.parameter) or remove the empty one",
            )
        if header.index(key) + 1 != column:
            raise fail(
                "table",
                f"{path}:1: column {column}: '{key}' is also column {header.index(key) + 1}",
                "name each key once",
            )
        check_key("table", key, fail, at=f"{path}:1: column {column}: ")
    if not body:
        raise fail("table", f"{path} has a header and no row", "add a row per variant")
    variants = []
    for line, cells in body:
        if len(cells) != len(header):
            raise fail(
                "table",
                f"{path}:{line}: {len(cells)} cells, the header has {len(header)}",
                "fix the row",
            )
        variants.append(
            {k: number_or_text(c.strip()) for k, c in zip(header, cells, strict=True) if c.strip()}
        )
    return Listed(tuple(variants))


def _text(path: Path, data: bytes, fail: Fail) -> str:
    data = data.removeprefix(b"\xef\xbb\xbf")  # a spreadsheet's "CSV UTF-8" starts with one
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - data.rfind(b"\n", 0, exc.start)
        raise fail(
            "table",
            f"{path}:{line}: not UTF-8 (byte 0x{data[exc.start]:02x} at column {column})",
            "save the file as UTF-8 (a spreadsheet's 'CSV UTF-8')",
        ) from None


def _rows(path: Path, text: str, fail: Fail) -> list[tuple[int, list[str]]]:
    """The file's rows that are not blank, each with the line it starts on; at most one more
    than MAXIMUM (the header)."""
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    rows: list[tuple[int, list[str]]] = []
    line = 1
    try:
        for cells in reader:
            if cells:
                rows.append((line, cells))
            if len(rows) > MAXIMUM + 1:
                raise fail(
                    "table",
                    f"{path} has more than {MAXIMUM:,} rows, the most a campaign may run",
                    "split the table into several campaigns",
                )
            line = reader.line_num + 1
    except csv.Error as exc:
        raise fail("table", f"{path}:{line}: {exc}", "fix the row (CSV, quotes paired)") from None
    return rows


def sample(raw: Any, fail: Fail) -> Sample:
    if raw is None:
        return Sample(0, 0, ())
    if not isinstance(raw, dict):
        raise fail("sample", "not a table", 'n = 20, seed = 7, "C.p" = { uniform = [0.5, 2.0] }')
    if "n" not in raw:
        raise fail("sample", "needs n (and a seed)", "n = 20, seed = 7")
    count: Any = raw["n"]
    seed: Any = raw.get("seed", 0)
    if not (_whole(count) and _whole(seed)):
        raise fail(
            "sample",
            f"n = {count!r}, seed = {seed!r}: both must be whole numbers",
            "n = 20, seed = 7",
        )
    count, seed = int(count), int(seed)
    if not 1 <= count <= MAXIMUM:
        raise fail(
            "sample",
            f"n = {count:,} is not between 1 and {MAXIMUM:,}",
            f"draw at most the {MAXIMUM:,} variants a campaign may run",
        )
    laws = {k: v for k, v in raw.items() if k not in ("n", "seed")}
    if not laws:
        raise fail("sample", "no parameter to sample", '"C.p" = { uniform = [0.5, 2.0] }')
    return Sample(count, seed, tuple(_law(key, law, fail) for key, law in laws.items()))


def _whole(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    return isinstance(value, int) or (isinstance(value, float) and value.is_integer())


def _law(key: str, law: Any, fail: Fail) -> tuple[str, str, tuple[Scalar, ...]]:
    check_key("sample", key, fail)
    if not (isinstance(law, dict) and len(law) == 1 and next(iter(law)) in ("uniform", "choice")):
        raise fail(
            "sample", f"'{key}' has no law", "{ uniform = [low, high] } or { choice = [a, b] }"
        )
    if "choice" in law:
        choices = law["choice"]
        if not isinstance(choices, list) or not choices:
            raise fail("sample", f"'{key}': choice = {choices!r}", "choice = [a, b, ...]")
        for choice in choices:
            check_scalar("sample", key, choice, fail)
        return key, "choice", tuple(choices)
    bounds = law["uniform"]
    numbers = (
        isinstance(bounds, list)
        and len(bounds) == 2
        and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds)
    )
    if not numbers or not all(math.isfinite(b) for b in bounds) or bounds[0] > bounds[1]:
        raise fail(
            "sample",
            f"'{key}': uniform = {bounds!r} is not [low, high]",
            "two finite numbers, low <= high: uniform = [0.5, 2.0]",
        )
    return key, "uniform", (float(bounds[0]), float(bounds[1]))


def check_key(where: str, key: str, fail: Fail, *, at: str = "") -> None:
    """A variant's key is ``Component.parameter`` or one of RUN_OPTIONS (``at``: where it is
    written, for the message)."""
    if key in RUN_OPTIONS:
        return
    component, _, name = key.partition(".")
    if not component or not name:
        raise fail(
            where,
            f"{at}'{key}' is neither Component.parameter nor one of {', '.join(RUN_OPTIONS)}",
            "name parameters as coupler run --param does (Gain.gain)",
        )


def check_scalar(where: str, key: str, value: Any, fail: Fail) -> None:
    if not isinstance(value, (int, float, str, bool)):
        raise fail(where, f"'{key}' = {value!r} is not a number, text or boolean", "give one value")


def number_or_text(text: str) -> Scalar:
    for kind in (int, float):
        with contextlib.suppress(ValueError):
            return kind(text)
    return {"true": True, "false": False}.get(text.lower(), text)


def variant_key(variant: Mapping[str, Scalar], scenario: ScenarioSpec) -> str:
    """A short hash of what makes a run: the variant, the scenario and the options."""
    identity = {
        "variant": {k: variant[k] for k in sorted(variant)},
        "ssp": str(scenario.ssp),
        "fleet": str(scenario.fleet or ""),
        "stop_time": scenario.stop_time,
        "args": list(scenario.args),
    }
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:12]
