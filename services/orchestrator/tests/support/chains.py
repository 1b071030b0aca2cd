"""A chain of the project's FMUs in an SSD of the test's own (master/test_native_kernel.py,
outputs/test_csv_rows.py).

    Source (FMI 2 or 3) --ramp, counter--> Feed1 --real, int, bool--> Feed2 --real--> Feed3
                                           (Feedthrough2, FMI 2)
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from coupler.testing import Annotation, Connection, Connector, SystemStructure, fmu

ROUTES = [
    ("Source", "ramp", "Feed1", "real_in"),
    ("Source", "counter", "Feed1", "int_in"),
    ("Feed1", "real_out", "Feed2", "real_in"),
    ("Feed1", "int_out", "Feed2", "int_in"),
    ("Feed1", "bool_out", "Feed2", "bool_in"),
    ("Feed2", "real_out", "Feed3", "real_in"),
    ("Feed3", "bool_out", "Feed1", "bool_in"),  # a loop: Jacobi and Gauss-Seidel differ
]
DECOUPLED = Annotation("org.coupler.connection", "Connection", {"decoupled": "true"})
"""The loop's last connection: Gauss-Seidel reads it from the previous step."""
STRING = ("Feed1", "string_out", "Feed2", "string_in")


TYPES = {"ramp": "Real", "sine": "Real", "counter": "Integer", "real": "Real", "int": "Integer",
         "bool": "Boolean", "string": "String"}  # fmt: skip


def connectors(outputs: list[str], inputs: list[str]) -> list[Connector]:
    """Connectors of every output and of the connected inputs."""
    return [
        Connector(name, kind, TYPES[name.split("_")[0]])
        for names, kind in ((outputs, "output"), (inputs, "input"))
        for name in names
    ]


def chain(
    folder: Path, fmus: Mapping[str, Path], source: str, routes: list[tuple[str, ...]]
) -> Path:
    def inputs(element: str) -> list[str]:
        return [d for _, _, c, d in routes if c == element]

    components = [fmu("Source", fmus[source], *connectors(["ramp", "sine", "counter"], []))] + [
        fmu(
            f"Feed{k}",
            fmus["Feedthrough2"],
            *connectors(["real_out", "int_out", "bool_out", "string_out"], inputs(f"Feed{k}")),
        )
        for k in (1, 2, 3)
    ]
    connections = [
        Connection(f"{a}.{b}", f"{c}.{d}", [DECOUPLED] if (a, c) == ("Feed3", "Feed1") else [])
        for a, b, c, d in routes
    ]
    return SystemStructure("Chain", components, connections, stop_time=2).write(
        folder / "chain.ssd"
    )


PARAMS = ("--param", "Feed2.gain=-1.5", "--param", "Feed1.int_offset=3", "--step", "0.01")
