"""The tight physical limit of the in-process chains: ``cloop/chain.c``, a bare C loop making the
FMI calls a Coupler run of the chain makes and writing the same results.csv text with the same
shortest round-trip formatter (CPython's, which Coupler's native row calls). Built here with the
machine's C compiler against this interpreter's libpython and FMPy's FMI headers."""

from __future__ import annotations

import asyncio
import shutil
import subprocess
import sysconfig
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import FMUS, STEP, Row, Sizes, chain_ssd, coupler_run, interleaved

SOURCE = Path(__file__).resolve().parents[1] / "cloop" / "chain.c"


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


async def tight_loop(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The chains against their physical limit: a bare C loop (cloop.py) making the same FMI
    calls and writing the same results.csv text with the same formatter; both files compared
    byte for byte. Ten times the chains' steps: the loop takes well under a second."""
    why = missing()
    if why:
        log(f"tight C-loop rows skipped: {why}")
        extra.setdefault("skipped", []).append(f"chain x2 and x10 vs a bare C loop: {why}")
        return
    binary = build(work)
    for n in (2, 10):
        log(f"in-process FMU chain x{n} against a bare C loop")
        ssd = chain_ssd(work, n)
        steps = 10 * (sizes.chain_steps if n == 2 else sizes.chain_steps // 2)
        ours, theirs = work / f"tight-coupler{n}", work / f"tight-c{n}.csv"

        async def coupler_chain(ssd: Path = ssd, steps: int = steps, out: Path = ours) -> float:
            return (await coupler_run(ssd, steps, out)).rate

        async def c_chain(n: int = n, steps: int = steps, out: Path = theirs) -> float:
            return await asyncio.to_thread(rate, binary, FMUS, n, steps, round(1 / STEP), out)

        coupler, reference = await interleaved(sizes.repeats, coupler_chain, c_chain)
        assert coupler is not None and reference is not None
        same = (ours / "results.csv").read_bytes() == theirs.read_bytes()
        rows.append(
            Row(f"in-process FMU chain x{n}", coupler, "bare C loop", reference, 0.5,
                note="same calls; results.csv byte-identical" if same
                else "RESULTS DIFFER from the C loop's",
                equal=same)
        )  # fmt: skip
