"""OpenMCx's dialect and semantics: the project's own models written for OpenMCx
(``data/openmcx/*.ssd``, its FMUs built from fmus/ and fmus/openmcx/) run with ``coupler run``
and equal the result files OpenMCx wrote for them (``data/openmcx/expected/``, provenance in
``data/openmcx/README.md``), and the values the models' equations give.

Equality with OpenMCx's files: every file, header, unit line, row count and time; every number
within 1e-9 of its column's largest magnitude (OpenMCx prints 14 digits, and hands its FMUs a
summed time where Coupler's is exact: docs/openmcx.md).
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coupler.testing import process_group
from coupler_tools.fmubuild import build_all

from ..support import DATA, REPO, Coupler
from ..support.openmcx_files import differences, table

CASES = DATA / "openmcx"


@pytest.fixture(scope="session")
def openmcx_fmus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """fmus/ and fmus/openmcx/ built into one folder, as data/openmcx/README.md says."""
    out = tmp_path_factory.mktemp("openmcx-fmus")
    build_all(REPO / "fmus", out)
    build_all(REPO / "fmus" / "openmcx", out)
    return out


@pytest.fixture(autouse=True)
def fmu_dir(openmcx_fmus: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("COUPLER_FMU_DIR", str(openmcx_fmus))
    return openmcx_fmus


def run_case(coupler: Coupler, case: str, out: Path, *options: str) -> None:
    outcome = coupler(
        "run", CASES / f"{case}.ssd", "--out", out, "--no-progress", "--openmcx-results", *options
    )
    assert outcome.code == 0, outcome.err


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(p.name for p in (CASES / "expected").iterdir()))
def test_equal_to_openmcx(coupler: Coupler, tmp_path: Path, case: str) -> None:
    """Each model, run by ``coupler run --openmcx-results``, writes the files OpenMCx wrote."""
    run_case(coupler, case, tmp_path)
    expected = sorted(p.name for p in (CASES / "expected" / case).glob("*.csv"))
    written = sorted(p.name for p in tmp_path.glob("*_*.csv"))
    assert written == expected
    problems: list[str] = []
    for name in expected:
        found, _ = differences(CASES / "expected" / case / name, tmp_path / name)
        problems += found
    assert not problems, "\n".join(problems[:20])


def column(out: Path, name: str) -> list[float]:
    return Coupler.column(out, name)


def test_constant_name_in_model_defaults(coupler: Coupler, tmp_path: Path) -> None:
    """
        C (Constant 3, (1 2 3)) --k--> Feed.in (nameInModel real_in)      Feed.out = 2 * 3
                                --v[1..3]--> Sum.a[1..3]
        Spare.real_in: unconnected, default 8          Spare.real_out = 16
        Sum.b[1..3]: unconnected, default (10 20 30)   Sum.s = (11, 22, 33), total 66

    From t = 0 on: OpenMCx initializes Feed with the constant it is connected to.
    """
    run_case(coupler, "constant_nameinmodel", tmp_path)
    rows = len(column(tmp_path, "time"))
    assert column(tmp_path, "Feed.real_out") == [6.0] * rows  # the SSD's Feed.out
    assert column(tmp_path, "Spare.real_out") == [16.0] * rows
    assert [column(tmp_path, f"Sum.s[{i}]")[0] for i in (1, 2, 3)] == [11.0, 22.0, 33.0]
    assert column(tmp_path, "Sum.total") == [66.0] * rows
    head, _, _ = table(tmp_path / "C_res.csv")
    assert head == ["Time", "v[1]", "v[2]", "v[3]"]  # k has writeResults="false"
    head, _, _ = table(tmp_path / "Feed_res.csv")
    assert head == ["Time", "out"]  # the SSD's connector names, not the FMU's
    assert coupler.summary(tmp_path)["semantics"] == "openmcx"


def test_vector_slices(coupler: Coupler, tmp_path: Path) -> None:
    """
        C.w[2..4] -> Sum1.a[1..3]   C.w[1] -> Sum1.b[1]   Sum1.b[2], b[3]: default (9 0.5 0.25)
        Sum1.s[2..3] -> Sum2.a[1..2]   Sum1.total -> Sum2.a[3]   Sum2.b: nothing (start 0)

    Sum1.s = (2+1, 3+0.5, 4+0.25), total 10.75; Sum2.s = (3.5, 4.25, 10.75), total 18.5.
    """
    run_case(coupler, "vector_slices", tmp_path)
    assert [column(tmp_path, f"Sum1.s[{i}]")[-1] for i in (1, 2, 3)] == [3.0, 3.5, 4.25]
    assert column(tmp_path, "Sum1.total")[-1] == 10.75
    assert [column(tmp_path, f"Sum2.s[{i}]")[-1] for i in (1, 2, 3)] == [3.5, 4.25, 10.75]
    assert column(tmp_path, "Sum2.total")[-1] == 18.5
    head, _, _ = table(tmp_path / "Sum2_in.csv")
    assert head == ["Time", "a[1]", "a[2]", "a[3]"]  # b: neither connected nor defaulted


@pytest.mark.parametrize("case", ["integrators_sequential", "integrators_parallel"])
def test_integrators(coupler: Coupler, tmp_path: Path, case: str) -> None:
    """
        Source (r = 1 + 2t, s = sin 2 pi t) --r--> Int (gain 3, y0 0.5, 2 sub-steps)
                                           --r--> Int1 (defaults: gain 1, y0 0)
                                           --r, s, r--> VInt (u[1], u[2], w -> y[0], y[1], y[2])

    Explicit Euler, h = 0.01: sequential reads r(t + h) (Source stepped first), parallel r(t).
    """
    run_case(coupler, case, tmp_path)
    h, lag = 0.01, (1 if case.endswith("sequential") else 0)
    int_y, int1_y, vint_y0 = [0.5], [0.0], [1.5]
    for k in range(5):
        r = 1 + 2 * (k + lag) * h
        int_y.append(int_y[-1] + 3 * h * r)
        int1_y.append(int1_y[-1] + h * r)
        vint_y0.append(vint_y0[-1] + h * r)
    assert column(tmp_path, "Int.y") == pytest.approx(int_y, rel=1e-12)
    assert column(tmp_path, "Int1.y") == pytest.approx(int1_y, rel=1e-12)
    assert column(tmp_path, "VInt.y[0]") == pytest.approx(vint_y0, rel=1e-12)
    assert column(tmp_path, "VInt.y[2]") == pytest.approx(vint_y0, rel=1e-12)
    sine = [1.5]
    for k in range(5):
        sine.append(sine[-1] + h * math.sin(2 * math.pi * (k + lag) * h))
    assert column(tmp_path, "VInt.y[1]") == pytest.approx(sine, rel=1e-12)


@pytest.mark.parametrize("case", ["multirate_parallel", "multirate_sequential"])
def test_multirate(coupler: Coupler, tmp_path: Path, case: str) -> None:
    """
        Slow (Source2, its own step 0.05 s) --sine--> HoldNone (no inter/extrapolation)
                                            --sine--> Hold0 (zero/zero), Hold1 (first/first)
        Fast (Source2, 0.01 s) --sine--> End0 (zero), End1 (first), both inputAtEndTime

    Slow runs ahead: at t it has already reached its next point. Hold1 interpolates linearly
    between Slow's points; HoldNone and Hold0 hold the point Slow reached. results.csv shows Slow's
    point of its latest time not after t.
    """
    run_case(coupler, case, tmp_path)

    def slow(t: float) -> float:
        return math.sin(2 * math.pi * 1.5 * t)

    times = column(tmp_path, "time")
    assert column(tmp_path, "Slow.sine")[1:5] == [0.0] * 4  # its point of t = 0
    assert column(tmp_path, "Slow.sine")[5] == pytest.approx(slow(0.05), rel=1e-12)
    _, _, rows = table(tmp_path / "Hold1_in.csv")
    for row in rows[:10]:  # within [0, 0.05] and [0.05, 0.1]: the line between Slow's points
        t = float(row[0])
        a, b = (0.0, 0.05) if t <= 0.05 else (0.05, 0.1)
        line = slow(a) + (t - a) * (slow(b) - slow(a)) / (b - a)
        assert float(row[1]) == pytest.approx(line, rel=1e-12, abs=1e-15)
    _, _, rows = table(tmp_path / "HoldNone_in.csv")
    assert float(rows[1][1]) == pytest.approx(slow(0.05), rel=1e-12)  # at t = 0.01
    assert len(times) == 21
    _, _, rows = table(tmp_path / "Slow_res.csv")
    assert [float(r[0]) for r in rows] == [0.0, 0.05, 0.1, 0.15, 0.2]  # its own times only


def test_units_fan_out(coupler: Coupler, tmp_path: Path) -> None:
    """
    C.length [m] = 3 --> Sum.a[1], a[2], a[3] [cm]  (cm = 0.01 m in the SSD's <Units>)
    Sum.b = (1 2 3) default                         s = (301, 302, 303), total 906
    C.temperature [degC] = 20 --> Kelvin.real_in [K]   real_out = 2 * 293.15
    """
    run_case(coupler, "units_fanout", tmp_path)
    assert [column(tmp_path, f"Sum.s[{i}]")[-1] for i in (1, 2, 3)] == [301.0, 302.0, 303.0]
    assert column(tmp_path, "Sum.total")[-1] == 906.0
    assert column(tmp_path, "Kelvin.real_out")[-1] == pytest.approx(586.3, rel=1e-15)
    _, units, rows = table(tmp_path / "Sum_in.csv")
    assert units[1:4] == ["cm", "cm", "cm"]
    assert [float(x) for x in rows[0][1:4]] == [300.0, 300.0, 300.0]


def test_first_component_ends_the_run(coupler: Coupler, tmp_path: Path) -> None:
    """Stair2 (terminate_at 0.035) finishes in [0.03, 0.04]; endType first_component ends the
    run after that step (no deltaTime: 0.01 s); its last row holds its outputs at 0.035."""
    run_case(coupler, "first_component", tmp_path)
    assert column(tmp_path, "time") == [0.0, 0.01, 0.02, 0.03, 0.04]
    assert column(tmp_path, "Stair.counter")[-1] == 4
    summary = coupler.summary(tmp_path)
    assert summary["status"] == "terminated"
    assert "first_component" in summary["reason"]


@pytest.mark.parametrize(
    ("case", "feed"),
    [("loop_ifneeded", [2.0, 2.4, 2.88]), ("loop_never", [0.0, 2.0, 2.4])],
)
def test_loops_cut_as_openmcx_cuts_them(
    coupler: Coupler, tmp_path: Path, case: str, feed: list[float]
) -> None:
    """
        Int (y0 = 1) --y--> Feed (x2) --real_out--> Int        h = 0.1, sequential

    Every connection may be cut (IfNeeded); OpenMCx cuts Feed -> Int (into the element listed
    first), or, that one marked Never, Int -> Feed: Feed then runs first on Int's previous y,
    and carries 0 at t = 0 (a cut connection has no value during initialization).
    y(t + 0.1) = y + 0.1 * 2y = 1.2 y either way.
    """
    run_case(coupler, case, tmp_path)
    assert column(tmp_path, "Int.y")[:3] == pytest.approx([1.0, 1.2, 1.44], rel=1e-15)
    assert column(tmp_path, "Feed.real_out")[:3] == pytest.approx(feed, rel=1e-15)


def test_port_transforms(coupler: Coupler, tmp_path: Path) -> None:
    """
    Source.ramp --> In.real_in (scale 2, offset 1, then clamped to [0.5, 1.06])
    Out.real_in: default 0.25; Out.real_out: clamped to [0.45, 0.5] first, then * 10 - 1
    """
    run_case(coupler, "port_transforms", tmp_path)
    assert column(tmp_path, "Out.real_out")[1:] == [4.0] * (len(column(tmp_path, "time")) - 1)
    _, _, rows = table(tmp_path / "In_in.csv")
    ramp = [0.01 * (k + 1) for k in range(len(rows))]  # sequential: r(t + h)
    want = [min(max(2 * r + 1, 0.5), 1.06) for r in ramp]
    assert [float(r[1]) for r in rows[:-1]] == pytest.approx(want[:-1], rel=1e-12)


def test_no_annotation_default_step_coupler_semantics(coupler: Coupler, tmp_path: Path) -> None:
    """No OpenMCx annotation at all: Coupler's semantics (Jacobi), OpenMCx's default step
    0.01 s; the same values as OpenMCx's parallel step types.

        Source (r = t) --> Feed1 (x2) --> Feed2 (x2)       Feed1(t) = 2 r(t - h)
    """
    outcome = coupler("run", CASES / "chain_default_task.ssd", "--out", tmp_path, "--no-progress")
    assert outcome.code == 0, outcome.err
    summary = coupler.summary(tmp_path)
    assert (summary["step_size"], summary["semantics"]) == (0.01, "coupler")
    times = column(tmp_path, "time")
    assert column(tmp_path, "Feed1.real_out") == pytest.approx(
        [0.0] + [2 * (t - 0.01) for t in times[1:]], abs=1e-15
    )
    _, _, rows = table(CASES / "expected" / "chain_default_task" / "Feed2_res.csv")
    assert column(tmp_path, "Feed2.real_out") == pytest.approx(
        [float(r[1]) for r in rows], rel=1e-12, abs=1e-15
    )


def test_forced_semantics_and_validate(coupler: Coupler, tmp_path: Path) -> None:
    """``--openmcx`` gives a plain SSD OpenMCx's semantics; validate accepts the dialect."""
    outcome = coupler(
        "run", CASES / "chain_sequential.ssd", "--out", tmp_path, "--no-progress", "--openmcx"
    )
    assert outcome.code == 0, outcome.err
    assert coupler.summary(tmp_path)["semantics"] == "openmcx"
    for case in sorted(CASES.glob("*.ssd")):
        outcome = coupler("validate", case)
        assert outcome.code == 0, (case.name, outcome.err)


# -- bad input ------------------------------------------------------------------------------

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<SystemStructureDescription xmlns="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="bad">
  <System name="Root">
    <Elements>
{elements}
    </Elements>{connections}
  </System>
  <DefaultExperiment startTime="0" stopTime="0.02">{task}</DefaultExperiment>
</SystemStructureDescription>
"""
PORT = 'type="com.avl.model.connect.ssp.port" xmlns:mc="com.avl.model.connect.ssp.port"'
SLICE = (
    'type="com.avl.model.connect.ssp.connection" xmlns:mc="com.avl.model.connect.ssp.connection"'
)


def vector(name: str, kind: str, port: str = '<mc:RealVector startIndex="1" endIndex="3"/>') -> str:
    return (
        f'<Connector name="{name}" kind="{kind}"><ssc:Real/><Annotations>'
        f"<ssc:Annotation {PORT}><mc:Port>{port}</mc:Port></ssc:Annotation>"
        "</Annotations></Connector>"
    )


CONSTANT = (
    '      <Component name="C" source="" type="application/avl-mcx-constant"><Connectors>'
    + vector("v", "output")
    + '</Connectors><Annotations><ssc:Annotation type="com.avl.model.connect.ssp.component.'
    'constant" xmlns:mc="com.avl.model.connect.ssp.component.constant"><mc:SpecificData>'
    '<mc:RealVector value="1 2 3"/></mc:SpecificData></ssc:Annotation></Annotations></Component>'
)
SUM = (
    '      <Component name="Sum" source="${COUPLER_FMU_DIR}/VectorSum2.fmu"><Connectors>'
    + vector("a", "input")
    + vector("b", "input", '<mc:RealVector startIndex="1" endIndex="3" default="0 0 0"/>')
    + "</Connectors></Component>"
)


def bad(
    tmp_path: Path,
    connections: str = "",
    elements: str = CONSTANT + "\n" + SUM,
    task: str = "",
) -> Path:
    path = tmp_path / "bad.ssd"
    if connections:
        connections = f"\n    <Connections>\n{connections}\n    </Connections>"
    path.write_text(SSD.format(elements=elements, connections=connections, task=task))
    return path


def sliced(start: str = "", end: str = "") -> str:
    return (
        '      <Connection startElement="C" startConnector="v" endElement="Sum" endConnector="a">'
        f"<Annotations><ssc:Annotation {SLICE}><mc:Connection>{start}{end}</mc:Connection>"
        "</ssc:Annotation></Annotations></Connection>"
    )


def refused(coupler: Coupler, path: Path, *fragments: str) -> str:
    """``coupler validate`` refuses the file: exit 1, one error naming the line, no traceback."""
    outcome = coupler("validate", path)
    assert outcome.code == 1, outcome
    assert outcome.err.startswith("error: ") and "Traceback" not in outcome.err, outcome.err
    for fragment in fragments:
        assert fragment in outcome.err, (fragment, outcome.err)
    return outcome.err


def line(path: Path, fragment: str) -> str:
    """``bad.ssd line N`` of the first line holding ``fragment``."""
    lines = path.read_text().splitlines()
    return f"bad.ssd line {next(i for i, t in enumerate(lines, 1) if fragment in t)}"


def test_a_slice_out_of_range_names_both_ends(coupler: Coupler, tmp_path: Path) -> None:
    path = bad(
        tmp_path,
        sliced('<mc:Start startIndex="1" endIndex="3"/>', '<mc:End startIndex="2" endIndex="4"/>'),
    )
    refused(
        coupler,
        path,
        line(path, 'endConnector="a"'),
        "connection C.v -> Sum.a",
        "the slice Sum.a[2..4] is out of range: 'Sum.a' has the elements a[1] .. a[3]",
    )
    path = bad(tmp_path, sliced('<mc:Start startIndex="0" endIndex="2"/>'))
    refused(coupler, path, "the slice C.v[0..2] is out of range: 'C.v' has the elements v[1]")


def test_slices_of_different_lengths_or_on_the_wrong_connectors(
    coupler: Coupler, tmp_path: Path
) -> None:
    path = bad(
        tmp_path,
        sliced('<mc:Start startIndex="1" endIndex="2"/>', '<mc:End startIndex="1" endIndex="3"/>'),
    )
    refused(coupler, path, "2 elements (C.v[1] .. C.v[2]) cannot drive 3 (Sum.a[1] .. Sum.a[3])")
    path = bad(tmp_path, sliced())
    refused(coupler, path, "'C.v' is a vector connector (v[1] .. v[3]); name the elements")
    elements = (
        CONSTANT
        + "\n"
        + SUM.replace(
            vector("a", "input"),
            vector("a", "input") + ('<Connector name="x" kind="input"><ssc:Real/></Connector>'),
        )
    )
    connection = sliced(
        '<mc:Start startIndex="1" endIndex="1"/>', '<mc:End startIndex="1" endIndex="1"/>'
    ).replace('endConnector="a"', 'endConnector="x"')
    refused(coupler, bad(tmp_path, connection, elements), "'Sum.x', which is a scalar connector")


def test_unknown_openmcx_types_and_attributes_name_their_line(
    coupler: Coupler, tmp_path: Path
) -> None:
    elements = CONSTANT.replace("avl-mcx-constant", "avl-mcx-sinus")
    path = bad(tmp_path, elements=elements)
    refused(
        coupler,
        path,
        line(path, "avl-mcx-sinus"),
        "component 'C' has type 'application/avl-mcx-sinus', which is not supported",
    )
    elements = CONSTANT + "\n" + SUM.replace('default="0 0 0"', 'defualt="0 0 0"')
    path = bad(tmp_path, elements=elements)
    refused(
        coupler, path, line(path, "defualt"), "<RealVector> has no attribute 'defualt' in OpenMCx"
    )
    elements = CONSTANT + "\n" + SUM.replace('default="0 0 0"', 'default="0 0"')
    path = bad(tmp_path, elements=elements)
    refused(coupler, path, line(path, 'default="0 0"'), "has 2 values for 3 elements")
    annotation = (
        '<Annotations><ssc:Annotation type="com.avl.model.connect.ssp.parameter">'
        "<x/></ssc:Annotation></Annotations>"
    )
    elements = CONSTANT + "\n" + SUM.replace("</Connectors>", "</Connectors>" + annotation)
    path = bad(tmp_path, elements=elements)
    refused(coupler, path, line(path, "ssp.parameter"), "parameter arrays (p[k,j]) are not")
    elements = CONSTANT + "\n" + SUM.replace("ssp.parameter", "ssp.componnet")
    path = bad(
        tmp_path,
        elements=CONSTANT
        + "\n"
        + SUM.replace(
            "</Connectors>", "</Connectors>" + annotation.replace("ssp.parameter", "ssp.componnet")
        ),
    )
    refused(coupler, path, "OpenMCx defines no such annotation")
    task = (
        '<Annotations><ssc:Annotation type="com.avl.model.connect.ssp.task">'
        '<mc:Task xmlns:mc="com.avl.model.connect.ssp.task" stepType="parallel_multithreaded"/>'
        "</ssc:Annotation></Annotations>"
    )
    path = bad(tmp_path, task=task)
    refused(coupler, path, line(path, "stepType"), "stepType 'parallel_multithreaded' is not one")


def test_constants_name_in_model_and_interpolation_checked(
    coupler: Coupler, tmp_path: Path
) -> None:
    elements = CONSTANT.replace('value="1 2 3"', 'value="1 2"') + "\n" + SUM
    path = bad(tmp_path, elements=elements)
    refused(coupler, path, "has 2 values for output 'C.v' of 3 elements")
    elements = CONSTANT + "\n" + SUM.replace("<mc:Port>", '<mc:Port nameInModel="z">', 1)
    path = bad(tmp_path, sliced(), elements)
    refused(coupler, bad(tmp_path, elements=elements), "(nameInModel 'z[1]') does not exist")
    interpolation = (
        '<ssc:Annotation type="com.avl.model.connect.ssp.connection.inter_extrapolation">'
        '<mc:InterExtrapolation xmlns:mc="com.avl.model.connect.ssp.connection.'
        'inter_extrapolation" extrapolationOrder="first"/></ssc:Annotation>'
    )
    connection = sliced(
        '<mc:Start startIndex="1" endIndex="3"/>', '<mc:End startIndex="1" endIndex="3"/>'
    ).replace("</Annotations>", interpolation + "</Annotations>")
    path = bad(tmp_path, connection)
    refused(
        coupler,
        path,
        line(path, "extrapolationOrder"),
        "lacks the attribute 'interpolationOrder' OpenMCx requires",
    )


def test_a_loop_nothing_may_cut(coupler: Coupler, tmp_path: Path) -> None:
    """Int -> Feed -> Int, both connections Never: OpenMCx cannot order it, nor can Coupler."""
    text = (
        (CASES / "loop_never.ssd")
        .read_text()
        .replace(
            '<Connection startElement="Int" startConnector="y" endElement="Feed" '
            'endConnector="real_in"/>',
            '<Connection startElement="Int" startConnector="y" endElement="Feed" '
            'endConnector="real_in"><Annotations><ssc:Annotation type="com.avl.model.connect.ssp.'
            'connection.decoupling" xmlns:mc="com.avl.model.connect.ssp.connection.decoupling">'
            "<mc:Decoupling><mc:Never/></mc:Decoupling></ssc:Annotation></Annotations></Connection>",
        )
    )
    path = tmp_path / "never.ssd"
    path.write_text(text)
    refused(coupler, path, "the loop Int -> Feed -> Int cannot be broken")


def test_slow_readers_run_ahead_and_past_the_stop_time(coupler: Coupler, tmp_path: Path) -> None:
    """
        Source (0.01 s, r = 100 t) --r--> Step (0.05 s, zero/zero), Line (0.05 s, first/first)
        sequential, stop 0.16 s

    Line interpolates r at its own times and extrapolates past the source's last point;
    Step reads "step right" at OpenMCx's summed time 0.1 + 0.05 = 0.15000000000000002, after
    the point 0.15: the value of 0.16. Both step on to 0.2, past the stop time.
    """
    run_case(coupler, "multirate_slow_reader", tmp_path)
    _, _, line = table(tmp_path / "Line_in.csv")
    assert [float(r[1]) for r in line] == pytest.approx([0.0, 5.0, 10.0, 15.0, 20.0], rel=1e-12)
    _, _, step = table(tmp_path / "Step_in.csv")
    assert [float(r[1]) for r in step] == pytest.approx([0.0, 5.0, 10.0, 16.0, 16.0], rel=1e-12)
    _, _, rows = table(tmp_path / "Step_res.csv")
    assert [round(float(r[0]), 12) for r in rows] == [0.0, 0.05, 0.1, 0.15, 0.2]
    assert column(tmp_path, "time")[-1] == 0.16  # results.csv ends at the stop time


# -- sizes written in the SSD, bounded before anything is built (issue 37) ----------------------

COUPLER_SCRIPT = Path(sys.executable).with_name("coupler")
MB = 1024 * 1024


PEAK_OF = (
    "import os, sys; pid = os.spawnv(os.P_NOWAIT, sys.argv[1], sys.argv[1:]); "
    "_, status, usage = os.wait4(pid, 0); print(usage.ru_maxrss); "
    "sys.exit(os.waitstatus_to_exitcode(status))"
)
"""Runs a command and prints its peak RSS [KiB]: forked from this small process, not from
pytest's (a child's peak counts what it had between fork and exec)."""


def refused_small(path: Path, *fragments: str) -> int:
    """``coupler validate`` as a process of its own refuses ``path`` (exit 1, one error naming
    its line, no traceback): its peak memory [bytes], read from the kernel at its end."""
    done = subprocess.run(
        [sys.executable, "-c", PEAK_OF, str(COUPLER_SCRIPT), "validate", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    err = done.stderr
    assert done.returncode == 1, err
    assert err.startswith("error: ") and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in err, (fragment, err)
    return int(done.stdout.split()[-1]) * 1024


INTEGRATOR = (
    '      <Component name="I" source="" type="application/avl-mcx-integrator"><Connectors>'
    '<Connector name="u" kind="input"><ssc:Real/></Connector>'
    '<Connector name="y" kind="output"><ssc:Real/></Connector></Connectors><Annotations>'
    '<ssc:Annotation type="com.avl.model.connect.ssp.component.integrator" '
    'xmlns:mc="com.avl.model.connect.ssp.component.integrator">'
    "<mc:SpecificData {data}/></ssc:Annotation></Annotations></Component>"
)


@pytest.mark.parametrize(
    ("elements", "connection", "at", "says"),
    [
        pytest.param(
            CONSTANT.replace('endIndex="3"', 'endIndex="1000000000"'),
            "",
            'endIndex="1000000000"',
            "vector connector 'C.v' has 1000000000 elements",
            id="a vector port",
        ),
        pytest.param(
            CONSTANT + "\n" + SUM,
            sliced('<mc:Start startIndex="1" endIndex="999999999"/>'),
            'endIndex="999999999"',
            "names 999999999 elements; a vector connector has at most 100000",
            id="a slice",
        ),
        pytest.param(
            CONSTANT.replace('endIndex="3"', 'endIndex="2000000"').replace(
                'value="1 2 3"', 'value="' + " ".join(["7"] * 2_000_000) + '"'
            ),
            "",
            'endIndex="2000000"',
            "has 2000000 elements",
            id="a constant vector",
        ),
        pytest.param(
            INTEGRATOR.format(data='numSubSteps="1000000000"'),
            "",
            "numSubSteps",
            'numSubSteps="1000000000" must be between 1 and 1000000',
            id="an integrator's sub-steps",
        ),
        pytest.param(
            INTEGRATOR.format(data='gain="nan"'),
            "",
            'gain="nan"',
            'gain="nan"> is not a finite number',
            id="a gain of NaN",
        ),
        pytest.param(
            CONSTANT.replace('value="1 2 3"', 'value="1 inf 3"'),
            "",
            'value="1 inf 3"',
            "is not a finite Real value",
            id="a constant of inf",
        ),
    ],
)
def test_sizes_and_numbers_written_in_the_ssd_are_bounded_before_anything_is_built(
    tmp_path: Path, elements: str, connection: str, at: str, says: str
) -> None:
    """A count in the SSD is checked against Coupler's ceiling (and the component's own range)
    before it is expanded: refused with its line, in a process that stays small (measured:
    about 0.8 s and 75 MB each; expanded, the vector port grew past 7 GB)."""
    path = bad(tmp_path, connection, elements)
    peak = refused_small(path, line(path, at), says)
    assert peak < 200 * MB, f"validate peaked at {peak / MB:.0f} MB"


def test_a_built_in_is_held_to_the_call_deadline(coupler: Coupler, tmp_path: Path) -> None:
    """
        Constant --c--> I (Integrator, 1,000,000 sub-steps a step)     --call-timeout 0.5

    One step of I is a million calls of the built-in, each quick: the deadline holds for the
    whole step, so the run fails naming it instead of computing on for seconds a step.
    """
    constant = (
        '      <Component name="C" source="" type="application/avl-mcx-constant"><Connectors>'
        '<Connector name="c" kind="output"><ssc:Real/></Connector></Connectors><Annotations>'
        '<ssc:Annotation type="com.avl.model.connect.ssp.component.constant" '
        'xmlns:mc="com.avl.model.connect.ssp.component.constant"><mc:SpecificData>'
        '<mc:Real value="1"/></mc:SpecificData></ssc:Annotation></Annotations></Component>'
    )
    elements = constant + "\n" + INTEGRATOR.format(data='numSubSteps="1000000"')
    connection = (
        '      <Connection startElement="C" startConnector="c" endElement="I" endConnector="u"/>'
    )
    path = bad(tmp_path, connection, elements)
    out = tmp_path / "out"
    outcome = coupler.process("run", path, "--out", out, "--call-timeout", "0.5")
    assert outcome.code == 1, outcome
    assert "I.DoStep [DEADLINE_EXCEEDED]: no answer within 0.5 s" in outcome.err, outcome.err
    assert coupler.summary(out)["status"] == "failed"


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_ends_a_long_set_up_at_once(tmp_path: Path, sig: signal.Signals) -> None:
    """An SSD at the ceilings (three vectors of 66,000 elements, a connection of each element)
    takes seconds to read and check; Ctrl-C or SIGTERM in the middle ends the command within
    about a second (measured 0.2-1.3 s), exit 130, one sentence, nothing left running."""
    n = 66_000
    port = f'<mc:RealVector startIndex="1" endIndex="{n}"/>'
    constant = CONSTANT.replace('endIndex="3"', f'endIndex="{n}"').replace(
        'value="1 2 3"', 'value="' + " ".join(["1"] * n) + '"'
    )
    integrator = (
        '      <Component name="I" source="" type="application/avl-mcx-vector-integrator">'
        f"<Connectors>{vector('u', 'input', port)}{vector('y', 'output', port)}</Connectors>"
        "</Component>"
    )
    connection = sliced(
        f'<mc:Start startIndex="1" endIndex="{n}"/>', f'<mc:End startIndex="1" endIndex="{n}"/>'
    ).replace('endElement="Sum" endConnector="a"', 'endElement="I" endConnector="u"')
    path = bad(tmp_path, connection, constant + "\n" + integrator)
    with process_group(
        [str(COUPLER_SCRIPT), "run", str(path), "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    ) as process:
        time.sleep(1.5)  # imported and reading (the whole set-up takes 4-6 s here)
        assert process.poll() is None, "the set-up ended before the interrupt"
        process.send_signal(sig)
        sent = time.monotonic()
        _, err = process.communicate(timeout=30)
        took = time.monotonic() - sent
    assert process.returncode == 130, err
    assert "interrupted before the run started; nothing was recorded" in err.decode(), err
    assert took < 3, f"the set-up went on for {took:.1f} s after the interrupt"
