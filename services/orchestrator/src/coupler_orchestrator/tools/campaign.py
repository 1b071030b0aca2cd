"""Campaigns: one scenario run under many variants, in parallel, into one table.

A campaign file (TOML) names the scenario and its variants::

    [scenario]
    fleet = "examples/ramp-gain/fleet.toml"   # services started per run, on free ports
    ssp = "examples/ramp-gain/SystemStructure.ssd"   # default: the fleet file's
    stop_time = 10.0
    out = "results/campaigns/ramp-gain"
    args = ["--step", "0.1"]                  # extra `coupler run` options
    timeout = 600                             # [s] per run

    [grid]                                    # every combination (cartesian product)
    "Gain.gain" = [1.0, 2.0, 3.0]
    "Source.slope" = [0.5, 1.0, 2.0]

    [[variant]]                               # and/or explicit variants
    "Gain.gain" = 10.0
    stop_time = 5.0

    [table]                                   # and/or one variant per row of a CSV file
    file = "variants.csv"

    [sample]                                  # and/or n sampled variants, reproducible
    n = 20
    seed = 7
    "Gain.gain" = { uniform = [0.5, 2.0] }
    "Source.slope" = { choice = [1.0, 2.0] }

    [outputs]                                 # campaign table columns from results.csv
    y_max = "max(Gain.y)"                     # max min first last mean count_changes
    y_final = "Gain.y"                        # a bare channel: its last value

    [[derive]]                                # columns computed by a Python function
    function = "coupler_railway.campaign:balise_detections"
    railml = "scenarios/railway/data/annaberg-schwarzenberg.railml"   # its keyword arguments

    [checks]                                  # true/false columns over the outputs
    y_ok = "y_max <= 2 * y_final"

    [pool]                                    # instead of starting services: running ones
    env = [{ GAIN_PORT = "50051" }, { GAIN_PORT = "50052" }]

A variant's keys are ``Component.parameter`` (as ``coupler run --param``; start values too),
``start_time``, ``stop_time`` and ``step``. Each run gets its own participants: the fleet
file's services started on free ports (every ``${NAME_PORT}`` variable of the fleet file gets
one; the SSD reads the same variables), or one entry of the pool, one run per entry at a time.
Each run is a ``coupler run`` process; its files go to ``out/runs/<n>-<key>/`` (results.csv,
summary.json, variant.json, run.log), the key being a hash of the variant and the scenario, so a
campaign run again skips what already completed (``--force`` runs it all again).

Runs execute on this machine (``--jobs N`` at once) or as tasks of a Dask cluster
(``--scheduler tcp://HOST:8786``, or ``local`` for a LocalCluster of worker processes): a task
starts its run's services on its worker, runs it in a scratch folder there and returns the
run's files, so the workers need the project at the same path (a checkout or the image), not a
shared file system.
"""

from __future__ import annotations

import ast
import asyncio
import contextlib
import csv
import hashlib
import importlib
import io
import itertools
import json
import logging
import math
import operator
import os
import random
import shutil
import sys
import tempfile
import time
import tomllib
from collections.abc import Awaitable, Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import IO, Any

import structlog

from coupler.errors import CouplerError, ScenarioError
from coupler_orchestrator.outputs.files import write_json
from coupler_orchestrator.outputs.parquet import parquet_available
from coupler_orchestrator.outputs.progress import duration
from coupler_orchestrator.tools.fleet import Fleet, FleetError, FleetSpec, free_port, port_variables

log = structlog.get_logger("coupler.campaign")

Scalar = float | int | str | bool
"""A variant's value, an output's value."""

RUN_OPTIONS = {"start_time": "--start-time", "stop_time": "--stop-time", "step": "--step"}
"""Variant keys that are options of ``coupler run`` rather than parameters."""

REDUCTIONS = ("max", "min", "first", "last", "mean", "count_changes")
COMPLETED = ("completed", "terminated")
"""Run statuses a re-run skips."""


