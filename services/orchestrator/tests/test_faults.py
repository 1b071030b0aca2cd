"""Faults with real processes: participants killed, stopped, hung, slow, late or restarted; the
orchestrator killed or interrupted; a second client meddling; a full disk. Every test asserts
what summary.json and results.csv say afterwards.

    Source (FMI 2) --ramp--> Gain (gRPC, its own process) --y--> Integ (FMI 2)

0 .. 20 s in steps of 0.1 s; paced (--realtime-factor) where a fault must hit mid-run.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import secrets
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import grpc
import pytest

from coupler.channels import RunSetup, Value
from coupler.client import parse_address
from coupler.examples.gain import GainParticipant
from coupler.participant import Values
from coupler.testing import SystemStructure, fmu, free_port, wait_until
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc

from .support import Coupler, serving
from .support.faults import FAULTY_SSD, RUN, SSD, Gain, assert_rows_kept, gain, rows, summary

pytestmark = pytest.mark.usefixtures("fmus")
PACED = ("--realtime-factor", "5")
"""200 steps in 4 s: the first rows reach the disk after 1 s (results.csv is flushed once a
second), and a fault caused then lands well before the run's end on a slow machine too."""


@pytest.fixture
def ssd(tmp_path: Path) -> Path:
    return SSD.write(tmp_path / "faults.ssd")


def later(seconds: float, action: Any) -> threading.Timer:
    timer = threading.Timer(seconds, action)
    timer.start()
    return timer


def once_rows(out: Path, count: int, action: Any) -> threading.Thread:
    """Do ``action`` as soon as ``count`` rows are in out/results.csv (the run is stepping)."""

    def watch() -> None:
        wait_for_rows(out, count)
        action()

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


