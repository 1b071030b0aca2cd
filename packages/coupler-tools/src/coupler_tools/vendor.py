"""Browser files from npm packages, copied into a service's static folder at set-up time.

Pages and reports load their JavaScript from the project's own files, never from a CDN at run
time (they must work offline). ``npm ci`` in a service folder installs the pinned versions
(package.json, package-lock.json); ``copy`` takes the files a page needs out of
``node_modules`` (``make assets`` does both); ``missing`` tells a server at run time whether
its page can work.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

__all__ = ["command", "copy", "missing"]


def missing(vendor: Path, names: Sequence[str]) -> list[str]:
    """The files of ``names`` absent from ``vendor``; empty when the page can work."""
    return [name for name in names if not (vendor / name).exists()]


def copy(dist: Path, names: Sequence[str], vendor: Path) -> Path:
    """Copy ``names`` (files or folders) from ``dist`` into ``vendor``; FileNotFoundError
    naming what is absent (``npm ci`` has not run)."""
    absent = missing(dist, names)
    if absent:
        raise FileNotFoundError(f"{dist} lacks {', '.join(absent)}: run `npm ci` first")
    vendor.mkdir(parents=True, exist_ok=True)
    for name in names:
        source, target = dist / name, vendor / name
        if source.is_dir():
            shutil.copytree(source, target, dirs_exist_ok=True)
        else:
            shutil.copy2(source, target)
    return vendor


def command(
    prog: str, what: str, copy_from: Callable[[Path], Path], default: Path, argv: list[str] | None
) -> int:
    """The body of a service's ``python -m <package>.assets``: ``copy_from(node_modules)``;
    the exit status, 1 with the reason on stderr when ``npm ci`` has not run."""
    parser = argparse.ArgumentParser(prog=prog, description=f"copy {what} out of node_modules")
    parser.add_argument("--node-modules", type=Path, default=default)
    args = parser.parse_args(argv)
    try:
        target = copy_from(args.node_modules)
    except FileNotFoundError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    print(f"{what} copied to {target}")
    return 0
