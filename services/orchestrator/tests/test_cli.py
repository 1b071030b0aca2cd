"""The ``coupler`` command's describe and validate against real participants.

coupler describe grpc://127.0.0.1:PORT  -->  Gain (example participant, gRPC)
coupler describe Source2.fmu            -->  FMU
"""

from __future__ import annotations

from pathlib import Path

from coupler.server import ParticipantServer

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
