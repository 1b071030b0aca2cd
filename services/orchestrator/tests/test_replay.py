"""Record & replay: ``coupler run --record``, ``--replay``, ``replay:`` sources and the
``coupler replay`` service, on the mixed scenario (every value type over gRPC):

    Source (FMI 2) --ramp, counter--> Gain (gRPC) --y, count, inverted, echo, blob_out-->
        Feed (FMI 3) --real_out, int_out, bool_out, string_out--> Feed2 (FMI 2)

Gain is recorded against the real example participant, then replayed three ways with that
participant out of reach; results.csv must be the recorded run's, byte for byte.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coupler.channels import Causality, Channel, Description, ValueType
from coupler.errors import ScenarioError
from coupler.server import ParticipantServer
from coupler.testing import free_port
from coupler_orchestrator import recording
from coupler_orchestrator.observer import Column, RunEnd, RunInfo
from coupler_orchestrator.pipeline.replay import ReplayParticipant

from .conftest import DATA, Coupler

BLOB = "00010203ff"


@pytest.fixture
def recorded(
    coupler: Coupler,
    tmp_path: Path,
    gain_server: ParticipantServer,
    fmus: dict[str, Path],
) -> Path:
    """The results directory of the mixed scenario run against the real Gain participant, Gain
    recorded."""
    out = tmp_path / "recorded"
    outcome = coupler(
        "run", DATA / "mixed.ssd", "--out", out, "--record", "Gain", "--param", f"Gain.blob={BLOB}"
    )
    assert outcome.code == 0, outcome.err
    return out


def test_recording_holds_every_output_typed(
    coupler: Coupler, tmp_path: Path, gain_server: ParticipantServer, fmus: dict[str, Path]
) -> None:
    """The recording has all of Gain's outputs, typed, even when the CSV selects none of them,
    plus its grid and declared channels."""
    out = tmp_path / "out"
    outcome = coupler(
        "run",
        DATA / "mixed.ssd",
        "--out",
        out,
        "--record",
        "Gain,Source",
        "--output-variables",
        "Feed2.*",
        "--param",
        f"Gain.blob={BLOB}",
    )
    assert outcome.code == 0, outcome.err
    assert "Gain.y" not in coupler.results(out)[0]
    assert f"recording: {out / 'recordings' / 'Gain.crec'}" in outcome.out
    assert coupler.summary(out)["recordings"] == {
        "Gain": "recordings/Gain.crec",
        "Source": "recordings/Source.crec",
    }
    gain = recording.read(out / "recordings" / "Gain.crec")
    assert gain.component == "Gain"
    assert [c.name for c in gain.outputs] == ["y", "x", "count", "inverted", "echo", "blob_out"]
    assert gain.times == (0.0, 0.5, 1.0, 1.5)
    assert [v["y"] for v in gain.values] == [0.0, 0.0, 1.5, 3.0]
    assert [v["count"] for v in gain.values] == [10, 10, 11, 12]
    assert [v["inverted"] for v in gain.values] == [True] * 4
    assert [v["echo"] for v in gain.values] == ["hi"] * 4
    assert [v["blob_out"] for v in gain.values] == [bytes.fromhex("ff03020100")] * 4
    assert gain.grid == recording.Grid(
        start_time=0.0, step_size=0.5, multiple=1, component_step=0.5
    )
    assert gain.description.name == "Gain"
    u = gain.description.channel("u")
    assert u is not None and (u.causality, u.type, u.unit) == (
        Causality.INPUT,
        ValueType.REAL,
        "m/s",
    )
    assert gain.summary().endswith("has t0=0 s, h=0.5 s, 3 steps to 1.5 s")
    assert (out / "recordings" / "Source.crec").is_file()
    with pytest.raises(ScenarioError, match=r"holds 2 recordings \(Gain, Source\); name the"):
        recording.locate(out, None)


def write_recording(path: Path, reals: list[float], *, multiple: int = 2) -> None:
    """A recording of "Slow" (Real, String, Binary outputs; step multiple ``multiple``) made
    by the Recorder from rows as the master hands them over, t0 = 1 s, h = 0.1 s."""
    channels = (
        Channel(name="r", causality=Causality.OUTPUT, type=ValueType.REAL),
        Channel(name="s", causality=Causality.OUTPUT, type=ValueType.STRING),
        Channel(
            name="state", causality=Causality.OUTPUT, type=ValueType.BINARY, message_type="x.Y"
        ),
        Channel(name="u", causality=Causality.INPUT, type=ValueType.BINARY, start=b"\x01"),
    )
    recorder = recording.Recorder(
        path,
        Description(name="Slow", channels=channels),
        component="Slow",
        multiple=multiple,
        step=0.1 * multiple,
    )
    steps = (len(reals) - 1) * multiple
    recorder.started(
        RunInfo(
            run_id="bits",
            algorithm="jacobi",
            members=("Other", "Slow"),
            multiples=(1, multiple),
            columns=(
                Column(name="Other.z", unit="", type="Real"),
                *(Column(name=f"Slow.{c.name}", unit="", type=str(c.type)) for c in channels[:3]),
            ),
            start_time=1.0,
            stop_time=1.0 + steps * 0.1,
            step_size=0.1,
            steps=steps,
        )
    )
    for k in range(steps + 1):
        j = k // multiple
        recorder.stepped(1.0 + k * 0.1, [float(k), reals[j], f"ü{j}", bytes([j]) * 3])
    recorder.finished(RunEnd(status="completed", reason="", steps=steps, end_time=0, wall_time=0))


def test_real_values_are_bit_exact(tmp_path: Path) -> None:
    """Reals keep their float64 bits (-0.0, NaN payloads, subnormals, inf); a component with
    step multiple 2 is recorded at its own communication points only; a run killed mid-record
    leaves every complete record readable."""
    path = tmp_path / "Slow.crec"
    nan = struct.unpack("<d", struct.pack("<Q", 0x7FF8_0000_DEAD_BEEF))[0]
    reals = [-0.0, nan, 5e-324, math.inf, 0.1 + 0.2]
    write_recording(path, reals)
    read = recording.read(path)
    assert read.steps == 4
    bits = [struct.pack("<d", v["r"]) for v in read.values]  # type: ignore[arg-type]
    assert bits == [struct.pack("<d", r) for r in reals]
    assert [v["s"] for v in read.values] == [f"ü{j}" for j in range(5)]
    assert read.outputs[2].message_type == "x.Y"
    assert read.description.channel("u") == Channel(
        name="u", causality=Causality.INPUT, type=ValueType.BINARY, start=b"\x01"
    )
    assert read.grid.multiple == 2 and read.grid.component_step == 0.2

    data = path.read_bytes()
    path.write_bytes(data[:-3])  # killed while writing the last record
    assert recording.read(path).steps == 3
    _, version, size = struct.unpack_from("<4sHI", data)
    header = json.loads(data[10 : 10 + size])
    header["description"]["capabilities"] = []  # valid JSON, not the format
    body = json.dumps(header).encode()
    path.write_bytes(struct.pack("<4sHI", b"CREC", version, len(body)) + body + data[10 + size :])
    with pytest.raises(ScenarioError, match="is not a readable Coupler recording"):
        recording.read(path)
    header["description"]["capabilities"] = {}
    body = json.dumps(header).encode()
    path.write_bytes(struct.pack("<4sHI", b"CREC", version, len(body)) + body + data[10 + size :])
    assert recording.read(path).steps == 4  # the rebuilt file is read, so the above was fair
    path.write_bytes(b"PK\x03\x04 not a recording")
    with pytest.raises(ScenarioError, match="is not a readable Coupler recording"):
        recording.read(path)


@settings(
    max_examples=int(os.environ.get("COUPLER_FUZZ_EXAMPLES", "120")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_any_bytes_give_a_recording_or_a_scenario_error(
    tmp_path: Path, data: st.DataObject
) -> None:
    """Arbitrary bytes and mutations of a real recording: a Recording or ScenarioError."""
    original = tmp_path / "original.crec"
    if not original.exists():
        write_recording(original, [0.0, 1.5, -2.0])
    content = bytearray(original.read_bytes())
    if data.draw(st.booleans()):
        content = bytearray(data.draw(st.binary(max_size=200)))
    for _ in range(data.draw(st.integers(0, 4))):
        at = data.draw(st.integers(0, max(len(content) - 1, 0)))
        size = data.draw(st.integers(1, 16))
        content[at : at + size] = data.draw(st.binary(max_size=size))
    case = tmp_path / "case.crec"
    case.write_bytes(bytes(content))
    with contextlib.suppress(ScenarioError):
        recording.read(case)


def test_replay_option_is_byte_identical(
    coupler: Coupler, tmp_path: Path, recorded: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--replay Gain=RESULTS``: the recording runs in-process in Gain's place."""
    monkeypatch.setenv("GAIN_PORT", str(free_port()))
    out = tmp_path / "replayed"
    outcome = coupler("run", DATA / "mixed.ssd", "--out", out, "--replay", f"Gain={recorded}")
    assert outcome.code == 0, outcome.err
    assert (out / "results.csv").read_bytes() == (recorded / "results.csv").read_bytes()
    assert coupler.summary(out)["implementations"]["Gain"].startswith(
        "coupler replay of coupler.examples.gain"
    )


