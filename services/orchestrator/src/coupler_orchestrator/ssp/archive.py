"""Extracting .ssp archives safely: no entry may escape the target directory (zip-slip),
and the archive may not expand beyond a size limit (zip bomb)."""

from __future__ import annotations

import shutil
import stat
import zipfile
from pathlib import Path, PurePosixPath

from coupler.errors import ScenarioError

MAX_EXTRACTED_BYTES = 2 * 1024 * 1024 * 1024
"""Default limit on the total uncompressed size of an .ssp archive."""
MAX_ENTRIES = 10_000
SSD_NAME = "SystemStructure.ssd"
_CHUNK = 1024 * 1024


def extract(archive: Path, target: Path, *, max_bytes: int = MAX_EXTRACTED_BYTES) -> Path:
    """Extract ``archive`` into ``target``; return the path of its SystemStructure.ssd.

    Sizes are counted while decompressing, not taken from the (forgeable) zip headers.
    """
    name = archive.name
    try:
        zf = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as exc:
        raise ScenarioError(f"{name}: not a readable .ssp (zip) archive: {exc}") from exc
    target = target.resolve()
    target.mkdir(parents=True, exist_ok=True)
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_ENTRIES:
            raise ScenarioError(
                f"{name}: {len(infos)} entries exceed the limit of {MAX_ENTRIES}; "
                "this does not look like an SSP archive"
            )
        declared = sum(i.file_size for i in infos)
        if declared > max_bytes:
            raise _bomb(name, declared, max_bytes)
        total = 0
        for info in infos:
            dest = _destination(name, target, info)
            if info.is_dir():
                dest.mkdir(parents=True, exist_ok=True)
                continue
            dest.parent.mkdir(parents=True, exist_ok=True)
            with zf.open(info) as src, dest.open("wb") as out:
                while chunk := src.read(_CHUNK):
                    total += len(chunk)
                    if total > max_bytes:
                        raise _bomb(name, total, max_bytes)
                    out.write(chunk)
    ssd = target / SSD_NAME
    if not ssd.is_file():
        raise ScenarioError(
            f"{name}: the archive has no {SSD_NAME} at its root; an .ssp must contain one"
        )
    return ssd


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


def _bomb(name: str, size: int, limit: int) -> ScenarioError:
    return ScenarioError(
        f"{name}: the archive expands to more than {limit} bytes (at least {size}); refusing it "
        "as a possible zip bomb - raise the size limit if the archive is genuine"
    )


def remove(directory: Path) -> None:
    """Delete an extraction directory (best effort)."""
    shutil.rmtree(directory, ignore_errors=True)
