"""How the participant reaches a mosaik simulator: in its process or over mosaik's TCP protocol.

``SimulatorLink`` is the seam (mosaik's own ``LocalProxy`` / ``RemoteProxy``): ``call`` one of
the simulator's methods, ``close``. Which link a participant gets is chosen once, by the
starter table ``STARTERS`` (mosaik's ``python``, ``cmd`` and ``connect``):

- ``python``: the class is imported and instantiated here; its methods run on the
  participant's event loop (generator-style steps that ask mosaik for something included).
- ``cmd``: the participant listens on loopback (port 0), starts the command with ``%(addr)s``
  replaced, and speaks mosaik's protocol (4-byte length + JSON ``[type, id, content]``) with the
  process once it has connected (``mosaik_api_v3.connection.Channel``).
- ``connect``: the same protocol to a simulator already listening (``--remote``).

A simulator may ask mosaik for things while it steps; the participant answers
``get_progress`` (the run's share done, in percent) and refuses the others by name (Coupler has
no entity graph to share, and no way to set another participant's data).

Foreign errors are translated here and nowhere else: a simulator's exception (in process, or
a mosaik ``RemoteException``) becomes a ``ParticipantError`` naming the simulator, the method
and its message; a process that has gone away becomes ``ParticipantUnavailable``.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import shlex
import subprocess
import sys
from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable
from typing import Any

from mosaik_api_v3 import MosaikProxy, get_wrapper
from mosaik_api_v3.connection import Channel, RemoteException

from coupler.errors import ParticipantError, ParticipantUnavailable, ScenarioError
from coupler_mosaik.config import SimulatorConfig

Progress = Callable[[], float]
"""The run's share done, in percent (mosaik's ``get_progress``)."""


class SimulatorLink(ABC):
    """One mosaik simulator, reached somehow."""

    name: str
    """The simulator's name in messages (the participant's)."""

    @abstractmethod
    async def call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        """The simulator's ``method(*args, **kwargs)``; ParticipantError when it fails."""

    @abstractmethod
    async def close(self) -> None:
        """End the simulator (``finalize`` / mosaik's ``stop``) and release it."""

    def _failed(self, method: str, message: str) -> ParticipantError:
        return ParticipantError(
            f"the mosaik simulator failed in {method}(): {message}",
            participant=self.name,
            call=method,
        )


class _Refusing(MosaikProxy):
    """What an in-process simulator's ``self.mosaik`` answers."""

    def __init__(self, progress: Progress) -> None:
        self._progress = progress

    async def get_progress(self) -> float:
        return self._progress()

    async def get_related_entities(self, entities: Any = None) -> Any:
        raise RuntimeError(refusal("get_related_entities"))

    async def get_data(self, attrs: Any) -> Any:
        raise RuntimeError(refusal("get_data"))

    async def set_data(self, data: Any) -> None:
        raise RuntimeError(refusal("set_data"))

    async def set_event(self, event_time: Any) -> None:
        raise RuntimeError(refusal("set_event"))


def refusal(method: str) -> str:
    """Why a request of the simulator to mosaik is not served."""
    return (
        f"mosaik.{method}() is not available to a simulator run as a Coupler participant: "
        "Coupler has no mosaik entity graph; exchange values through channels"
    )


class InProcessLink(SimulatorLink):
    """A simulator object in this process."""

    def __init__(self, name: str, simulator: Any, progress: Progress) -> None:
        self.name = name
        self.simulator = simulator
        simulator.mosaik = _Refusing(progress)
        self._methods: dict[str, Callable[..., Awaitable[Any]]] = {}

    async def call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        wrapped = self._methods.get(method)
        if wrapped is None:
            wrapped = self._methods[method] = get_wrapper(getattr(self.simulator, method))
        try:
            return await wrapped(*args, **kwargs)
        except Exception as exc:  # the simulator's own code: anything
            raise self._failed(method, f"{type(exc).__name__}: {exc}") from exc

    async def close(self) -> None:
        with contextlib.suppress(Exception):
            await get_wrapper(self.simulator.finalize)()