@pytest.mark.usefixtures("step_path")
def test_a_killed_participant_fails_the_run_rows_kept(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with gain(monkeypatch) as process:
        once_rows(tmp_path, 3, lambda: process.signal(signal.SIGKILL))
        outcome = coupler("run", ssd, "--out", tmp_path, *RUN, *PACED)
    assert outcome.code == 1
    result = summary(tmp_path)
    assert result["status"] == "failed"
    # gRPC's core reports a stream whose peer vanished mid-read as UNAVAILABLE, or (a reset
    # racing the read, seen on a busy machine) as INTERNAL
    assert re.search(r"Gain\.DoStep \[(UNAVAILABLE|INTERNAL)\]", result["reason"]), result
    assert "the run had reached t=" in result["reason"]
    assert 1 < len(assert_rows_kept(tmp_path)) < 201


@pytest.mark.usefixtures("step_path")
def test_a_stopped_participant_says_it_is_shutting_down(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with gain(monkeypatch) as process:
        once_rows(tmp_path, 3, lambda: process.signal(signal.SIGTERM))
        outcome = coupler("run", ssd, "--out", tmp_path, *RUN, *PACED)
    assert outcome.code == 1
    result = summary(tmp_path)
    assert result["status"] == "failed"
    assert "Gain.DoStep [UNAVAILABLE]" in result["reason"]
    assert_rows_kept(tmp_path)


@pytest.mark.parametrize("flag", ["--hang-at", "--block-at"])
@pytest.mark.usefixtures("step_path")
def test_a_hung_participant_fails_within_the_deadline(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, flag: str
) -> None:
    """An async hang (the participant's loop still answers) and a blocked process (nothing
    answers): both end at the call deadline, naming participant, call and time."""
    with gain(monkeypatch, flag, "1.0"):
        started = time.monotonic()
        outcome = coupler("run", ssd, "--out", tmp_path, *RUN, "--call-timeout", "1")
        took = time.monotonic() - started
    assert outcome.code == 1
    result = summary(tmp_path)
    assert result["status"] == "failed"
    assert "Gain.DoStep [DEADLINE_EXCEEDED]: no answer within 1 s" in result["reason"]
    assert "the run had reached t=1 s" in result["reason"]
    assert len(assert_rows_kept(tmp_path)) == 11
    assert took < 10  # the deadline, Terminate's deadline, and start-up


def test_a_slow_participant_is_waited_for(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with gain(monkeypatch, "--slow", "0.02"):
        outcome = coupler("run", ssd, "--out", tmp_path, "--step", "0.5", "--call-timeout", "5")
    assert outcome.code == 0, outcome.err
    assert summary(tmp_path)["participants"]["Gain"]["do_step_latency_ms"]["p50"] >= 20


def test_a_participant_that_starts_late_is_waited_for(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    port = free_port()
    monkeypatch.setenv("GAIN_PORT", str(port))
    started: list[Gain] = []
    later(1.0, lambda: started.append(Gain(port)))
    try:
        outcome = coupler("run", ssd, "--out", tmp_path, "--step", "0.5")
    finally:
        time.sleep(0.1)
        for process in started:
            process.stop()
    assert outcome.code == 0, outcome.err
    assert summary(tmp_path)["status"] == "completed"


def test_a_restarted_participant_serves_the_next_run(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    port = free_port()
    with gain(monkeypatch, port=port):
        assert coupler("run", ssd, "--out", tmp_path / "a", "--step", "0.5").code == 0
    with gain(monkeypatch, port=port):
        assert coupler("run", ssd, "--out", tmp_path / "b", "--step", "0.5").code == 0
    assert rows(tmp_path / "a") == rows(tmp_path / "b")


def orchestrator(ssd: Path, out: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "coupler_orchestrator", "run", str(ssd), "--out", str(out), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_for_rows(out: Path, count: int, within: float = 20.0) -> None:
    """Until results.csv has ``count`` complete rows (its lines counted, not parsed: a fast
    run writes megabytes between two looks)."""
    wait_until(
        lambda: (
            (out / "results.csv").exists()
            and (out / "results.csv").read_bytes().count(b"\n") > count
        ),
        within,
        what=f"{count} rows in {out}",
    )


@pytest.mark.slow
@pytest.mark.known_leak(
    temp="coupler-run-*",
    reason="SIGKILL of `coupler run`: no code of it runs after it, so the run's scratch folder "
    "(its TMPDIR, cli.supervisor) stays; the child dies with it",
)
def test_a_killed_orchestrator_leaves_a_summary_and_frees_its_participants(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGKILL: no clean-up runs. summary.json (written at the start) and the flushed rows
    remain; the participant ends the run with its broken step stream, so the next run starts
    at once — long before the 600 s lease."""
    with gain(monkeypatch):
        killed = orchestrator(ssd, tmp_path / "killed", *RUN, "--realtime-factor", "5")
        wait_for_rows(tmp_path / "killed", 6)
        time.sleep(1.2)  # past a flush
        killed.send_signal(signal.SIGKILL)
        killed.communicate(timeout=10)
        left = summary(tmp_path / "killed")
        assert left["status"] == "running"
        kept = rows(tmp_path / "killed")
        assert len(kept) >= 6 and all(None not in row.values() for row in kept)
        started = time.monotonic()
        outcome = coupler("run", ssd, "--out", tmp_path / "next", "--step", "0.5", "--lease", "600")
        while outcome.code != 0 and "is in another run" in outcome.err:
            # the killed run's stream may still be ending in the participant (seen once, on a
            # busy machine): the claim is "long before the lease", not "in the same instant"
            assert time.monotonic() - started < 30, outcome.err
            time.sleep(0.5)
            outcome = coupler(
                "run", ssd, "--out", tmp_path / "next", "--step", "0.5", "--lease", "600",
                "--force",
            )  # fmt: skip
        assert outcome.code == 0, outcome.err
        assert time.monotonic() - started < 30


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_orchestrator_ends_cleanly(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sig: int
) -> None:
    with gain(monkeypatch):
        run = orchestrator(ssd, tmp_path / "o", *RUN, "--realtime-factor", "5")
        wait_for_rows(tmp_path / "o", 4)
        sent = time.monotonic()
        run.send_signal(sig)
        _, err = run.communicate(timeout=20)
        assert time.monotonic() - sent < 5
        assert run.returncode == 130, err
        result = summary(tmp_path / "o")
        assert (result["status"], result["reason"]) == ("aborted", "interrupted by the user")
        assert_rows_kept(tmp_path / "o")
        # Terminate reached the participant: the next run starts at once
        assert coupler("run", ssd, "--out", tmp_path / "next", "--step", "0.5").code == 0


def meddle(port: int, stop: threading.Event, refused: list[grpc.StatusCode]) -> None:
    """Another process's client: DoStep (an invented and no run id), Terminate, Initialize."""
    with grpc.insecure_channel(parse_address(f"grpc://127.0.0.1:{port}")) as channel:
        stub = pb_grpc.GRPCComponentServiceStub(channel)
        bad = [pb.VariableBinding(channel="u", real=5e9)]
        calls = [
            (stub.DoStep, pb.DoStepRequest(run_id="guess", step_size=0.1, inputs=bad)),
            (stub.DoStep, pb.DoStepRequest(step_size=0.1, inputs=bad)),
            (stub.Terminate, pb.TerminateRequest(run_id="guess")),
        ]
        while not stop.is_set():
            for call, request in calls:
                try:
                    call(request, timeout=1)
                except grpc.RpcError as exc:
                    refused.append(exc.code())
            time.sleep(0.01)


def meddled_run(
    coupler: Coupler, ssd: Path, out: Path, port: int, *options: str
) -> tuple[int, list[grpc.StatusCode]]:
    refused: list[grpc.StatusCode] = []
    stop = threading.Event()
    meddler = threading.Thread(target=meddle, args=(port, stop, refused), daemon=True)
    meddler.start()
    try:
        outcome = coupler("run", ssd, "--out", out, *RUN, "--realtime-factor", "20", *options)
    finally:
        stop.set()
        meddler.join(5)
    return outcome.code, refused


def test_calls_from_a_second_client_change_nothing(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without the run's id, another client can neither step nor end the run: every call is
    refused and the results equal an undisturbed run's."""
    with gain(monkeypatch) as process:
        code, refused = meddled_run(coupler, ssd, tmp_path / "meddled", process.port)
        assert code == 0
        assert coupler("run", ssd, "--out", tmp_path / "clean", *RUN).code == 0
    assert refused and set(refused) == {grpc.StatusCode.FAILED_PRECONDITION}
    assert (tmp_path / "meddled" / "results.csv").read_bytes() == (
        tmp_path / "clean" / "results.csv"
    ).read_bytes()


def what_a_local_user_reads(out: Path, *logs: Path) -> list[str]:
    """Everything another local user can read about a run: its results folder (summary.json
    names the run id), the participant's log and every command line (`ps`)."""
    texts = [path.read_text(errors="replace") for path in out.rglob("*") if path.is_file()]
    texts += [log.read_text(errors="replace") for log in logs]
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        with contextlib.suppress(OSError):
            texts.append(cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace"))
    return texts


def intrude(port: int, run_id: str, guesses: list[bytes]) -> list[tuple[grpc.StatusCode, str]]:
    """DoStep(u=1e300) of run ``run_id``: without a secret, then with each guess."""
    answers = []
    with grpc.insecure_channel(parse_address(f"grpc://127.0.0.1:{port}")) as channel:
        stub = pb_grpc.GRPCComponentServiceStub(channel)
        huge = [pb.VariableBinding(channel="u", real=1e300)]
        for guess in [b"", *guesses]:
            request = pb.DoStepRequest(run_id=run_id, run_secret=guess, step_size=0.1, inputs=huge)
            try:
                stub.DoStep(request, timeout=5)
                answers.append((grpc.StatusCode.OK, ""))
            except grpc.RpcError as exc:
                answers.append((exc.code(), exc.details() or ""))
    return answers


@pytest.mark.slow
@pytest.mark.usefixtures("step_path")
def test_a_stranger_with_the_run_id_cannot_change_the_run_and_the_run_fails_naming_it(
    ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With everything a local user can read (summary.json, results, logs, `ps` lines, hence
    the run id), a stranger's DoStep(u=1e300) changes nothing: the participant refuses it
    (PERMISSION_DENIED), and the orchestrator's next call of the run is told, so the run fails
    naming the intrusion (exit 1). The secret (here chosen through COUPLER_RUN_SECRET, as a
    parent process would hand it over) is in none of what the stranger could read.

        stranger --DoStep(run id, no secret)--> Gain <--DoStep(run id, secret)-- coupler run
    """
    secret = secrets.token_hex(16)
    with gain(monkeypatch) as process:
        monkeypatch.setenv("COUPLER_RUN_SECRET", secret)
        out = tmp_path / "o"
        run = orchestrator(ssd, out, *RUN, *PACED)
        wait_for_rows(out, 4, within=90)  # start-up takes long on a busy machine
        seen = what_a_local_user_reads(out, process.log)
        run_id = summary(out)["run_id"]
        guesses = [run_id.encode(), secret[:16].encode(), secrets.token_bytes(32)]
        guesses += [word.encode() for text in seen for word in text.split() if len(word) >= 16]
        answers = intrude(process.port, run_id, guesses)
        printed, err = run.communicate(timeout=60)
        seen += [*what_a_local_user_reads(out, process.log), printed, err]
    assert all(secret not in text for text in seen)
    code, details = answers[0]
    assert code is grpc.StatusCode.PERMISSION_DENIED, answers[0]
    assert "names participant 'Gain's active run but does not carry that run's secret" in details
    assert all(code is not grpc.StatusCode.OK for code, _ in answers)  # none was stepped
    assert run.returncode == 1, err
    result = summary(out)
    assert result["status"] == "failed"
    assert re.search(
        r"^Gain\.DoStep \[ABORTED\]: Gain refused the run: a call without this run's secret "
        r"arrived from ipv4:127\.0\.0\.1:\d+ \(DoStep at t=[0-9.]+ s\); the run is no longer "
        r"trusted.* \(the run had reached t=",
        result["reason"],
    ), result["reason"]
    recorded = assert_rows_kept(out)
    assert 4 <= len(recorded) < 201
    assert max(abs(float(row["Gain.y"])) for row in recorded) < 100  # nothing injected


class Betrayed(GainParticipant):
    """During its last step a stranger calls DoStep with the run's id and no secret; the call
    waits for the step and reaches the participant before the orchestrator's Terminate."""

    def __init__(self, last: float) -> None:
        super().__init__("Gain")
        self.last, self.run_id, self.port = last, "", 0
        self.answers: list[tuple[grpc.StatusCode, str]] = []

    async def initialize(self, setup: RunSetup) -> Values:
        self.run_id = setup.run_id
        return await super().initialize(setup)

    async def do_step(self, time_s: float, step: float, inputs: Mapping[str, Value]) -> Values:
        if time_s >= self.last:
            meddler = threading.Thread(
                target=lambda: self.answers.extend(intrude(self.port, self.run_id, []))
            )
            meddler.start()
            await asyncio.sleep(0.5)  # the stranger's call is queued behind this step
        return await super().do_step(time_s, step, inputs)


@pytest.mark.usefixtures("step_path")
def test_a_stranger_after_the_last_step_still_fails_the_run(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An intrusion between the run's last step and its Terminate changes nothing either, and
    the run does not pass for completed: Terminate is answered ABORTED naming it."""
    participant = Betrayed(last=0.5)
    with serving(participant) as server:
        participant.port = server.port
        monkeypatch.setenv("GAIN_PORT", str(server.port))
        outcome = coupler("run", ssd, "--out", tmp_path, "--step", "0.5", "--stop-time", "1")
    assert [code for code, _ in participant.answers] == [grpc.StatusCode.PERMISSION_DENIED]
    assert outcome.code == 1, outcome.err
    result = summary(tmp_path)
    assert result["status"] == "failed"
    assert result["reason"].startswith(
        "Gain.Terminate [ABORTED]: Gain refused the run: a call without this run's secret "
        "arrived from ipv4:127.0.0.1:"
    ), result["reason"]
    assert (
        "(DoStep at t=1 s); the run is no longer trusted (after the run's last step)"
        in (result["reason"])
    )
    assert len(assert_rows_kept(tmp_path)) == 3


def test_with_a_token_a_stranger_cannot_even_start_a_run(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A participant that requires a token refuses every call of a client without it —
    including an Initialize that would hold the participant."""
    token = tmp_path / "token"
    token.write_text("s3cret-token")
    with gain(monkeypatch, "--token-file", str(token)) as process:
        channel = grpc.insecure_channel(parse_address(f"grpc://127.0.0.1:{process.port}"))
        with channel:
            stub = pb_grpc.GRPCComponentServiceStub(channel)
            with pytest.raises(grpc.RpcError) as info:
                stub.Initialize(pb.InitializeRequest(run_id="mine", step_size=0.1), timeout=2)
            assert info.value.code() is grpc.StatusCode.UNAUTHENTICATED
        code, refused = meddled_run(
            coupler, ssd, tmp_path / "o", process.port, "--token-file", str(token)
        )
    assert code == 0
    assert refused and set(refused) == {grpc.StatusCode.UNAUTHENTICATED}


@pytest.mark.skipif(os.geteuid() != 0, reason="mounting a small tmpfs needs root")
def test_a_full_disk_fails_the_run_keeping_whole_rows(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    full = tmp_path / "full"
    full.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=24k", "tmpfs", str(full)], capture_output=True
    )
    if mounted.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        with gain(monkeypatch):
            outcome = coupler("run", ssd, "--out", full, "--step", "0.001", "--stop-time", "60")
        assert outcome.code == 1
        result = summary(full)
        assert result["status"] == "failed"
        assert "No space left on device" in result["reason"]
        recorded = rows(full)
        assert recorded and all(None not in row.values() for row in recorded)
        assert all(float(row["Integ.x"]) >= 0 for row in recorded)
    finally:
        subprocess.run(["umount", str(full)], check=False)


CHAIN = SystemStructure(
    "Chain",
    components=[
        fmu("Source", "${COUPLER_FMU_DIR}/Source2.fmu", outputs=["ramp"]),
        fmu("Integ", "${COUPLER_FMU_DIR}/Integrator2.fmu", inputs=["u"]),
    ],
    connections=[("Source.ramp", "Integ.u")],
    stop_time=10,
)


@pytest.mark.skipif(os.geteuid() != 0, reason="mounting a small tmpfs needs root")
def test_a_disk_that_fills_at_the_last_flush_fails_the_run(tmp_path: Path) -> None:
    """
        Source --ramp--> Integ (in-process, 1000 steps in a few ms), results on a 16 KiB disk

    Every row waits in results.csv's buffer until the run's end, when the disk is found full:
    the run fails (exit 1, summary.json ``failed``) naming the file and the rows it keeps,
    which are whole. (It used to end ``completed``, exit 0, with a fraction of the rows.)"""
    full = tmp_path / "full"
    full.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(full)], capture_output=True
    )
    if mounted.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        out = full / "o"
        outcome = Coupler.process(
            "run", CHAIN.write(tmp_path / "chain.ssd"), "--out", out, "--step", "0.01"
        )
        assert outcome.code == 1, outcome
        assert outcome.err.count("\n") == 1 and "Traceback" not in outcome.err, outcome.err
        recorded = rows(out)
        last = float(recorded[-1]["time"])
        said = (
            f"cannot write {out.resolve() / 'results.csv'}: No space left on device; it keeps "
            f"the rows up to t={last:g} s ({len(recorded)} rows) (the run itself had completed "
            "at t=10 s)"
        )
        assert outcome.err == f"error: run failed: {said}\n"
        result = summary(out)
        assert (result["status"], result["reason"]) == ("failed", said)
        assert 0 < len(recorded) < 1001 and all(None not in row.values() for row in recorded)
    finally:
        subprocess.run(["umount", str(full)], check=False)


@pytest.mark.slow
@pytest.mark.skipif(os.geteuid() != 0, reason="mounting a small tmpfs needs root")
def test_a_full_disk_leaves_no_unreadable_parquet_behind(
    ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``coupler run --parquet`` on a disk that fills up: results.csv keeps its whole rows, and
    results.parquet, which could not be finished, is removed (it used to stay, 4 KiB without
    its footer: "Parquet magic bytes not found")."""
    import pyarrow.parquet as pq

    full = tmp_path / "full"
    full.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(full)], capture_output=True
    )
    if mounted.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        with gain(monkeypatch):
            outcome = Coupler.process(
                "run", ssd, "--out", full, "--parquet", "--step", "0.001", "--stop-time", "60"
            )
        assert outcome.code == 1, outcome.err
        assert "No space left on device" in summary(full)["reason"]
        assert rows(full) and all(None not in row.values() for row in rows(full))
        assert "Traceback" not in outcome.err
        parquet = full / "results.parquet"
        if parquet.exists():  # only when it could be finished: then it reads whole
            assert pq.read_table(parquet).num_rows > 0
    finally:
        subprocess.run(["umount", str(full)], check=False)


@pytest.fixture
def faulty_ssd(
    tmp_path: Path, faulty_fmus: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> Path:
    """Source (FMI 2) --ramp--> Faulty (FMI 2: crash_at / hang_at), 0 .. 10 s."""
    monkeypatch.setenv("FAULTY_FMU_DIR", str(faulty_fmus["Faulty2"].parent))
    return FAULTY_SSD.write(tmp_path / "faulty.ssd")


@pytest.mark.slow
def test_an_isolated_fmu_that_crashes_fails_the_run_naming_how(
    coupler: Coupler, faulty_ssd: Path, tmp_path: Path
) -> None:
    out = tmp_path / "o"
    outcome = coupler(
        "run", faulty_ssd, "--out", out, *RUN, "--isolate-fmus", "--param", "Faulty.crash_at=1"
    )
    assert outcome.code == 1
    result = summary(out)
    assert result["status"] == "failed"
    assert "Faulty.DoStep" in result["reason"] and "killed by SIGSEGV" in result["reason"]
    assert "the run had reached t=1 s" in result["reason"]
    assert len(assert_rows_kept(out)) == 11


@pytest.mark.slow
def test_an_isolated_fmu_that_hangs_fails_within_the_deadline(
    coupler: Coupler, faulty_ssd: Path, tmp_path: Path
) -> None:
    out = tmp_path / "o"
    started = time.monotonic()
    outcome = coupler(
        "run", faulty_ssd, "--out", out, *RUN, "--isolate-fmus", "--call-timeout", "1",
        "--param", "Faulty.hang_at=1",
    )  # fmt: skip
    took = time.monotonic() - started
    assert outcome.code == 1
    result = summary(out)
    assert "Faulty.DoStep [DEADLINE_EXCEEDED]" in result["reason"]
    assert len(assert_rows_kept(out)) == 11
    assert took < 15  # start-up, the 1 s deadline, Terminate's 3 s, killing the host


@pytest.mark.usefixtures("fmu_path")
@pytest.mark.parametrize("semantics", ["coupler", "openmcx"])
def test_an_fmu_hanging_in_process_ends_the_run_at_its_deadline(
    faulty_ssd: Path, tmp_path: Path, semantics: str
) -> None:
    """The FMU blocks the orchestrator's thread: the watchdog ends the run from its own thread,
    results written, and the process exits (the only way to leave a thread stuck in C) — with
    OpenMCx's semantics (its master) as with Coupler's: both step it with the same stepper."""
    out = tmp_path / "o"
    started = time.monotonic()
    dialect = ["--openmcx"] if semantics == "openmcx" else []
    run = orchestrator(
        faulty_ssd, out, *RUN, *dialect, "--call-timeout", "1", "--param", "Faulty.hang_at=1"
    )
    _, err = run.communicate(timeout=30)
    assert time.monotonic() - started < 20
    assert run.returncode == 1, err
    result = summary(out)
    assert result["status"] == "failed"
    assert result["semantics"] == semantics
    assert "Faulty.DoStep [DEADLINE_EXCEEDED]: no answer within 1 s" in result["reason"]
    assert "the FMU hangs in-process" in result["reason"]
    assert len(assert_rows_kept(out)) == 11
    assert "error: run failed: Faulty.DoStep [DEADLINE_EXCEEDED]" in err


@pytest.mark.slow
@pytest.mark.usefixtures("fmu_path")
def test_an_interrupt_reaches_an_orchestrator_blocked_in_an_fmu(
    faulty_ssd: Path, tmp_path: Path
) -> None:
    """SIGTERM while an in-process FMU hangs (long before its deadline): ended within seconds,
    summary aborted, rows kept."""
    out = tmp_path / "o"
    run = orchestrator(
        faulty_ssd, out, *RUN, "--call-timeout", "600", "--param", "Faulty.hang_at=1"
    )
    # blocked in doStep at t = 1 once started (the rows stay buffered: the loop is blocked)
    deadline = time.monotonic() + 20
    while not (out / "summary.json").exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(2.0)
    assert run.poll() is None
    sent = time.monotonic()
    run.send_signal(signal.SIGTERM)
    _, err = run.communicate(timeout=20)
    assert time.monotonic() - sent < 5
    assert run.returncode == 130, err
    result = summary(out)
    assert (result["status"], result["reason"]) == ("aborted", "interrupted by the user")
    assert len(assert_rows_kept(out)) == 11


@pytest.mark.usefixtures("fmu_path")
def test_an_interrupt_reaches_a_run_of_fast_in_process_fmus(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """No step ever awaits in a run of in-process FMUs: the step loop still gives the event
    loop a turn every few milliseconds, so SIGINT ends it at once (before, it ran on to its
    end); rows kept."""
    out = tmp_path / "o"
    run = orchestrator(fmus["Source2"], out, "--stop-time", "1e6", "--step", "0.01")
    try:
        wait_for_rows(out, 1000)
        sent = time.monotonic()
        run.send_signal(signal.SIGINT)
        _, err = run.communicate(timeout=60)
    finally:
        run.kill()
    assert time.monotonic() - sent < 10, err
    assert run.returncode == 130, err
    result = summary(out)
    assert (result["status"], result["reason"]) == ("aborted", "interrupted by the user")
    assert 1000 <= len(assert_rows_kept(out)) < 100_000_001


def test_a_crash_in_c_says_how_far_the_run_got(faulty_ssd: Path, tmp_path: Path) -> None:
    """Unpaced, in-process FMUs step in C several hundred steps a call: a segfault at t = 30 s
    (step 300) comes before any of them is told. The time reached is the step the native FMU
    step had under way (it keeps it in the watching parent's shared page), not t = 0 (which it
    used to say, with a header-only results.csv and no word why)."""
    out = tmp_path / "o"
    run = orchestrator(faulty_ssd, out, *RUN, "--stop-time", "100", "--param", "Faulty.crash_at=30")
    _, err = run.communicate(timeout=60)
    assert run.returncode == 128 + signal.SIGSEGV, err
    assert err.startswith("error: run crashed at t=30 s: "), err
    result = summary(out)
    assert (result["status"], result["end_time"], result["steps"]) == ("crashed", 30.0, 300)
    if len(rows(out)) < 300:  # rows told before the crash are kept whole; the rest said lost
        assert "the steps computed in C since were lost with the process" in err, err


def test_a_crash_before_the_first_step_leaves_no_summary_running(
    faulty_fmus: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An FMU that segfaults in fmi2Instantiate ends the process before the first step:
    summary.json says ``crashed`` (it stayed ``running`` for good)."""
    monkeypatch.setenv("FAULTY_FMU_DIR", str(faulty_fmus["Faulty2"].parent))
    ssd = tmp_path / "crash.ssd"
    ssd.write_text(FAULTY_SSD.xml().replace("Faulty2.fmu", "CrashOnInstantiate2.fmu"))
    out = tmp_path / "o"
    run = orchestrator(ssd, out, *RUN)
    _, err = run.communicate(timeout=60)
    assert run.returncode == 128 + signal.SIGSEGV, err
    assert err.startswith("error: run crashed before its first step: "), err
    assert err.rstrip().endswith(
        f"nothing was recorded, in {out.resolve()} (summary.json: status crashed)"
    )
    result = summary(out)
    assert result["status"] == "crashed" and "before its first step" in result["reason"]


def test_an_fmu_crashing_in_process_ends_the_run_crashed_with_a_sentence(
    faulty_ssd: Path, tmp_path: Path
) -> None:
    """A segfault in-process ends the process running the run (no Python code runs after it);
    the ``coupler`` process watching it says so in one sentence, exits 128 + SIGSEGV and marks
    summary.json ``crashed`` with the time reached; every row flushed before is whole. (It
    used to end silently, exit 139, summary.json ``running``.) An FMU one does not trust runs
    isolated."""
    out = tmp_path / "o"
    run = orchestrator(
        faulty_ssd, out, *RUN, "--realtime-factor", "2", "--param", "Faulty.crash_at=3"
    )
    _, err = run.communicate(timeout=30)
    assert run.returncode == 128 + signal.SIGSEGV, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("error: run crashed at t=3 s: ")
    assert "killed by SIGSEGV" in err and "--isolate-fmus" in err
    assert f"in {out.resolve()} (summary.json: status crashed)" in err
    result = summary(out)
    assert result["status"] == "crashed"
    assert "killed by SIGSEGV" in result["reason"]
    assert "the run had reached t=3 s" in result["reason"]
    assert (result["end_time"], result["steps"]) == (3.0, 30)
    kept = rows(out)
    assert 10 <= len(kept) <= 31 and all(None not in row.values() for row in kept)
    assert f"results.csv keeps the rows up to t={float(kept[-1]['time']):g} s" in err
