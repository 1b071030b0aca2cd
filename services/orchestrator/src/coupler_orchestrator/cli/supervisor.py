"""``coupler run`` (and ``fleet``) watched by a parent: what no code in a crashed process can do.

An FMU running in the orchestrator's process that segfaults takes the process with it, and no
Python code runs after that. So the command forks once its arguments are parsed (``--help``
never gets here): the child runs the command as before; the parent only waits for it. When the
child is killed by a signal it did not handle (SIGSEGV, SIGBUS, SIGABRT, SIGKILL from the
kernel's out-of-memory killer, ...), the parent says so in one sentence, rewrites summary.json
as ``crashed`` with the last time reached, cuts results.csv back to its last whole row (every
row flushed before is kept) and exits 128 + the signal's number, as a shell reports a crash.

The child tells the parent where its results go and how far the run got through a page of
shared memory (``Beacon``: two numbers stored per communication point, nothing else). Ctrl-C
and SIGTERM reach the child as before (the parent passes on what is sent to it alone), so an
interrupted run still ends ``aborted``, exit 130; the child dies with the parent (a parent
killed by SIGKILL kills the run, as before). The run's temporary files (unpacked FMUs, an FMU
host's folder, whatever the FMUs write to TMPDIR) go into one folder the parent removes however
the child ended.
"""

from __future__ import annotations

import contextlib
import json
import math
import mmap
import os
import shutil
import signal
import struct
import sys
import tempfile
import time as wallclock
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from coupler.lifetimes import die_with_parent
from coupler_orchestrator.cli.exits import EXIT_INTERRUPTED
from coupler_orchestrator.observer import Observer, RunInfo, Steps

SUPERVISED = frozenset({"run", "fleet"})
"""The commands that run a scenario in this process."""
PASSED_ON = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Signals the parent passes on to the child (which ends the run ``aborted``)."""

_HEAD = struct.Struct("<dqdI")
"""The beacon: time reached [s], communication points recorded, when the run started
(``time.monotonic()``, the same clock in both processes), length of the results path."""
_PAGE = 4096
_WATCH = _PAGE - 24
"""Where the native FMU step keeps the step under way: three doubles (member slot, since,
time; ``RunOptions.progress``), at the page's end."""

_beacon: Beacon | None = None


def beacon() -> Beacon | None:
    """The beacon of this process when it is a supervised child, else None."""
    return _beacon


class Beacon(Observer):
    """Shared memory the child writes and the parent reads once the child is gone."""

    def __init__(self) -> None:
        self.page = mmap.mmap(-1, _PAGE)  # anonymous and shared: the child writes, we read
        _HEAD.pack_into(self.page, 0, math.nan, 0, math.nan, 0)
        self._time = memoryview(self.page)[:8].cast("d")
        self._points = memoryview(self.page)[8:16].cast("q")
        self._count = 0
        self.progress = memoryview(self.page)[_WATCH:]
        """``RunOptions.progress``: the native FMU step writes the step under way here."""
        struct.pack_into("<3d", self.page, _WATCH, -1.0, 0.0, math.nan)

    def results(self, directory: Path) -> None:
        """Where the run writes its results (``RunOptions.on_results``)."""
        encoded = str(directory.resolve()).encode()[: _WATCH - _HEAD.size]
        self.page[_HEAD.size : _HEAD.size + len(encoded)] = encoded
        struct.pack_into("<I", self.page, 24, len(encoded))

    def started(self, info: RunInfo) -> None:
        struct.pack_into("<d", self.page, 16, wallclock.monotonic())

    def stepped(self, time: float, row: Sequence[Any]) -> None:
        self._count += 1
        self._time[0] = time
        self._points[0] = self._count

    def stepped_batch(self, steps: Steps) -> None:
        self._count += len(steps.times)
        self._time[0] = steps.times[-1]
        self._points[0] = self._count

    def read(self) -> tuple[float, int, float, Path | None, bool]:
        """(time reached, communication points recorded, wall time since the run started,
        results directory, whether the time is the native FMU step's). The time reached is the
        later of the last point told and the start of the step the native FMU step had under
        way (its points since its last batch died with the process)."""
        time, points, started, length = _HEAD.unpack_from(self.page, 0)
        slot, _, under_way = struct.unpack_from("<3d", self.page, _WATCH)
        in_c = slot >= 0 and not math.isnan(under_way) and not under_way <= time
        if in_c:
            time = under_way
        raw = self.page[_HEAD.size : _HEAD.size + length]
        wall = wallclock.monotonic() - started
        return time, points, wall, Path(raw.decode(errors="replace")) if length else None, in_c


