"""Leases, deadlines, timeouts and pacing are finite, positive and bounded on the orchestrator's
side too: the command line refuses the rest (argparse, exit 2, naming the option) before
anything runs, so no participant is ever asked for an endless lease.

    coupler run mixed.ssd --lease inf  -x->  Gain (gRPC; Initialize(lease_seconds=inf) once
                                             locked it for good)
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from coupler.server import ParticipantServer
from coupler.testing import Annotation, SystemStructure

from ..support import DATA, Coupler, project_fmu

COUPLER = str(Path(sys.executable).with_name("coupler"))
SECONDS = "must be a number of seconds > 0 and <= 86400 (24 h)"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("option", "value", "says"),
    [
        ("--lease", "inf", f"{SECONDS}, got inf"),
        ("--realtime-factor", "1e-300", "must be 0 (as fast as possible) or at least 0.001"),
    ],
)
def test_the_attacks_are_refused_before_anything_runs(
    fmus: dict[str, Path],
    gain_server: ParticipantServer,
    tmp_path: Path,
    option: str,
    value: str,
    says: str,
) -> None:
    """As the user runs it: `--lease inf` locked the participant for good, `--realtime-factor
    1e-300` never ended."""
    done = subprocess.run(
        [COUPLER, "run", DATA / "mixed.ssd", "--out", tmp_path / "out", option, value],
        capture_output=True,
        text=True,
        timeout=60,
        env=os.environ,
    )
    assert done.returncode == 2, done.stderr
    assert f"coupler run: error: argument {option}: {says}" in done.stderr
    assert not (tmp_path / "out").exists()  # nothing ran


@pytest.mark.parametrize(
    ("command", "option", "value", "says"),
    [
        ("run", "--lease", "nan", f"{SECONDS}, got nan"),
        ("run", "--lease", "-5", f"{SECONDS}, got -5.0"),
        ("run", "--lease", "86401", f"{SECONDS}, got 86401.0"),
        ("run", "--lease", "0", f"{SECONDS}, got 0.0"),
        ("run", "--lease", "1e-300", "must be at least 1 s, got 1e-300: a participant would end"),
        ("run", "--lease", "0.5", "must be at least 1 s, got 0.5"),
        ("run", "--call-timeout", "inf", f"{SECONDS}, got inf"),
        ("run", "--call-timeout", "0", f"{SECONDS}, got 0.0"),
        ("validate", "--call-timeout", "nan", f"{SECONDS}, got nan"),
        ("run", "--connect-timeout", "-1", f"{SECONDS}, got -1.0"),
        ("run", "--connect-timeout", "1e9", f"{SECONDS}, got 1000000000.0"),
        ("run", "--realtime-factor", "nan", "must be a finite number, got 'nan'"),
        ("run", "--realtime-factor", "inf", "must be a finite number, got 'inf'"),
        ("run", "--realtime-factor", "-2", "must be 0 (as fast as possible) or at least 0.001"),
        ("run", "--monitor-linger", "inf", f"{SECONDS}, got inf"),
        ("fleet", "--realtime-factor", "1e-9", "must be 0 (as fast as possible) or at least 0.001"),
        ("fleet", "--health-timeout", "inf", f"{SECONDS}, got inf"),
        ("describe", "--timeout", "nan", f"{SECONDS}, got nan"),
        ("export-fmu", "--call-timeout", "inf", f"{SECONDS}, got inf"),
        ("export-fmu", "--timeout", "0", f"{SECONDS}, got 0.0"),
    ],
)
def test_every_duration_option_is_bounded(
    coupler: Coupler,
    capsys: pytest.CaptureFixture[str],
    command: str,
    option: str,
    value: str,
    says: str,
) -> None:
    target = {"describe": "grpc://127.0.0.1:1", "export-fmu": "grpc://127.0.0.1:1"}.get(
        command, "scenario.ssd"
    )
    extra = ["--out", "x.fmu"] if command == "export-fmu" else []
    with pytest.raises(SystemExit) as exit_:
        coupler(command, target, *extra, option, value)
    assert exit_.value.code == 2
    assert f"coupler {command}: error: argument {option}: {says}" in capsys.readouterr().err


def test_the_ceilings_themselves_are_accepted(
    fmus: dict[str, Path], gain_server: ParticipantServer, coupler: Coupler, tmp_path: Path
) -> None:
    outcome = coupler(
        "run", DATA / "mixed.ssd", "--out", tmp_path, "--lease", "86400", "--call-timeout", "86400"
    )
    assert outcome.code == 0, outcome.err
    assert coupler.summary(tmp_path)["status"] == "completed"


def test_a_default_lease_stays_under_the_ceiling(
    fmus: dict[str, Path], gain_server: ParticipantServer, coupler: Coupler, tmp_path: Path
) -> None:
    """The default lease is four call deadlines: with a deadline of 24 h it would be 96 h, which
    participants refuse; it is capped at 24 h."""
    outcome = coupler("run", DATA / "mixed.ssd", "--out", tmp_path, "--call-timeout", "86400")
    assert outcome.code == 0, outcome.err


def test_pacing_slower_than_any_lease_is_refused(
    fmus: dict[str, Path], gain_server: ParticipantServer, coupler: Coupler, tmp_path: Path
) -> None:
    """At 0.001 a step of 100 s waits 100000 s: longer than a participant keeps a silent run."""
    outcome = coupler(
        "run",
        DATA / "mixed.ssd",
        "--out",
        tmp_path,
        "--step",
        "100",
        "--stop-time",
        "200",
        "--realtime-factor",
        "0.001",
    )
    assert outcome.code == 1
    assert (
        "--realtime-factor 0.001 waits 100000 s between two steps of a participant" in outcome.err
    )


def annotated(timeout: str) -> SystemStructure:
    """Source (FMI 2) alone, with a call timeout of ``timeout`` in its component annotation."""
    bound = Annotation("org.coupler.component", "Component", {"callTimeout": timeout})
    source = project_fmu("Source", "Source2", outputs=["ramp"], annotations=[bound])
    return SystemStructure("Slow", [source])


@pytest.mark.parametrize("timeout", ["INF", "1e9", "0"])
def test_a_components_call_timeout_is_bounded(
    fmus: dict[str, Path], coupler: Coupler, tmp_path: Path, timeout: str
) -> None:
    ssd = annotated(timeout).write(tmp_path / "slow.ssd")
    outcome = coupler("validate", ssd, "--step", "0.5")
    assert outcome.code == 1
    assert "slow.ssd line 13" in outcome.err and f"callTimeout {SECONDS}" in outcome.err
