"""The ``coupler`` command's describe and validate against real participants.

coupler describe grpc://127.0.0.1:PORT  -->  Gain (example participant, gRPC)
coupler describe Source2.fmu            -->  FMU
"""

from __future__ import annotations

import csv
import io
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coupler.server import ParticipantServer
from coupler.testing import SystemStructure, fmu
from coupler_orchestrator.observer import RunEnd, RunInfo
from coupler_orchestrator.outputs.progress import ProgressLines

from ..support import DATA, REPO, Coupler


def test_describe_grpc_participant(coupler: Coupler, gain_server: ParticipantServer) -> None:
    outcome = coupler("describe", f"grpc://127.0.0.1:{gain_server.port}")
    assert outcome.code == 0, outcome.err
    lines = outcome.out.splitlines()
    assert lines[0] == "Gain  (coupler.examples.gain)"
    assert lines[1].startswith("capabilities: streaming=True")
    table = {line.split()[0]: line.split() for line in lines[3:]}
    assert list(table) == [
        "CHANNEL", "gain", "x0", "offset", "u", "n", "flag", "label", "blob",
        "y", "x", "count", "inverted", "echo", "blob_out",
    ]  # fmt: skip
    assert table["u"][:5] == ["u", "input", "Real", "m/s", "0.0"]
    assert table["blob_out"][:3] == ["blob_out", "output", "Binary"]


def test_describe_fmu(coupler: Coupler, fmus: dict[str, Path]) -> None:
    outcome = coupler("describe", fmus["Integrator3"])
    assert outcome.code == 0, outcome.err
    assert outcome.out.startswith("Integrator  (FMI 3.0 FMU Integrator")
    assert "\nx0       parameter  Real  m     0.0    Initial value of x\n" in outcome.out


def test_describe_unreachable(coupler: Coupler) -> None:
    outcome = coupler("describe", "grpc://127.0.0.1:1", "--timeout", "0.2")
    assert outcome.code == 1
    assert "not SERVING at grpc://127.0.0.1:1 within 0.2 s" in outcome.err


def test_validate_valid_scenario(
    coupler: Coupler, fmus: dict[str, Path], gain_server: ParticipantServer
) -> None:
    outcome = coupler("validate", DATA / "mixed.ssd")
    assert outcome.code == 0, outcome.err
    assert outcome.out.endswith("mixed.ssd: valid (4 components, 11 connections)\n")


def test_progress_lines_when_not_on_a_terminal(tmp_path: Path) -> None:
    """Off a terminal (CI, compose) progress is a plain line every few seconds, not a bar."""
    stream = io.StringIO()
    lines = ProgressLines(stream, every=0.05)
    info = RunInfo(
        run_id="r",
        algorithm="jacobi",
        members=("A",),
        multiples=(1,),
        columns=(),
        start_time=0.0,
        stop_time=10.0,
        step_size=1.0,
        steps=10,
    )
    lines.started(info)
    for k in range(11):
        time.sleep(0.03)
        lines.stepped(float(k), [])
    lines.finished(RunEnd(status="completed", reason="", steps=10, end_time=10.0, wall_time=0.3))
    text = stream.getvalue()
    assert "\r" not in text
    written = text.splitlines()
    assert 2 <= len(written) <= 8
    assert all(line.startswith("progress: t=") and "x real time  ETA" in line for line in written)
    assert "%" in written[-1]


# The first hour's papercuts: what a new user typed, and what the command must say.


def chain(fmus: dict[str, Path], *, ramp: bool = False) -> str:
    """A (Source2) --ramp--> B (Integrator2); A's ``ramp`` connector declared or not."""
    return SystemStructure(
        "T",
        components=[
            fmu("A", fmus["Source2"], outputs=["ramp"] if ramp else []),
            fmu("B", fmus["Integrator2"], inputs=["u"]),
        ],
        connections=[("A.ramp", "B.u")],
        stop_time=1,
    ).xml()


def test_an_undeclared_connector_says_how_to_declare_it(
    coupler: Coupler, fmus: dict[str, Path], tmp_path: Path
) -> None:
    ssd = tmp_path / "t.ssd"
    ssd.write_text(chain(fmus))
    outcome = coupler("validate", ssd, "--step", "0.1")
    assert outcome.code == 1
    assert (
        "t.ssd line 16: connection A.ramp -> B.u: component 'A' declares no connector 'ramp' "
        "(it declares none); a connection joins declared connectors: add "
        '<ssd:Connector name="ramp" kind="output"/> to its <ssd:Connectors> (`coupler '
        "describe` lists the participant's channels)"
    ) in outcome.err
    assert outcome.err.count("\n") == 1  # one problem: one line (not "1 problem(s)")


