"""Writing result files: the results directory checked before a run, JSON written atomically,
and the one error every output raises when the disk refuses (a full disk, a directory gone)."""

from __future__ import annotations

import contextlib
import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from coupler.errors import CouplerError, ScenarioError


class ResultsError(CouplerError):
    """Results cannot be written (a full disk, a directory that went away)."""


def check_writable(directory: Path) -> None:
    """ScenarioError unless results can be written into ``directory`` (created if missing) —
    checked before any participant starts."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".coupler-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ScenarioError(
            f"cannot write results into {directory}: {exc.strerror or exc}; choose another "
            "--out directory"
        ) from exc


def write_failed(path: Path, exc: OSError) -> ResultsError:
    return ResultsError(
        f"cannot write {path}: {exc.strerror or exc}; every complete row before it is kept"
    )


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """Write ``data`` to ``path`` atomically (a reader never sees half a file)."""
    text = io.StringIO()
    json.dump(data, text, indent=2)
    text.write("\n")
    partial = path.with_name(f".{path.name}.partial")
    encoded = text.getvalue().encode()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial.write_bytes(encoded)
        os.replace(partial, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            partial.unlink()
        try:  # a full disk: rewrite in place, in the blocks the file already has
            with path.open("r+b") as file:
                file.write(encoded)
                file.truncate()
        except OSError:
            raise ResultsError(f"cannot write {path}: {exc.strerror or exc}") from exc
