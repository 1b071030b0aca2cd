"""FMI 3.0 arrays are indexed channels; clocks and scheduled execution are refused.

    StateSpace (FMI 3, arrays A[2,2] B[2,3] C[2,2] D[2,3] x0[2] u[3] -> y[2] x[2]), alone
    Source (FMI 3) --ramp--> StateSpace.u[2];  StateSpace.y[1] --> Integrator (FMI 3).u

StateSpace (fmus/common/statespace.h) is x' = A x + B u, y = C x + D u by explicit Euler, one
step per communication step. Its channels are the elements, 1-based and row-major: ``A[2,1]``
is row 2, column 1. Alone under ``coupler run`` with dyadic steps it must equal
``fmpy.simulate_fmu`` bit for bit (see test_fmpy_reference.py).
"""

from __future__ import annotations

import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path

import fmpy
import pytest

from coupler.testing import Component, Connector, SystemStructure, fmu

from .support import Coupler

#: The model description's start values (row-major), and the elements the tests bind.
STARTS = {
    "A": [0.0, 1.0, -2.0, -0.5],
    "B": [1.0, 0.0, 0.0, 0.0, 1.0, 0.5],
    "C": [1.0, 0.0, 0.5, 1.0],
    "D": [0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
    "x0": [1.0, 0.0],
    "u": [0.5, -1.0, 2.0],
}
BOUND = {"A[2,1]": -3.0, "B[2,3]": 0.75, "x0[2]": 0.25, "u[1]": -0.5, "u[3]": 1.5}


def _component(
    name: str,
    source: Path,
    parameters: Mapping[str, float | int],
    connectors: Mapping[str, str] | None = None,
) -> Component:
    """A component; ``connectors`` maps connector names to kinds (all Real)."""
    typed = [Connector(n, kind, "Real") for n, kind in (connectors or {}).items()]
    return fmu(name, source, *typed, parameters=parameters)


def _ssd(
    tmp_path: Path,
    components: Sequence[Component],
    connections: Sequence[tuple[str, str]] = (),
    stop: float = 2.0,
) -> Path:
    system = SystemStructure("Arrays", components, connections, stop_time=stop)
    return system.write(tmp_path / "arrays.ssd")


def _full(bound: Mapping[str, float]) -> dict[str, list[float]]:
    """The start values with the bound elements replaced, as whole arrays for FMPy."""
    cols = {"A": 2, "B": 3, "C": 2, "D": 3}
    arrays = {name: list(values) for name, values in STARTS.items()}
    for element, value in bound.items():
        name, index = element[:-1].split("[")
        position = [int(i) - 1 for i in index.split(",")]
        flat = position[0] * cols[name] + position[1] if len(position) == 2 else position[0]
        arrays[name][flat] = value
    return arrays


def test_array_fmu_alone_equals_fmpy(
    fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    ssd = _ssd(tmp_path, [_component("SS", fmus["StateSpace3"], BOUND)])
    out = tmp_path / "out"
    outcome = coupler("run", ssd, "--out", out, "--step", 0.125)
    assert outcome.code == 0, outcome.err

    reference = fmpy.simulate_fmu(
        str(fmus["StateSpace3"]),
        stop_time=2.0,
        output_interval=0.125,
        start_values=_full(BOUND),
    )
    rows = coupler.results(out)
    assert list(rows[0]) == ["time", "SS.y[1]", "SS.y[2]", "SS.x[1]", "SS.x[2]"]
    assert len(rows) == len(reference) == 17
    for row, expected in zip(rows, reference, strict=True):
        assert float(row["time"]) == float(expected["time"])
        for name in ("y", "x"):
            for i in (1, 2):
                assert float(row[f"SS.{name}[{i}]"]) == float(expected[name][i - 1]), (
                    name,
                    i,
                    row["time"],
                )
    # The bound elements took effect, row-major: x0[2] = 0.25 and y[2] = 0.5 x0[1] + x0[2] + u[3].
    assert (rows[0]["SS.x[2]"], rows[0]["SS.y[2]"]) == ("0.25", "2.25")


def test_array_elements_are_connectable(
    fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    """Jacobi, h = 0.25: SS steps from t_k with u[2] = ramp(t_k); Integ with u = y[1](t_k)."""
    ssd = _ssd(
        tmp_path,
        [
            _component("Source", fmus["Source3"], {"slope": 2.0}, {"ramp": "output"}),
            _component("SS", fmus["StateSpace3"], BOUND, {"u[2]": "input", "y[1]": "output"}),
            _component("Integ", fmus["Integrator3"], {}, {"u": "input"}),
        ],
        [
            ("Source.ramp", "SS.u[2]"),
            ("SS.y[1]", "Integ.u"),
        ],
        stop=1.0,
    )
    out = tmp_path / "out"
    outcome = coupler("run", ssd, "--out", out, "--step", 0.25, "--algorithm", "jacobi")
    assert outcome.code == 0, outcome.err

    h, p = 0.25, _full(BOUND)
    a, b, x = p["A"], p["B"], list(p["x0"])
    integral, xs, integrals = 0.0, [], []
    for k in range(5):
        xs.append(list(x))
        integrals.append(integral)
        u = [p["u"][0], 2.0 * k * h, p["u"][2]]
        y1 = x[0]  # C[1,:] = (1, 0), D[1,:] = 0
        integral += h * y1
        dx = [
            a[0] * x[0] + a[1] * x[1] + b[0] * u[0] + b[1] * u[1] + b[2] * u[2],
            a[2] * x[0] + a[3] * x[1] + b[3] * u[0] + b[4] * u[1] + b[5] * u[2],
        ]
        x = [x[0] + h * dx[0], x[1] + h * dx[1]]
    assert coupler.column(out, "SS.x[1]") == pytest.approx([v[0] for v in xs], rel=1e-12)
    assert coupler.column(out, "SS.x[2]") == pytest.approx([v[1] for v in xs], rel=1e-12)
    assert coupler.column(out, "Integ.x") == pytest.approx(integrals, rel=1e-12)


def _tampered(source: Path, target: Path, old: str, new: str) -> Path:
    with zipfile.ZipFile(source) as fmu, zipfile.ZipFile(target, "w") as copy:
        for item in fmu.infolist():
            data = fmu.read(item)
            if item.filename == "modelDescription.xml":
                assert old.encode() in data
                data = data.replace(old.encode(), new.encode(), 1)
            copy.writestr(item, data)
    return target


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            'variability="fixed" start="2" description="Number of states',
            'variability="fixed" description="Number of states',
            "the size of array 'A' is given by 'nx' (value reference 1), which has no start value",
        ),
        (
            '<Dimension valueReference="1"/>\n    </Float64>\n    <Float64 name="u"',
            '<Dimension valueReference="99"/>\n    </Float64>\n    <Float64 name="u"',
            "the size of array 'x0' is given by value reference 99, which no variable has",
        ),
        (
            'name="nx" valueReference="1" causality="structuralParameter"',
            'name="nx" valueReference="1" causality="parameter"',
            "not a UInt64 constant or structural parameter with a start value",
        ),
    ],
    ids=["no-start", "unknown-reference", "not-structural"],
)
def test_unresolvable_array_size_is_refused(
    fmus: Mapping[str, Path],
    coupler: Coupler,
    tmp_path: Path,
    old: str,
    new: str,
    message: str,
) -> None:
    fmu = _tampered(fmus["StateSpace3"], tmp_path / "StateSpace3.fmu", old, new)
    for argv in (("describe", fmu), ("validate", _ssd(tmp_path, [_component("SS", fmu, {})]))):
        outcome = coupler(*argv)
        assert outcome.code == 1, argv
        assert message in outcome.err
        assert "Traceback" not in outcome.err


