"""One scenario end to end: load -> (its semantics) -> participants -> checks -> wiring -> plan
-> master -> results. The CLI calls this; ``validate`` stops after the checks.

Every path cleans up: participants are closed and an extracted archive is removed, also when
loading, checking or running fails or the run is interrupted.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import structlog

from coupler.archives import Budget, remove_scratch, scratch_folder
from coupler.channels import Description
from coupler.errors import ScenarioError
from coupler_orchestrator import ssp
from coupler_orchestrator.master import native_step_channel
from coupler_orchestrator.master.openmcx import master_of
from coupler_orchestrator.model import Checked, Plan
from coupler_orchestrator.observer import Observer, RunEnd
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.outputs.csv import CsvRecorder, Selection
from coupler_orchestrator.outputs.files import check_writable, claim, default_base, new_run_folder
from coupler_orchestrator.outputs.kept_frames import KeptFrames
from coupler_orchestrator.outputs.openmcx import openmcx_results
from coupler_orchestrator.outputs.parquet import ParquetRecorder, parquet_available
from coupler_orchestrator.outputs.summary import SummaryWriter, coupler_version
from coupler_orchestrator.pipeline.checks import check
from coupler_orchestrator.pipeline.openmcx import semantics_of
from coupler_orchestrator.pipeline.participants import opened
from coupler_orchestrator.pipeline.plan import build_plan
from coupler_orchestrator.pipeline.wiring import wire
from coupler_orchestrator.recording import SUFFIX as RECORDING_SUFFIX
from coupler_orchestrator.recording import Recorder

log = structlog.get_logger("coupler.runner")


@dataclass(frozen=True, kw_only=True)
class RunOutcome:
    """A finished run and where its results are."""

    end: RunEnd
    summary: dict[str, Any]
    """What summary.json holds."""
    results_csv: Path
    summary_json: Path
    recordings: tuple[Path, ...] = ()
    """The ``--record`` files written."""
    openmcx_files: tuple[Path, ...] = ()
    """OpenMCx's result files written (``--openmcx-results``)."""


@dataclass(frozen=True, kw_only=True)
class Validation:
    """A scenario that passed every check."""

    scenario: ssp.Scenario
    warnings: tuple[str, ...]


@asynccontextmanager
async def loaded(path: Path, budget: Budget | None = None) -> AsyncIterator[ssp.Scenario]:
    """The scenario at ``path`` (.ssp, unpacked folder, .ssd or .fmu), read off the event loop;
    an archive unpacks within ``budget``; it is removed on the way out, however it is left."""
    if path.suffix.lower() == ".fmu":
        yield await asyncio.to_thread(ssp.scenario_of_fmu, path)
        return
    workdir = scratch_folder("coupler-ssp-")
    stop = threading.Event()
    loop = asyncio.get_running_loop()
    reading = loop.run_in_executor(
        None, lambda: ssp.load_ssp(path, workdir=workdir, budget=budget, cancelled=stop)
    )
    try:
        try:
            scenario = await asyncio.shield(reading)
        except asyncio.CancelledError:
            stop.set()  # the load stops at its next chunk or element; wait, then remove
            done, _ = await asyncio.wait([reading], timeout=10)
            for future in done:
                future.exception()  # LoadCancelled, or whatever ended it: the command ends
            raise
        for warning in scenario.warnings:
            log.warning("scenario_warning", detail=warning)
        yield scenario
    finally:
        await asyncio.to_thread(remove_scratch, workdir)


async def validate_scenario(path: Path, options: RunOptions) -> Validation:
    """Every check of ``run`` without running; ValidationError lists every problem."""
    budget = Budget.of(options.unpack_limit)
    async with loaded(path, budget) as scenario, opened(scenario, options, budget) as roster:
        checked = check(scenario, roster, options, semantics_of(scenario, options))
    return Validation(scenario=scenario, warnings=checked.warnings)


