"""Ctrl-C and SIGTERM: the first one cancels the command, so a run ends ``aborted`` with its
summary written and every service stopped; and the last resort when the event loop's thread is
stuck in C code (``end_abandoned``)."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Coroutine
from typing import Any, NoReturn

from coupler_orchestrator.cli.exits import EXIT_ERROR, EXIT_INTERRUPTED
from coupler_orchestrator.master.watchdog import active as active_watchdog
from coupler_orchestrator.observer import RunEnd


class Interrupted(Exception):
    """SIGINT or SIGTERM ended the command."""


async def interruptible(command: Coroutine[Any, Any, int]) -> int:
    """Run ``command``; the first SIGINT/SIGTERM cancels it, so the run ends as ``aborted`` with
    its summary written and every service stopped; further signals during that clean-up (a
    terminal and ``uv run`` may both deliver Ctrl-C) are ignored.

    Signals are heard by a thread (through the signal wakeup pipe), not by the event loop's
    thread: when that thread is blocked in a participant computing in-process (an FMU hanging
    in doStep), the watchdog ends the run from there instead, within a second.
    """
    loop = asyncio.get_running_loop()
    task = asyncio.ensure_future(command)
    interrupted = asyncio.Event()

    def interrupt() -> None:
        if not interrupted.is_set():
            interrupted.set()
            task.cancel()

    with Signals(loop, interrupt):
        try:
            return await task
        except asyncio.CancelledError:
            if interrupted.is_set():
                raise Interrupted from None
            raise


class Signals:
    """SIGINT and SIGTERM, heard by a thread of their own through the signal wakeup pipe."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, loop: asyncio.AbstractEventLoop, interrupt: Callable[[], None]) -> None:
        self.loop = loop
        self.interrupt = interrupt
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)
        self._previous: dict[int, Any] = {}
        self._previous_fd = -1

    def __enter__(self) -> Signals:
        self._previous_fd = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        for sig in self.SIGNALS:  # the handler only has to exist; the thread acts
            self._previous[sig] = signal.signal(sig, lambda number, frame: None)
        threading.Thread(target=self._listen, name="coupler-signals", daemon=True).start()
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(self._previous_fd)
        os.close(self._write)  # ends the listening thread

    def _listen(self) -> None:
        while True:
            try:
                if not os.read(self._read, 64):
                    break
            except OSError:
                break
            heard = threading.Event()

            def interrupt(heard: threading.Event = heard) -> None:
                heard.set()
                self.interrupt()

            try:
                self.loop.call_soon_threadsafe(interrupt)
            except RuntimeError:  # the loop has closed: nothing to tell
                continue
            self._unless_heard(heard)
        os.close(self._read)

    @staticmethod
    def _unless_heard(heard: threading.Event) -> None:
        """When the loop's thread does not take the interrupt (``heard``): end the run from
        here once a call blocks it for 0.5 s (the watchdog), or anything else for 1 s."""
        given_up = time.monotonic() + 1.0
        while not heard.wait(0.1):
            watchdog = active_watchdog()
            if watchdog is not None and watchdog.blocked_for() > 0.5:
                watchdog.end("aborted", "interrupted by the user")
                return
            if time.monotonic() > given_up:
                if watchdog is None:
                    end_busy()  # set-up (reading, checking) holds the thread: nothing ran
                watchdog.end("aborted", "interrupted by the user")
                return


def end_busy() -> NoReturn:
    """End the process when an interrupt finds the event loop's thread busy outside a run (the
    scenario being read, checked or built: nothing recorded yet) for 1 s; a run's own
    blocked calls are the watchdog's."""
    from coupler.archives import remove_all_scratch

    print("interrupted before the run started; nothing was recorded", file=sys.stderr, flush=True)
    remove_all_scratch()
    os._exit(EXIT_INTERRUPTED)


def end_abandoned(end: RunEnd) -> None:
    """End the process: a run was abandoned because the event loop's thread is stuck in a
    participant computing in-process (an FMU hanging in doStep), the one way out of a thread
    stuck in C code. Its observers have written how it ended (``RunOptions.on_abandoned``);
    the folders the run unpacked into are removed here, as no ``finally`` runs past
    ``os._exit``."""
    from coupler.archives import remove_all_scratch

    print(f"error: run {end.status}: {end.reason}", file=sys.stderr, flush=True)
    remove_all_scratch()
    os._exit(EXIT_INTERRUPTED if end.status == "aborted" else EXIT_ERROR)
