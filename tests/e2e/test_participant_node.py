"""A participant written from component.proto alone, in another language, follows the
protocol: examples/participant-node (Node.js, @grpc/grpc-js loading the .proto at run time)
is driven by `coupler run` over both step paths, and a stranger's DoStep that carries the run
id (read from summary.json) but not the run secret is refused and fails the run.

    Source (FMI 2) --ramp--> Scale (Node.js participant process)     y = gain * u
                               ^
                    stranger --DoStep(run id, no secret, u=1e300)
"""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest

from coupler.testing import SystemStructure, fmu, remote
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc
from coupler_orchestrator.master import native_step_channel as steps
from coupler_orchestrator.native import MISSING
from coupler_orchestrator.options import NATIVE_STEPS_VARIABLE

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "participant-node"
COUPLER = str(Path(sys.executable).with_name("coupler"))
SSD = SystemStructure(
    "Node",
    components=[
        fmu("Source", ROOT / "build" / "fmus" / "Source2.fmu", outputs=["ramp"]),
        remote("Scale", "grpc://127.0.0.1:${SCALE_PORT}", inputs=["u"], outputs=["y", "steps"]),
    ],
    connections=[("Source.ramp", "Scale.u")],
    stop_time=20,
)
KEY = bytes(range(32))
PACED = ("--realtime-factor", "5")


