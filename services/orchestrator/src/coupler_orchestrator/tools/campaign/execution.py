"""Every run of a campaign: ``jobs`` at once on this machine or as tasks of a Dask cluster, the
runs that completed before skipped (unless forced), each report stored with its files, and the
table written at the end — also when the campaign is interrupted."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import shutil
import tempfile
from collections.abc import Awaitable, Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from coupler_orchestrator.outputs.files import write_json
from coupler_orchestrator.tools.campaign.model import (
    COMPLETED,
    CampaignError,
    CampaignResult,
    CampaignSpec,
    RunJob,
    RunReport,
)
from coupler_orchestrator.tools.campaign.progress import CampaignProgress
from coupler_orchestrator.tools.campaign.table import write_table
from coupler_orchestrator.tools.campaign.variants import variant_key
from coupler_orchestrator.tools.campaign.worker import KEPT, execute, run_job

Executor = Callable[[RunJob], Awaitable[RunReport]]


async def run_campaign(
    spec: CampaignSpec,
    *,
    jobs: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: CampaignProgress | None = None,
    logs: tuple[str, bool] = ("WARNING", False),
) -> CampaignResult:
    """Run every variant of ``spec`` (``jobs`` at once; on a Dask cluster with ``scheduler``)
    and write the campaign table; a run that fails is a row with its reason, never the end of
    the campaign. Interrupted, the table holds the runs that ended. ``logs``: the log level and
    JSON-ness of the runs' workers (``RunJob.logs``)."""
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
            logs=logs,
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
        try:
            yield run_job, jobs or os.cpu_count() or 1
        finally:
            await KEPT.close()  # the services kept between runs ([scenario] keep_services)
        return
    try:
        import dask
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
            # the workers' scratch space is the campaign's, removed with it (Dask's default,
            # TMPDIR/dask-scratch-space, outlives every campaign)
            scratch = stack.enter_context(tempfile.TemporaryDirectory(prefix="coupler-dask-"))
            stack.enter_context(dask.config.set({"temporary-directory": scratch}))
            cluster = await stack.enter_async_context(
                LocalCluster(
                    local_directory=scratch,
                    n_workers=jobs or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address="127.0.0.1:0",  # None would still try port 8787
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
        (directory / name).parent.mkdir(parents=True, exist_ok=True)
        (directory / name).write_bytes(content)
    report.files = {}
    write_json(directory / "variant.json", job.variant)
    write_json(directory / "report.json", asdict(report))
