"""Writing result files: the run's own results folder, checked before a run; JSON written
atomically; and the one error every output raises when the disk refuses (a full disk, a
directory gone).

Every run writes into a folder of its own, so results are never overwritten silently and two
runs' files never mix (a replay can only find the recording of the run whose results it is
given):

- without ``--out``: a new folder ``BASE/<UTC time>-<run id>/`` under the scenario's base
  folder (``results/<scenario>/``, the SSD's OpenMCx outputDirectory, a fleet file's ``out``),
  with ``BASE/latest`` a link to the newest;
- ``--out DIR``: that folder, refused when it holds an earlier run's results unless the user
  says ``--force``, which removes exactly those files first.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from coupler.errors import CouplerError, ScenarioError

RUN_FILES = (
    "results.csv",
    "results.parquet",
    "summary.json",
    "recordings",
    "frames",
    "kept-frames",
)
"""What a run writes into its folder (``--force`` removes these, and nothing else)."""
LATEST = "latest"
"""The link, in a base folder, to its newest run's folder."""
RESULTS_ROOT = "COUPLER_RESULTS_DIR"
"""Environment variable: where ``results/<scenario>/`` folders go (default ``results``)."""


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


def scenario_name(path: Path) -> str:
    """A scenario's name for its results folder: the file's stem (``railway.ssp`` ->
    ``railway``), the folder's name for an unpacked SSP or an SSP's standard
    ``SystemStructure.ssd`` (``examples/ramp-gain/SystemStructure.ssd`` -> ``ramp-gain``)."""
    path = path.resolve()
    if path.is_dir() or path.name == "SystemStructure.ssd":
        name = path.name if path.is_dir() else path.parent.name
    else:
        name = path.stem
    return re.sub(r"[^\w.+-]+", "-", name).strip("-.") or "scenario"


def default_base(path: Path) -> Path:
    """Where runs of the scenario at ``path`` go without ``--out``: ``results/<scenario>``
    (``$COUPLER_RESULTS_DIR/<scenario>`` when that is set)."""
    return Path(os.environ.get(RESULTS_ROOT) or "results") / scenario_name(path)


def new_run_folder(base: Path, run_id: str) -> Path:
    """A new, empty folder ``base/<UTC time>-<run id>`` (never one that exists), and
    ``base/latest`` pointing at it; ScenarioError when it cannot be made."""
    stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
    tag = re.sub(r"[^\w.+-]+", "-", run_id).strip("-.")[:8] or "run"
    try:
        base.mkdir(parents=True, exist_ok=True)
        for attempt in range(1, 1000):
            folder = base / (f"{stamp}-{tag}" + (f"-{attempt}" if attempt > 1 else ""))
            try:
                folder.mkdir()
                break
            except FileExistsError:
                continue
        else:  # pragma: no cover - a thousand runs of one id in one second
            raise FileExistsError(base / f"{stamp}-{tag}")
    except OSError as exc:
        raise ScenarioError(
            f"cannot make a results folder in {base}: {exc.strerror or exc}; choose another "
            "--out directory"
        ) from exc
    _point_latest(base, folder.name)
    return folder


def _point_latest(base: Path, name: str) -> None:
    """``base/latest`` -> ``name``, replaced atomically; best effort (a file system without
    symbolic links keeps the runs, only without the link)."""
    link = base / LATEST
    partial = base / f".{LATEST}-{os.getpid()}"
    with contextlib.suppress(OSError):
        partial.unlink(missing_ok=True)
        partial.symlink_to(name, target_is_directory=True)
        if link.is_symlink() or not link.exists():
            os.replace(partial, link)
    with contextlib.suppress(OSError):
        partial.unlink(missing_ok=True)


def claim(directory: Path, *, replace: bool) -> None:
    """Make ``directory`` this run's own: refuse it when it holds an earlier run's results
    (ScenarioError saying what to do), or with ``replace`` (``--force``) remove those files."""
    earlier = [directory / name for name in RUN_FILES if (directory / name).exists()]
    if not earlier:
        return
    if not replace:
        raise ScenarioError(
            f"{directory} already holds the results of an earlier run{_which(directory)}; "
            "a run writes into a folder of its own: leave --out out (each run gets a new "
            "folder under results/<scenario>/, `latest` links to the newest), choose another "
            "--out, or add --force to replace them"
        )
    try:
        for path in earlier:
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
    except OSError as exc:
        raise ScenarioError(
            f"cannot remove the earlier run's {path} (--force): {exc.strerror or exc}"
        ) from exc


def _which(directory: Path) -> str:
    """`` (run ID, completed)`` from its summary.json, when it says."""
    try:
        summary = json.loads((directory / "summary.json").read_text(encoding="utf-8"))
        return f" (run {summary['run_id']}, {summary['status']})"
    except (OSError, ValueError, KeyError, TypeError):
        return ""


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
