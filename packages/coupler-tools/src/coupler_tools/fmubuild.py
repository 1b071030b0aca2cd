"""Build co-simulation FMUs from the project's own C sources with gcc.

A *model folder* holds a ``modelDescription.xml`` and the model's ``*.c`` files (which may
``#include "../common/..."``); an optional ``resources/`` folder is packed as the FMU's
resources. ``build_fmu`` compiles the C files against FMPy's bundled FMI headers into
``binaries/<platform>/<modelIdentifier>.so`` and zips it with the model description:

    fmiVersion 1.0, 2.0  ->  binaries/linux64/<modelIdentifier>.so
    fmiVersion 3.0       ->  binaries/x86_64-linux/<modelIdentifier>.so

The build defines ``MODEL_IDENTIFIER`` (bare) and ``INSTANTIATION_TOKEN`` (the guid or
instantiationToken as a C string literal) so the C code can check what it is instantiated as.
An FMU newer than all its inputs (the model folder, the headers it includes by relative path,
its resources) is not rebuilt.

Compiling needs FMPy (for its headers: the ``fmu`` extra, ``coupler-tools[fmu]``); packing an
archive (``write_archive``, which ``coupler export-fmu`` uses too) does not.

Command line: ``python -m coupler_tools.fmubuild SRC_ROOT OUT_DIR`` builds every model folder of
SRC_ROOT (SRC_ROOT itself or its direct subfolders) into ``OUT_DIR/<folder name>.fmu`` and
prints their paths. Deeper folders are sets of their own: ``fmus`` holds the examples,
``fmus/faulty`` the FMUs that crash, hang or must be refused (built on their own).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from coupler.errors import ScenarioError

__all__ = [
    "FmuBuildError",
    "build_all",
    "build_fmu",
    "find_model_folders",
    "main",
    "write_archive",
]

CFLAGS: tuple[str, ...] = ("-shared", "-fPIC", "-O2", "-std=c99", "-Wall", "-Wextra", "-Werror")
"""Flags every model is compiled with (plus -I for FMPy's headers and -D for the model)."""

_PLATFORM = {"1.0": "linux64", "2.0": "linux64", "3.0": "x86_64-linux"}
_INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.MULTILINE)


class FmuBuildError(ScenarioError):
    """An FMU could not be built: bad model description, no sources, or gcc failed."""


@dataclass(frozen=True, kw_only=True)
class _Description:
    fmi_version: str
    model_identifier: str
    token: str


def fmi_headers() -> Path:
    """The folder of FMI headers FMPy ships (fmi1Functions.h, fmi2Functions.h, fmi3...)."""
    try:
        import fmpy
    except ImportError as exc:
        raise FmuBuildError(
            "building FMUs needs FMPy's FMI headers: install coupler-tools[fmu]"
        ) from exc
    return Path(fmpy.__file__).parent / "c-code"


def _read_description(path: Path) -> _Description:
    try:
        root = ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as exc:
        raise FmuBuildError(f"{path}: cannot read the model description: {exc}") from exc
    version = root.get("fmiVersion", "")
    if version not in _PLATFORM:
        raise FmuBuildError(f"{path}: fmiVersion {version!r} is not one of 1.0, 2.0, 3.0")
    if version == "1.0":
        identifier = root.get("modelIdentifier")
        token = root.get("guid")
        if root.find("Implementation/CoSimulation_StandAlone") is None:
            raise FmuBuildError(f"{path}: only FMI 1.0 co-simulation stand-alone is supported")
    else:
        # FMI 3.0 Scheduled Execution is built too: test FMUs that Coupler must refuse.
        interface = root.find("CoSimulation")
        if interface is None and version == "3.0":
            interface = root.find("ScheduledExecution")
        if interface is None:
            raise FmuBuildError(
                f"{path}: no <CoSimulation> element (co-simulation, or FMI 3.0 scheduled "
                f"execution, only)"
            )
        identifier = interface.get("modelIdentifier")
        token = root.get("guid" if version == "2.0" else "instantiationToken")
    if not identifier or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", identifier):
        raise FmuBuildError(f"{path}: modelIdentifier {identifier!r} is not a C identifier")
    if not token or '"' in token or "\\" in token:
        raise FmuBuildError(f"{path}: missing or unusable guid / instantiationToken {token!r}")
    return _Description(fmi_version=version, model_identifier=identifier, token=token)


def _included_files(sources: Iterable[Path]) -> set[Path]:
    """The sources and every file they include by a path relative to themselves."""
    seen: set[Path] = set()
    todo = [p.resolve() for p in sources]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        text = path.read_text(encoding="utf-8", errors="replace")
        for name in _INCLUDE.findall(text):
            candidate = (path.parent / name).resolve()
            if candidate.is_file():
                todo.append(candidate)
    return seen


def _inputs(source_dir: Path, sources: Sequence[Path], resources: Path | None) -> set[Path]:
    inputs = {p for p in source_dir.rglob("*") if p.is_file()}
    inputs |= _included_files(sources)
    if resources is not None:
        inputs |= {p for p in resources.rglob("*") if p.is_file()}
    return inputs


