"""Helpers for testing participants (and the project's own tests): real servers, real processes.

- ``served(participant)``: the participant on a real gRPC server on a free port of this event
  loop, stopped on the way out; ``served_in_thread(participant)`` does the same for
  synchronous code, with an event loop in a thread of its own.
- ``wait_until_serving(address)``: returns once a participant (a process started elsewhere)
  answers SERVING on its health service.
- ``wait_until(condition)`` / ``eventually(attempt)``: poll until something holds, then give
  what it gave; past the deadline, an error saying what was waited for.
- ``free_port()``: a port nothing listens on now (for programs that must be given one);
  ``free_ports(n)``: n different ones.
- ``process_group(command)``: a process in a process group of its own, ended on every path out
  (passed, failed, timed out, interrupted) with everything it started, and waited for.
- ``SystemStructure`` with ``fmu(...)`` and ``remote(...)`` components: a small SSD written for
  ``coupler run`` (``coupler.testing.ssd``).
- ``run_coupler(*argv)``: the ``coupler`` command as a process of its own; ``recorded(out)`` and
  ``summary(out)``: what the run wrote (``coupler.testing.cli``).

No pytest needed: these are context managers and functions a test of any framework can use.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import subprocess
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

from coupler.errors import CouplerError
from coupler.participant import Participant
from coupler.server import ParticipantServer
from coupler.testing.cli import recorded, run_coupler, summary
from coupler.testing.ssd import (
    Annotation,
    Binding,
    Component,
    Connection,
    Connector,
    SystemStructure,
    fmu,
    remote,
)

if TYPE_CHECKING:
    from coupler.security import ClientSecurity

T = TypeVar("T")

__all__ = [
    "Annotation",
    "Binding",
    "Component",
    "Connection",
    "Connector",
    "SystemStructure",
    "end_group",
    "eventually",
    "fmu",
    "free_port",
    "free_ports",
    "process_group",
    "recorded",
    "remote",
    "run_coupler",
    "served",
    "served_in_thread",
    "summary",
    "wait_until",
    "wait_until_serving",
]


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on at this moment (another process may take it before it is
    used: prefer port 0 where the program reports the port it bound)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


def free_ports(count: int, host: str = "127.0.0.1") -> list[int]:
    """``count`` different ports nothing listens on at this moment (held together while they
    are chosen, so no two are the same; the caveat of ``free_port`` holds)."""
    with contextlib.ExitStack() as stack:
        probes = [
            stack.enter_context(socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET))
            for _ in range(count)
        ]
        for probe in probes:
            probe.bind((host, 0))
        return [int(probe.getsockname()[1]) for probe in probes]


@contextlib.asynccontextmanager
async def served(participant: Participant, **options: Any) -> AsyncIterator[ParticipantServer]:
    """``participant`` on a real gRPC server of this event loop, on a free port (``options``:
    those of ``ParticipantServer``, e.g. ``security``); stopped on the way out."""
    server = ParticipantServer(participant, **{"port": 0, **options})
    await server.start()
    try:
        yield server
    finally:
        await server.stop(grace=0.1)


@contextlib.contextmanager
def served_in_thread(participant: Participant, **options: Any) -> Iterator[ParticipantServer]:
    """``served`` for synchronous code: the server runs on an event loop in a thread of its own
    until the block ends (then it is stopped and the thread joined)."""
    ready = threading.Event()
    started: list[ParticipantServer] = []
    failed: list[BaseException] = []
    stop: list[asyncio.Event] = []
    loop_of: list[asyncio.AbstractEventLoop] = []

    async def main() -> None:
        stop.append(asyncio.Event())
        loop_of.append(asyncio.get_running_loop())
        try:
            async with served(participant, **options) as server:
                started.append(server)
                ready.set()
                await stop[0].wait()
        except BaseException as exc:
            failed.append(exc)
            raise
        finally:
            ready.set()

    def run() -> None:
        with contextlib.suppress(BaseException):  # kept in ``failed``; raised below
            asyncio.run(main())

    thread = threading.Thread(target=run, name="coupler-testing-server", daemon=True)
    thread.start()
    ready.wait()
    try:
        if failed or not started:
            reason = failed[0] if failed else "the server did not start"
            raise CouplerError(f"the participant could not be served: {reason}")
        yield started[0]
    finally:
        if loop_of and stop:
            with contextlib.suppress(RuntimeError):  # the loop has ended already
                loop_of[0].call_soon_threadsafe(stop[0].set)
        thread.join(timeout=30)


async def wait_until_serving(
    address: str, within: float = 30.0, *, security: ClientSecurity | None = None
) -> None:
    """Return once the participant at ``address`` answers SERVING and describes itself;
    ParticipantUnavailable (naming the address and why) when it has not ``within`` seconds.
    ``grpcs://``: ``security``, else the ``COUPLER_TLS_*`` environment."""
    from coupler.client import RemoteParticipant
    from coupler.security import ClientSecurity

    remote = RemoteParticipant(
        address, connect_timeout=within, security=security or ClientSecurity.from_environment()
    )
    try:
        await remote.open()
    finally:
        await remote.close()


