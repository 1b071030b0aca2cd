"""The tight physical limit of the in-process chains: ``cloop/chain.c``, a bare C loop making the
FMI calls a Coupler run of the chain makes and writing the same results.csv text with the same
shortest round-trip formatter (CPython's, which Coupler's native row calls). Built here with the
machine's C compiler against this interpreter's libpython and FMPy's FMI headers."""

from __future__ import annotations

import shutil
import subprocess
import sysconfig
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "cloop" / "chain.c"


def missing() -> str:
    """Why the loop cannot be built here ('' when it can)."""
    if shutil.which("cc") is None:
        return "no C compiler (cc) on this machine"
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").exists():
        return "this Python has no headers (Python.h) to build against"
    return ""


def build(work: Path) -> Path:
    """The loop's binary, compiled into ``work``."""
    from coupler_tools.fmubuild import fmi_headers

    binary = (work / "cloop-chain").resolve()
    libdir = sysconfig.get_config_var("LIBDIR")
    version = sysconfig.get_config_var("VERSION")
    subprocess.run(
        ["cc", "-O2", "-o", str(binary), str(SOURCE), f"-I{sysconfig.get_paths()['include']}",
         f"-I{fmi_headers()}", f"-L{libdir}", f"-Wl,-rpath,{libdir}", f"-lpython{version}",
         "-ldl", "-lm"],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    return binary


def rate(binary: Path, fmus: Path, n: int, steps: int, denominator: int, out: Path) -> float:
    """Steps/s of the loop over Source2 -> Feedthrough2 x ``n`` for ``steps`` steps of
    1/``denominator`` s, writing ``out``."""
    from fmpy import extract, read_model_description

    arguments: list[str] = []
    unpacked = []
    for name in ("Source2", "Feedthrough2"):
        fmu = fmus / f"{name}.fmu"
        folder = Path(extract(fmu))
        unpacked.append(folder)
        guid = read_model_description(fmu).guid
        library = folder / "binaries" / "linux64" / f"{name}.so"
        arguments += [str(library), guid, (folder / "resources").as_uri()]
    try:
        ran = subprocess.run(
            [str(binary), str(n), str(steps), str(denominator), str(out), *arguments],
            check=True, capture_output=True, text=True,
        )  # fmt: skip
    finally:
        for folder in unpacked:
            shutil.rmtree(folder, ignore_errors=True)
    return steps / float(ran.stdout)
