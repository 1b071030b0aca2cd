"""Run FMUs with ``fmpy.simulate_fmu`` in a process of their own, as an FMI tool would.

    python fmpy_driver.py SPEC.json

SPEC: ``{"runs": [{"fmu": PATH, "stop": S, "step": H, "start_values": {...},
"outputs": [...]}, ...]}``. The runs happen one after the other in this one process (several
exported FMUs share it, as in any FMI tool). Prints one JSON line: ``{"results": [{"name":
[values...]}, ...]}`` (floats as JSON numbers: exact; FMPy records no String or Binary), or
``{"error": TEXT}``; the FMUs' log lines go to stdout before it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import fmpy


def simulate(run: dict[str, Any]) -> dict[str, list[Any]]:
    result = fmpy.simulate_fmu(
        run["fmu"],
        start_time=0.0,
        stop_time=run["stop"],
        step_size=run["step"],
        output_interval=run["step"],
        start_values=run.get("start_values", {}),
        output=run["outputs"],
    )
    return {name: result[name].tolist() for name in result.dtype.names}


def main() -> int:
    spec = json.loads(Path(sys.argv[1]).read_text())
    try:
        results = [simulate(run) for run in spec["runs"]]
    except Exception as exc:  # the FMU's failure is what the test looks at
        print(json.dumps({"error": str(exc)}), flush=True)
        return 1
    print(json.dumps({"results": results}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
