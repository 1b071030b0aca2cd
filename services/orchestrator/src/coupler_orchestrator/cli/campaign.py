"""``coupler campaign``: a scenario under many variants, in parallel, into one table."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import TextIO

from coupler_orchestrator.cli.exits import EXIT_ERROR, EXIT_OK
from coupler_orchestrator.cli.session import Session, shown

HELP = "run a scenario under many variants, in parallel, into one table"
DESCRIPTION = (
    "Runs every variant of a campaign file (docs/campaigns.md): here, --jobs at once, or as "
    "tasks of a Dask cluster (--scheduler). Runs that completed before are skipped unless "
    "--force."
)


def arguments(campaign: argparse.ArgumentParser) -> None:
    campaign.add_argument("campaign", type=Path, help="campaign file (TOML)")
    campaign.add_argument("--jobs", type=int, help="runs at once (default: one per core)")
    campaign.add_argument(
        "--scheduler",
        help="tcp://HOST:8786 (a Dask scheduler) or local (a Dask LocalCluster); default: "
        "runs as local processes",
    )
    campaign.add_argument("--force", action="store_true", help="run completed variants again")
    campaign.add_argument("--out", type=Path, help="campaign folder (default: [scenario] out)")


async def execute(args: argparse.Namespace, out: TextIO, session: Session) -> int:
    from coupler_orchestrator.tools.campaign import (
        CampaignError,
        CampaignProgress,
        CampaignSpec,
        format_table,
        run_campaign,
    )

    spec = CampaignSpec.load(args.campaign)
    if args.out is not None:
        spec = replace(spec, out=args.out)
    if args.jobs is not None and args.jobs < 1:
        raise CampaignError(f"--jobs {args.jobs}: give at least 1")
    session.campaign = spec.out
    print(
        f"campaign: {len(spec.variants)} runs of {shown(spec.scenario.ssp)} into {shown(spec.out)}",
        file=out,
        flush=True,
    )
    result = await run_campaign(
        spec,
        jobs=args.jobs,
        scheduler=args.scheduler,
        force=args.force,
        progress=CampaignProgress(sys.stderr),
        logs=(
            args.log_level,
            {"auto": not sys.stderr.isatty(), "console": False, "json": True}[args.log_format],
        ),
    )
    print(format_table(spec, result.reports), file=out)
    print(f"table: {shown(result.table_csv)}", file=out)
    if result.table_parquet is not None:
        print(f"table: {shown(result.table_parquet)}", file=out)
    if result.failed:
        print(
            f"error: {len(result.failed)} of {len(result.reports)} runs did not complete "
            f"(status and reason in the table; run.log in each run's folder)",
            file=sys.stderr,
        )
        return EXIT_ERROR
    return EXIT_OK