def supervised() -> int | None:
    """Fork. In the child: None (go on with the command). In the parent: the exit code the
    command ends with, once the child has ended (``Crash`` says what a crash left)."""
    global _beacon
    shared = Beacon()
    scratch = tempfile.mkdtemp(prefix="coupler-run-")
    parent = os.getpid()
    sys.stdout.flush()
    sys.stderr.flush()
    child = os.fork()
    if child == 0:
        if not die_with_parent(parent):
            os._exit(EXIT_INTERRUPTED)
        os.environ["TMPDIR"] = tempfile.tempdir = scratch
        _beacon = shared
        return None
    try:
        return _watch(child, shared)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _watch(child: int, shared: Beacon) -> int:
    """Wait for the child, passing signals on; its exit code, or what its crash means."""
    sent: list[int] = []

    def pass_on(number: int, frame: object) -> None:
        sent.append(number)
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, number)

    for sig in PASSED_ON:
        signal.signal(sig, pass_on)
    _, status = os.waitpid(child, 0)
    code = os.waitstatus_to_exitcode(status)
    if code >= 0:
        return code
    number = -code
    if number in sent or number in PASSED_ON:
        print(f"interrupted ({signal.Signals(number).name})", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    print(f"error: {Crash(number, *shared.read()).record()}", file=sys.stderr, flush=True)
    return 128 + number


class Crash:
    """A child killed by signal ``number`` at ``time`` (NaN: before the run's first point),
    ``wall`` seconds after the run started, with ``points`` communication points recorded into
    ``directory`` (None: not chosen yet)."""

    def __init__(
        self,
        number: int,
        time: float,
        points: int,
        wall: float,
        directory: Path | None,
        in_c: bool = False,
    ) -> None:
        self.signal = signal.Signals(number).name
        self.in_c = in_c
        """``time`` is the step the native FMU step had under way, past the last point told."""
        self.time = time
        self.points = points
        self.wall = wall
        self.directory = directory

    def record(self) -> str:
        """Fix what the crash left (summary.json ``crashed``, results.csv cut to whole rows)
        and say in one sentence what happened and where the results are."""
        if self.signal == "SIGKILL":
            how = (
                "the orchestrator process was killed by SIGKILL (by the kernel when memory ran "
                "out, or by a user)"
            )
        else:
            how = (
                f"the orchestrator process was killed by {self.signal}: something running in it "
                "crashed - most likely an FMU running in-process; run FMUs you do not trust with "
                "--isolate-fmus, so that a crash fails the run instead"
            )
        if self.directory is None:
            return f"run crashed before it started: {how}; nothing was recorded"
        if math.isnan(self.time):
            self._summary(self.directory / "summary.json", f"{how} (before its first step)")
            return (
                f"run crashed before its first step: {how}; nothing was recorded, in "
                f"{self.directory} (summary.json: status crashed)"
            )
        kept = _whole_rows(self.directory / "results.csv")
        if self.in_c:
            kept += " (the steps computed in C since were lost with the process)"
        reason = f"{how} (the run had reached t={self.time:g} s; results.csv keeps {kept})"
        self._summary(self.directory / "summary.json", reason)
        return (
            f"run crashed at t={self.time:g} s: {how}; results.csv keeps {kept}, in "
            f"{self.directory} (summary.json: status crashed)"
        )

    def _summary(self, path: Path, reason: str) -> None:
        """summary.json, still ``running``, as ``crashed``."""
        from coupler_orchestrator.outputs.files import write_json

        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return
        if data.get("status") != "running":
            return  # the run had ended; the crash came after it (while closing)
        start = data.get("start_time", 0.0)
        reached = start if math.isnan(self.time) else self.time
        simulated = reached - start
        step = data.get("step_size") or 0.0
        data.update(
            status="crashed",
            reason=reason,
            end_time=reached,
            steps=round(simulated / step) if step > 0 else max(self.points - 1, 0),
            wall_time_s=round(self.wall, 6) if math.isfinite(self.wall) else None,
            realtime_factor=round(simulated / self.wall, 3) if self.wall > 0 else None,
        )
        with contextlib.suppress(Exception):
            write_json(path, data)


def _whole_rows(results: Path) -> str:
    """Cut ``results`` after its last whole row; say which rows it keeps."""
    try:
        with results.open("rb+") as file:
            size = file.seek(0, os.SEEK_END)
            file.seek(max(0, size - 65536))
            tail = file.read()
            end = tail.rfind(b"\n")
            if end < 0:
                return "no row"
            file.truncate(size - len(tail) + end + 1)
            lines = tail[: end + 1].splitlines()
    except OSError:
        return "no row"
    last = lines[-1].split(b",", 1)[0] if lines else b""
    try:
        return f"the rows up to t={float(last):g} s"
    except ValueError:
        return "its header only"
