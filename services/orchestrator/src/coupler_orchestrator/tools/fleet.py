"""A scenario's fleet as local processes: each service its own process, on this host.

A fleet file (TOML; every key in docs/fleet.md, ``SCENARIO_KEYS`` and ``SERVICE_KEYS``) names the
scenario and the services::

    [scenario]
    ssp = "scenarios/railway/SystemStructure.ssd"
    out = "results/railway"           # each run: a new folder in it (default results/<scenario>)
    args = ["--realtime-factor", "20"]       # extra `coupler run` options
    # unix_sockets = false                   # keep the participants on TCP (coupler fleet --tcp)

    [[service]]
    name = "openrails-mock"
    command = ["python", "-m", "openrails_mock", "--port", "${MOCK_PORT:-2150}"]
    health = "http://127.0.0.1:${MOCK_PORT:-2150}/API/READY"   # or grpc(s)://HOST:PORT
    # ports = [2150]    # default: the health URL's port and every --*port option's value
    # socket = false    # a grpc:// participant stays on TCP although the fleet uses sockets

    [urls]
    map = "http://127.0.0.1:${MAP_HTTP_PORT:-8080}/"

Commands, health and URLs expand ``${VAR}`` / ``${VAR:-default}`` as SSD sources do (names
ending in ``_PORT``, ``_HOST``, ...), so the same variables move a fleet and its SSD.

``coupler fleet`` has the participants talk over unix sockets (``Fleet(sockets=True)``): a
service whose health is
``grpc://HOST:PORT`` is started with ``--socket PATH`` added to its command (a socket in a
private folder of this fleet, mode 0700, removed when it stops), so it serves there instead of
on its TCP port; its health is checked there, and the run is told to reach the SSD's
``grpc://HOST:PORT`` at ``unix:///PATH`` instead (``Fleet.addresses``). The results are the
same bytes either way; ``unix_sockets = false`` (``coupler fleet --tcp``) keeps TCP, and
``grpcs://`` services (TLS: another host's business) always do.

``Fleet`` first checks that every port it needs is free (naming the process that holds one)
and that no other fleet writes the same results directory; then it starts the services (logs
in a folder of their own under ``build/logs/``), waits for their health and stops them all on
the way out (SIGTERM, then SIGKILL after a grace period), also when something fails.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import time
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import IO, Any
from urllib.parse import urlsplit

import aiohttp
import structlog

from coupler.errors import CouplerError, ScenarioError
from coupler.health import probe
from coupler.ports import holders_of, port_is_free
from coupler_orchestrator.outputs.files import default_base
from coupler_orchestrator.ssp.expansion import expand, variables_in

log = structlog.get_logger("coupler.fleet")

_PORT_OPTION = re.compile(r"^--[a-z-]*port$")
_VARIABLE = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-[^}]*)?\}")


SCENARIO_KEYS = ("ssp", "out", "args", "unix_sockets")
"""The keys of a fleet file's ``[scenario]`` (docs/fleet.md); another is refused, naming it."""
SERVICE_KEYS = ("name", "command", "health", "ports", "socket")
"""The keys of a ``[[service]]``."""
TABLES = ("scenario", "service", "urls")
"""A fleet file's tables."""


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
    ports: tuple[int, ...] = ()
    """TCP ports the service listens on, checked free before anything starts; default: the
    health URL's port and the value of every ``--*port`` option of the command."""
    port_variables: Mapping[int, str] = field(default_factory=dict)
    """The environment variable each port came from (``MOCK_PORT``), for messages."""
    socket: bool = True
    """Whether the service may serve on a unix socket (``--socket PATH``) when the fleet uses
    them; false keeps it on TCP (a command without ``--socket``)."""

    def needed_ports(self) -> tuple[int, ...]:
        """The ports this service will listen on."""
        if self.ports:
            return self.ports
        found: list[int] = []
        port = urlsplit(self.health).port
        if port:
            found.append(port)
        for option, value in zip(self.command, self.command[1:], strict=False):
            if _PORT_OPTION.match(option) and value.isdigit() and int(value) > 0:
                found.append(int(value))
        return tuple(dict.fromkeys(found))


