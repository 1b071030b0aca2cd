"""The ``coupler`` command's describe and validate against real participants.

coupler describe grpc://127.0.0.1:PORT  -->  Gain (example participant, gRPC)
coupler describe Source2.fmu            -->  FMU
"""

from __future__ import annotations

import io
import time
from pathlib import Path

from coupler.server import ParticipantServer
from coupler_orchestrator.observer import RunEnd, RunInfo
from coupler_orchestrator.outputs.progress import ProgressLines

from .conftest import DATA, Coupler


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
