"""Record & replay: ``coupler run --record``, ``--replay``, ``replay:`` sources and the
``coupler replay`` service, on the mixed scenario (every value type over gRPC):

    Source (FMI 2) --ramp, counter--> Gain (gRPC) --y, count, inverted, echo, blob_out-->
        Feed (FMI 3) --real_out, int_out, bool_out, string_out--> Feed2 (FMI 2)

Gain is recorded against the real example participant, then replayed three ways with that
participant out of reach; results.csv must be the recorded run's, byte for byte.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import struct
import subprocess
import sys
import tracemalloc
import zlib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coupler.channels import Causality, Channel, Description, RunSetup, ValueType
from coupler.errors import ScenarioError
from coupler.server import ParticipantServer
from coupler.testing import free_port
from coupler_orchestrator import recording
from coupler_orchestrator.observer import Column, RunEnd, RunInfo
from coupler_orchestrator.pipeline.replay import ReplayParticipant

from ..support import DATA, Coupler

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
    times, values = zip(*gain.rows(), strict=True)
    assert times == (0.0, 0.5, 1.0, 1.5)
    assert [v["y"] for v in values] == [0.0, 0.0, 1.5, 3.0]
    assert [v["count"] for v in values] == [10, 10, 11, 12]
    assert [v["inverted"] for v in values] == [True] * 4
    assert [v["echo"] for v in values] == ["hi"] * 4
    assert [v["blob_out"] for v in values] == [bytes.fromhex("ff03020100")] * 4
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
    recorder.closing(RunEnd(status="completed", reason="", steps=steps, end_time=0, wall_time=0))


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
    values = [v for _, v in read.rows()]
    bits = [struct.pack("<d", v["r"]) for v in values]  # type: ignore[arg-type]
    assert bits == [struct.pack("<d", r) for r in reals]
    assert [v["s"] for v in values] == [f"ü{j}" for j in range(5)]
    assert read.outputs[2].message_type == "x.Y"
    assert read.description.channel("u") == Channel(
        name="u", causality=Causality.INPUT, type=ValueType.BINARY, start=b"\x01"
    )
    assert read.grid.multiple == 2 and read.grid.component_step == 0.2

    data = path.read_bytes()
    _, version, size, _ = struct.unpack_from("<4sHII", data)
    header = json.loads(data[14 : 14 + size])
    header["description"]["capabilities"] = []  # valid JSON, not the format
    body = json.dumps(header).encode()
    prefix = struct.pack("<4sHII", b"CREC", version, len(body), zlib.crc32(body))
    path.write_bytes(prefix + body + data[14 + size :])
    with pytest.raises(ScenarioError, match="is not a readable Coupler recording"):
        recording.read(path)
    header["description"]["capabilities"] = {}
    body = json.dumps(header).encode()
    prefix = struct.pack("<4sHII", b"CREC", version, len(body), zlib.crc32(body))
    path.write_bytes(prefix + body + data[14 + size :])
    assert recording.read(path).steps == 4  # the rebuilt file is read, so the above was fair
    path.write_bytes(b"PK\x03\x04 not a recording")
    with pytest.raises(ScenarioError, match="is not a readable Coupler recording"):
        recording.read(path)


def test_a_killed_run_leaves_every_whole_block_readable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Blocks of one point each: the file of a run killed while writing its last block (no
    seal) keeps every block before it; cut anywhere else, it is refused."""
    monkeypatch.setattr(recording, "BLOCK_BYTES", 1)
    path = tmp_path / "Slow.crec"
    write_recording(path, [0.0, 1.0, 2.0, 3.0, 4.0])
    data = path.read_bytes()
    assert recording.read(path).sealed and recording.read(path).steps == 4
    path.write_bytes(data[: -24 - 3])  # the seal and the end of the last block are missing
    read = recording.read(path)
    assert (read.steps, read.sealed, read.end_time) == (3, False, 1.6)
    assert [v["r"] for _, v in read.rows()] == [0.0, 1.0, 2.0, 3.0]
    path.write_bytes(data[:-24] + data[-24:-3])  # only the seal is cut: every point is there
    assert recording.read(path).steps == 4
    path.write_bytes(data + b"\0")
    with pytest.raises(ScenarioError, match="is damaged: bytes follow the seal"):
        recording.read(path)


