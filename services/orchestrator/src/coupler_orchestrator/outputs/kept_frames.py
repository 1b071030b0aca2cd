"""Camera frames kept around the moments a domain package cares about, without recording every
frame: a report that wants to show the frames around a miss gets them, a run of 4,500 frames
writes a few hundred.

The orchestrator knows no domain: an installed package names a keeper in the entry point group
``coupler.frames`` (``pyproject.toml``)::

    [project.entry-points."coupler.frames"]
    perception = "coupler_railway.frames:keeper"

At the start of every run each is called with the recorded columns (name -> protobuf message
type, ``""`` for none) and returns None (not its business) or a ``Keeper``: the frame column it
keeps, the columns it watches, and a window. At every communication point the keeper is shown
the watched columns' values; when it wants the point, the ``before`` points before it (held in
memory: references to frames the run has anyway) and the ``after`` points after it are written
as PNG files ``kept-frames/<Component.channel>/<point>.png`` (``point``: the communication
point's index, 0 at t_0), with ``index.json`` beside them: each file's point, time and the
frame's sensor, size and intrinsics. The package's report reads them when the run ends.

The PNG files are encoded and written by one thread of their own (zlib lets go of the GIL), so
that the step loop goes on while they are made; at most ``PENDING`` frames wait for it, and a
file that cannot be written fails the run at the next point or at its end.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Protocol

import structlog

from coupler.channels import Value
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo, Steps
from coupler_orchestrator.outputs.files import write_failed, write_json
from coupler_orchestrator.outputs.frames import is_frame, png, read_image

ENTRY_POINTS = "coupler.frames"
"""The entry point group installed packages name their frame keepers in."""
FOLDER = "kept-frames"
"""Where kept frames go in a run folder."""
LEVEL = 1
"""zlib level of kept frames: half the default level's time (4 ms for an 800 x 600 frame of the
mock), twice its bytes (22 kB)."""
PENDING = 8
"""Frames at most waiting for the writer thread; the step loop waits beyond."""

log = structlog.get_logger("coupler.frames")


class Keeper(Protocol):
    """Which frames a package wants kept."""

    frames: str
    """The frame column (``Component.channel`` carrying ``coupler.v1.Image``)."""
    watches: Sequence[str]
    """The columns ``wants`` is shown, in this order."""
    before: int
    """Points kept before a wanted one."""
    after: int
    """Points kept after a wanted one."""

    def wants(self, values: Sequence[Value]) -> bool:
        """Whether the frames around this point are kept (``values``: of ``watches``)."""
        ...


MakeKeeper = Callable[[Mapping[str, str]], Keeper | None]


@dataclass
class _Kept:
    keeper: Keeper
    frame: int
    watched: list[int]
    folder: Path
    ring: deque[tuple[int, float, Value]]
    until: int = -1
    """Points up to this one are kept as they come."""
    written: int = -1
    """The last point written."""
    index: list[dict[str, Any]] = field(default_factory=list)


class KeptFrames(Observer):
    """Writes the frames the installed keepers want into ``<run folder>/kept-frames/``."""

    def __init__(self, run_folder: Path) -> None:
        self.run_folder = run_folder
        self._kept: list[_Kept] = []
        self._point = -1
        self._writer: ThreadPoolExecutor | None = None
        self._pending: deque[tuple[_Kept, Future[dict[str, Any] | None]]] = deque()

    def started(self, info: RunInfo) -> None:
        recorded = {c.name: c.message_type for c in info.columns}
        at = {c.name: i for i, c in enumerate(info.columns)}
        frames = {c.name for c in info.columns if is_frame(c)}
        for entry in entry_points(group=ENTRY_POINTS):
            try:
                make: MakeKeeper = entry.load()
                keeper = make(recorded)
            except Exception as exc:  # a keeper's failure is its own, never the run's
                log.warning("frame_keeper_failed", keeper=entry.name, error=repr(exc))
                continue
            if keeper is None or keeper.frames not in frames:
                continue
            if any(name not in at for name in keeper.watches):
                continue
            self._kept.append(
                _Kept(
                    keeper=keeper,
                    frame=at[keeper.frames],
                    watched=[at[name] for name in keeper.watches],
                    folder=self.run_folder / FOLDER / keeper.frames,
                    ring=deque(maxlen=max(keeper.before, 0) + 1),
                )
            )

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        self._collect(wait=len(self._pending) >= PENDING)
        self._point += 1
        point = self._point
        for kept in self._kept:
            kept.ring.append((point, time, row[kept.frame]))
            if kept.keeper.wants([row[i] for i in kept.watched]):
                kept.until = point + max(kept.keeper.after, 0)
                for entry in kept.ring:
                    self._write(kept, *entry)
            elif point <= kept.until:
                self._write(kept, point, time, row[kept.frame])

    def stepped_batch(self, steps: Steps) -> None:
        if not self._kept:  # the native FMU step's batches: no camera, nothing to look at
            self._point += len(steps.times)
            return
        super().stepped_batch(steps)

    def closing(self, end: RunEnd) -> None:
        try:
            self._collect(wait=True, every=True)
        finally:
            if self._writer is not None:
                self._writer.shutdown(wait=True, cancel_futures=True)
                self._writer = None
        for kept in self._kept:
            if kept.index:
                write_json(kept.folder / "index.json", {"frames": kept.index})

    def _write(self, kept: _Kept, point: int, time: float, value: Value) -> None:
        if point <= kept.written:
            return
        kept.written = point
        if not isinstance(value, bytes):
            return
        if self._writer is None:
            self._writer = ThreadPoolExecutor(1, thread_name_prefix="coupler-kept-frames")
        job = self._writer.submit(_write_png, kept.folder / f"{point:06d}.png", point, time, value)
        self._pending.append((kept, job))

    def _collect(self, *, wait: bool, every: bool = False) -> None:
        """The written frames' index entries, in order; waits for the oldest (``wait``) or for
        all (``every``); a frame that could not be written raises here."""
        while self._pending:
            kept, job = self._pending[0]
            if not (wait or job.done()):
                return
            self._pending.popleft()
            entry = job.result()
            if entry is not None:
                kept.index.append(entry)
            wait = every


def _write_png(path: Path, point: int, time: float, value: bytes) -> dict[str, Any] | None:
    """The frame ``value`` as the PNG file ``path`` and its index entry (None: no image PNG
    can show); on the writer thread."""
    image = read_image(value)
    encoded = png(image, LEVEL) if image is not None else None
    if image is None or encoded is None:
        return None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(encoded)
    except OSError as exc:
        raise write_failed(path, exc) from exc
    k = image.intrinsics
    return {
        "point": point,
        "time": time,
        "file": path.name,
        "sensor": image.sensor,
        "time_s": image.time_s,
        "width": image.width,
        "height": image.height,
        "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
    }