class TcpLink(SimulatorLink):
    """mosaik's protocol over one TCP connection (and the process behind it, when started)."""

    def __init__(
        self,
        name: str,
        channel: Channel,
        progress: Progress,
        process: subprocess.Popen[bytes] | None = None,
    ) -> None:
        self.name = name
        self.channel = channel
        self.process = process
        self._progress = progress
        self._answering = asyncio.get_running_loop().create_task(self._answer())

    async def call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        try:
            return await self.channel.send([method, list(args), kwargs])
        except RemoteException as exc:
            raise self._failed(method, f"{exc.remote_type}: {exc.remote_msg}") from exc
        except (asyncio.IncompleteReadError, ConnectionError) as exc:
            raise ParticipantUnavailable(
                f"the mosaik simulator's connection ended during {method}(){self._exit()}",
                participant=self.name,
                call=method,
                status="UNAVAILABLE",
            ) from exc

    async def _answer(self) -> None:
        """Answer what the simulator asks mosaik while it steps."""
        while True:
            try:
                request = await self.channel.next_request()
            except Exception:  # the connection ended: calls report it
                return
            method = request.content[0] if request.content else "?"
            if method == "get_progress":
                await request.set_result(self._progress())
            else:
                await request.set_exception(RuntimeError(refusal(method)))

    def _exit(self) -> str:
        if self.process is None:
            return ""
        code = self.process.poll()
        return f" (its process ended with exit code {code})" if code is not None else ""

    async def close(self) -> None:
        with contextlib.suppress(Exception):  # mosaik's stop has no answer
            self.channel._writer.write(_stop())
            await self.channel._writer.drain()
        with contextlib.suppress(Exception):
            await self.channel.close()
        self._answering.cancel()
        if self.process is not None:
            await asyncio.to_thread(_end, self.process)


def _stop() -> bytes:
    from mosaik_api_v3.connection import REQUEST, encode

    return encode([REQUEST, 0x7FFFFFFF, ["stop", [], {}]])


def _end(process: subprocess.Popen[bytes], grace: float = 5.0) -> None:
    """Wait for the simulator's process to leave after stop; end it when it does not."""
    try:
        process.wait(grace)
    except subprocess.TimeoutExpired:
        process.terminate()
        try:
            process.wait(grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


# -- starters (mosaik's table: python, cmd, connect) ------------------------------------------


async def start_in_process(name: str, config: SimulatorConfig, progress: Progress) -> SimulatorLink:
    module_name, _, class_name = config.python.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as exc:
        raise ScenarioError(
            f"{name}: cannot import the mosaik simulator {config.python!r} ({exc}); is its "
            "package installed in this environment?"
        ) from exc
    return InProcessLink(name, cls(), progress)


async def start_command(name: str, config: SimulatorConfig, progress: Progress) -> SimulatorLink:
    connected: asyncio.Future[Channel] = asyncio.get_running_loop().create_future()

    def on_connect(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if not connected.done():
            connected.set_result(Channel(reader, writer, name=name))
        else:
            writer.close()

    server = await asyncio.start_server(on_connect, "127.0.0.1", 0)
    try:
        host, port = server.sockets[0].getsockname()[:2]
        command = config.cmd % {"addr": f"{host}:{port}", "python": sys.executable}
        try:
            process = subprocess.Popen(shlex.split(command))  # noqa: ASYNC220 - returns at once
        except OSError as exc:
            raise ScenarioError(f"{name}: cannot start {command!r}: {exc.strerror}") from exc
        try:
            channel = await _connected(connected, process, config.start_timeout)
        except BaseException:
            await asyncio.to_thread(_end, process, 0.0)
            raise
    except ParticipantUnavailable as exc:
        raise ParticipantUnavailable(
            f"{command!r} {exc.detail}", participant=name, call="start", status="UNAVAILABLE"
        ) from None
    finally:
        server.close()
    return TcpLink(name, channel, progress, process)


async def _connected(
    connected: asyncio.Future[Channel], process: subprocess.Popen[bytes], within: float
) -> Channel:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + within
    while not connected.done():
        code = process.poll()
        if code is not None:
            raise ParticipantUnavailable(
                f"ended (exit code {code}) before it connected", participant="", call="start"
            )
        if loop.time() > deadline:
            raise ParticipantUnavailable(
                f"did not connect within {within:g} s", participant="", call="start"
            )
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(asyncio.shield(connected), 0.05)
    return connected.result()


async def connect_to(name: str, config: SimulatorConfig, progress: Progress) -> SimulatorLink:
    host, _, port = config.connect.rpartition(":")
    try:
        reader, writer = await asyncio.wait_for(
            asyncio.open_connection(host, int(port)), config.start_timeout
        )
    except (OSError, ValueError, TimeoutError) as exc:
        raise ParticipantUnavailable(
            f"cannot reach the mosaik simulator at {config.connect} ({exc}); is it running "
            "with --remote on that address?",
            participant=name,
            call="connect",
            status="UNAVAILABLE",
        ) from exc
    return TcpLink(name, Channel(reader, writer, name=name), progress)


STARTERS = {"python": start_in_process, "cmd": start_command, "connect": connect_to}
"""mosaik's starters by the key that selects them in the simulator's configuration."""


async def start(name: str, config: SimulatorConfig, progress: Progress) -> SimulatorLink:
    """The link the configuration asks for."""
    kind = next(k for k in STARTERS if getattr(config, k))
    return await STARTERS[kind](name, config, progress)
