"""Extracting zip archives (.ssp, .fmu) safely, into folders that never outlive the process.

No entry may escape the target directory (zip slip, absolute paths, symbolic links); the
archive may not expand beyond a byte budget (zip bomb): the sizes its headers declare are
reserved before anything is written (an honest archive too large is refused at once), and the
bytes are counted while decompressing, so a forged header gains nothing; one ``Budget`` is
shared by several archives (an .ssp and every FMU it runs, in this process or isolated) and by
the threads unpacking them at once; a forged or corrupt archive is a ScenarioError, never a
zipfile traceback; ``cancelled`` stops an extraction between chunks (an interrupted run ends
promptly).

``scratch_folder`` makes the folders archives are unpacked into; each is removed by its owner
(``remove_scratch``) and, when the process must end without unwinding (``os._exit`` past an FMU
stuck in C), all at once by ``remove_all_scratch``.

Only reading is here: a participant unpacks archives it is given, and never makes one. Writing
an FMU is the build helpers' (``coupler_tools.fmubuild.write_archive``).
"""

from __future__ import annotations

import asyncio
import shutil
import stat
import tempfile
import threading
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from coupler.errors import ScenarioError

DEFAULT_BUDGET_BYTES = 2 * 1024 * 1024 * 1024
"""Default limit on what one scenario may extract: the .ssp and every FMU together."""
MAX_ENTRIES = 10_000
_CHUNK = 1024 * 1024


class Cancelled(ScenarioError):
    """The extraction was stopped from outside (the run is being interrupted)."""


@dataclass
class Budget:
    """Bytes that may still be extracted; shared by every archive of one run."""

    remaining: int = DEFAULT_BUDGET_BYTES
    limit: int = DEFAULT_BUDGET_BYTES
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    @classmethod
    def of(cls, limit: int) -> Budget:
        return cls(remaining=limit, limit=limit)

    def spend(self, amount: int, name: str) -> None:
        """Take ``amount`` bytes for ``name``; ScenarioError (nothing taken) when they are not
        left."""
        with self._lock:
            if amount > self.remaining:
                used = self.limit - self.remaining
                raise ScenarioError(
                    f"{name}: extracting it would exceed the {self.limit} bytes a scenario may "
                    f"unpack (archive and FMUs together): it needs {_mib(amount)} more, "
                    f"{_mib(used)} of {_mib(self.limit)} are taken; refusing it as a possible zip "
                    "bomb - raise the limit (--unpack-limit MB) if the archive is genuine"
                )
            self.remaining -= amount

    def check(self, sizes: dict[str, int], what: str) -> None:
        """ScenarioError when archives of these declared sizes (label -> bytes) cannot all be
        unpacked: checked before unpacking any of them, so none is (``declared_size``)."""
        total = sum(sizes.values())
        with self._lock:
            remaining = self.remaining
        if total <= remaining:
            return
        each = ", ".join(f"{label} {_mib(size)}" for label, size in sizes.items())
        together = f", {_mib(total)} together" if len(sizes) > 1 else ""
        taken = self.limit - remaining
        already = f", {_mib(taken)} of which are taken already" if taken else ""
        raise ScenarioError(
            f"{what}: {each}{together}: that would exceed the {self.limit} bytes a scenario may "
            f"unpack (archive and FMUs together){already}; nothing was unpacked - raise the "
            "limit (--unpack-limit MB) if they are genuine"
        )

    def refund(self, amount: int) -> None:
        """Give back bytes reserved but not written (a header that declared more)."""
        with self._lock:
            self.remaining = min(self.limit, self.remaining + amount)


def _mib(size: int) -> str:
    return f"{size / 1024 / 1024:.1f} MB"


_scratch: set[Path] = set()
_scratch_lock = threading.Lock()