class CampaignError(ScenarioError):
    """A campaign file that cannot be run as written."""


@dataclass(frozen=True, kw_only=True)
class Output:
    """A campaign table column read off a run's results.csv."""

    name: str
    reduction: str
    """One of REDUCTIONS."""
    channel: str
    """``Component.connector`` (a results.csv column)."""


@dataclass(frozen=True, kw_only=True)
class Derive:
    """Columns computed by ``function(finished, **options)`` from a finished run."""

    function: str
    """``package.module:function``."""
    options: dict[str, Scalar] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Check:
    """A true/false column: an expression over outputs, derived values and parameters."""

    name: str
    expression: str


@dataclass(frozen=True, kw_only=True)
class ScenarioSpec:
    """What every run of the campaign runs."""

    root: Path
    """Directory commands run in and relative paths start from."""
    ssp: Path
    fleet: Path | None = None
    """Services to start per run; None: the SSD's participants are running (or a pool)."""
    stop_time: float | None = None
    args: tuple[str, ...] = ()
    """Extra ``coupler run`` options of every run."""
    timeout: float = 3600.0
    """[s] a run may take, services' start included."""
    health_timeout: float = 60.0
    """[s] a service may take to become healthy."""


@dataclass(frozen=True, kw_only=True)
class CampaignSpec:
    """A campaign file."""

    source: Path
    scenario: ScenarioSpec
    out: Path
    variants: tuple[dict[str, Scalar], ...]
    outputs: tuple[Output, ...] = ()
    derive: tuple[Derive, ...] = ()
    """Functions computing more columns from a finished run (:class:`Finished`)."""
    checks: tuple[Check, ...] = ()
    pool: tuple[dict[str, str], ...] = ()
    """Environments naming running participants (``GAIN_PORT``...), one run each at a time."""

    @classmethod
    def load(cls, path: Path, *, root: Path | None = None) -> CampaignSpec:
        """Read a campaign file; relative paths are taken from ``root`` (default: the working
        directory), the [table] file from the campaign file's folder."""
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise CampaignError(f"cannot read campaign file {path}: {exc.strerror}") from exc
        except tomllib.TOMLDecodeError as exc:
            raise CampaignError(f"{path}: not TOML: {exc}") from exc
        return _Reader(path, root or Path.cwd()).read(data)


@dataclass(frozen=True, kw_only=True)
class Finished:
    """What a ``[[derive]]`` function is given: one finished run."""

    directory: Path
    """Its results.csv and summary.json."""
    variant: Mapping[str, Scalar]
    root: Path
    """The campaign's root (the project checkout)."""
    columns: Mapping[str, list[str]]
    """results.csv, column name -> cells (text)."""


@dataclass(frozen=True, kw_only=True)
class RunJob:
    """One run, as sent to a worker (picklable)."""

    index: int
    key: str
    variant: dict[str, Scalar]
    scenario: ScenarioSpec
    outputs: tuple[Output, ...]
    derive: tuple[Derive, ...]
    env: dict[str, str] | None = None
    """A pool entry; None: start the fleet's services on free ports."""


@dataclass(kw_only=True)
class RunReport:
    """One run's row of the campaign table, and its files (from the worker)."""

    index: int
    key: str
    variant: dict[str, Scalar]
    status: str
    """completed, terminated, failed, aborted, timeout or skipped-from-earlier statuses."""
    reason: str = ""
    wall_time_s: float | None = None
    realtime_factor: float | None = None
    values: dict[str, Scalar | None] = field(default_factory=dict)
    worker: str = ""
    files: dict[str, bytes] = field(default_factory=dict)