def flipped(data: bytes, start: int, count: int) -> bytes:
    """``data`` with ``count`` bytes after ``start``, spread evenly, inverted."""
    damaged = bytearray(data)
    stride = max(1, (len(data) - start) // count)
    for at in range(start, len(data), stride)[:count]:
        damaged[at] ^= 0xFF
    return bytes(damaged)


def test_a_damaged_recording_is_refused(
    coupler: Coupler, tmp_path: Path, recorded: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """40 bytes flipped in the points (or one in the header) of a recording: ``--replay``
    refuses it naming the file and the damaged block (they used to pass as a truncated
    recording, or as other values: the run completed)."""
    monkeypatch.setenv("GAIN_PORT", str(free_port()))
    path = recorded / "recordings" / "Gain.crec"
    data = path.read_bytes()
    _, _, size, _ = struct.unpack_from("<4sHII", data)
    for name, damaged, said in (
        ("points", flipped(data, 14 + size, 40), f"the block header at byte {14 + size} "),
        ("values", flipped(data, 14 + size + 40, 40), "the block of points 0.. at byte "),
        ("header", flipped(data, 30, 1), "its header does not match its checksum"),
    ):
        path.write_bytes(damaged)
        outcome = coupler(
            "run", DATA / "mixed.ssd", "--out", tmp_path / name, "--replay", f"Gain={recorded}"
        )
        assert outcome.code == 1, (name, outcome)
        assert f"{path} is damaged: {said}" in outcome.err, outcome.err
        assert "record it again" in outcome.err and "Traceback" not in outcome.err
        assert not (tmp_path / name / "results.csv").exists()


def test_a_recording_of_version_1_is_refused_by_its_version(tmp_path: Path) -> None:
    path = tmp_path / "old.crec"
    path.write_bytes(struct.pack("<4sHI", b"CREC", 1, 2) + b"{}")
    with pytest.raises(ScenarioError, match=r"format version 1; this Coupler reads version 2"):
        recording.read(path)


def test_a_replay_holds_one_block_in_memory_not_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A 24 MB recording (4000 points of 6 kB): opening it and replaying 10 steps allocates
    a small part of the file, not the file (it used to be read whole, and every point
    decoded: 1.43 GB of memory for 10 steps of a 159 MB file). Allocations counted by
    tracemalloc, not timed; ``make bench`` measures the process's memory."""
    path = tmp_path / "Big.crec"
    blob = os.urandom(6000)
    channels = (Channel(name="b", causality=Causality.OUTPUT, type=ValueType.BINARY),)
    recorder = recording.Recorder(
        path, Description(name="Big", channels=channels), component="Big", multiple=1, step=0.1
    )
    steps = 4000
    recorder.started(
        RunInfo(
            run_id="big", algorithm="jacobi", members=("Big",), multiples=(1,),
            columns=(Column(name="Big.b", unit="", type="Binary"),), start_time=0.0,
            stop_time=steps * 0.1, step_size=0.1, steps=steps,
        )
    )  # fmt: skip
    for k in range(steps + 1):
        recorder.stepped(k * 0.1, [blob])
    recorder.closing(RunEnd(status="completed", reason="", steps=steps, end_time=0, wall_time=0))
    size = path.stat().st_size
    assert size > 24_000_000

    async def replay_ten_steps() -> None:
        replay = ReplayParticipant(path)
        await replay.open()
        try:
            await replay.initialize(
                RunSetup(run_id="r", start_time=0.0, stop_time=1.0, step_size=0.1)
            )
            for k in range(10):
                assert (await replay.do_step(k * 0.1, 0.1, {}))["b"] == blob
        finally:
            await replay.close()

    tracemalloc.start()
    try:
        asyncio.run(replay_ten_steps())
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < size / 10, (peak, size)


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
        assert outcome.err.count("\n") == 1, outcome.err  # one problem, one line
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
    try:
        assert (await replay.do_step(0.5, 0.5, {"u": 99.0}))["y"] == 1.5  # inputs are ignored
        with pytest.raises(ScenarioError, match=r"step from t=1.5 s by 0.5 s, which it does"):
            await replay.do_step(1.5, 0.5, {})
        with pytest.raises(ScenarioError, match=r"step from t=0.25 s"):
            await replay.do_step(0.25, 0.5, {})
    finally:
        await replay.close()


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
    assert [t for t, _ in source.rows()] == [0.0, 1.0, 2.0]
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
