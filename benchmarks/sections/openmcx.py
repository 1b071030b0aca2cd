"""In-process FMU chain x2 and x10 against OpenMCx (C; the binary named by $OPENMCX, else the
rows are skipped, saying so): the same chains with OpenMCx's task annotation (Jacobi,
``parallel_single_thread``), OpenMCx's simulation phase timed as it reports it; and a check:
every value of OpenMCx's result files equals Coupler's results.csv within 1e-9 of the column's
largest magnitude (a row whose results differ FAILs).
"""

from __future__ import annotations

import asyncio
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import STEP, Row, Sizes, chain_ssd, coupler_run, interleaved

OPENMCX_STEPS = 20000
"""The most steps the OpenMCx rows run (200 s simulated): OpenMCx's summed time drifts from the
exact grid as it goes, past 1e-9 of the Source's sine amplitude by t = 335 s (a 600 s run: 1.0e-9
at a zero crossing), where the check could no longer tell a wrong result from the drift."""


OPENMCX_TOLERANCE = 1e-9
"""Largest difference between OpenMCx's value and Coupler's, relative to the column's largest
magnitude: OpenMCx gives its FMUs a summed time (t + h + h ...), Coupler the exact grid, which
shows only where a value crosses zero (docs/openmcx.md)."""


def openmcx_missing(binary: str) -> str:
    """Why ``$OPENMCX`` cannot run; empty when it can."""
    if not binary:
        return (
            "OPENMCX is not set (the path of an openmcx binary; docs/performance.md says how to "
            "build one)"
        )
    if not (Path(binary).is_file() and os.access(binary, os.X_OK)):
        return f"OPENMCX={binary} is not an executable file"
    return ""


def openmcx_chain_ssd(folder: Path, n: int, steps: int) -> Path:
    """``chain_ssd``'s chain for ``steps`` steps, with OpenMCx's task annotation: its Jacobi
    scheme (``parallel_single_thread``, Coupler's default; OpenMCx's own default runs a thread
    per component) and the step. In a folder of its own: OpenMCx writes beside it."""
    own = folder / f"openmcx-chain{n}"
    own.mkdir(exist_ok=True)
    task = (
        '<ssd:Annotations><ssc:Annotation type="com.avl.model.connect.ssp.task" '
        'xmlns:mc="com.avl.model.connect.ssp.task"><mc:Task stepType="parallel_single_thread" '
        f'deltaTime="{STEP}" endType="end_time"/></ssc:Annotation></ssd:Annotations>'
    )
    text = chain_ssd(own, n).read_text(encoding="utf-8")
    text = text.replace(
        '<ssd:DefaultExperiment startTime="0.0" stopTime="1.0"/>',
        f'<ssd:DefaultExperiment startTime="0.0" stopTime="{steps * STEP:.2f}">{task}'
        "</ssd:DefaultExperiment>",
    )
    path = own / "chain.ssd"
    path.write_text(text, encoding="utf-8")
    return path


def openmcx_rate(binary: str, ssd: Path, steps: int) -> float:
    """Steps/s of OpenMCx's simulation phase (the wall time it reports after "Simulation
    done.": its stepping loop with its result files, not reading, unpacking and initializing;
    as Coupler's first to last communication point). Results in ``results/`` beside the SSD."""
    import re

    for made in ("results", "temp"):  # OpenMCx refuses to unpack into an existing folder
        shutil.rmtree(ssd.parent / made, ignore_errors=True)
    done = subprocess.run(
        [binary, "-r", "results", "-t", "temp", "-L", "openmcx.log", ssd.name],
        cwd=ssd.parent,
        capture_output=True,
        text=True,
        check=False,
    )
    found = re.search(r"Simulation done\.[^\n]*\n[^\n]*\n[^\n]*Wall-Time:\s*([\d.]+)s", done.stdout)
    if done.returncode != 0 or found is None:
        raise RuntimeError(f"OpenMCx failed on {ssd} ({done.returncode}): {done.stdout[-1500:]}")
    return steps / float(found.group(1))


