"""One run of a campaign, as a worker executes it (here, or a Dask task): its services started on
free ports (or its pool entry taken, or services kept from an earlier run taken), ``coupler
run`` as a process in a scratch folder, its results reduced to the table's values; the run's
files sent back whole.

With ``[scenario] keep_services = true`` a worker keeps a fleet's services up between runs
(``KEPT``): a run takes an idle fleet of its fleet file, or starts one; a run that did not
complete, or a fleet one of whose services ended, is stopped rather than kept. A Dask worker
runs its jobs on one event loop of its own (``_kept_loop``) so that the fleets it keeps outlive a
job, and stops them when its process ends; a kept service also ends with the thread that started
it (``Fleet(die_with_parent=True)``), should the worker be killed."""

from __future__ import annotations

import asyncio
import atexit
import contextlib
import csv
import importlib
import itertools
import json
import math
import os
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from coupler.errors import CouplerError
from coupler.logs import configure_logging
from coupler_orchestrator.tools.campaign.model import (
    COMPLETED,
    CampaignError,
    Finished,
    Output,
    RunJob,
    RunReport,
    Scalar,
)
from coupler_orchestrator.tools.campaign.variants import RUN_OPTIONS, number_or_text
from coupler_orchestrator.tools.fleet import Fleet, FleetError, FleetSpec, free_port, port_variables

REPORTS = "reports."
"""An output read off the run's summary.json (``reports.<name>.<key>``), not results.csv."""
SERVICE_LOGS = "service-logs"
"""The folder of a run's scratch folder its fleet's services log into (``service-NAME.log`` in
the run's folder when the run did not complete)."""


def execute(job: RunJob) -> RunReport:
    """Run ``job`` to its report (a Dask task, in a worker's process; blocks)."""
    level, json_lines = job.logs
    configure_logging(level, json=json_lines)
    if job.scenario.keep_services and job.env is None and job.scenario.fleet is not None:
        return asyncio.run_coroutine_threadsafe(run_job(job), _kept_loop()).result()
    return asyncio.run(run_job(job))


class KeptFleets:
    """Fleets kept up between runs, the idle ones by fleet file (one run on a fleet at once)."""

    def __init__(self) -> None:
        self._idle: dict[Path, list[tuple[Fleet, dict[str, str]]]] = {}
        self._busy: set[Fleet] = set()

    async def take(self, job: RunJob) -> tuple[Fleet, dict[str, str]]:
        """An idle fleet of the job's fleet file whose services all still run, else a new one."""
        assert job.scenario.fleet is not None
        idle = self._idle.setdefault(job.scenario.fleet, [])
        while idle:
            fleet, env = idle.pop()
            if fleet.running():
                self._busy.add(fleet)
                return fleet, env
            await fleet.stop()
        root = Path(tempfile.mkdtemp(prefix="coupler-kept-services-"))
        fleet, env = await _start_fleet(job, root, root / SERVICE_LOGS, die_with_parent=True)
        self._busy.add(fleet)
        return fleet, env

    async def give_back(self, job: RunJob, fleet: Fleet, env: dict[str, str], keep: bool) -> None:
        """``fleet`` idle again (``keep``: the run completed), or stopped."""
        assert job.scenario.fleet is not None
        self._busy.discard(fleet)
        if keep and fleet.running():
            self._idle.setdefault(job.scenario.fleet, []).append((fleet, env))
        else:
            await _stop_kept(fleet)

    async def close(self) -> None:
        """Stop every fleet kept (the campaign, or the worker's process, ends)."""
        fleets = [f for idle in self._idle.values() for f, _ in idle] + list(self._busy)
        self._idle.clear()
        self._busy.clear()
        for fleet in fleets:
            await _stop_kept(fleet)


KEPT = KeptFleets()
"""This process's kept fleets."""

_LOOP: asyncio.AbstractEventLoop | None = None
_LOOP_LOCK = threading.Lock()


def _kept_loop() -> asyncio.AbstractEventLoop:
    """The event loop a Dask worker runs kept-services jobs on (started on the first)."""
    global _LOOP
    with _LOOP_LOCK:
        if _LOOP is None:
            loop = asyncio.new_event_loop()
            threading.Thread(
                target=loop.run_forever, name="coupler-kept-services", daemon=True
            ).start()
            atexit.register(_close_kept_loop, loop)
            _LOOP = loop
        return _LOOP


def _close_kept_loop(loop: asyncio.AbstractEventLoop) -> None:
    with contextlib.suppress(Exception):
        asyncio.run_coroutine_threadsafe(KEPT.close(), loop).result(30)
    loop.call_soon_threadsafe(loop.stop)