def test_structural_parameter_keeps_its_start_value(
    fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    """nx sizes A, B, C, x0 and x: the channels exist for nx = 2, so a run cannot change it."""
    same = _ssd(tmp_path, [_component("SS", fmus["StateSpace3"], {"nx": 2})])
    assert coupler("run", same, "--out", tmp_path / "same", "--step", 0.5).code == 0

    other = _ssd(tmp_path, [_component("SS", fmus["StateSpace3"], {"nx": 3})])
    outcome = coupler("run", other, "--out", tmp_path / "other", "--step", 0.5)
    assert outcome.code == 1
    assert "structural parameter 'nx' sizes the array(s) A, B, C, x0, x" in outcome.err
    assert "it cannot be set to 3" in outcome.err
    assert "Traceback" not in outcome.err


@pytest.mark.parametrize(
    ("fmu", "message"),
    [
        ("Clocks3", "has FMI 3.0 Clock variable(s) 'tick' (input)"),
        ("Scheduled3", "implements FMI 3.0 Scheduled Execution only"),
    ],
)
def test_clocks_and_scheduled_execution_are_refused(
    fmu: str,
    message: str,
    faulty_fmus: Mapping[str, Path],
    coupler: Coupler,
    tmp_path: Path,
) -> None:
    ssd = _ssd(tmp_path, [_component("F", faulty_fmus[fmu], {})])
    for argv in (("describe", faulty_fmus[fmu]), ("validate", ssd)):
        outcome = coupler(*argv)
        assert outcome.code == 1, argv
        assert message in outcome.err
        assert "Traceback" not in outcome.err