def test_replay_source_in_the_ssd(coupler: Coupler, tmp_path: Path, recorded: Path) -> None:
    """``source="replay:PATH#Gain"``, PATH relative to the SSD."""
    ssd = (DATA / "mixed.ssd").read_text()
    grpc_source = 'source="grpc://${GAIN_HOST:-127.0.0.1}:${GAIN_PORT}"'
    assert grpc_source in ssd
    copy = tmp_path / "mixed-replay.ssd"
    copy.write_text(ssd.replace(grpc_source, 'source="replay:recorded#Gain"'))
    out = tmp_path / "replayed"
    outcome = coupler("run", copy, "--out", out)
    assert outcome.code == 0, outcome.err
    assert (out / "results.csv").read_bytes() == (recorded / "results.csv").read_bytes()

    copy.write_text(ssd.replace(grpc_source, 'source="replay:recorded#Feed"'))
    outcome = coupler("run", copy, "--out", tmp_path / "wrong")
    assert outcome.code == 1
    assert "no recording of 'Feed'" in outcome.err


def test_replay_refuses_another_grid(coupler: Coupler, tmp_path: Path, recorded: Path) -> None:
    """Another step, start or a stop beyond the recording: one problem, the recorded grid."""
    recorded_grid = "has t0=0 s, h=0.5 s, 3 steps to 1.5 s"
    for flags, asked in (
        (["--step", "0.25"], "the run asks h=0.25 s"),
        (["--start-time", "0.5", "--stop-time", "1.5"], "the run asks t0=0.5 s"),
        (["--stop-time", "2"], "the run asks a stop time of 2 s, beyond its end"),
    ):
        outcome = coupler(
            "run",
            DATA / "mixed.ssd",
            "--out",
            tmp_path / "x",
            "--replay",
            f"Gain={recorded}",
            *flags,
        )
        assert outcome.code == 1
        assert "1 problem\n" in outcome.err
        assert recorded_grid in outcome.err and asked in outcome.err, outcome.err
    checked = coupler(
        "validate", DATA / "mixed.ssd", "--replay", f"Gain={recorded}", "--step", "0.25"
    )
    assert checked.code == 1 and recorded_grid in checked.err
    shorter = coupler(
        "run", DATA / "mixed.ssd", "--out", tmp_path / "y", "--replay", f"Gain={recorded}",
        "--stop-time", "1",
    )  # fmt: skip
    assert shorter.code == 0, shorter.err


