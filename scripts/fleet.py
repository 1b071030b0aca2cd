"""Run a scenario's fleet as local processes: start, wait for health, run, show, stop.

    python scripts/fleet.py scenarios/railway/fleet.toml [--exit] [--out DIR]

Each service of the fleet file is started as its own process (logs in build/logs/), the
orchestrator runs once every service is healthy, the URLs and result paths are printed, and
(without --exit) the services stay up until Ctrl-C. Every process is stopped on the way out,
also when something fails.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import aiohttp

from coupler.client import RemoteParticipant
from coupler.errors import CouplerError

ROOT = Path(__file__).resolve().parents[1]
LOGS = ROOT / "build" / "logs"


@dataclass
class Service:
    name: str
    command: list[str]
    health: str
    process: asyncio.subprocess.Process | None = None

    @property
    def log(self) -> Path:
        return LOGS / f"{self.name}.log"


async def start(service: Service) -> None:
    LOGS.mkdir(parents=True, exist_ok=True)
    with service.log.open("wb") as log:
        service.process = await asyncio.create_subprocess_exec(
            *service.command, cwd=ROOT, stdout=log, stderr=asyncio.subprocess.STDOUT,
            start_new_session=True,
        )


async def wait_healthy(service: Service, timeout: float) -> None:
    if service.health.startswith("grpc://"):
        remote = RemoteParticipant(service.health, name=service.name, connect_timeout=timeout)
        try:
            await remote.open()
        finally:
            await remote.close()
        return
    deadline = time.monotonic() + timeout
    async with aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=2)) as session:
        while True:
            with contextlib.suppress(aiohttp.ClientError, TimeoutError):
                async with session.get(service.health) as response:
                    if response.status == 200:
                        return
            if service.process is not None and service.process.returncode is not None:
                raise RuntimeError(f"{service.name} exited with {service.process.returncode}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{service.name} not healthy at {service.health} in {timeout:g} s")
            await asyncio.sleep(0.2)


async def stop(services: list[Service]) -> None:
    running = [s for s in services if s.process and s.process.returncode is None]
    for s in running:
        assert s.process
        with contextlib.suppress(ProcessLookupError):
            os.killpg(s.process.pid, signal.SIGTERM)
    for s in running:
        assert s.process
        try:
            await asyncio.wait_for(s.process.wait(), 10)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(s.process.pid, signal.SIGKILL)
            await s.process.wait()
    if running:
        print(f"fleet: stopped {', '.join(s.name for s in running)}", flush=True)


def tail(path: Path, lines: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


async def main(args: argparse.Namespace) -> int:
    fleet = tomllib.loads(args.fleet.read_text())
    services = [
        Service(name=s["name"], command=[sys.executable if c == "python" else c for c in s["command"]],
                health=s["health"])
        for s in fleet.get("service", [])
    ]
    scenario = fleet["scenario"]
    out = args.out or Path(scenario.get("out", "results"))
    stopping = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stopping.set)
    try:
        for service in services:
            await start(service)
            print(f"fleet: started {service.name} (pid {service.process.pid if service.process else '?'})",
                  flush=True)
        for service in services:
            try:
                await wait_healthy(service, args.health_timeout)
            except (CouplerError, RuntimeError) as exc:
                print(f"fleet: {service.name} is not healthy: {exc}\n--- {service.log} ---\n"
                      f"{tail(service.log)}", file=sys.stderr)
                return 1
            print(f"fleet: {service.name} healthy ({service.health})", flush=True)
        command = [sys.executable, "-m", "coupler_orchestrator", "run", scenario["ssp"],
                   "--out", str(out), *scenario.get("args", [])]
        run = await asyncio.create_subprocess_exec(*command, cwd=ROOT, start_new_session=True)
        run_done = asyncio.ensure_future(run.wait())
        stop_wait = asyncio.ensure_future(stopping.wait())
        await asyncio.wait({run_done, stop_wait}, return_when=asyncio.FIRST_COMPLETED)
        if not run_done.done():
            with contextlib.suppress(ProcessLookupError):
                os.killpg(run.pid, signal.SIGINT)
            await run_done
        stop_wait.cancel()
        code = run.returncode or 0
        for name, url in fleet.get("urls", {}).items():
            print(f"fleet: {name}: {url}", flush=True)
        print(f"fleet: results: {out / 'results.csv'}\nfleet: summary: {out / 'summary.json'}",
              flush=True)
        if code != 0:
            print(f"fleet: the run ended with exit code {code}; service logs in {LOGS}",
                  file=sys.stderr)
            return code
        if not args.exit and not stopping.is_set():
            print("fleet: services stay up; Ctrl-C stops them", flush=True)
            await stopping.wait()
        return 0
    finally:
        await stop(services)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fleet", type=Path, help="fleet file (TOML)")
    parser.add_argument("--exit", action="store_true", help="stop the services when the run ends")
    parser.add_argument("--out", type=Path, help="results directory (default from the fleet file)")
    parser.add_argument("--health-timeout", type=float, default=60.0, help="[s] per service")
    sys.exit(asyncio.run(main(parser.parse_args())))
