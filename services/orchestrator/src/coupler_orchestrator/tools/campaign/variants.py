"""The sections of a campaign file that make variants — [grid] (every combination), [[variant]]
(explicit), [table] (one per row of a CSV file), [sample] (n drawn with a seed) — and the key
that names a variant's run."""

from __future__ import annotations

import contextlib
import csv
import hashlib
import itertools
import json
import random
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from coupler_orchestrator.tools.campaign.spec import ScenarioSpec

Scalar = float | int | str | bool
"""A variant's value, an output's value."""

RUN_OPTIONS = {"start_time": "--start-time", "stop_time": "--stop-time", "step": "--step"}
"""Variant keys that are options of ``coupler run`` rather than parameters."""

Fail = Callable[[str, str, str], Exception]
"""``fail(section, problem, fix)``: the error naming the campaign file, section and fix."""


def grid(raw: Any, fail: Fail) -> list[dict[str, Scalar]]:
    if not isinstance(raw, dict):
        raise fail("grid", "not a table", '"Component.parameter" = [values...]')
    for key, values in raw.items():
        check_key("grid", key, fail)
        if not isinstance(values, list) or not values:
            raise fail("grid", f"'{key}' is not a list of values", f'"{key}" = [1.0, 2.0]')
    if not raw:
        return []
    keys = list(raw)
    return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*raw.values())]


def explicit(raw: Any, fail: Fail) -> list[dict[str, Scalar]]:
    if not isinstance(raw, list):
        raise fail("variant", "must be [[variant]] tables", "write [[variant]] per variant")
    for variant in raw:
        for key, value in variant.items():
            check_key("variant", key, fail)
            check_scalar("variant", key, value, fail)
    return [dict(v) for v in raw]


def table(raw: Any, folder: Path, fail: Fail) -> list[dict[str, Scalar]]:
    if raw is None:
        return []
    if not isinstance(raw, dict) or "file" not in raw:
        raise fail("table", "no file", 'file = "variants.csv" (a header of parameter names)')
    path = folder / raw["file"]
    try:
        with path.open(encoding="utf-8", newline="") as file:
            rows = list(csv.DictReader(file))
    except OSError as exc:
        raise fail("table", f"cannot read {path}: {exc.strerror}", "fix file = ...") from exc
    variants = []
    for number, row in enumerate(rows, start=2):
        variant: dict[str, Scalar] = {}
        for key, text in row.items():
            if key is None or text is None:
                raise fail(
                    "table",
                    f"{path}:{number} has more or fewer cells than the header",
                    "fix the row",
                )
            check_key("table", key, fail)
            if text.strip() != "":
                variant[key] = number_or_text(text.strip())
        variants.append(variant)
    return variants


def sample(raw: Any, fail: Fail) -> list[dict[str, Scalar]]:
    if raw is None:
        return []
    try:
        count, seed = int(raw["n"]), int(raw.get("seed", 0))
    except (KeyError, TypeError, ValueError) as exc:
        raise fail("sample", "needs n (and a seed)", "n = 20, seed = 7") from exc
    laws = {k: v for k, v in raw.items() if k not in ("n", "seed")}
    if not laws:
        raise fail("sample", "no parameter to sample", '"C.p" = { uniform = [0.5, 2.0] }')
    for key, law in laws.items():
        check_key("sample", key, fail)
        if not (
            isinstance(law, dict) and len(law) == 1 and next(iter(law)) in ("uniform", "choice")
        ):
            raise fail(
                "sample",
                f"'{key}' has no law",
                "{ uniform = [low, high] } or { choice = [a, b] }",
            )
    draw = random.Random(seed)
    variants = []
    for _ in range(count):
        variant: dict[str, Scalar] = {}
        for key, law in laws.items():
            if "uniform" in law:
                low, high = (float(x) for x in law["uniform"])
                variant[key] = draw.uniform(low, high)
            else:
                variant[key] = draw.choice(law["choice"])
        variants.append(variant)
    return variants


def check_key(where: str, key: str, fail: Fail) -> None:
    """A variant's key is ``Component.parameter`` or one of RUN_OPTIONS."""
    if key in RUN_OPTIONS:
        return
    component, _, name = key.partition(".")
    if not component or not name:
        raise fail(
            where,
            f"'{key}' is neither Component.parameter nor one of {', '.join(RUN_OPTIONS)}",
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