@pytest.fixture
def scale() -> Iterator[int]:
    """The Node.js participant on a port of its own; yields the port."""
    node = shutil.which("node")
    if node is None or not (EXAMPLE / "node_modules" / "@grpc" / "grpc-js").is_dir():
        pytest.skip("needs node and `npm ci` in examples/participant-node (make setup does it)")
    process = subprocess.Popen(
        [node, str(EXAMPLE / "participant.js"), "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        assert line.startswith("serving Scale at grpc://127.0.0.1:"), line
        yield int(line.rsplit(":", 1)[1])
    finally:
        process.terminate()
        process.wait(10)
        if process.stdout is not None:
            process.stdout.close()


@pytest.fixture(params=["native", "grpc.aio"])
def env(request: pytest.FixtureRequest, scale: int, tmp_path: Path) -> dict[str, str]:
    """`coupler run`'s environment: the participant's port, one step path or the other."""
    if request.param == "native" and steps.library() is None:
        if steps.library.problem == MISSING:
            pytest.skip(MISSING)
        pytest.fail(f"the native step channel: {steps.library.problem}")
    SSD.write(tmp_path / "node.ssd")
    native = "1" if request.param == "native" else "0"
    return {**os.environ, "SCALE_PORT": str(scale), NATIVE_STEPS_VARIABLE: native}


def results(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as file:
        return list(csv.DictReader(file))


@pytest.mark.slow
def test_coupler_runs_the_node_participant(env: dict[str, str], tmp_path: Path) -> None:
    done = subprocess.run(
        [COUPLER, "run", tmp_path / "node.ssd", "--out", tmp_path / "o", "--step", "0.5"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    rows = results(tmp_path / "o")
    assert len(rows) == 41
    # Jacobi: y at t_k+1 is gain (2) times the ramp at t_k
    assert [float(r["Scale.y"]) for r in rows[1:]] == [2 * 0.5 * k for k in range(40)]
    assert [int(r["Scale.steps"]) for r in rows] == list(range(41))


@pytest.mark.slow
def test_a_strangers_secretless_dostep_is_refused_and_fails_the_run(
    env: dict[str, str], scale: int, tmp_path: Path
) -> None:
    out = tmp_path / "o"
    run = subprocess.Popen(
        [COUPLER, "run", tmp_path / "node.ssd", "--out", out, *("--step", "0.1"), *PACED],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    deadline = time.monotonic() + 90  # start-up takes long on a busy machine
    while not ((out / "results.csv").exists() and len(results(out)) >= 4):
        assert time.monotonic() < deadline and run.poll() is None, run.communicate()
        time.sleep(0.05)
    run_id = json.loads((out / "summary.json").read_text())["run_id"]
    with grpc.insecure_channel(f"127.0.0.1:{scale}") as channel:
        stranger = pb_grpc.GRPCComponentServiceStub(channel)
        huge = [pb.VariableBinding(channel="u", real=1e300)]
        with pytest.raises(grpc.RpcError) as refused:
            stranger.DoStep(pb.DoStepRequest(run_id=run_id, step_size=0.1, inputs=huge))
    assert refused.value.code() is grpc.StatusCode.PERMISSION_DENIED
    _, err = run.communicate(timeout=60)
    assert run.returncode == 1, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert re.match(
        r"Scale\.DoStep \[ABORTED\]: Scale refused the run: a call without this run's secret "
        r"arrived from 127\.0\.0\.1:\d+ \(DoStep at t=[0-9.]+ s\); the run is no longer trusted",
        summary["reason"],
    ), summary["reason"]
    assert max(abs(float(r["Scale.y"])) for r in results(out)) < 100  # nothing injected


def test_the_node_participant_follows_the_rules(scale: int) -> None:
    """The rules of docs/protocol.md, call by call, on the wire."""
    with grpc.insecure_channel(f"127.0.0.1:{scale}") as channel:
        stub = pb_grpc.GRPCComponentServiceStub(channel)

        def refused(call: object, request: object) -> tuple[grpc.StatusCode, str]:
            with pytest.raises(grpc.RpcError) as info:
                call(request, timeout=5)  # type: ignore[operator]
            return info.value.code(), info.value.details() or ""

        code, said = refused(stub.Initialize, pb.InitializeRequest(run_id="r", step_size=0.1))
        assert (code, said) == (
            grpc.StatusCode.INVALID_ARGUMENT,
            "run_secret must be 16 to 256 random bytes, got 0",
        )
        code, said = refused(
            stub.Initialize,
            pb.InitializeRequest(
                run_id="r", run_secret=KEY, step_size=0.1, lease_seconds=float("inf")
            ),
        )
        assert code is grpc.StatusCode.INVALID_ARGUMENT and "<= 86400 (24 h), got Infinity" in said
        stub.Initialize(pb.InitializeRequest(run_id="r", run_secret=KEY, step_size=0.1))
        code, _ = refused(
            stub.Initialize, pb.InitializeRequest(run_id="s", run_secret=KEY, step_size=0.1)
        )
        assert code is grpc.StatusCode.FAILED_PRECONDITION  # one run at a time
        step = pb.DoStepRequest(run_id="r", run_secret=KEY, step_size=0.1)
        assert stub.DoStep(step).outputs[1].integer == 1
        code, _ = refused(stub.DoStep, pb.DoStepRequest(run_id="other", step_size=0.1))
        assert code is grpc.StatusCode.FAILED_PRECONDITION  # another run's id
        code, _ = refused(stub.DoStep, pb.DoStepRequest(run_id="r", step_size=0.1))
        assert code is grpc.StatusCode.PERMISSION_DENIED  # the run's id without its secret
        code, said = refused(stub.DoStep, step)
        assert code is grpc.StatusCode.ABORTED and "Scale refused the run" in said
        code, said = refused(stub.Terminate, pb.TerminateRequest(run_id="r", run_secret=KEY))
        assert code is grpc.StatusCode.ABORTED  # told again, and the run is over
        stub.Initialize(
            pb.InitializeRequest(run_id="t", run_secret=KEY, step_size=0.1, lease_seconds=0.3)
        )
        time.sleep(0.6)  # silent past its lease: the run ends, the participant is free
        stub.Initialize(pb.InitializeRequest(run_id="u", run_secret=KEY, step_size=0.1))
        stub.Terminate(pb.TerminateRequest(run_id="u", run_secret=KEY))
        stub.Terminate(pb.TerminateRequest(run_id="u", run_secret=KEY))  # idempotent