def wait_until(
    condition: Callable[[], T], within: float = 30.0, *, interval: float = 0.05, what: str = ""
) -> T:
    """``condition()`` once it is true (anything but None, False, 0 or empty), polled every
    ``interval`` seconds; TimeoutError saying ``what`` was awaited after ``within`` seconds."""
    deadline = time.monotonic() + within
    while True:
        found = condition()
        if found:
            return found
        if time.monotonic() > deadline:
            raise TimeoutError(f"not within {within:g} s: {what or condition!r}")
        time.sleep(interval)


async def eventually(
    attempt: Callable[[], Awaitable[T]],
    within: float = 5.0,
    *,
    interval: float = 0.05,
    retry: type[BaseException] | tuple[type[BaseException], ...] = AssertionError,
) -> T:
    """``await attempt()``'s result once it stops raising ``retry``; its last error after
    ``within`` seconds."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + within
    while True:
        try:
            return await attempt()
        except retry:
            if loop.time() > deadline:
                raise
            await asyncio.sleep(interval)


@contextlib.contextmanager
def process_group(
    command: Sequence[str], *, grace: float = 5.0, **popen: Any
) -> Iterator[subprocess.Popen[Any]]:
    """``command`` started in a session (and process group) of its own; on every way out of the
    block — it ended, the test failed, a timeout or Ctrl-C interrupted it — the whole group
    (its children and theirs too) gets SIGTERM, after ``grace`` seconds SIGKILL, and the
    process is waited for, its pipes closed. ``popen``: ``subprocess.Popen``'s options."""
    process = subprocess.Popen(list(command), start_new_session=True, **popen)
    try:
        yield process
    finally:
        end_group(process, grace=grace)


def end_group(process: subprocess.Popen[Any], *, grace: float = 5.0, close: bool = True) -> None:
    """End ``process``'s process group (SIGTERM, then SIGKILL after ``grace`` s) and reap it;
    ``close``: its pipes too (not while threads of the caller still read them). What it had
    started in sessions of their own (as ``coupler fleet`` starts its services) and what is
    still running once the group has gone gets SIGKILL too (where /proc lists children)."""
    group = process.pid  # a session leader's group id is its pid
    started = _descendants(process.pid)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(group, signal.SIGTERM)
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.wait(grace)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(group, signal.SIGKILL)  # whatever is left of the group, grandchildren too
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.wait(10)
    for pid in started:  # left the group (a session of its own) and outlived its parent
        if _running(pid):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
    for stream in (process.stdin, process.stdout, process.stderr):
        if close and stream is not None:
            with contextlib.suppress(OSError):
                stream.close()


def _descendants(pid: int) -> list[int]:
    """The processes below ``pid`` now, as /proc lists them (none without /proc)."""
    found: list[int] = []
    todo = [pid]
    while todo:
        parent = todo.pop()
        with contextlib.suppress(OSError):
            for task in os.listdir(f"/proc/{parent}/task"):
                with contextlib.suppress(OSError, ValueError):
                    with open(f"/proc/{parent}/task/{task}/children") as children:
                        below = [int(child) for child in children.read().split()]
                    found += below
                    todo += below
    return found


def _running(pid: int) -> bool:
    """Whether ``pid`` runs (ended and waiting for its parent counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        return False
