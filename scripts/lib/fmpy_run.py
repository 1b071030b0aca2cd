"""Run an exported gain FMU with FMPy and check its outputs (scripts/native-check.sh runs it in
the orchestrator image, against the gain participant the FMU was exported from).

    python fmpy_run.py Gain.fmu

Prints ``fmpy: ok ...`` when y = gain * u and x = the integral of u at every point, else exits 1.
"""

from __future__ import annotations

import math
import sys

import fmpy

GAIN, U, STEP, STOP = 3.0, 1.5, 0.125, 1.0


def main(fmu: str) -> int:
    result = fmpy.simulate_fmu(
        fmu,
        start_time=0.0,
        stop_time=STOP,
        step_size=STEP,
        output_interval=STEP,
        start_values={"gain": GAIN, "u": U},
        output=["y", "x"],
    )
    rows = [(float(t), float(y), float(x)) for t, y, x in result]
    wrong = [
        row
        for row in rows
        if row[1] != GAIN * U or not math.isclose(row[2], U * row[0], abs_tol=1e-12)
    ]
    if wrong or len(rows) != round(STOP / STEP) + 1:
        print(f"fmpy: wrong values: {wrong or rows}")
        return 1
    print(f"fmpy: ok, {len(rows)} points, y = {GAIN * U}, x(t={STOP}) = {rows[-1][2]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
