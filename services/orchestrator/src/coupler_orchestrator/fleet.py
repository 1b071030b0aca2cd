"""A scenario's fleet as local processes: each service its own process, on loopback.

A fleet file (TOML) names the scenario and the services::

    [scenario]
    ssp = "scenarios/railway/SystemStructure.ssd"
    out = "results/railway"
    args = ["--realtime-factor", "20"]       # extra `coupler run` options

    [[service]]
    name = "openrails-mock"
    command = ["python", "-m", "openrails_mock", "--port", "2150"]
    health = "http://127.0.0.1:2150/API/READY"   # or grpc(s)://HOST:PORT (gRPC health)

    [urls]
    map = "http://127.0.0.1:8080/"

``Fleet`` starts the services (logs in ``build/logs/``), waits for their health and stops them
all on the way out (SIGTERM, then SIGKILL after a grace period), also when something fails.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType

import aiohttp
import structlog

from coupler.errors import CouplerError, ScenarioError
from coupler.health import probe

log = structlog.get_logger("coupler.fleet")


class FleetError(CouplerError):
    """A service of the fleet did not start or did not become healthy."""


@dataclass(frozen=True, kw_only=True)
class ServiceSpec:
    """One service of the fleet."""

    name: str
    """Name in logs and messages."""
    command: tuple[str, ...]
    """Command line; a leading ``python`` means this interpreter."""
    health: str
    """``grpc://HOST:PORT`` or ``grpcs://HOST:PORT`` (gRPC health SERVING; TLS from the
    ``COUPLER_TLS_*`` environment) or an http URL answering 200."""


@dataclass(frozen=True, kw_only=True)
class FleetSpec:
    """A fleet file, with paths resolved against ``root``."""

    root: Path
    """Directory the commands run in and paths are relative to."""
    ssp: Path
    """The scenario."""
    out: Path
    """Results directory."""
    run_args: tuple[str, ...] = ()
    """Extra ``coupler run`` options."""
    services: tuple[ServiceSpec, ...] = ()
    """Started in order."""
    urls: dict[str, str] = field(default_factory=dict)
    """Printed when the run ends (e.g. the map)."""

    @classmethod
    def load(cls, path: Path, *, root: Path | None = None) -> FleetSpec:
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
            scenario = data["scenario"]
            root = root or Path.cwd()
            return cls(
                root=root,
                ssp=root / scenario["ssp"],
                out=root / scenario.get("out", "results"),
                run_args=tuple(scenario.get("args", ())),
                services=tuple(
                    ServiceSpec(name=s["name"], command=tuple(s["command"]), health=s["health"])
                    for s in data.get("service", ())
                ),
                urls=dict(data.get("urls", {})),
            )
        except OSError as exc:
            raise ScenarioError(f"cannot read fleet file {path}: {exc.strerror}") from exc
        except (tomllib.TOMLDecodeError, KeyError, TypeError) as exc:
            raise ScenarioError(
                f"{path}: not a fleet file ({type(exc).__name__}: {exc}); see "
                f"coupler_orchestrator.fleet for the format"
            ) from exc


class Fleet:
    """Starts the services on enter (healthy or FleetError), stops them all on exit."""

    def __init__(self, spec: FleetSpec, *, health_timeout: float = 60.0) -> None:
        self.spec = spec
        self.health_timeout = health_timeout
        self.logs = spec.root / "build" / "logs"
        self._processes: dict[str, asyncio.subprocess.Process] = {}

    async def __aenter__(self) -> Fleet:
        try:
            for service in self.spec.services:
                await self._start(service)
            for service in self.spec.services:
                await self._wait_healthy(service)
                log.info("service_healthy", service=service.name, health=service.health)
        except BaseException:
            await self.stop()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()

    def log_of(self, name: str) -> Path:
        return self.logs / f"{name}.log"

    async def _start(self, service: ServiceSpec) -> None:
        self.logs.mkdir(parents=True, exist_ok=True)
        command = [sys.executable if c == "python" else c for c in service.command]
        with self.log_of(service.name).open("wb") as output:
            try:
                process = await asyncio.create_subprocess_exec(
                    *command,
                    cwd=self.spec.root,
                    stdout=output,
                    stderr=asyncio.subprocess.STDOUT,
                    start_new_session=True,
                )
            except OSError as exc:
                raise FleetError(f"cannot start {service.name} ({command[0]}): {exc}") from exc
        self._processes[service.name] = process
        log.info("service_started", service=service.name, pid=process.pid)

    async def _wait_healthy(self, service: ServiceSpec) -> None:
        process = self._processes[service.name]
        deadline = time.monotonic() + self.health_timeout
        while True:
            if process.returncode is not None:
                raise FleetError(self._failure(service, f"exited with code {process.returncode}"))
            if await self._healthy(service.health):
                return
            if time.monotonic() > deadline:
                raise FleetError(
                    self._failure(
                        service, f"not healthy at {service.health} within {self.health_timeout:g} s"
                    )
                )
            await asyncio.sleep(0.2)

    async def _healthy(self, url: str) -> bool:
        if url.startswith(("grpc://", "grpcs://")):
            try:
                await probe(url, connect_timeout=0.5)
                return True
            except CouplerError:
                return False
        timeout = aiohttp.ClientTimeout(total=1.0)
        with contextlib.suppress(aiohttp.ClientError, TimeoutError):
            async with aiohttp.ClientSession(timeout=timeout) as session, session.get(url) as reply:
                return reply.status == 200
        return False

    def _failure(self, service: ServiceSpec, what: str) -> str:
        path = self.log_of(service.name)
        try:
            lines = path.read_text(errors="replace").splitlines()[-15:]
        except OSError:
            lines = ["(no log)"]
        return f"service '{service.name}' {what}; last lines of {path}:\n" + "\n".join(lines)

    async def stop(self, grace: float = 10.0) -> None:
        running = {n: p for n, p in self._processes.items() if p.returncode is None}
        for process in running.values():
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGTERM)
        for name, process in running.items():
            try:
                await asyncio.wait_for(process.wait(), grace)
            except TimeoutError:
                log.warning("service_killed", service=name, grace_s=grace)
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                await process.wait()
        if running:
            log.info("fleet_stopped", services=list(running))
        self._processes.clear()
