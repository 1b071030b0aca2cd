"""An FMU that asks to end the run ends it as ``terminated``, exit 0, like FMPy ends it.

    Stair (FMI 2 or 3, alone)                      h = 0.5 s, 0 .. 20 s, stops at t = 9 s
    Stair (FMU) + Gain (gRPC, records Terminate)   in-process FMU, remote participant
    Stair (FMU served by ParticipantServer) + Source2 (FMU)    the request over the wire

Stair (fmus/common/stair.h, after the Modelica Reference FMU) counts 1 + floor(t) and asks to
end the simulation at t = 9: FMI 2 by fmi2Discard with fmi2Terminated, FMI 3 by
terminateSimulation. Dyadic steps make FMPy's steps (differences of grid times) the same
doubles as Coupler's, so the recorded rows must be equal to ``fmpy.simulate_fmu``'s.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import fmpy
import pytest

from coupler.examples.gain import GainParticipant
from coupler.fmu import FmuParticipant
from coupler.participant import Participant
from coupler.testing import Component, SystemStructure, remote

from .support import Coupler, Outcome, serving


class RecordsTerminate(Participant):
    """Mixed into a participant: remembers the reasons of its Terminate calls."""

    terminated: list[str]

    async def terminate(self, reason: str = "") -> None:
        self.terminated.append(reason)
        await super().terminate(reason)


class RecordingGain(RecordsTerminate, GainParticipant):
    def __init__(self) -> None:
        super().__init__("Gain")
        self.terminated = []


class RecordingFmu(RecordsTerminate, FmuParticipant):
    def __init__(self, path: Path) -> None:
        super().__init__(path, name="Stair")
        self.terminated = []


def _write(tmp_path: Path, *components: Component) -> Path:
    return SystemStructure("Stair", components, stop_time=20).write(tmp_path / "stair.ssd")


def _fmu(name: str, source: Path) -> Component:
    return Component(name, str(source))


def _remote(name: str, port: int) -> Component:
    return remote(name, f"grpc://127.0.0.1:{port}")


def _run_alone(coupler: Coupler, fmu: Path, out: Path, *, step: float) -> Outcome:
    """``coupler run`` of the Stair FMU alone, 0 .. 20 s."""
    return coupler(
        "run",
        _write(out.parent, _fmu("Stair", fmu)),
        "--out",
        out,
        "--step",
        step,
    )


@pytest.mark.usefixtures("fmu_path")
@pytest.mark.parametrize("fmu", ["Stair2", "Stair3"])
def test_termination_request_ends_the_run_like_fmpy(
    fmu: str, fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    outcome = _run_alone(coupler, fmus[fmu], out, step=0.5)
    assert outcome.code == 0, outcome.err
    assert "Traceback" not in outcome.err
    summary = coupler.summary(out)
    assert summary["status"] == "terminated"
    assert summary["end_time"] == 9.0
    assert summary["reason"].startswith("Stair asked to end the run at t=9 s: the FMU requested")
    how = "fmi2Discard, fmi2Terminated" if fmu == "Stair2" else "terminateSimulation"
    assert how in summary["reason"]
    assert f"terminated early: {summary['reason']}" in outcome.out

    reference = fmpy.simulate_fmu(
        str(fmus[fmu]), start_time=0.0, stop_time=20.0, output_interval=0.5
    )
    rows = coupler.results(out)
    assert len(rows) == len(reference) == 19
    for row, expected in zip(rows, reference, strict=True):
        assert float(row["time"]) == float(expected["time"])
        assert int(row["Stair.counter"]) == int(expected["counter"])
    assert (rows[-1]["time"], rows[-1]["Stair.counter"]) == ("9.0", "10")


@pytest.mark.usefixtures("fmu_path")
@pytest.mark.parametrize("fmu", ["Stair2", "Stair3"])
def test_stop_inside_a_step_is_named_in_the_reason(
    fmu: str, fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    """Steps of 2 s: the FMU stops at t = 9 inside the step 8 -> 10; the row at the step's end
    holds the outputs at 9 (FMPy records FMI 2's at 9, FMI 3's at 10), and the reason says so."""
    out = tmp_path / "out"
    outcome = _run_alone(coupler, fmus[fmu], out, step=2)
    assert outcome.code == 0, outcome.err
    summary = coupler.summary(out)
    assert summary["status"] == "terminated"
    assert "it stopped at t=9 s, before the step's end t=10 s" in summary["reason"]
    rows = coupler.results(out)
    assert [(r["time"], r["Stair.counter"]) for r in rows[-2:]] == [("8.0", "9"), ("10.0", "10")]
    reference = fmpy.simulate_fmu(str(fmus[fmu]), stop_time=20.0, output_interval=2.0)
    assert int(reference["counter"][-1]) == 10


@pytest.mark.parametrize("fmu", ["Stair2", "Stair3"])
def test_every_participant_is_terminated(
    fmu: str, fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    """The in-process FMU's request terminates the remote participant too."""
    gain = RecordingGain()
    with serving(gain) as server:
        ssd = _write(
            tmp_path,
            _fmu("Stair", fmus[fmu]),
            _remote("Gain", server.port),
        )
        out = tmp_path / "out"
        outcome = coupler("run", ssd, "--out", out, "--step", 0.5)
    assert outcome.code == 0, outcome.err
    assert coupler.summary(out)["status"] == "terminated"
    assert coupler.results(out)[-1]["time"] == "9.0"
    assert len(gain.terminated) == 1
    assert "Stair asked to end the run at t=9 s" in gain.terminated[0]


@pytest.mark.parametrize("fmu", ["Stair2", "Stair3"])
def test_termination_request_over_the_wire(
    fmu: str, fmus: Mapping[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    """The FMU served by the generic FMU host: DoStepResponse.terminate ends the run; the host
    is terminated and serves the next run."""
    stair = RecordingFmu(fmus[fmu])
    with serving(stair) as server:
        ssd = _write(
            tmp_path,
            _remote("Stair", server.port),
            _fmu("Source", fmus["Source2"]),
        )
        for run in ("first", "second"):
            out = tmp_path / run
            outcome = coupler("run", ssd, "--out", out, "--step", 0.5)
            assert outcome.code == 0, outcome.err
            summary = coupler.summary(out)
            assert summary["status"] == "terminated"
            assert summary["end_time"] == 9.0
            assert "the FMU requested to terminate the simulation" in summary["reason"]
            last = coupler.results(out)[-1]
            assert (last["time"], last["Stair.counter"], last["Source.counter"]) == (
                "9.0",
                "10",
                "18",
            )
    assert len(stair.terminated) == 2
