"""Bad input: each refused with a message naming the culprit and the fix, and exit code 1.

Also: a participant failing mid-run keeps every completed step, and ``validate`` lists every
problem at once.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from coupler.channels import Capabilities, Description
from coupler.examples.gain import GainParticipant
from coupler.server import ParticipantServer
from coupler.testing import (
    Annotation,
    Component,
    Connection,
    Connector,
    SystemStructure,
    fmu,
    free_port,
    remote,
)

from .support import DATA, Coupler, Stepper, project_fmu, serving

pytestmark = pytest.mark.usefixtures("fmus")


def ssd(
    tmp_path: Path,
    components: Sequence[Component],
    connections: Sequence[Connection | tuple[str, str]] = (),
    name: str = "bad.ssd",
) -> Path:
    return SystemStructure("Bad", components, connections).write(tmp_path / name)


def connector(name: str, kind: str, type_: str = "Real") -> Connector:
    return Connector(name, kind, type_)


def assert_refused(coupler: Coupler, path: Path, *fragments: str, command: str = "validate") -> str:
    extra = ["--out", str(path.parent / "out")] if command == "run" else []
    outcome = coupler(command, path, "--step", "0.5", *extra)
    assert outcome.code == 1, outcome
    assert outcome.err.startswith("error: "), outcome.err
    assert "Traceback" not in outcome.err
    for fragment in fragments:
        assert fragment in outcome.err, (fragment, outcome.err)
    return outcome.err


@pytest.mark.parametrize("command", ["validate", "run"])
def test_malformed_xml(coupler: Coupler, tmp_path: Path, command: str) -> None:
    path = tmp_path / "broken.ssd"
    path.write_text('<?xml version="1.0"?>\n<ssd:SystemStructureDescription>\n  <b>\n</a>\n')
    assert_refused(coupler, path, "broken.ssd line", "malformed XML", command=command)


def test_schema_violation(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(tmp_path, [project_fmu("Source", "Source2")])
    path.write_text(path.read_text().replace("<ssd:Component ", '<ssd:Component bogus="1" '))
    assert_refused(coupler, path, "bad.ssd line 8: schema violation", "bogus")


def test_unknown_component_type(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(tmp_path, [Component("A", "x", type="application/x-other")])
    assert_refused(
        coupler,
        path,
        "bad.ssd line 8: component 'A' has type 'application/x-other', which is not supported",
        "use application/x-fmu-sharedlibrary or application/x-coupler-grpc",
    )


@pytest.mark.parametrize("command", ["validate", "run"])
def test_duplicate_component_names(coupler: Coupler, tmp_path: Path, command: str) -> None:
    """Two components of one name: refused naming both lines (the second used to replace the
    first silently: "valid (1 components)" and a run of the other FMU)."""
    path = ssd(
        tmp_path,
        [
            project_fmu("Source", "Source2", connector("ramp", "output")),
            project_fmu("Source", "Integrator2", connector("u", "input")),
        ],
    )
    assert_refused(
        coupler,
        path,
        "bad.ssd line 13: element 'Source' in system 'Bad' is already defined at line 8",
        "rename or remove one of the two",
        command=command,
    )
    assert not (tmp_path / "out" / "results.csv").exists()


def test_duplicate_connector_names(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(
        tmp_path,
        [
            project_fmu(
                "Source", "Source2", connector("ramp", "output"), connector("ramp", "parameter")
            )
        ],
    )
    assert_refused(
        coupler,
        path,
        "bad.ssd line 11: connector 'ramp' of component 'Source' is already defined at line 10",
    )


def test_zip_slip_entry(coupler: Coupler, tmp_path: Path) -> None:
    archive = tmp_path / "evil.ssp"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("SystemStructure.ssd", (DATA / "chain.ssd").read_text())
        zf.writestr("../../escape.txt", "x")
    assert_refused(
        coupler, archive, "evil.ssp: entry '../../escape.txt'", "zip-slip", "relative paths only"
    )
    assert not (tmp_path.parent / "escape.txt").exists()


def test_missing_fmu(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(tmp_path, [fmu("A", "resources/Missing.fmu")])
    assert_refused(
        coupler,
        path,
        "bad.ssd line 8: component 'A': FMU file 'resources/Missing.fmu' does not exist",
        "add the FMU",
    )


def test_connector_missing_on_the_participant(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(tmp_path, [project_fmu("Source", "Source2", connector("speed", "output"))])
    assert_refused(
        coupler,
        path,
        "bad.ssd line 10: connector 'Source.speed' does not exist on participant 'Source'",
        "its channels: slope, offset, amplitude, freq, ramp, sine, counter",
        "rename the connector or the channel",
    )


def test_type_mismatch_with_the_participant(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(tmp_path, [project_fmu("Source", "Source2", connector("ramp", "output", "Integer"))])
    assert_refused(
        coupler,
        path,
        "connector 'Source.ramp' expects Integer, but the participant declares Real",
    )


def test_type_mismatch_between_connectors(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(
        tmp_path,
        [
            project_fmu("Source", "Source2", connector("ramp", "output")),
            project_fmu("Feed", "Feedthrough3", connector("int_in", "input", "Integer")),
        ],
        [("Source.ramp", "Feed.int_in")],
    )
    assert_refused(
        coupler,
        path,
        "bad.ssd line 20: connection Source.ramp -> Feed.int_in: connector 'Feed.int_in' "
        "expects Integer, but 'Source.ramp' is Real; connect compatible channels or add a "
        "transformation",
    )


def test_unconnected_input_without_start_value(
    coupler: Coupler, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with serving(Stepper()) as server:
        monkeypatch.setenv("STEPPER_PORT", str(server.port))
        path = ssd(tmp_path, [remote("S", "grpc://127.0.0.1:${STEPPER_PORT}")])
        assert_refused(
            coupler,
            path,
            "bad.ssd line 8: input 'S.aspect' is neither connected nor has a start value",
            "connect it or bind a value to it",
        )


LOOP = (
    [
        project_fmu(
            "Feed", "Feedthrough3", connector("real_in", "input"), connector("real_out", "output")
        ),
        project_fmu(
            "Feed2", "Feedthrough2", connector("real_in", "input"), connector("real_out", "output")
        ),
        project_fmu("Analyzer", "Integrator2", connector("u", "input")),
    ],
    [("Feed.real_out", "Feed2.real_in"), ("Feed2.real_out", "Analyzer.u")],
)


@pytest.mark.parametrize("command", ["validate", "run"])
def test_loop_without_decoupling(coupler: Coupler, tmp_path: Path, command: str) -> None:
    """Gauss-Seidel cannot order an algebraic loop that no connection breaks.

    Feed --real_out--> Feed2 --real_out--> Feed.real_in
                       Feed2 --real_out--> Analyzer.u
    """
    elements, links = LOOP
    path = ssd(tmp_path, elements, [*links, ("Feed2.real_out", "Feed.real_in")])
    outcome = (
        coupler(command, path, "--algorithm", "gauss-seidel", "--out", tmp_path / "o")
        if (command == "run")
        else coupler(command, path, "--algorithm", "gauss-seidel", "--step", "0.5")
    )
    assert outcome.code == 1, outcome
    assert "Gauss-Seidel cannot order the loop Feed -> Feed2 -> Feed" in outcome.err
    assert "mark one connection of it decoupled" in outcome.err
    # the same loop runs under Jacobi, and under Gauss-Seidel once a connection is decoupled
    assert coupler("validate", path, "--step", "0.5").code == 0
    decoupled = Annotation("org.coupler.connection", "Connection", {"decoupled": "true"})
    path = ssd(
        tmp_path,
        elements,
        [*links, Connection("Feed2.real_out", "Feed.real_in", [decoupled])],
        name="decoupled.ssd",
    )
    assert coupler("validate", path, "--algorithm", "gauss-seidel", "--step", "0.5").code == 0


def test_unreachable_participant(coupler: Coupler, tmp_path: Path) -> None:
    port = free_port()
    path = ssd(tmp_path, [remote("Gain", f"grpc://127.0.0.1:{port}")])
    outcome = coupler("run", path, "--step", "0.5", "--connect-timeout", "0.3", "--out", tmp_path)
    assert outcome.code == 1
    assert (
        f"bad.ssd line 8: component 'Gain': Gain.connect [UNAVAILABLE]: not SERVING at "
        f"grpc://127.0.0.1:{port} within 0.3 s" in outcome.err
    )
    assert "is the participant running and listening on that address?" in outcome.err


def test_an_undefined_unit_is_one_error_line_naming_each_use(tmp_path: Path) -> None:
    """One cause, one message: a unit missing from <Units> used to be followed by "component
    'Train' could not be loaded" for each of its connections and a second error for a parameter
    in that unit; now it is one line, with its file and line, naming every use.

        Train.speed [km/h, undefined] ==> Driver.speed, Map.speed
        Train.distance ==> Driver.distance, Map.distance;  Driver.throttle ==> Train.throttle
        Driver.target_speed [m/s] = 60 km/h
    """
    path = SystemStructure(
        "Line",
        [
            remote("Train", "grpc://127.0.0.1:1", Connector("speed", "output", "Real", "km/h"),
                   Connector("distance", "output", "Real", "m"), connector("throttle", "input")),
            remote("Driver", "grpc://127.0.0.1:1", Connector("speed", "input", "Real", "m/s"),
                   Connector("distance", "input", "Real", "m"), connector("throttle", "output"),
                   Connector("target_speed", "parameter", "Real", "m/s"),
                   parameters={"target_speed": 60.0}),
            remote("Map", "grpc://127.0.0.1:1", Connector("speed", "input", "Real", "m/s"),
                   Connector("distance", "input", "Real", "m")),
        ],
        [("Train.speed", "Driver.speed"), ("Train.distance", "Driver.distance"),
         ("Driver.throttle", "Train.throttle"), ("Train.speed", "Map.speed"),
         ("Train.distance", "Map.distance")],
        units={"m": {"m": 1}, "m/s": {"m": 1, "s": -1}},
    ).write(tmp_path / "line.ssd")  # fmt: skip
    text = path.read_text()
    path.write_text(text.replace('<ssv:Real value="60.0"/>', '<ssv:Real value="60" unit="km/h"/>'))
    for command in (["validate"], ["run", "--out", str(tmp_path / "out")]):
        outcome = Coupler.process(*command, path, "--step", "0.5")
        assert outcome.code == 1
        assert outcome.err.splitlines() == [
            "error: line.ssd line 10: connector 'Train.speed' uses unit 'km/h', which is not "
            "defined in <Units> (units: m, m/s); define it; it is also used by parameter "
            "'Driver.target_speed' (line.ssd line 24)"
        ], outcome.err


def test_an_input_driven_twice_names_the_lines_of_its_connections(
    coupler: Coupler, tmp_path: Path
) -> None:
    path = ssd(
        tmp_path,
        [
            project_fmu(
                "Source", "Source2", connector("ramp", "output"), connector("sine", "output")
            ),
            project_fmu("Feed", "Feedthrough3", connector("real_in", "input")),
        ],
        [("Source.ramp", "Feed.real_in"), ("Source.sine", "Feed.real_in")],
    )
    assert_refused(
        coupler,
        path,
        "bad.ssd line 21: input 'Feed.real_in' is driven by 2 connections (line 21 from "
        "'Source.ramp', line 22 from 'Source.sine'); an input takes exactly one driver: remove "
        "all but one",
    )


def test_validate_lists_every_problem(coupler: Coupler, tmp_path: Path) -> None:
    path = ssd(
        tmp_path,
        [
            project_fmu(
                "Source",
                "Source2",
                connector("speed", "output"),
                connector("ramp", "output", "Boolean"),
            ),
            project_fmu("Feed", "Feedthrough3", connector("int_in", "input", "Integer")),
            remote("Far", "grpc://127.0.0.1:1"),
        ],
        [("Source.ramp", "Feed.int_in")],
    )
    outcome = coupler("validate", path, "--connect-timeout", "0.2", "--step", "0.5")
    assert outcome.code == 1
    problems = [line for line in outcome.err.splitlines() if line.startswith("  - ")]
    assert len(problems) == 4, outcome.err
    assert "bad.ssd: 4 problems" in outcome.err
    for fragment in (
        "bad.ssd line 10: connector 'Source.speed' does not exist on participant 'Source'",
        "bad.ssd line 11: connector 'Source.ramp' expects Boolean, but the participant declares "
        "Real; declare the connector <ssc:Real/>",
        # the connection is checked once, with the types the participants declare
        "bad.ssd line 22: connection Source.ramp -> Feed.int_in: connector 'Feed.int_in' expects "
        "Integer, but 'Source.ramp' is Real; connect compatible channels or add a transformation",
        "component 'Far': Far.connect [UNAVAILABLE]",
    ):
        assert fragment in outcome.err, fragment


def test_failed_run_keeps_completed_steps(
    tmp_path: Path, failing_gain_server: ParticipantServer
) -> None:
    """The gain participant raises in every DoStep from t = 1.0 on.

        Source (FMI 2) --ramp--> Gain (gRPC, fails at t >= 1.0) --> Feed (FMI 3) --> Feed2

    h = 0.5: steps 0 -> 0.5 and 0.5 -> 1.0 complete, the step from 1.0 fails.
    """
    out = tmp_path / "out"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "coupler_orchestrator",
            "run",
            str(DATA / "mixed.ssd"),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        env=os.environ.copy(),
        timeout=60,
        check=False,
    )
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr
    assert (
        "error: run failed: Gain.DoStep [INTERNAL]: RuntimeError: gain overheated at t=1"
        in result.stderr
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert summary["reason"].startswith("Gain.DoStep [INTERNAL]: RuntimeError: gain overheated")
    assert (summary["steps"], summary["end_time"], summary["steps_planned"]) == (2, 1.0, 3)
    rows = (out / "results.csv").read_text().splitlines()
    assert [row.split(",")[0] for row in rows] == ["time", "0.0", "0.5", "1.0"]


class FixedStepGain(GainParticipant):
    """The example gain participant, declaring a fixed simulator step of 0.2 s."""

    async def describe(self) -> Description:
        described = await super().describe()
        return replace(described, capabilities=Capabilities(fixed_step_size=0.2))


def test_step_not_a_multiple_of_participant_fixed_step(coupler: Coupler, tmp_path: Path) -> None:
    with serving(FixedStepGain()) as server:
        path = ssd(tmp_path, [remote("Gain", f"grpc://127.0.0.1:{server.port}")])
        outcome = coupler("validate", path, "--step", "0.3", "--stop-time", "0.6")
        assert outcome.code == 1
        assert (
            "bad.ssd line 8: participant 'Gain' steps in whole multiples of 0.2 s, but its "
            "communication step is 0.3 s; choose --step (or its deltaTime) as a multiple of 0.2 s"
        ) in outcome.err
        assert coupler("validate", path, "--step", "0.4", "--stop-time", "0.8").code == 0


LEAKY_SSD = SystemStructure(
    "Leak",
    components=[
        remote("A", "grpc://${LEAK_HOST}:${LEAK_PORT}", outputs=["y"]),
        fmu("B", "${LEAK_DIR}/b.fmu", inputs=["u"]),
        fmu("C", "${SCHEME_DIR}/c.fmu", inputs=["u"]),
    ],
    stop_time=None,
)


def test_a_source_in_error_names_its_variables_never_their_values(tmp_path: Path) -> None:
    """An SSD may read ``${..._HOST}``, ``_PORT`` and ``_DIR`` variables into its sources; a
    source that then does not work is quoted as written, naming the variables — their values
    (here made to look like secrets) are never shown (they were: "source
    'grpc://127.0.0.1:s3cr3t-port' is not of the form ...", "FMU file '/s3cr3t-dir/b.fmu'")."""
    path = LEAKY_SSD.write(tmp_path / "leak.ssd")
    values = {
        "LEAK_HOST": "127.0.0.1",
        "LEAK_PORT": "s3cr3t-port",
        "LEAK_DIR": "/s3cr3t-dir",
        "SCHEME_DIR": "https://s3cr3t.example",
    }
    outcome = Coupler.process("validate", path, env=values)
    assert outcome.code == 1, outcome
    assert "source 'grpc://${LEAK_HOST}:${LEAK_PORT}' (with LEAK_HOST, LEAK_PORT from the " in (
        outcome.err
    )
    assert "FMU file '${LEAK_DIR}/b.fmu' (with LEAK_DIR from the environment) does not exist" in (
        outcome.err
    )
    assert "FMU source '${SCHEME_DIR}/c.fmu' (with SCHEME_DIR from the environment) uses a " in (
        outcome.err
    )
    assert "s3cr3t" not in outcome.err + outcome.out, outcome.err


def test_a_fleet_health_url_in_error_names_its_variables_never_their_values(
    tmp_path: Path,
) -> None:
    """A fleet file's health URL that does not work once expanded: one sentence naming the
    variables (it was a traceback ending "Port could not be cast to integer value as
    's3cr3t-port'")."""
    LEAKY_SSD.write(tmp_path / "leak.ssd")
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(
        '[scenario]\nssp = "leak.ssd"\n\n[[service]]\nname = "gain"\n'
        'command = ["python", "-m", "coupler.examples", "gain", "--port", "${GAIN_PORT}"]\n'
        'health = "grpc://${GAIN_HOST}:${GAIN_PORT}"\n'
    )
    values = {"GAIN_HOST": "127.0.0.1", "GAIN_PORT": "s3cr3t-port"}
    outcome = Coupler.process("fleet", fleet, env=values, cwd=tmp_path)
    assert outcome.code == 1, outcome
    assert outcome.err.startswith(
        f"error: {fleet} service 'gain': health 'grpc://${{GAIN_HOST}}:${{GAIN_PORT}}' (with "
        "GAIN_HOST, GAIN_PORT from the environment) is not grpc://HOST:PORT"
    ), outcome.err
    assert "s3cr3t" not in outcome.err + outcome.out and "Traceback" not in outcome.err


class ForgingGain(GainParticipant):
    """A participant whose error message tries to take the terminal over: erase the line,
    then print a run that completed."""

    async def do_step(self, time_s: float, step: float, inputs: Any) -> Any:
        raise RuntimeError(
            "\x1b[1A\x1b[2K\rcompleted: 3 steps to t=1.5 s in 0.01 s\n\u202eresults: /etc/passwd"
        )


def test_a_participants_words_cannot_forge_a_line(tmp_path: Path) -> None:
    """What a participant says reaches the terminal with its control characters escaped
    (``\\x1b``, ``\\n``): its escape sequences could erase Coupler's lines and print a
    ``completed:`` of their own."""
    with serving(ForgingGain()) as server:
        out = tmp_path / "out"
        command = ["run", str(DATA / "mixed.ssd"), "--out", str(out)]
        result = subprocess.run(
            [sys.executable, "-m", "coupler_orchestrator", *command],
            capture_output=True,
            text=True,
            env={**os.environ, "GAIN_PORT": str(server.port)},
            timeout=60,
            check=False,
        )
    assert result.returncode == 1, result.stderr
    shown = result.stdout + result.stderr
    assert "\x1b" not in shown and "\u202e" not in shown and "\r" not in shown
    assert not any(line.startswith("completed:") for line in shown.splitlines())
    assert "RuntimeError: \\x1b[1A\\x1b[2K\\rcompleted: 3 steps" in result.stderr
    assert "\\n\\u202eresults: /etc/passwd" in result.stderr
