"""``coupler validate``: every check of ``run``, without running."""

from __future__ import annotations

import argparse
from collections.abc import Sized
from dataclasses import replace
from typing import TextIO

from coupler_orchestrator.cli.exits import EXIT_OK
from coupler_orchestrator.cli.parser import (
    options_of,
    replay_option,
    run_options,
    scenario_argument,
)
from coupler_orchestrator.cli.session import Session

HELP = "check a scenario and its participants"


def arguments(validate: argparse.ArgumentParser) -> None:
    scenario_argument(validate)
    run_options(validate)
    replay_option(validate)


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    from coupler_orchestrator.runner import validate_scenario

    options = replace(options_of(args), on_waiting=session.waiting)
    validation = await validate_scenario(args.ssp, options)
    for warning in validation.warnings:
        print(f"warning: {warning}", file=out)
    scenario = validation.scenario
    components = count(scenario.components, "component")
    connections = count(scenario.connections, "connection")
    print(f"{args.ssp}: valid ({components}, {connections})", file=out)
    reason = scenario.openmcx or ("--openmcx" if options.openmcx else "")
    if reason:
        print(f"runs with OpenMCx's semantics ({reason})", file=out)
    return EXIT_OK


def count(items: Sized, noun: str) -> str:
    """``1 component``, ``2 components``, ``0 connections``."""
    number = len(items)
    return f"{number} {noun}{'' if number == 1 else 's'}"