# --------------------------------------------------------------------------- reading the file


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
        variants = [
            *self.grid(data.get("grid", {})),
            *self.explicit(data.get("variant", [])),
            *self.table(data.get("table")),
            *self.sample(data.get("sample")),
        ]
        outputs = self.outputs(data.get("outputs", {}))
        derive = self.derive(data.get("derive", []))
        checks = self.checks(data.get("checks", {}), outputs)
        pool = self.pool(data.get("pool"))
        return CampaignSpec(
            source=self.path,
            scenario=scenario,
            out=out,
            variants=tuple(variants) or ({},),
            outputs=outputs,
            derive=derive,
            checks=checks,
            pool=pool,
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
            )
        except (TypeError, ValueError) as exc:
            raise self.fail("scenario", str(exc), "stop_time and timeout are numbers [s]") from exc
        out = self.root / raw.get("out", f"results/campaigns/{self.path.stem}")
        return spec, out

    def grid(self, raw: Any) -> list[dict[str, Scalar]]:
        if not isinstance(raw, dict):
            raise self.fail("grid", "not a table", '"Component.parameter" = [values...]')
        for key, values in raw.items():
            self.key("grid", key)
            if not isinstance(values, list) or not values:
                raise self.fail("grid", f"'{key}' is not a list of values", f'"{key}" = [1.0, 2.0]')
        if not raw:
            return []
        keys = list(raw)
        return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*raw.values())]

    def explicit(self, raw: Any) -> list[dict[str, Scalar]]:
        if not isinstance(raw, list):
            raise self.fail(
                "variant", "must be [[variant]] tables", "write [[variant]] per variant"
            )
        for variant in raw:
            for key, value in variant.items():
                self.key("variant", key)
                self.scalar("variant", key, value)
        return [dict(v) for v in raw]

    def table(self, raw: Any) -> list[dict[str, Scalar]]:
        if raw is None:
            return []
        if not isinstance(raw, dict) or "file" not in raw:
            raise self.fail(
                "table", "no file", 'file = "variants.csv" (a header of parameter names)'
            )
        path = self.path.parent / raw["file"]
        try:
            with path.open(encoding="utf-8", newline="") as file:
                rows = list(csv.DictReader(file))
        except OSError as exc:
            raise self.fail(
                "table", f"cannot read {path}: {exc.strerror}", "fix file = ..."
            ) from exc
        variants = []
        for number, row in enumerate(rows, start=2):
            variant: dict[str, Scalar] = {}
            for key, text in row.items():
                if key is None or text is None:
                    raise self.fail(
                        "table",
                        f"{path}:{number} has more or fewer cells than the header",
                        "fix the row",
                    )
                self.key("table", key)
                if text.strip() != "":
                    variant[key] = _number_or_text(text.strip())
            variants.append(variant)
        return variants

    def sample(self, raw: Any) -> list[dict[str, Scalar]]:
        if raw is None:
            return []
        try:
            count, seed = int(raw["n"]), int(raw.get("seed", 0))
        except (KeyError, TypeError, ValueError) as exc:
            raise self.fail("sample", "needs n (and a seed)", "n = 20, seed = 7") from exc
        laws = {k: v for k, v in raw.items() if k not in ("n", "seed")}
        if not laws:
            raise self.fail("sample", "no parameter to sample", '"C.p" = { uniform = [0.5, 2.0] }')
        for key, law in laws.items():
            self.key("sample", key)
            if not (
                isinstance(law, dict) and len(law) == 1 and next(iter(law)) in ("uniform", "choice")
            ):
                raise self.fail(
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

    def outputs(self, raw: Any) -> tuple[Output, ...]:
        outputs = []
        for name, text in raw.items():
            self.name("outputs", name)
            reduction, channel = "last", str(text).strip()
            if channel.endswith(")") and "(" in channel:
                reduction, _, channel = channel[:-1].partition("(")
                reduction, channel = reduction.strip(), channel.strip()
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
            options = {k: v for k, v in entry.items() if k != "function"}
            functions.append(Derive(function=target, options=options))
        return tuple(functions)

    def checks(self, raw: Any, outputs: Sequence[Output]) -> tuple[Check, ...]:
        checks = []
        for name, expression in raw.items():
            self.name("checks", name)
            try:
                _Expression(str(expression))
            except CampaignError as exc:
                raise self.fail(
                    "checks",
                    f'{name} = "{expression}": {exc}',
                    "use outputs, numbers, comparisons, and/or/not, + - * /",
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

    def key(self, where: str, key: str) -> None:
        if key in RUN_OPTIONS:
            return
        component, _, name = key.partition(".")
        if not component or not name:
            raise self.fail(
                where,
                f"'{key}' is neither Component.parameter nor one of {', '.join(RUN_OPTIONS)}",
                "name parameters as coupler run --param does (Gain.gain)",
            )

    def scalar(self, where: str, key: str, value: Any) -> None:
        if not isinstance(value, (int, float, str, bool)):
            raise self.fail(
                where, f"'{key}' = {value!r} is not a number, text or boolean", "give one value"
            )

    def name(self, where: str, name: str) -> None:
        if not name.isidentifier():
            raise self.fail(where, f"'{name}' is not a column name", "use letters, digits and _")


def _number_or_text(text: str) -> Scalar:
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


# ------------------------------------------------------------------------ checks' expressions

_OPERATORS: dict[type, Callable[..., Any]] = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.USub: operator.neg,
    ast.Not: operator.not_,
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
}


class _Expression:
    """A check's expression: names, numbers, arithmetic, comparisons, and/or/not; nothing else
    (no calls, no attributes), evaluated without eval."""

    def __init__(self, text: str) -> None:
        try:
            self.tree = ast.parse(text, mode="eval").body
        except SyntaxError as exc:
            raise CampaignError(f"not an expression ({exc.msg})") from None
        for node in ast.walk(self.tree):
            allowed = (
                ast.BoolOp,
                ast.And,
                ast.Or,
                ast.BinOp,
                ast.UnaryOp,
                ast.Compare,
                ast.Name,
                ast.Load,
                ast.Constant,
            )
            if not isinstance(node, allowed) and type(node) not in _OPERATORS:
                raise CampaignError(f"{type(node).__name__} is not allowed")

    def evaluate(self, names: Mapping[str, Any]) -> Any:
        return self._value(self.tree, names)

    def _value(self, node: ast.expr, names: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.Name):
            if names.get(node.id) is None:
                raise KeyError(node.id)
            return names[node.id]
        if isinstance(node, ast.BoolOp):
            values = (self._value(v, names) for v in node.values)
            return all(values) if isinstance(node.op, ast.And) else any(values)
        if isinstance(node, ast.UnaryOp):
            return _OPERATORS[type(node.op)](self._value(node.operand, names))
        if isinstance(node, ast.BinOp):
            return _OPERATORS[type(node.op)](
                self._value(node.left, names), self._value(node.right, names)
            )
        assert isinstance(node, ast.Compare)
        left = self._value(node.left, names)
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = self._value(right_node, names)
            if not _OPERATORS[type(op)](left, right):
                return False
            left = right
        return True


def evaluate_checks(checks: Sequence[Check], values: Mapping[str, Any]) -> dict[str, bool | None]:
    """Each check's truth over ``values``; None when a name it uses has no value (a failed
    run, an output missing)."""
    found: dict[str, bool | None] = {}
    for check in checks:
        try:
            found[check.name] = bool(_Expression(check.expression).evaluate(values))
        except (KeyError, TypeError, ZeroDivisionError):
            found[check.name] = None
    return found


# -------------------------------------------------------------------------------- reductions


def read_columns(path: Path) -> dict[str, list[str]]:
    """results.csv as column name -> cells."""
    with path.open(encoding="utf-8", newline="") as file:
        reader = csv.reader(file)
        header = next(reader, [])
        cells: list[list[str]] = [[] for _ in header]
        for row in reader:
            for column, cell in zip(cells, row, strict=False):
                column.append(cell)
    return dict(zip(header, cells, strict=True))


def reduce(output: Output, cells: Sequence[str]) -> Scalar | None:
    """``output`` over a column's cells (numbers where the cells are numbers)."""
    if not cells:
        return None
    if output.reduction == "count_changes":
        return sum(1 for a, b in itertools.pairwise(cells) if a != b)
    if output.reduction in ("first", "last"):
        return _number_or_text(cells[0] if output.reduction == "first" else cells[-1])
    numbers = [float(c) for c in cells if c != ""]
    if not numbers:
        return None
    if output.reduction == "mean":
        return math.fsum(numbers) / len(numbers)
    return max(numbers) if output.reduction == "max" else min(numbers)


# ----------------------------------------------------------------------------- one run (worker)


def execute(job: RunJob) -> RunReport:
    """Run ``job`` to its report (a Dask task; blocks)."""
    return asyncio.run(run_job(job))


async def run_job(job: RunJob) -> RunReport:
    """Start the run's services (or take its pool entry), run it as a ``coupler run`` process in
    a scratch folder, reduce its results; never raises for the run's own failures."""
    report = RunReport(index=job.index, key=job.key, variant=job.variant, status="failed")
    report.worker = os.uname().nodename
    scratch = Path(tempfile.mkdtemp(prefix=f"coupler-run-{job.index}-"))
    started = time.monotonic()
    ran = False
    try:
        try:
            async with asyncio.timeout(job.scenario.timeout):
                await _run_with_services(job, scratch)
        except TimeoutError:
            report.status = "timeout"
            report.reason = (
                f"the run did not end within {job.scenario.timeout:g} s ([scenario] timeout)"
            )
        except (CouplerError, OSError) as exc:
            report.reason = str(exc)
        else:
            ran = True
        await asyncio.to_thread(_collect, job, scratch, report, ran)
    finally:
        await asyncio.to_thread(shutil.rmtree, scratch, True)
    if report.wall_time_s is None:
        report.wall_time_s = round(time.monotonic() - started, 3)
    return report


def _collect(job: RunJob, scratch: Path, report: RunReport, ran: bool) -> None:
    """The run's status from its summary.json (when its process ran), values and files."""
    if ran:
        try:
            summary = json.loads((scratch / "summary.json").read_text(encoding="utf-8"))
            report.status, report.reason = summary["status"], summary.get("reason", "")
            report.wall_time_s = summary.get("wall_time_s")
            report.realtime_factor = summary.get("realtime_factor")
        except (OSError, ValueError, KeyError):
            report.reason = "the run wrote no summary: " + _error_of(scratch / "run.log")
    try:
        if (scratch / "results.csv").is_file():
            report.values = _values(job, scratch)
    except Exception as exc:  # a derive function is user code: its failure is the run's reason
        report.reason = (report.reason + "; " if report.reason else "") + f"outputs: {exc}"
    for path in scratch.iterdir():
        if path.is_file() and not path.name.startswith("."):
            report.files[path.name] = path.read_bytes()


async def _run_with_services(job: RunJob, scratch: Path) -> None:
    scenario = job.scenario
    if job.env is not None or scenario.fleet is None:
        await _coupler_run(job, scratch, {**os.environ, **(job.env or {})})
        return
    for attempt in range(3):  # another process may take a free port before the fleet binds it
        env = {**os.environ, **{name: str(free_port()) for name in port_variables(scenario.fleet)}}
        spec = replace(FleetSpec.load(scenario.fleet, root=scenario.root, env=env), out=scratch)
        fleet = Fleet(spec, health_timeout=scenario.health_timeout)
        try:
            fleet.check_ports()
        except FleetError:
            if attempt == 2:
                raise
            continue
        async with fleet:
            await _coupler_run(job, scratch, env)
        return


async def _coupler_run(job: RunJob, scratch: Path, env: Mapping[str, str]) -> None:
    scenario = job.scenario
    command = [
        sys.executable, "-m", "coupler_orchestrator", "--log-format", "json",
        "run", str(scenario.ssp), "--out", str(scratch), "--no-progress",
        "--run-id", f"campaign-{job.index}-{job.key}",
    ]  # fmt: skip
    if scenario.stop_time is not None:
        command += ["--stop-time", repr(scenario.stop_time)]
    command += scenario.args
    for key, value in job.variant.items():
        text = ("true" if value else "false") if isinstance(value, bool) else str(value)
        command += [RUN_OPTIONS[key], text] if key in RUN_OPTIONS else ["--param", f"{key}={text}"]
    with (scratch / "run.log").open("wb") as output:
        output.write(("$ " + " ".join(command) + "\n").encode())
        output.flush()
        process = await asyncio.create_subprocess_exec(
            *command, cwd=scenario.root, env=dict(env), stdout=output, stderr=output
        )
        try:
            await process.wait()
        finally:
            if process.returncode is None:  # timed out or the campaign was interrupted
                with contextlib.suppress(ProcessLookupError):
                    process.terminate()
                try:
                    await asyncio.wait_for(asyncio.shield(process.wait()), 10)
                except TimeoutError:
                    process.kill()
                    await process.wait()


def _values(job: RunJob, scratch: Path) -> dict[str, Scalar | None]:
    columns = read_columns(scratch / "results.csv")
    values: dict[str, Scalar | None] = {}
    for output in job.outputs:
        if output.channel not in columns:
            raise CampaignError(
                f"output {output.name}: channel '{output.channel}' is not in results.csv "
                f"(its columns: {', '.join(list(columns)[1:])})"
            )
        values[output.name] = reduce(output, columns[output.channel])
    finished = Finished(
        directory=scratch, variant=job.variant, root=job.scenario.root, columns=columns
    )
    for derive in job.derive:
        module, _, name = derive.function.partition(":")
        try:
            function = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as exc:
            raise CampaignError(f"[[derive]] {derive.function}: {exc}") from None
        values.update(function(finished, **derive.options))
    return values


def _error_of(path: Path) -> str:
    """The run's ``error:`` line, else the last lines of its log."""
    try:
        lines = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return "(no log)"
    starts = [i for i, line in enumerate(lines) if line.startswith("error: ")]
    if not starts:
        return " | ".join(lines[-5:]) or "(empty log)"
    error = [lines[starts[-1]].removeprefix("error: ")]
    error += [line.strip() for line in lines[starts[-1] + 1 :] if line.startswith((" ", "\t"))]
    return " ".join(error)


# --------------------------------------------------------------------------- the campaign


@dataclass(frozen=True, kw_only=True)
class CampaignResult:
    """A finished (or interrupted) campaign."""

    reports: tuple[RunReport, ...]
    """One per variant that ran or was skipped, in variant order."""
    table_csv: Path
    table_parquet: Path | None
    skipped: int
    """Runs taken from an earlier campaign run."""

    @property
    def failed(self) -> list[RunReport]:
        return [r for r in self.reports if r.status not in COMPLETED]


Executor = Callable[[RunJob], Awaitable[RunReport]]


async def run_campaign(
    spec: CampaignSpec,
    *,
    jobs: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: CampaignProgress | None = None,
) -> CampaignResult:
    """Run every variant of ``spec`` (``jobs`` at once; on a Dask cluster with ``scheduler``)
    and write the campaign table; a run that fails is a row with its reason, never the end of
    the campaign. Interrupted, the table holds the runs that ended."""
    runs_dir = spec.out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    jobs_of = [
        RunJob(
            index=i,
            key=variant_key(v, spec.scenario),
            variant=v,
            scenario=spec.scenario,
            outputs=spec.outputs,
            derive=spec.derive,
        )
        for i, v in enumerate(spec.variants, start=1)
    ]
    reports: dict[int, RunReport] = {}
    pending = []
    for job in jobs_of:
        earlier = None if force else _earlier(runs_dir, job.key)
        if earlier is not None:
            reports[job.index] = earlier
        else:
            pending.append(job)
    skipped = len(reports)
    progress = progress or CampaignProgress(None)
    progress.begin(len(jobs_of), skipped)
    try:
        async with _executor(scheduler, jobs) as (execute_on, width):
            if spec.pool:
                width = min(width, len(spec.pool))
            slots: asyncio.Queue[dict[str, str] | None] = asyncio.Queue()
            for entry in spec.pool or [None] * width:
                slots.put_nowait(entry)

            async def one(job: RunJob) -> None:
                slot = await slots.get()
                try:
                    progress.running(job)
                    report = await execute_on(replace(job, env=slot))
                except Exception as exc:  # the worker itself went away, not the run
                    report = RunReport(
                        index=job.index,
                        key=job.key,
                        variant=job.variant,
                        status="failed",
                        reason=f"the worker failed: {type(exc).__name__}: {exc}",
                    )
                finally:
                    slots.put_nowait(slot)
                _store(runs_dir, job, report)
                reports[job.index] = report
                progress.done(report)

            async with asyncio.TaskGroup() as group:
                for job in pending:
                    group.create_task(one(job))
    finally:
        ordered = tuple(reports[i] for i in sorted(reports))
        table_csv, table_parquet = write_table(spec, ordered)
        progress.end()
    return CampaignResult(
        reports=ordered, table_csv=table_csv, table_parquet=table_parquet, skipped=skipped
    )


@contextlib.asynccontextmanager
async def _executor(scheduler: str | None, jobs: int | None) -> Any:
    """(execute(job) awaitable, how many runs at once)."""
    if scheduler is None:
        yield run_job, jobs or os.cpu_count() or 1
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise CampaignError(
            "--scheduler needs Dask distributed: install coupler-orchestrator[campaign] "
            "(pip install 'dask[distributed]'), or leave --scheduler out to run locally"
        ) from None
    if logging.getLogger().getEffectiveLevel() > logging.DEBUG:  # --log-level DEBUG shows all
        logging.getLogger("distributed").setLevel(logging.WARNING)
    async with contextlib.AsyncExitStack() as stack:
        if scheduler == "local":
            cluster = await stack.enter_async_context(
                LocalCluster(
                    n_workers=jobs or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    asynchronous=True,
                    silence_logs=logging.WARNING,
                )
            )
            address: Any = cluster
        else:
            address = scheduler
        try:
            client = await stack.enter_async_context(
                Client(address, asynchronous=True, timeout="20s")
            )
        except (OSError, TimeoutError) as exc:
            raise CampaignError(
                f"cannot reach the Dask scheduler at {scheduler} ({exc}); start one with "
                f"'dask scheduler' and workers with 'dask worker {scheduler}', or use "
                "--scheduler local"
            ) from None
        threads = sum((await client.nthreads()).values())
        width = jobs or max(threads, 1)

        async def on_cluster(job: RunJob) -> RunReport:
            future = client.submit(
                execute, job, pure=False, key=f"coupler-run-{job.index}-{job.key}"
            )
            try:
                report: RunReport = await future
            except asyncio.CancelledError:
                await client.cancel(future)
                raise
            return report

        yield on_cluster, width


def _earlier(runs_dir: Path, key: str) -> RunReport | None:
    """The report of a run of the same variant that completed before, if any."""
    for path in sorted(runs_dir.glob(f"*-{key}/report.json")):
        with contextlib.suppress(OSError, ValueError, TypeError, KeyError):
            data = json.loads(path.read_text(encoding="utf-8"))
            if data["status"] in COMPLETED:
                return RunReport(**data)
    return None


def _store(runs_dir: Path, job: RunJob, report: RunReport) -> None:
    directory = runs_dir / f"{job.index:03d}-{job.key}"
    shutil.rmtree(directory, ignore_errors=True)
    directory.mkdir(parents=True)
    for name, content in report.files.items():
        (directory / name).write_bytes(content)
    report.files = {}
    write_json(directory / "variant.json", job.variant)
    write_json(directory / "report.json", asdict(report))


def run_directory(spec: CampaignSpec, report: RunReport) -> Path:
    return spec.out / "runs" / f"{report.index:03d}-{report.key}"


def table_rows(
    spec: CampaignSpec, reports: Iterable[RunReport]
) -> tuple[list[str], list[dict[str, Any]]]:
    """The campaign table: header and one row per run."""
    parameters = list(dict.fromkeys(k for v in spec.variants for k in v))
    values = [o.name for o in spec.outputs]
    rows = []
    for report in reports:
        found = dict(report.values)
        row: dict[str, Any] = {"run": report.index, "key": report.key}
        row |= {p: report.variant.get(p) for p in parameters}
        row |= {
            "status": report.status,
            "reason": report.reason,
            "wall_time_s": report.wall_time_s,
            "realtime_factor": report.realtime_factor,
        }
        row |= {name: found.pop(name, None) for name in values}
        row |= found  # derived columns
        names = {**{k: v for k, v in report.variant.items() if k.isidentifier()}, **row}
        row |= evaluate_checks(spec.checks, names)
        row["directory"] = str(run_directory(spec, report).relative_to(spec.out))
        rows.append(row)
    header = list(dict.fromkeys(k for row in rows for k in row)) if rows else [
        "run", "key", *parameters, "status", "reason", "wall_time_s", "realtime_factor", *values,
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


# ---------------------------------------------------------------------------------- progress


class CampaignProgress:
    """Runs done/failed/running and an ETA: redrawn in place on a terminal, a line per ended run
    otherwise."""

    def __init__(self, stream: IO[str] | None, *, tty: bool | None = None) -> None:
        self._stream = stream
        self.tty = stream.isatty() if tty is None and stream is not None else bool(tty)
        self.total = self.done_count = self.failed = self.skipped = 0
        self._running = 0
        self._started = 0.0

    def begin(self, total: int, skipped: int) -> None:
        self.total, self.skipped, self.done_count = total, skipped, skipped
        self._started = time.monotonic()
        if skipped:
            self._write(
                f"campaign: {skipped} of {total} runs completed earlier (--force runs them again)\n"
            )

    def running(self, job: RunJob) -> None:
        self._running += 1
        if self.tty:
            self._draw()

    def done(self, report: RunReport) -> None:
        self._running -= 1
        self.done_count += 1
        if report.status not in COMPLETED:
            self.failed += 1
        if self.tty:
            self._draw()
        else:
            reason = (
                f": {report.reason}" if report.reason and report.status not in COMPLETED else ""
            )
            self._write(f"campaign: run {report.index} {report.status}{reason} ({self.line()})\n")

    def line(self) -> str:
        ran = self.done_count - self.skipped
        left = self.total - self.done_count
        elapsed = time.monotonic() - self._started
        eta = elapsed / ran * left if ran else float("inf")
        return (
            f"{self.done_count}/{self.total} done, {self.failed} failed, {self._running} running, "
            f"ETA {duration(eta) if left else '0 s'}"
        )

    def end(self) -> None:
        if self.tty:
            self._write("\n")

    def _draw(self) -> None:
        width = 30
        filled = round(width * self.done_count / self.total) if self.total else width
        self._write(f"\r[{'#' * filled}{'.' * (width - filled)}] runs {self.line()} ")

    def _write(self, text: str) -> None:
        stream = self._stream
        if stream is None:
            return
        stream.write(text)
        stream.flush()