def openmcx_differences(results: Path, coupler_csv: Path) -> tuple[list[str], float]:
    """Where OpenMCx's result files (``<Component>_res.csv``) and Coupler's results.csv differ
    by more than OPENMCX_TOLERANCE, and the largest difference seen (of the column's scale)."""
    import csv

    with coupler_csv.open(newline="") as file:
        ours = list(csv.DictReader(file))
    problems: list[str] = []
    worst = 0.0
    for path in sorted(results.glob("*_res.csv")):
        component = path.name.removesuffix("_res.csv")
        with path.open(newline="") as file:
            lines = list(csv.reader(file))
        header, theirs = [h.strip() for h in lines[1]], lines[3:]
        if len(theirs) != len(ours):
            problems.append(f"{path.name}: {len(theirs)} rows, Coupler's {len(ours)}")
            continue
        for j, name in enumerate(header[1:], start=1):
            column = f"{component}.{name}"
            if column not in ours[0]:
                problems.append(f"{path.name}: {name}, which Coupler's results.csv has not")
                continue
            pairs = [
                (_value(r[j]), _value(row[column])) for r, row in zip(theirs, ours, strict=True)
            ]
            scale = max((abs(a) for a, _ in pairs if isinstance(a, float)), default=0.0) or 1.0
            for (a, b), r in zip(pairs, theirs, strict=True):
                if isinstance(a, float) and isinstance(b, float):
                    error = abs(a - b) / scale
                    worst = max(worst, error)
                    if error <= OPENMCX_TOLERANCE:
                        continue
                elif a == b:
                    continue
                problems.append(f"{column} at t={r[0].strip()}: Coupler {b!r}, OpenMCx {a!r}")
                break
    if not any(results.glob("*_res.csv")):
        problems.append(f"OpenMCx wrote no result files into {results}")
    return problems, worst


def _value(text: str) -> float | str:
    """A result file's value: a number (booleans as 1 and 0), else the text."""
    text = text.strip().strip('"')
    if text.lower() in ("true", "false"):
        return float(text.lower() == "true")
    try:
        return float(text)
    except ValueError:
        return text


async def openmcx(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    """The FMU chains against OpenMCx (the binary ``$OPENMCX``) on the same SSD, and a check
    that both computed the same results."""
    binary = os.environ.get("OPENMCX", "")
    why = openmcx_missing(binary)
    if why:
        log(f"OpenMCx rows skipped: {why}")
        extra.setdefault("skipped", []).append(f"chain x2 and x10 vs OpenMCx: skipped, {why}")
        return
    for n in (2, 10):
        log(f"in-process FMU chain x{n} against OpenMCx ({binary})")
        steps = min(sizes.chain_steps, OPENMCX_STEPS) // (1 if n == 2 else 2)
        ssd = openmcx_chain_ssd(work, n, steps)
        out = work / f"openmcx-coupler{n}"

        async def coupler_chain(ssd: Path = ssd, steps: int = steps, out: Path = out) -> float:
            return (await coupler_run(ssd, steps, out)).rate

        async def openmcx_chain(ssd: Path = ssd, steps: int = steps) -> float:
            return await asyncio.to_thread(openmcx_rate, binary, ssd, steps)

        coupler, reference = await interleaved(sizes.repeats, coupler_chain, openmcx_chain)
        assert coupler is not None and reference is not None
        problems, worst = openmcx_differences(ssd.parent / "results", out / "results.csv")
        rows.append(
            Row(
                f"in-process FMU chain x{n}",
                coupler,
                "OpenMCx (C)",
                reference,
                3.0,  # the core held at 3x OpenMCx (docs/performance.md)
                note=(
                    f"results equal, worst {worst:.1e} of the column's scale"
                    if not problems
                    else f"RESULTS DIFFER: {'; '.join(problems[:3])}"
                ),
                equal=not problems,
            )
        )
