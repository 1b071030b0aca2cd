"""An FMU in a child process: ``IsolatedFmu`` runs the generic FMU host
(``python -m coupler.fmu.host FMU``) and talks to it over the protocol.

A segfault or a hang inside the FMU then is a participant fault — the run ends ``failed``
naming the FMU, the call and how the host died, every completed row kept — never a crash of
the orchestrator. The host serves on a unix socket in a private folder (mode 0700) and requires
a random bearer token, so no other process can drive it; it exits when its parent dies.

This process unpacks the FMU into that folder, within the run's one unpack budget, before the
host starts (a host that crashes or is killed leaves nothing of its own behind: ``close``
removes the folder); a host that ends before it serves fails ``open`` at once with its own last
words.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import secrets
import signal
import sys
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from coupler.archives import Budget, extracted, remove_scratch, scratch_folder
from coupler.channels import Description, RunSetup, Value
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError, ParticipantUnavailable, ScenarioError
from coupler.participant import Participant, Values
from coupler.security import ClientSecurity

START_TIMEOUT = 30.0
"""How long the host may take to load the FMU and serve [s]."""


class IsolatedFmu(Participant):
    """An FMU run by the generic FMU host in a child process; unpacked here within ``budget``."""

    def __init__(
        self,
        path: str | Path,
        *,
        name: str,
        call_timeout: float = 30.0,
        budget: Budget | None = None,
    ) -> None:
        self.path = Path(path)
        self.name = name
        self.call_timeout = call_timeout
        self.budget = budget
        self.model_description: Any = None
        """The FMU's modelDescription (FMPy's), read in this process for its unit definitions."""
        self._dir: Path | None = None
        self._process: asyncio.subprocess.Process | None = None
        self._remote: RemoteParticipant | None = None
        self._last_words: deque[str] = deque(maxlen=5)
        """The host's last lines on stderr (passed on to ours as they come)."""
        self._relay: asyncio.Task[None] | None = None

    async def open(self) -> None:
        if self._remote is not None:
            return
        if not self.path.is_file():
            raise ScenarioError(f"FMU not found: {self.path} (check the component's source)")
        import fmpy

        try:
            self.model_description = await asyncio.to_thread(
                fmpy.read_model_description, str(self.path), validate=False
            )
        except Exception as exc:  # FMPy raises plain exceptions for any broken FMU
            raise ScenarioError(f"{self.path}: not a readable FMU: {exc}") from exc
        self._dir = scratch_folder("coupler-fmuhost-")  # mode 0700
        unpacked = self._dir / "fmu"
        await extracted(self.path, unpacked, budget=self.budget)
        token = self._dir / "token"
        token.write_text(secrets.token_urlsafe(32))
        token.chmod(0o600)
        socket = self._dir / "host.sock"
        self._process = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "coupler.fmu.host",
            str(self.path),
            "--name",
            self.name,
            "--unpacked",
            str(unpacked),
            "--socket",
            str(socket),
            "--token-file",
            str(token),
            stdin=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
            start_new_session=True,  # the terminal's Ctrl-C is the orchestrator's to handle
        )
        self._relay = asyncio.create_task(self._relay_stderr(self._process))
        self._remote = RemoteParticipant(
            f"unix://{socket}",
            name=self.name,
            connect_timeout=START_TIMEOUT,
            call_timeout=self.call_timeout,
            security=ClientSecurity(token_file=token),
        )
        await self._started(self._remote.open())

    async def _started(self, opening: Any) -> None:
        """``opening`` (the host's first Describe), or at once the reason the host ended
        before it served (not the connection's 30 s timeout)."""
        assert self._process is not None
        opened = asyncio.ensure_future(self._call("open", opening))
        ended = asyncio.ensure_future(self._process.wait())
        try:
            await asyncio.wait({opened, ended}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            ended.cancel()
        if opened.done() or not ended.done():
            await opened
            return
        opened.cancel()
        with contextlib.suppress(BaseException):
            await opened
        if self._relay is not None:  # its last words are on the way
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(self._relay), 1.0)
        said = self._last_words[-1] if self._last_words else "nothing on stderr"
        raise ParticipantUnavailable(
            f"the FMU host process {await self._death()} before serving {self.path.name}: "
            f"{said.removeprefix('coupler.fmu.host: ')}",
            participant=self.name,
            call="open",
            status="UNAVAILABLE",
        )

    async def _relay_stderr(self, process: asyncio.subprocess.Process) -> None:
        """Pass the host's stderr on to ours, line by line, keeping the last lines."""
        assert process.stderr is not None
        while line := await process.stderr.readline():
            text = line.decode(errors="replace")
            self._last_words.append(text.strip())
            sys.stderr.write(text)
            sys.stderr.flush()

    async def describe(self) -> Description:
        await self.open()
        return await self._call("describe", self._live().describe())

    async def initialize(self, setup: RunSetup) -> Values:
        return await self._call("Initialize", self._live().initialize(setup))

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return await self._call(f"DoStep at t={time:g}", self._live().do_step(time, step, inputs))

    async def terminate(self, reason: str = "") -> None:
        if self._process is not None and self._process.returncode is None:
            await self._call("Terminate", self._live().terminate(reason))

    async def close(self) -> None:
        remote, self._remote = self._remote, None
        if remote is not None:
            await remote.close()
        process, self._process = self._process, None
        if process is not None and process.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                process.terminate()
            try:
                await asyncio.wait_for(process.wait(), 2.0)
            except TimeoutError:  # a host stuck in the FMU does not answer SIGTERM
                with contextlib.suppress(ProcessLookupError):
                    process.kill()
                await process.wait()
        if self._relay is not None:
            self._relay.cancel()
            self._relay = None
        if self._dir is not None:
            remove_scratch(self._dir)
            self._dir = None

    def _live(self) -> RemoteParticipant:
        if self._remote is None:
            raise ParticipantError("FMU host not started", participant=self.name, call="call")
        return self._remote

    async def _call(self, call: str, pending: Any) -> Any:
        """``pending``'s result; a failure caused by the host's death says how it died."""
        try:
            return await pending
        except ParticipantError as exc:
            died = await self._death()
            if died is None:
                raise
            raise ParticipantUnavailable(
                f"the FMU host process {died} during {call} ({self.path.name} runs isolated; "
                "the FMU itself crashed)",
                participant=self.name,
                call=call.split()[0],
                status=exc.status,
            ) from exc

    async def _death(self) -> str | None:
        """How the host process ended, if it did (it gets a moment to be reaped)."""
        process = self._process
        if process is None:
            return None
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(process.wait(), 0.5)
        code = process.returncode
        if code is None:
            return None
        if code < 0:
            return f"was killed by {signal.Signals(-code).name}"
        return f"exited with code {code}"


def parent_alive(parent: int) -> bool:
    """Whether the process that started this one still runs (the host watches it)."""
    return os.getppid() == parent
