"""A campaign file read into a ``CampaignSpec``: the scenario every run runs, its variants, the
table's columns ([outputs], [[derive]], [checks]) and the pool of running participants. A file
that cannot run is refused before anything starts, naming the file, the section and the fix."""

from __future__ import annotations

import importlib
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from coupler_orchestrator.tools.campaign import variants
from coupler_orchestrator.tools.campaign.checks import Expression, ExpressionError
from coupler_orchestrator.tools.campaign.model import (
    REDUCTIONS,
    CampaignError,
    CampaignSpec,
    Check,
    Derive,
    Listed,
    Output,
    ScenarioSpec,
    Variants,
)
from coupler_orchestrator.tools.fleet import FleetSpec

SCENARIO_KEYS = frozenset(
    {
        "fleet",
        "ssp",
        "stop_time",
        "out",
        "args",
        "timeout",
        "health_timeout",
        "keep_services",
        "timings",
    }
)
"""The keys of a campaign file's [scenario]."""


def read(path: Path, *, root: Path | None = None) -> CampaignSpec:
    """Read a campaign file; relative paths are taken from ``root`` (default: the working
    directory), the [table] file from the campaign file's folder."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CampaignError(f"cannot read campaign file {path}: {exc.strerror}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{path}: not TOML: {exc}") from exc
    return _Reader(path, root or Path.cwd()).read(data)


class _Reader:
    def __init__(self, path: Path, root: Path) -> None:
        self.path = path
        self.root = root

    def fail(self, where: str, problem: str, fix: str) -> CampaignError:
        return CampaignError(f"{self.path} [{where}]: {problem}; {fix}")

    def read(self, data: Mapping[str, Any]) -> CampaignSpec:
        known = {"scenario", "grid", "variant", "table", "sample", "outputs", "derive"}
        unknown = sorted(set(data) - known - {"checks", "pool"})
        if unknown:
            raise self.fail(
                unknown[0],
                "unknown section",
                f"sections are {', '.join(sorted(known))}, checks, pool",
            )
        scenario, out = self.scenario(data.get("scenario"))
        timings = data["scenario"].get("timings", True)
        if not isinstance(timings, bool):
            raise self.fail(
                "scenario",
                f"timings = {timings!r} is not true or false",
                "write timings = false to leave the runs' wall times out of the table",
            )
        made = variants.counted(
            {
                "grid": variants.grid(data.get("grid", {}), self.fail),
                "variant": variants.explicit(data.get("variant", []), self.fail),
                "table": variants.table(data.get("table"), self.path.parent, self.fail),
                "sample": variants.sample(data.get("sample"), self.fail),
            },
            self.fail,
        )
        outputs = self.outputs(data.get("outputs", {}))
        derive = self.derive(data.get("derive", []))
        checks = self.checks(data.get("checks", {}), outputs)
        pool = self.pool(data.get("pool"))
        return CampaignSpec(
            source=self.path,
            scenario=scenario,
            out=out,
            variants=made or Variants([Listed(({},))]),
            outputs=outputs,
            derive=derive,
            checks=checks,
            pool=pool,
            timings=timings,
        )

    def scenario(self, raw: Any) -> tuple[ScenarioSpec, Path]:
        if not isinstance(raw, dict):
            raise self.fail(
                "scenario", "missing", 'name the scenario: fleet = "..." and/or ssp = "..."'
            )
        fleet = self.root / raw["fleet"] if "fleet" in raw else None
        if fleet is not None and not fleet.is_file():
            raise self.fail("scenario", f"fleet file {fleet} does not exist", "fix the path")
        if "ssp" in raw:
            ssp = self.root / raw["ssp"]
        elif fleet is not None:
            ssp = FleetSpec.load(fleet, root=self.root, env={}).ssp
        else:
            raise self.fail("scenario", "no ssp and no fleet", 'add ssp = "path/to/the.ssd"')
        if not ssp.exists():
            raise self.fail("scenario", f"scenario {ssp} does not exist", "fix ssp = ...")
        unknown = sorted(set(raw) - SCENARIO_KEYS)
        if unknown:
            raise self.fail(
                "scenario",
                f"unknown key {unknown[0]!r}",
                f"keys are {', '.join(sorted(SCENARIO_KEYS))}",
            )
        keep = raw.get("keep_services", False)
        if not isinstance(keep, bool):
            raise self.fail(
                "scenario", "keep_services must be true or false", "keep_services = true"
            )
        args = raw.get("args", [])
        if not isinstance(args, list) or not all(isinstance(a, str) for a in args):
            raise self.fail(
                "scenario", "args must be a list of strings", 'e.g. args = ["--step", "0.1"]'
            )
        try:
            spec = ScenarioSpec(
                root=self.root,
                ssp=ssp,
                fleet=fleet,
                stop_time=float(raw["stop_time"]) if "stop_time" in raw else None,
                args=tuple(args),
                timeout=float(raw.get("timeout", 3600.0)),
                health_timeout=float(raw.get("health_timeout", 60.0)),
                keep_services=keep,
            )
        except (TypeError, ValueError) as exc:
            raise self.fail("scenario", str(exc), "stop_time and timeout are numbers [s]") from exc
        out = self.root / raw.get("out", f"results/campaigns/{self.path.stem}")
        return spec, out

    def outputs(self, raw: Any) -> tuple[Output, ...]:
        outputs = []
        for name, text in raw.items():
            self.name("outputs", name)
            reduction, channel = "last", str(text).strip()
            if channel.endswith(")") and "(" in channel:
                reduction, _, channel = channel[:-1].partition("(")
                reduction, channel = reduction.strip(), channel.strip()
            if channel.startswith("reports.") and reduction != "last":
                raise self.fail(
                    "outputs",
                    f'{name} = "{text}": a report\'s value is one value per run',
                    f'write {name} = "{channel}" (summary.json\'s reports, as the run wrote them)',
                )
            if reduction not in REDUCTIONS or "." not in channel:
                raise self.fail(
                    "outputs",
                    f'{name} = "{text}" is not a channel or a reduction of one',
                    f"write Component.connector or one of {', '.join(REDUCTIONS)}"
                    "(Component.connector)",
                )
            outputs.append(Output(name=name, reduction=reduction, channel=channel))
        return tuple(outputs)

    def derive(self, raw: Any) -> tuple[Derive, ...]:
        functions = []
        for entry in raw if isinstance(raw, list) else [None]:
            target = str(entry.get("function", "")) if isinstance(entry, dict) else ""
            module, _, name = target.partition(":")
            if not module or not name:
                raise self.fail(
                    "derive",
                    f"'{target}' is not module:function",
                    'write [[derive]] tables with function = "package.module:function"',
                )
            assert isinstance(entry, dict)
            try:
                function = getattr(importlib.import_module(module), name)
            except Exception as exc:  # user code: any failure to import it is the file's
                raise self.fail(
                    "derive",
                    f"function = '{target}' cannot be loaded ({type(exc).__name__}: {exc})",
                    "install the module where the campaign runs, or fix the name",
                ) from None
            if not callable(function):
                raise self.fail("derive", f"'{target}' is not a function", "name a function")
            options = {k: v for k, v in entry.items() if k != "function"}
            functions.append(Derive(function=target, options=options))
        return tuple(functions)

    def checks(self, raw: Any, outputs: Sequence[Output]) -> tuple[Check, ...]:
        checks = []
        for name, expression in raw.items():
            self.name("checks", name)
            try:
                Expression(str(expression))
            except ExpressionError as exc:
                text = str(expression)
                shown = text if len(text) <= 80 else text[:77] + "..."
                raise self.fail(
                    "checks",
                    f'{name} = "{shown}": {exc}',
                    "use outputs, numbers, comparisons, and/or/not, + - * / on numbers",
                ) from None
            checks.append(Check(name=name, expression=str(expression)))
        return tuple(checks)

    def pool(self, raw: Any) -> tuple[dict[str, str], ...]:
        if raw is None:
            return ()
        entries = raw.get("env") if isinstance(raw, dict) else None
        if (
            not isinstance(entries, list)
            or not entries
            or not all(isinstance(e, dict) for e in entries)
        ):
            raise self.fail(
                "pool", "env must be a list of tables", 'env = [{ GAIN_PORT = "50051" }, ...]'
            )
        return tuple({str(k): str(v) for k, v in e.items()} for e in entries)

    def name(self, where: str, name: str) -> None:
        if not name.isidentifier():
            raise self.fail(where, f"'{name}' is not a column name", "use letters, digits and _")
