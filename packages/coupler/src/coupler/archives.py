"""Extracting zip archives (.ssp, .fmu) safely.

No entry may escape the target directory (zip slip, absolute paths, symbolic links); the
archive may not expand beyond a byte budget (zip bomb) — sizes are counted while decompressing,
never taken from the forgeable headers; one ``Budget`` can be shared by several archives (an
.ssp and the FMUs inside it); a forged or corrupt archive is a ScenarioError, never a zipfile
traceback; ``cancelled`` stops an extraction between chunks (an interrupted run ends promptly).
"""

from __future__ import annotations

import stat
import threading
import zipfile
import zlib
from dataclasses import dataclass
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
    """Bytes that may still be extracted; shared by every archive of one scenario."""

    remaining: int = DEFAULT_BUDGET_BYTES
    limit: int = DEFAULT_BUDGET_BYTES

    @classmethod
    def of(cls, limit: int) -> Budget:
        return cls(remaining=limit, limit=limit)

    def spend(self, amount: int, name: str) -> None:
        self.remaining -= amount
        if self.remaining < 0:
            raise ScenarioError(
                f"{name}: extracting it would exceed the {self.limit} bytes a scenario may "
                f"unpack (archive and FMUs together); refusing it as a possible zip bomb - "
                f"raise the limit if the archive is genuine"
            )


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
            if sum(i.file_size for i in infos) > budget.remaining:
                budget.spend(sum(i.file_size for i in infos), name)
            for info in infos:
                _extract_entry(zf, info, name, target, budget, cancelled)
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


def _extract_entry(
    zf: zipfile.ZipFile,
    info: zipfile.ZipInfo,
    name: str,
    target: Path,
    budget: Budget,
    cancelled: threading.Event | None,
) -> None:
    dest = _destination(name, target, info)
    if info.is_dir():
        dest.mkdir(parents=True, exist_ok=True)
        return
    dest.parent.mkdir(parents=True, exist_ok=True)
    with zf.open(info) as src, dest.open("wb") as out:
        while chunk := src.read(_CHUNK):
            if cancelled is not None and cancelled.is_set():
                raise Cancelled(f"{name}: extraction interrupted")
            budget.spend(len(chunk), name)
            out.write(chunk)


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