def scratch_folder(prefix: str) -> Path:
    """A new private temporary folder (mode 0700, in TMPDIR) for unpacking into, known to
    ``remove_all_scratch`` until ``remove_scratch`` removes it."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    with _scratch_lock:
        _scratch.add(folder)
    return folder


def remove_scratch(folder: Path) -> None:
    """Remove a folder made by ``scratch_folder`` (or any folder), whatever it holds."""
    shutil.rmtree(folder, ignore_errors=True)
    with _scratch_lock:
        _scratch.discard(folder)


def remove_all_scratch() -> None:
    """Remove every scratch folder still there: the process is about to end without running
    its clean-up (``os._exit``, the one way past an FMU stuck in C)."""
    with _scratch_lock:
        folders = list(_scratch)
    for folder in folders:
        remove_scratch(folder)


def declared_size(archive: Path) -> int:
    """What ``archive``'s headers say it unpacks to [bytes]; 0 when it cannot be read (its
    extraction reports why)."""
    try:
        with zipfile.ZipFile(archive) as zf:
            return sum(i.file_size for i in zf.infolist())
    except (OSError, zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError):
        return 0


def extract(
    archive: Path,
    target: Path,
    *,
    budget: Budget | None = None,
    cancelled: threading.Event | None = None,
) -> None:
    """Extract ``archive`` into ``target`` (created if needed) within ``budget``."""
    name = archive.name
    budget = budget if budget is not None else Budget()
    target = target.resolve()
    target.mkdir(parents=True, exist_ok=True)
    try:
        with zipfile.ZipFile(archive) as zf:
            infos = zf.infolist()
            if len(infos) > MAX_ENTRIES:
                raise ScenarioError(
                    f"{name}: {len(infos)} entries exceed the limit of {MAX_ENTRIES}; "
                    "this does not look like an SSP or FMU archive"
                )
            declared = sum(i.file_size for i in infos)
            budget.spend(declared, name)  # before anything is written
            written = 0
            try:
                for info in infos:
                    written += _extract_entry(
                        zf, info, name, target, budget, cancelled, declared - written
                    )
            finally:
                if written < declared:
                    budget.refund(declared - written)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError) as exc:
        raise ScenarioError(
            f"{name}: not a readable zip archive ({exc}); the file is corrupt or not an .ssp/.fmu"
        ) from exc
    except NotImplementedError as exc:  # e.g. an unsupported compression method
        raise ScenarioError(f"{name}: cannot be unpacked: {exc}") from exc
    except OSError as exc:
        raise ScenarioError(
            f"{name}: cannot extract it into {target}: {exc.strerror or exc}"
        ) from exc


async def extracted(archive: Path, target: Path, *, budget: Budget | None = None) -> None:
    """``extract`` off the event loop; a cancelled caller stops it at its next chunk and waits
    for that, so nothing is written into ``target`` once this has returned."""
    stop = threading.Event()
    work = asyncio.ensure_future(
        asyncio.to_thread(extract, archive, target, budget=budget, cancelled=stop)
    )
    try:
        await asyncio.shield(work)
    except asyncio.CancelledError:
        stop.set()
        await asyncio.wait([work], timeout=10)
        raise


def _extract_entry(
    zf: zipfile.ZipFile,
    info: zipfile.ZipInfo,
    name: str,
    target: Path,
    budget: Budget,
    cancelled: threading.Event | None,
    reserved: int,
) -> int:
    """Extract one entry; the bytes written are counted against ``reserved`` (what the headers
    declared, not yet written), and any beyond it against ``budget``. Returns the bytes."""
    dest = _destination(name, target, info)
    if info.is_dir():
        dest.mkdir(parents=True, exist_ok=True)
        return 0
    dest.parent.mkdir(parents=True, exist_ok=True)
    written = 0
    with zf.open(info) as src, dest.open("wb") as out:
        while chunk := src.read(_CHUNK):
            if cancelled is not None and cancelled.is_set():
                raise Cancelled(f"{name}: extraction interrupted")
            beyond = written + len(chunk) - max(reserved, written)
            if beyond > 0:  # a header that declared less than the entry holds
                budget.spend(beyond, name)
            written += len(chunk)
            out.write(chunk)
    return written


def _destination(name: str, target: Path, info: zipfile.ZipInfo) -> Path:
    entry = info.filename
    mode = info.external_attr >> 16
    pure = PurePosixPath(entry.replace("\\", "/"))
    escapes = (
        pure.is_absolute()
        or ".." in pure.parts
        or (len(entry) > 1 and entry[1] == ":")  # Windows drive letter
        or stat.S_ISLNK(mode)
    )
    dest = (target / pure).resolve()
    if escapes or not dest.is_relative_to(target):
        raise ScenarioError(
            f"{name}: entry '{entry}' would be written outside the extraction directory "
            "(zip-slip); refusing the archive - rebuild it with relative paths only"
        )
    return dest