async def test_replay_participant_refuses_steps_it_does_not_have(recorded: Path) -> None:
    replay = ReplayParticipant(recorded, "Gain")
    await replay.open()
    assert (await replay.do_step(0.5, 0.5, {"u": 99.0}))["y"] == 1.5  # inputs are ignored
    with pytest.raises(ScenarioError, match=r"step from t=1.5 s by 0.5 s, which it does not"):
        await replay.do_step(1.5, 0.5, {})
    with pytest.raises(ScenarioError, match=r"step from t=0.25 s"):
        await replay.do_step(0.25, 0.5, {})


def test_coupler_replay_service(
    coupler: Coupler, tmp_path: Path, recorded: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``coupler replay RESULTS --token-file F`` as its own process, reached over gRPC as the
    SSD's Gain (with the token; without it, refused); asked for another step it refuses at
    Initialize with the recorded grid."""
    token = tmp_path / "token"
    token.write_text("replay-token-0123456789abcdef\n")
    token.chmod(0o600)
    monkeypatch.setenv("COUPLER_TOKEN_FILE", str(token))
    service = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "coupler_orchestrator",
            "replay",
            str(recorded),  # its only recording: no --component needed
            "--port",
            "0",
            "--token-file",
            str(token),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert service.stdout is not None
        first = service.stdout.readline()
        assert "has t0=0 s, h=0.5 s, 3 steps to 1.5 s" in first
        serving = service.stdout.readline()
        assert serving.startswith("serving Gain at grpc://127.0.0.1:"), serving
        monkeypatch.setenv("GAIN_PORT", serving.strip().rpartition(":")[2])
        out = tmp_path / "served"
        outcome = coupler("run", DATA / "mixed.ssd", "--out", out)
        assert outcome.code == 0, outcome.err
        assert (out / "results.csv").read_bytes() == (recorded / "results.csv").read_bytes()
        monkeypatch.delenv("COUPLER_TOKEN_FILE")
        anonymous = coupler("run", DATA / "mixed.ssd", "--out", tmp_path / "anonymous")
        assert anonymous.code == 1 and "Gain.Describe [UNAUTHENTICATED]" in anonymous.err
        monkeypatch.setenv("COUPLER_TOKEN_FILE", str(token))
        refused = coupler("run", DATA / "mixed.ssd", "--out", tmp_path / "x", "--step", "0.25")
        assert refused.code == 1
        assert "Gain.Initialize [INVALID_ARGUMENT]" in refused.err
        assert "has t0=0 s, h=0.5 s, 3 steps to 1.5 s; the run asks h=0.25 s" in refused.err
    finally:
        service.terminate()
        assert service.wait(10) == 0
        assert service.stdout is not None
        service.stdout.close()


def test_record_and_replay_names_are_checked(
    coupler: Coupler, tmp_path: Path, recorded: Path
) -> None:
    outcome = coupler(
        "run", DATA / "mixed.ssd", "--out", tmp_path / "x", "--record", "Gian",
        "--replay", f"Feed3={recorded}",
    )  # fmt: skip
    assert outcome.code == 1
    assert "--record Gian: no component 'Gian' in the scenario" in outcome.err
    assert "--replay Feed3: no component 'Feed3'" in outcome.err


def test_a_terminated_run_replays_its_end(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """Stair (FMI 2) alone asks to end the run at t=9 s; its replay asks again there, with the
    same reason, though the run plans to go to 20 s."""
    recorded, replayed = tmp_path / "recorded", tmp_path / "replayed"
    runs = {}
    for out, flags in (
        (recorded, ["--record", "Stair"]),
        (replayed, ["--replay", f"Stair={recorded}"]),
    ):
        outcome = coupler(
            "run", fmus["Stair2"], "--out", out, "--step", "0.5", "--stop-time", "20", *flags
        )
        assert outcome.code == 0, outcome.err
        runs[out.name] = coupler.summary(out)
        assert runs[out.name]["status"] == "terminated"
    assert runs["replayed"]["reason"] == runs["recorded"]["reason"]
    assert "Stair asked to end the run at t=9 s" in runs["replayed"]["reason"]
    assert (replayed / "results.csv").read_bytes() == (recorded / "results.csv").read_bytes()


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_step_multiples_replay(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path], algorithm: str
) -> None:
    """Source steps every 2 base steps (deltaTime 1 s, h 0.5 s): recorded at t = 0, 1, 2 only,
    replayed in its place with the same rows; with h 0.25 (multiple 4) its own step is still
    1 s, so the replay serves that run too."""
    recorded, replayed = tmp_path / "recorded", tmp_path / "replayed"
    for out, flags in (
        (recorded, ["--record", "Source"]),
        (replayed, ["--replay", f"Source={recorded}"]),
    ):
        outcome = coupler(
            "run", DATA / "multiples.ssd", "--out", out, "--algorithm", algorithm, *flags
        )
        assert outcome.code == 0, outcome.err
    source = recording.read(recorded / "recordings" / "Source.crec")
    assert source.times == (0.0, 1.0, 2.0)
    assert (source.grid.multiple, source.grid.component_step) == (2, 1.0)
    assert (replayed / "results.csv").read_bytes() == (recorded / "results.csv").read_bytes()
    finer = coupler(
        "run", DATA / "multiples.ssd", "--out", tmp_path / "finer", "--step", "0.25",
        "--algorithm", algorithm, "--replay", f"Source={recorded}",
    )  # fmt: skip
    assert finer.code == 0, finer.err
    assert coupler.column(tmp_path / "finer", "Source.ramp")[::4] == [0.0, 1.0, 2.0]


def test_fleet_passes_record_on(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``coupler fleet FLEET --record Gain``: the fleet's run records Gain (in a folder of its
    own in the fleet file's ``out``, ``latest`` linking to it)."""
    monkeypatch.setenv("GAIN_PORT", str(free_port()))
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(
        f'[scenario]\nssp = "{DATA / "mixed.ssd"}"\nout = "{tmp_path / "out"}"\n\n'
        '[[service]]\nname = "gain"\n'
        'command = ["python", "-m", "coupler.examples", "gain", "--port", "${GAIN_PORT}"]\n'
        'health = "grpc://127.0.0.1:${GAIN_PORT}"\n'
    )
    outcome = coupler("fleet", fleet, "--exit", "--record", "Gain")
    assert outcome.code == 0, outcome.err
    assert recording.read(tmp_path / "out" / "latest" / "recordings" / "Gain.crec").steps == 3


def test_replay_never_picks_up_another_runs_recording(
    coupler: Coupler, tmp_path: Path, recorded: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A results folder whose own run recorded nothing, holding an older run's recordings/
    (as the old single ./results folder left them): refused, not replayed."""
    monkeypatch.setenv("GAIN_PORT", str(free_port()))
    other = tmp_path / "other"
    other.mkdir()
    for name in ("results.csv", "summary.json"):
        (other / name).write_bytes((recorded / name).read_bytes())
    summary = json.loads((other / "summary.json").read_text())
    summary.pop("recordings")
    summary["run_id"] = "later-run"
    (other / "summary.json").write_text(json.dumps(summary))
    (other / "recordings").mkdir()
    (other / "recordings" / "Gain.crec").write_bytes(
        (recorded / "recordings" / "Gain.crec").read_bytes()
    )
    outcome = coupler(
        "run", DATA / "mixed.ssd", "--out", tmp_path / "o", "--replay", f"Gain={other}"
    )
    assert outcome.code == 1
    assert (
        f"{other}/recordings/Gain.crec is not a recording of the run whose results are in "
        f"{other} (run later-run did not --record Gain): another run left it there"
    ) in outcome.err
    ok = coupler("run", DATA / "mixed.ssd", "--out", tmp_path / "p", "--replay", f"Gain={recorded}")
    assert ok.code == 0, ok.err
