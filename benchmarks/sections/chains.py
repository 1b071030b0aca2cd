"""In-process FMU chain xN: Source2 feeding N Feedthrough2 (real_out -> real_in), every output
recorded, `coupler`'s runner, the FMUs stepped by the native FMU step (C; with
COUPLER_NATIVE_STEPS=0 through Python, one ctypes call per FMI call); against a hand-written
FMPy FMU2Slave loop over the same FMUs (every output read each step) and libcosim (libcosimpy,
C++) with the same connections.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import Row, Sizes, chain_ssd, coupler_run, interleaved
from sections.peers import fmpy_loop, libcosim_loop


async def chains(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    for n in (2, 10):
        log(f"in-process FMU chain x{n}")
        ssd = chain_ssd(work, n)
        steps = sizes.chain_steps if n == 2 else sizes.chain_steps // 2

        async def coupler_chain(ssd: Path = ssd, steps: int = steps) -> float:
            return (await coupler_run(ssd, steps, work / "out")).rate

        async def fmpy_chain(n: int = n, steps: int = steps) -> float:
            return fmpy_loop(n, steps)

        async def cosim_chain(n: int = n, steps: int = steps) -> float | None:
            return libcosim_loop(n, steps * 5)

        coupler, fmpy, cosim = await interleaved(
            sizes.repeats, coupler_chain, fmpy_chain, cosim_chain
        )
        assert coupler is not None and fmpy is not None
        rows.append(Row(f"in-process FMU chain x{n}", coupler, "FMPy loop", fmpy, 1.0))
        if cosim is not None:
            rows.append(Row(f"in-process FMU chain x{n}", coupler, "libcosim (C++)", cosim, 0.5,
                            note="stretch target"))  # fmt: skip