def test_a_step_size_in_the_default_experiment_says_where_a_step_goes(
    coupler: Coupler, fmus: dict[str, Path], tmp_path: Path
) -> None:
    ssd = tmp_path / "t.ssd"
    ssd.write_text(chain(fmus).replace('stopTime="1"/>', 'stopTime="1" stepSize="0.1"/>'))
    outcome = coupler("validate", ssd)
    assert outcome.code == 1
    assert (
        "attribute 'stepSize': The attribute 'stepSize' is not allowed: SSP's "
        "DefaultExperiment has no step size; remove stepSize and give the step with --step "
        "0.1, or in the SSD inside the DefaultExperiment: <ssd:Annotations><ssc:Annotation "
        'type="com.avl.model.connect.ssp.task"><mc:Task xmlns:mc="com.avl.model.connect.ssp.task" '
        'stepType="parallel_single_thread" deltaTime="0.1"/></ssc:Annotation></ssd:Annotations>'
    ) in outcome.err

    # the fix it gives works: that annotation carries the step
    annotation = re.search(r"<ssd:Annotations>.*</ssd:Annotations>", outcome.err)
    assert annotation is not None
    fixed = chain(fmus, ramp=True)
    assert 'stopTime="1"/>' in fixed
    fixed = fixed.replace('stopTime="1"/>', f'stopTime="1">{annotation[0]}</ssd:DefaultExperiment>')
    ssd.write_text(fixed)
    outcome = coupler("run", ssd, "--out", tmp_path / "out")
    assert outcome.code == 0, outcome.err
    with (tmp_path / "out" / "results.csv").open() as results:
        times = [float(row["time"]) for row in csv.DictReader(results)]
    assert times == pytest.approx([k / 10 for k in range(11)])


def test_a_param_typo_names_what_can_be_set(coupler: Coupler, fmus: dict[str, Path]) -> None:
    outcome = coupler("validate", fmus["Source2"], "--param", "Source.slop=2")
    assert outcome.code == 1
    assert (
        "--param Source.slop: no parameter or input 'slop' on component 'Source'; did you mean "
        "'Source.slope'? (its parameters and inputs: slope, offset, amplitude, freq)"
    ) in outcome.err


def test_validate_counts_in_words(coupler: Coupler, fmus: dict[str, Path]) -> None:
    outcome = coupler("validate", fmus["Source2"])
    assert outcome.code == 0, outcome.err
    assert outcome.out.endswith("Source2.fmu: valid (1 component, 0 connections)\n")


def test_describe_says_at_once_what_it_waits_for() -> None:
    """Nothing listens there: the first line says so while the command still waits."""
    script = Path(sys.executable).with_name("coupler")
    with subprocess.Popen(
        [str(script), "describe", "grpc://127.0.0.1:1", "--timeout", "60"],
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    ) as process:
        try:
            assert process.stderr is not None
            first = process.stderr.readline()
            still_waiting = process.poll() is None
        finally:
            process.kill()
    assert first == (
        "waiting up to 60 s for a participant at grpc://127.0.0.1:1 (connection refused: "
        "nothing listens on that port yet)\n"
    )
    assert still_waiting


def test_a_failed_run_is_said_once_off_a_terminal(tmp_path: Path) -> None:
    """stderr a file (CI, compose): one ``error:`` line, not a JSON log line saying it too."""
    fmu = REPO / "build" / "faulty-fmus" / "Faulty2.fmu"
    if not fmu.exists():
        pytest.fail(f"{fmu} is missing: run `make setup` (make test does)")
    outcome = Coupler.process(
        "run", fmu, "--isolate-fmus", "--param", "crash_at=0.5", "--stop-time", "1",
        "--step", "0.25", "--out", tmp_path / "o", "--no-progress",
    )  # fmt: skip
    assert outcome.code == 1
    assert outcome.err.splitlines() == [
        "error: run failed: Faulty.DoStep [UNAVAILABLE]: the FMU host process was killed by "
        "SIGSEGV during DoStep at t=0.5 (Faulty2.fmu runs isolated; the FMU itself crashed) "
        "(the run had reached t=0.5 s)"
    ]