@dataclass(frozen=True, kw_only=True)
class FleetSpec:
    """A fleet file, with paths resolved against ``root``."""

    root: Path
    """Directory the commands run in and paths are relative to."""
    ssp: Path
    """The scenario."""
    out: Path
    """Results base folder: each run writes a new folder in it (``outputs.files``)."""
    run_args: tuple[str, ...] = ()
    """Extra ``coupler run`` options."""
    services: tuple[ServiceSpec, ...] = ()
    """Started in order."""
    urls: dict[str, str] = field(default_factory=dict)
    """Printed before the run (e.g. the map)."""
    unix_sockets: bool = True
    """Serve the ``grpc://`` participants on unix sockets (false: on their TCP ports)."""
    source: Path | None = None
    """The fleet file, when loaded from one."""

    @classmethod
    def load(
        cls, path: Path, *, root: Path | None = None, env: Mapping[str, str] | None = None
    ) -> FleetSpec:
        """Read a fleet file; ``${VAR:-default}`` from ``env`` (default: the environment)."""
        env = os.environ if env is None else env
        try:
            text = path.read_text(encoding="utf-8")
            data = tomllib.loads(text)
            _refuse_unknown(path, text, data)
            scenario = data["scenario"]
            root = root or Path.cwd()
            ssp = root / scenario["ssp"]
            return cls(
                root=root,
                ssp=ssp,
                out=root / scenario["out"] if "out" in scenario else root / default_base(ssp),
                run_args=tuple(
                    expand(str(a), env, what=f"{path} [scenario] args")
                    for a in scenario.get("args", ())
                ),
                services=tuple(_service(path, s, env) for s in data.get("service", ())),
                urls={
                    k: expand(v, env, what=f"{path} [urls] {k}")
                    for k, v in data.get("urls", {}).items()
                },
                unix_sockets=_flag(scenario, "unix_sockets"),
                source=path,
            )
        except OSError as exc:
            raise ScenarioError(f"cannot read fleet file {path}: {exc.strerror}") from exc
        except (tomllib.TOMLDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ScenarioError(
                f"{path}: not a fleet file ({type(exc).__name__}: {exc}); see docs/fleet.md for "
                f"the format"
            ) from exc


def _refuse_unknown(path: Path, text: str, data: Mapping[str, Any]) -> None:
    """ScenarioError naming the first table or key a fleet file may not have (a typo such as
    ``unix_socket`` would otherwise be ignored), with its line."""
    known: list[tuple[str, Mapping[str, Any], tuple[str, ...]]] = [("", data, TABLES)]
    if isinstance(data.get("scenario"), Mapping):
        known.append(("[scenario]", data["scenario"], SCENARIO_KEYS))
    services = data.get("service", ())
    if isinstance(services, list):
        known += [("[[service]]", s, SERVICE_KEYS) for s in services if isinstance(s, Mapping)]
    for where, table, keys in known:
        for key in table:
            if key in keys:
                continue
            if not where:
                raise ScenarioError(
                    f"{path} line {_line_of(text, key)}: unknown table [{key}]; a fleet file "
                    f"has [scenario], [[service]] and [urls] (docs/fleet.md)"
                )
            raise ScenarioError(
                f"{path} line {_line_of(text, key)}: unknown key '{key}' in {where}; its keys "
                f"are {', '.join(keys)} (docs/fleet.md)"
            )


def _line_of(text: str, key: str) -> int:
    """The first line of ``text`` that sets ``key`` or opens a table of that name (1 if none)."""
    pattern = re.compile(rf"^\s*(\[+\s*{re.escape(key)}\s*\]+|\"?{re.escape(key)}\"?\s*=)")
    for number, line in enumerate(text.splitlines(), 1):
        if pattern.match(line):
            return number
    return 1


def _service(path: Path, raw: Mapping[str, Any], env: Mapping[str, str]) -> ServiceSpec:
    what = f"{path} service '{raw['name']}'"
    command = tuple(expand(str(c), env, what=what) for c in raw["command"])
    health = expand(raw["health"], env, what=what)
    if not _health_url(health):
        used = variables_in(raw["health"])
        given = f" (with {', '.join(used)} from the environment)" if used else ""
        raise ScenarioError(
            f"{what}: health '{raw['health']}'{given} is not grpc://HOST:PORT, grpcs://HOST:PORT, "
            "unix:///PATH or an http URL; fix it" + (" or the variables" if used else "")
        )
    variables: dict[int, str] = {}
    for text, value in [*zip(raw["command"], command, strict=True), (raw["health"], health)]:
        for match in _VARIABLE.finditer(str(text)):
            if match.group(1).endswith("_PORT"):
                with contextlib.suppress(ValueError):
                    port = int(value) if value.isdigit() else urlsplit(value).port
                    if port:
                        variables.setdefault(port, match.group(1))
    return ServiceSpec(
        name=raw["name"],
        command=command,
        health=health,
        ports=tuple(int(p) for p in raw.get("ports", ())),
        port_variables=variables,
        socket=_flag(raw, "socket"),
    )


def _health_url(text: str) -> bool:
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        return False
    if parts.scheme in ("http", "https"):
        return bool(parts.hostname)
    if parts.scheme == "unix":
        return not parts.netloc and parts.path.startswith("/")
    return parts.scheme in ("grpc", "grpcs") and bool(parts.hostname) and port is not None


def _flag(table: Mapping[str, Any], key: str) -> bool:
    value = table.get(key, True)
    if not isinstance(value, bool):
        raise TypeError(f"{key} = {value!r} must be true or false")
    return value


def port_variables(path: Path) -> tuple[str, ...]:
    """The ``${NAME_PORT}`` variables a fleet file uses, in order of appearance: setting each
    to a free port moves the whole fleet (and an SSD reading the same variables)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"cannot read fleet file {path}: {exc.strerror}") from exc
    names = (m.group(1) for m in _VARIABLE.finditer(text))
    return tuple(dict.fromkeys(n for n in names if n.endswith("_PORT")))


_handed_out: set[int] = set()


def free_port() -> int:
    """A TCP port free on every address now, never the same twice in this process (two runs
    started at once get different ports; another process may still take it, which the fleet's
    port check then reports)."""
    while True:
        with socket.socket() as probe_socket:
            probe_socket.bind(("", 0))
            port = int(probe_socket.getsockname()[1])
        if port not in _handed_out and port_is_free(port):
            _handed_out.add(port)
            return port


class Fleet:
    """Checks ports and results directory, starts the services on enter (healthy or
    FleetError), stops them all on exit."""

    def __init__(
        self,
        spec: FleetSpec,
        *,
        health_timeout: float = 60.0,
        logs: Path | None = None,
        sockets: bool = False,
        die_with_parent: bool = False,
    ) -> None:
        self.spec = spec
        self.die_with_parent = die_with_parent
        """Each service gets SIGTERM when the thread that started it ends (Linux; a campaign
        worker's kept services, which must not outlive a worker that is killed)."""
        self.use_sockets = sockets
        """Serve the ``grpc://`` participants on unix sockets (``coupler fleet`` asks for it
        unless ``--tcp`` or the fleet file's ``unix_sockets = false``); off for callers that
        reach the services by their TCP addresses (a separate ``coupler run``, other hosts)."""
        self.health_timeout = health_timeout
        self.logs = logs or spec.root / "build" / "logs"
        """This fleet's own log folder (``<logs>/fleet-<UTC time>-<random>/`` once entered,
        ``logs`` defaulting to the project's ``build/logs``): no other fleet writes there."""
        self._processes: dict[str, asyncio.subprocess.Process] = {}
        self._lock: IO[str] | None = None
        self.sockets: Path | None = None
        """The private folder (mode 0700) of the participants' unix sockets, while up."""
        self.addresses: dict[str, str] = {}
        """The SSD's address of each participant on a socket -> ``unix:///PATH`` (the run's
        ``RunOptions.addresses``)."""

    def on_socket(self, service: ServiceSpec) -> bool:
        """Whether ``service`` serves on a unix socket in this fleet."""
        return (
            self.use_sockets
            and self.spec.unix_sockets
            and service.socket
            and service.health.startswith("grpc://")
        )

    async def __aenter__(self) -> Fleet:
        self.check_ports()
        self._lock_results()
        try:
            self.logs.mkdir(parents=True, exist_ok=True)
            stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
            self.logs = Path(tempfile.mkdtemp(prefix=f"fleet-{stamp}-", dir=self.logs))
            if any(map(self.on_socket, self.spec.services)):
                self.sockets = Path(tempfile.mkdtemp(prefix="coupler-fleet-", dir=_socket_base()))
            for service in self.spec.services:
                await self._start(service)
            for service in self.spec.services:
                await self._wait_healthy(service)
                log.info("service_healthy", service=service.name, health=self.health_of(service))
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

    def running(self) -> bool:
        """Whether the fleet is up and every one of its services still runs."""
        return bool(self._processes) and all(p.returncode is None for p in self._processes.values())

    def check_ports(self) -> None:
        """FleetError naming every port that is taken and the process holding it, before
        anything starts (a service that cannot bind would otherwise look healthy through
        the process already there)."""
        taken = []
        for service in self.spec.services:
            for port in self.ports_of(service):
                if port_is_free(port):
                    continue
                holders = holders_of(port)
                by = (
                    ", ".join(f"pid {h.pid} ({_short(h.command)})" for h in holders)
                    if holders
                    else "a process this user cannot see"
                )
                variable = service.port_variables.get(port)
                move = f"; or move this fleet with {variable}=<free port>" if variable else ""
                taken.append(f"port {port} ({service.name}) is in use by {by}{move}")
        if taken:
            raise FleetError(
                "cannot start the fleet: "
                + "; ".join(taken)
                + ". Another fleet (make demo?) is probably running: stop it first (Ctrl-C in "
                "its terminal, or kill the pid)"
            )

    def ports_of(self, service: ServiceSpec) -> tuple[int, ...]:
        """The TCP ports ``service`` will listen on: its gRPC port not, on a socket."""
        ports = service.needed_ports()
        if self.on_socket(service):
            ports = tuple(p for p in ports if p != urlsplit(service.health).port)
        return ports

    def health_of(self, service: ServiceSpec) -> str:
        """Where the service's health is checked: its socket's address, on one."""
        return self.addresses.get(service.health, service.health)

    def _lock_results(self) -> None:
        """Hold ``out/.fleet.lock`` while the fleet lives, so two fleets never write one
        results directory; the lock goes with the process, however it ends, and the file with
        the fleet when it stops (``stop``). A lock taken on a file that its owner removed
        meanwhile is no lock: then the file is opened again."""
        self.spec.out.mkdir(parents=True, exist_ok=True)
        path = self.spec.out / ".fleet.lock"
        while True:
            lock = path.open("a+", encoding="utf-8")
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                lock.seek(0)
                owner = lock.read().strip() or "another process"
                lock.close()
                raise FleetError(
                    f"{self.spec.out} is being written by another fleet ({owner}); stop it, or "
                    f"give this one its own results directory with --out"
                ) from None
            with contextlib.suppress(OSError):
                if os.stat(path).st_ino == os.fstat(lock.fileno()).st_ino:
                    break
            lock.close()
        lock.truncate(0)
        lock.write(f"pid {os.getpid()}\n")
        lock.flush()
        self._lock = lock

    async def _start(self, service: ServiceSpec) -> None:
        command = [sys.executable if c == "python" else c for c in service.command]
        if self.sockets is not None and self.on_socket(service):
            path = self.sockets / f"{service.name}.sock"
            command += ["--socket", str(path)]
            self.addresses[service.health] = f"unix://{path}"
        with self.log_of(service.name).open("xb") as output:
            try:
                process = await asyncio.create_subprocess_exec(
                    *command,
                    cwd=self.spec.root,
                    stdout=output,
                    stderr=asyncio.subprocess.STDOUT,
                    start_new_session=True,
                    preexec_fn=_die_with_parent if self.die_with_parent else None,
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
            if await self._healthy(self.health_of(service)):
                return
            if time.monotonic() > deadline:
                raise FleetError(
                    self._failure(
                        service,
                        f"not healthy at {self.health_of(service)} within "
                        f"{self.health_timeout:g} s",
                    )
                )
            await asyncio.sleep(0.2)

    async def _healthy(self, url: str) -> bool:
        if url.startswith(("grpc://", "grpcs://", "unix://")):
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
        if self.on_socket(service):  # a program of the user's may not know --socket
            what += (
                " (started with --socket PATH, to serve on a unix socket: a program without that "
                "option needs socket = false in its [[service]], or run coupler fleet --tcp)"
            )
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
        if self.sockets is not None:
            shutil.rmtree(self.sockets, ignore_errors=True)
            self.sockets = None
            self.addresses.clear()
        if self._lock is not None:
            with contextlib.suppress(OSError):  # removed while held: no one else holds it
                os.unlink(self._lock.name)
            self._lock.close()
            self._lock = None


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the thread that forked it ends (prctl
    PR_SET_PDEATHSIG)."""
    if sys.platform == "linux":
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)


def _socket_base() -> str:
    """Where the sockets' folder goes: the temp folder, unless its path leaves too little of
    a socket address's 107 bytes for the sockets' names."""
    base = tempfile.gettempdir()
    return base if len(os.fsencode(base)) <= 60 else "/tmp"


def _short(command: str, limit: int = 80) -> str:
    return command if len(command) <= limit else command[: limit - 3] + "..."