async def run_scenario(
    path: Path,
    options: RunOptions,
    *,
    out_dir: Path | None = None,
    base: Path | None = None,
    replace: bool = False,
    observers: Sequence[Observer] = (),
    on_results: Callable[[Path], None] | None = None,
) -> RunOutcome:
    """Run the scenario at ``path``; results go to a folder of the run's own
    (``outputs.files``): ``out_dir`` when given — refused when it holds an earlier run's
    results, unless ``replace`` — else a new folder in ``base`` (default: the OpenMCx results
    annotation's outputDirectory, else ``results/<scenario>``). ``on_results`` is told that
    folder before any participant starts.

    Raises ScenarioError/ValidationError before anything runs; a participant failing during
    the run ends it as ``failed`` with every completed step recorded.
    """
    options = options.switched()  # the environment's switches, read here only
    budget = Budget.of(options.unpack_limit)  # the archive and its FMUs together
    async with loaded(path, budget) as scenario:
        if out_dir is None and base is None:
            configured = scenario.results.output_directory if scenario.results else None
            base = Path(configured) if configured else default_base(path)
        check_writable(out_dir or base)  # before any participant starts
        if out_dir is not None and not replace:
            claim(out_dir, replace=False)
        if options.parquet and not parquet_available():
            raise ScenarioError(
                "--parquet needs the pyarrow package: install it (pip install pyarrow, or "
                "uv sync in a checkout) or leave --parquet out (results.csv is always written)"
            )
        steps = native_step_channel.transport(options.native_steps, options.step_socket)
        async with opened(scenario, options, budget, steps=steps) as roster:
            checked = check(scenario, roster, options, semantics_of(scenario, options))
            plan = build_plan(checked, wire(checked), options)
            if out_dir is None:  # made once the run is sure to start: no empty folders
                out_dir = new_run_folder(base, options.run_id)
            else:
                claim(out_dir, replace=replace)
            if on_results is not None:
                on_results(out_dir)
            csv_path, summary_path = out_dir / "results.csv", out_dir / "summary.json"
            recordings = recorders_of(plan, roster.described(), out_dir, options)
            selection = Selection(patterns=options.output_variables, every=checked.record_every)
            results = CsvRecorder(csv_path, selection)
            extra = _extra(checked, roster.described())
            extra["results_rows"] = results.rows
            if recordings:
                extra["recordings"] = {r.component: f"recordings/{r.path.name}" for r in recordings}
            summary = SummaryWriter(summary_path, extra=extra)
            # frames kept for the reports: told the end before the summary makes the reports
            recorders: list[Observer] = [results, KeptFrames(out_dir), summary]
            if options.parquet:
                recorders.append(ParquetRecorder(out_dir / "results.parquet", selection))
            recorders.extend(recordings)
            files = openmcx_results(out_dir, scenario, options)
            recorders.extend(files)
            recorders.extend(observers)
            end = await master_of(plan)(plan, recorders).run()
    return RunOutcome(
        end=end,
        summary=summary.summary,
        results_csv=csv_path,
        summary_json=summary_path,
        recordings=tuple(r.path for r in recordings),
        openmcx_files=tuple(path for f in files for path in f.paths),
    )


def recorders_of(
    plan: Plan, descriptions: Mapping[str, Description], out_dir: Path, options: RunOptions
) -> list[Recorder]:
    """A recorder per ``--record`` component: ``OUT/recordings/COMPONENT.crec``."""
    members = {m.name: m for m in plan.members}
    return [
        Recorder(
            out_dir / "recordings" / f"{name}{RECORDING_SUFFIX}",
            descriptions[name],
            component=name,
            multiple=members[name].multiple,
            step=members[name].step,
        )
        for name in dict.fromkeys(options.record)
    ]


def _extra(checked: Checked, descriptions: dict[str, Any]) -> dict[str, Any]:
    scenario = checked.scenario
    return {
        "coupler_version": coupler_version(),
        "ssp": {"path": str(scenario.source), "sha256": scenario.sha256},
        "implementations": {n: d.implementation for n, d in descriptions.items()},
        "semantics": checked.semantics.name,
        "warnings": list(checked.warnings),
        "parameters": {
            f"{member.name}.{name}": value
            for member in checked.members
            for name, value in member.parameters.items()
            if not isinstance(value, bytes)
        },
    }
