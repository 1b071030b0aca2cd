"""One scenario run end to end: load, describe and check, plan, run, record, clean up."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import structlog

from coupler.channels import Description
from coupler.participant import Participant
from coupler_orchestrator import ssp
from coupler_orchestrator.master import Master, RunResult
from coupler_orchestrator.observer import Observer
from coupler_orchestrator.plan import Plan
from coupler_orchestrator.planning import RunOptions, build_plan, close_all, describe_all
from coupler_orchestrator.results import CsvRecorder, SummaryWriter, coupler_version

log = structlog.get_logger("coupler.runner")


@dataclass(frozen=True, kw_only=True)
class RunOutcome:
    """A finished run and where its results are."""

    result: RunResult
    results_csv: Path
    summary_json: Path


async def plan_scenario(
    scenario: ssp.Scenario, options: RunOptions
) -> tuple[Plan, dict[str, Participant], dict[str, Description]]:
    """Describe every participant, check everything, plan; ValidationError lists every
    problem. The participants are open on return: the caller closes them."""
    participants, descriptions, problems = await describe_all(scenario, options)
    try:
        plan = build_plan(
            scenario,
            participants,
            descriptions,
            options,
            problems=[*problems, *ssp.check_connections(scenario)],
        )
    except BaseException:
        await close_all(list(participants.values()))
        raise
    return plan, participants, descriptions


async def validate_scenario(path: Path, options: RunOptions) -> ssp.Scenario:
    """Schema and participant checks; ValidationError lists every problem."""
    scenario = ssp.load_ssp(path)
    _, participants, _ = await plan_scenario(scenario, options)
    await close_all(list(participants.values()))
    return scenario


async def run_scenario(
    path: Path,
    options: RunOptions,
    *,
    out_dir: Path | None = None,
    observers: Sequence[Observer] = (),
) -> RunOutcome:
    """Run the scenario at ``path``; results go to ``out_dir`` (default: the OpenMCx results
    annotation's outputDirectory, else ``results``).

    Raises ScenarioError/ValidationError before anything runs; a participant failing during
    the run ends it as ``failed`` with every completed step recorded.
    """
    scenario = ssp.load_ssp(path)
    for warning in scenario.warnings:
        log.warning("scenario_warning", detail=warning)
    if out_dir is None:
        configured = scenario.results.output_directory if scenario.results else None
        out_dir = Path(configured) if configured else Path("results")
    plan, participants, descriptions = await plan_scenario(scenario, options)
    try:
        csv_path, summary_path = out_dir / "results.csv", out_dir / "summary.json"
        summary = SummaryWriter(
            summary_path,
            extra={
                "coupler_version": coupler_version(),
                "ssp": {"path": str(scenario.source), "sha256": scenario.sha256},
                "implementations": {n: d.implementation for n, d in descriptions.items()},
                "warnings": list(scenario.warnings),
            },
        )
        master = Master(plan, [CsvRecorder(csv_path), summary, *observers])
        result = await master.run()
    finally:
        await close_all(list(participants.values()))
    return RunOutcome(result=result, results_csv=csv_path, summary_json=summary_path)