async def _stop_kept(fleet: Fleet) -> None:
    await fleet.stop()
    shutil.rmtree(fleet.spec.out, ignore_errors=True)


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
    for path in sorted(scratch.rglob("*")):
        name = path.relative_to(scratch).as_posix()
        hidden = any(part.startswith(".") for part in path.relative_to(scratch).parts)
        if path.is_file() and not hidden and not name.startswith(f"{SERVICE_LOGS}/"):
            report.files[name] = path.read_bytes()  # the reports' folders too (their frames)
    if report.status not in COMPLETED:  # what its services said, to debug it
        for path in sorted(scratch.glob(f"{SERVICE_LOGS}/*/*.log")):
            report.files[f"service-{path.name}"] = path.read_bytes()


async def _run_with_services(job: RunJob, scratch: Path) -> None:
    scenario = job.scenario
    if job.env is not None or scenario.fleet is None:
        await _coupler_run(job, scratch, {**os.environ, **(job.env or {})})
        return
    if scenario.keep_services:
        fleet, env = await KEPT.take(job)
        completed = False
        try:
            await _coupler_run(job, scratch, env, fleet.addresses)
            completed = _completed(scratch)
        finally:
            if not completed:  # what its services said, with the run (as a run's own fleet)
                shutil.copytree(fleet.logs, scratch / SERVICE_LOGS / fleet.logs.name,
                                dirs_exist_ok=True)  # fmt: skip
            await KEPT.give_back(job, fleet, env, keep=completed)
        return
    fleet, env = await _start_fleet(job, scratch, scratch / SERVICE_LOGS)
    try:
        await _coupler_run(job, scratch, env, fleet.addresses)
    finally:
        await fleet.stop()


async def _start_fleet(
    job: RunJob, out: Path, logs: Path, *, die_with_parent: bool = False
) -> tuple[Fleet, dict[str, str]]:
    """The job's fleet file's services started (healthy) on free ports, and the environment
    naming those ports (the SSD reads the same variables)."""
    scenario = job.scenario
    assert scenario.fleet is not None
    for attempt in range(3):  # another process may take a free port before the fleet binds it
        env = {**os.environ, **{name: str(free_port()) for name in port_variables(scenario.fleet)}}
        spec = replace(FleetSpec.load(scenario.fleet, root=scenario.root, env=env), out=out)
        fleet = Fleet(  # its services' logs stay with the run (kept when it fails)
            spec,
            health_timeout=scenario.health_timeout,
            logs=logs,
            sockets=True,  # on unix sockets, as `coupler fleet` (unless unix_sockets = false)
            die_with_parent=die_with_parent,
        )
        try:
            fleet.check_ports()
        except FleetError:
            if attempt == 2:
                raise
            continue
        await fleet.__aenter__()
        return fleet, env
    raise AssertionError("unreachable")


def _completed(scratch: Path) -> bool:
    """Whether the run in ``scratch`` completed (its summary.json says so)."""
    try:
        summary = json.loads((scratch / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return summary.get("status") in COMPLETED


async def _coupler_run(
    job: RunJob, scratch: Path, env: Mapping[str, str], addresses: Mapping[str, str] | None = None
) -> None:
    """``coupler run`` of ``job`` in ``scratch``; ``addresses`` move participants (the SSD's
    address of each -> where its fleet serves it, e.g. a unix socket)."""
    scenario = job.scenario
    command = [
        sys.executable, "-m", "coupler_orchestrator", "--log-format", "json",
        "run", str(scenario.ssp), "--out", str(scratch), "--no-progress",
        "--run-id", f"campaign-{job.index}-{job.key}",
    ]  # fmt: skip
    for source, address in sorted((addresses or {}).items()):
        command += ["--address", f"{source}={address}"]
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
    summary: Mapping[str, Any] | None = None
    for output in job.outputs:
        if output.channel.startswith(REPORTS):
            if summary is None:
                summary = json.loads((scratch / "summary.json").read_text(encoding="utf-8"))
            values[output.name] = report_value(summary, output.channel)
            continue
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


def report_value(summary: Mapping[str, Any], path: str) -> Scalar | None:
    """The value at ``path`` (``reports.perception.recall``; a number picks an item of a list:
    ``reports.perception.by_distance.0.recall``) in a run's summary.json; None where the run
    has no such value (a run its report did not cover, a report that failed)."""
    value: Any = summary
    for part in path.split("."):
        if isinstance(value, dict):
            value = value.get(part)
        elif isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        else:
            return None
    if isinstance(value, list | dict):
        return json.dumps(value, sort_keys=True)
    return value


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
        return number_or_text(cells[0] if output.reduction == "first" else cells[-1])
    numbers = [(float(c), c) for c in cells if c != ""]
    if not numbers:
        return None
    if output.reduction == "mean":
        return math.fsum(n for n, _ in numbers) / len(numbers)
    # the cell as the column has it: an Integer's maximum is 3, not 3.0
    extreme = max if output.reduction == "max" else min
    return number_or_text(extreme(numbers, key=lambda pair: pair[0])[1])