def _up_to_date(out_path: Path, inputs: Iterable[Path]) -> bool:
    if not out_path.is_file():
        return False
    built = out_path.stat().st_mtime
    return all(p.stat().st_mtime < built for p in inputs)


def build_fmu(source_dir: Path, out_path: Path, *, resources: Path | None = None) -> Path:
    """Compile the model folder ``source_dir`` into the FMU ``out_path`` and return out_path.

    ``resources`` defaults to ``source_dir/resources`` when that exists. Nothing is done when
    out_path is newer than every input. Raises FmuBuildError with gcc's output on failure.
    """
    source_dir = Path(source_dir)
    out_path = Path(out_path)
    md_path = source_dir / "modelDescription.xml"
    if not md_path.is_file():
        raise FmuBuildError(f"{source_dir}: no modelDescription.xml, so not a model folder")
    if resources is None and (source_dir / "resources").is_dir():
        resources = source_dir / "resources"
    if resources is not None and not resources.is_dir():
        raise FmuBuildError(f"resources folder {resources} does not exist")
    sources = sorted(source_dir.glob("*.c"))
    if not sources:
        raise FmuBuildError(f"{source_dir}: no C sources (*.c) next to modelDescription.xml")
    desc = _read_description(md_path)

    if _up_to_date(out_path, _inputs(source_dir, sources, resources)):
        return out_path

    binary = f"binaries/{_PLATFORM[desc.fmi_version]}/{desc.model_identifier}.so"
    with tempfile.TemporaryDirectory(prefix="fmubuild-") as tmp:
        library = Path(tmp) / f"{desc.model_identifier}.so"
        _compile_library(
            "gcc",
            [
                *CFLAGS,
                f"-I{fmi_headers()}",
                f"-I{source_dir}",
                f"-DMODEL_IDENTIFIER={desc.model_identifier}",
                f'-DINSTANTIATION_TOKEN="{desc.token}"',
                "-o",
                str(library),
                *(str(s) for s in sources),
                "-lm",
            ],
            what=source_dir.name,
        )
        members: dict[str, Path | bytes] = {"modelDescription.xml": md_path, binary: library}
        if resources is not None:
            for path in sorted(p for p in resources.rglob("*") if p.is_file()):
                members[f"resources/{path.relative_to(resources).as_posix()}"] = path
        write_archive(out_path, members)
    return out_path


def _compile_library(compiler: str, arguments: Sequence[str], *, what: str) -> None:
    """Run ``compiler`` (gcc, g++) with ``arguments``; FmuBuildError with its output naming
    ``what`` was built when it is missing or fails."""
    found = shutil.which(compiler)
    if found is None:
        raise FmuBuildError(f"{compiler} not found on PATH; install {compiler} to build FMUs")
    result = subprocess.run([found, *arguments], capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise FmuBuildError(
            f"{compiler} failed (exit {result.returncode}) building {what}:\n"
            f"{result.stdout}{result.stderr}".rstrip()
        )


def write_archive(out_path: Path, members: Mapping[str, Path | bytes]) -> Path:
    """The FMU ``out_path`` holding ``members`` (archive name -> file, kept with its mode, or
    bytes), written whole or not at all."""
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    partial = out_path.with_name(out_path.name + ".part")
    try:
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as fmu:
            for name, member in members.items():
                if isinstance(member, bytes):
                    fmu.writestr(name, member)
                else:
                    fmu.write(member, name)
        partial.replace(out_path)
    except OSError as exc:
        partial.unlink(missing_ok=True)
        raise FmuBuildError(f"cannot write {out_path}: {exc}") from exc
    return out_path


def find_model_folders(src_root: Path) -> list[Path]:
    """src_root and its direct subfolders that hold a modelDescription.xml (not deeper ones)."""
    root = Path(src_root)
    return sorted(
        p.parent
        for p in (root / "modelDescription.xml", *root.glob("*/modelDescription.xml"))
        if p.is_file()
    )


def build_all(src_root: Path, out_dir: Path) -> list[Path]:
    """Build every model folder under src_root into ``out_dir/<folder name>.fmu``.

    gcc runs for several models at once; the first failure is raised after all have finished.
    """
    folders = find_model_folders(src_root)
    if not folders:
        raise FmuBuildError(f"{src_root}: no model folders (folders with modelDescription.xml)")
    names = [folder.name for folder in folders]
    if len(set(names)) != len(names):
        raise FmuBuildError(f"{src_root}: model folder names must be unique, got {names}")
    with ThreadPoolExecutor(max_workers=min(len(folders), os.cpu_count() or 1)) as pool:
        futures = [
            pool.submit(build_fmu, folder, Path(out_dir) / f"{folder.name}.fmu")
            for folder in folders
        ]
    return [future.result() for future in futures]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m coupler_tools.fmubuild SRC_ROOT OUT_DIR``: build all FMUs, print their paths."""
    parser = argparse.ArgumentParser(
        prog="python -m coupler_tools.fmubuild", description=main.__doc__ and __doc__.split("\n")[0]
    )
    parser.add_argument("src_root", type=Path, help="folder searched for model folders")
    parser.add_argument("out_dir", type=Path, help="where <folder name>.fmu files are written")
    args = parser.parse_args(argv)
    try:
        paths = build_all(args.src_root, args.out_dir)
    except FmuBuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
