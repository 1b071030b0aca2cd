"""A HELICS federation and a Coupler run exchange values both ways over a real broker.

    helics_broker (the wheel's binary, 127.0.0.1 only)
      |-- "ramp": a federate written with the HELICS Python API (ramp_federate.py):
      |           publishes ramp = SLOPE * t, records what it receives on coupler/y
      '-- "coupler": the HelicsParticipant (coupler-helics, its own process)
                     ramp -> HELICS.ramp (output)        HELICS.y (input) -> coupler/y
    coupler run:  HELICS.ramp --> Gain.u (the example gain participant);  Gain.y --> HELICS.y

A ramp value published at t is in results.csv at t; Gain.y as Coupler gave it at t is what the
HELICS federate holds when it is next granted (t + h). A broker killed mid-run ends the run
with an error naming the broker, results kept.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest

from coupler.channels import RunSetup
from coupler.examples.gain import GainParticipant
from coupler.testing import (
    SystemStructure,
    free_port,
    process_group,
    recorded,
    remote,
    run_coupler,
    served_in_thread,
    summary,
    wait_until,
)
from coupler_helics import HelicsConfig, HelicsParticipant
from coupler_helics.broker import command as broker_command

FEDERATE = Path(__file__).with_name("ramp_federate.py")
SLOPE, GAIN, STEP = 0.5, 4.0, 0.1


def helics_toml(path: Path, port: int) -> Path:
    path.write_text(
        f"""name = "HELICS"
federate = "coupler"
broker = "127.0.0.1:{port}"

[[publication]]
channel = "y"
key = "coupler/y"
unit = "m/s"
start = 0.0

[[subscription]]
channel = "ramp"
key = "ramp"
unit = "m/s"
start = 0.0
"""
    )
    return path


@contextmanager
def federation(tmp_path: Path, steps: int, *extra: str) -> Iterator[tuple[int, Path]]:
    """A broker for two federates and the ramp federate (``steps`` steps of STEP) joined to
    it; (the broker's port, the file the federate writes what it received to)."""
    port = free_port()
    received = tmp_path / "received.json"
    with ExitStack() as stack:
        stack.enter_context(process_group(broker_command(port, 2)))
        ramp = [sys.executable, FEDERATE, port, steps, STEP, SLOPE, received, *extra]
        stack.enter_context(process_group([str(a) for a in ramp]))
        yield port, received


@contextmanager
def helics_participant(config: Path) -> Iterator[str]:
    """``coupler-helics CONFIG --port 0`` as a process; its address once it serves."""
    cmd = [sys.executable, "-m", "coupler_helics", str(config), "--port", "0", "--log-level",
           "WARNING"]  # fmt: skip
    with process_group(cmd, stdout=subprocess.PIPE, text=True) as process:
        assert process.stdout is not None
        line = process.stdout.readline()
        found = re.search(r"serving HELICS at (\S+)", line)
        assert found, f"coupler-helics said {line!r}"
        yield found.group(1)


def ramp_gain(tmp_path: Path, helics: str, gain: str, stop: float) -> Path:
    return SystemStructure(
        "HelicsGain",
        [
            remote("HELICS", helics, inputs=["y"], outputs=["ramp"]),
            remote("Gain", gain, inputs=["u"], outputs=["y"], parameters={"gain": GAIN}),
        ],
        [("HELICS.ramp", "Gain.u"), ("Gain.y", "HELICS.y")],
        stop_time=stop,
    ).write(tmp_path / "helics-gain.ssd")


async def test_units_convert_and_time_is_granted_in_lockstep(tmp_path: Path) -> None:
    """In this process: HELICS converts the ramp's m/s to the subscription's km/h; each
    DoStep is one time request and grant; the ramp federate sees what was published."""
    steps = 5
    with federation(tmp_path, steps) as (port, received):
        config = HelicsConfig.model_validate(
            {
                "broker": f"127.0.0.1:{port}",
                "publication": [{"channel": "y", "key": "coupler/y", "start": 0.0}],
                "subscription": [{"channel": "ramp", "key": "ramp", "unit": "km/h"}],
            }
        )
        participant = HelicsParticipant(config)
        setup = RunSetup(run_id="r", start_time=10.0, step_size=STEP, stop_time=10.5)
        got = [await participant.initialize(setup)]
        for k in range(steps):
            t = float(f"{10 + k * STEP:.1f}")
            got.append(await participant.do_step(t, STEP, {"y": 100.0 + k}))
        await participant.terminate()
        wait_until(received.exists, within=30, what="the ramp federate's record")
    ramp = [g["ramp"] for g in got]
    assert ramp == pytest.approx([3.6 * SLOPE * STEP * k for k in range(steps + 1)], rel=1e-12)
    heard = json.loads(received.read_text())
    assert [round(t, 9) for t, _ in heard] == [round(k * STEP, 9) for k in range(steps + 1)]
    assert [v for _, v in heard] == [0.0, *(100.0 + k for k in range(steps))]


@pytest.mark.slow
def test_values_cross_both_ways_under_coupler_run(tmp_path: Path) -> None:
    steps = 20
    with (
        federation(tmp_path, steps) as (port, received),
        helics_participant(helics_toml(tmp_path / "helics.toml", port)) as helics,
        served_in_thread(GainParticipant()) as gain,
    ):
        ssd = ramp_gain(tmp_path, helics, gain.address, stop=steps * STEP)
        done = run_coupler("run", ssd, "--step", STEP, "--no-progress", "--out", tmp_path / "run")
        assert done.returncode == 0, done.stderr
        wait_until(received.exists, within=30, what="the ramp federate's record")
    rows = recorded(tmp_path / "run")
    assert len(rows) == steps + 1
    for k, row in enumerate(rows):
        assert float(row["time"]) == pytest.approx(k * STEP, abs=1e-12)
        assert float(row["HELICS.ramp"]) == pytest.approx(SLOPE * k * STEP, rel=1e-12)
    heard = json.loads(received.read_text())
    assert len(heard) == steps + 1
    # what Coupler gave HELICS.y at t_k is what the federate holds once granted t_{k+1}
    for k in range(steps):
        assert heard[k + 1][1] == float(rows[k]["Gain.y"])
    assert heard[-1][1] == GAIN * SLOPE * (steps - 2) * STEP  # Jacobi: two steps behind


@pytest.mark.slow
def test_a_broker_that_dies_ends_the_run_with_a_clear_error(tmp_path: Path) -> None:
    steps = 2000  # the federate waits 20 ms a step: 40 s, far longer than the test
    port = free_port()
    received = tmp_path / "received.json"
    ramp = [sys.executable, FEDERATE, port, steps, STEP, SLOPE, received, "--delay", "0.02"]
    with (
        process_group(broker_command(port, 2)) as broker,
        process_group([str(a) for a in ramp]),
        helics_participant(helics_toml(tmp_path / "helics.toml", port)) as helics,
        served_in_thread(GainParticipant()) as gain,
    ):
        ssd = ramp_gain(tmp_path, helics, gain.address, stop=steps * STEP)
        out = tmp_path / "run"
        run = subprocess.Popen(
            [Path(sys.executable).with_name("coupler"), "run", ssd, "--step", str(STEP),
             "--no-progress", "--out", out],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        try:
            wait_until(lambda: _rows(out) >= 20, within=60, what="20 rows in results.csv")
            broker.kill()
            began = time.monotonic()
            _, err = run.communicate(timeout=60)
        finally:
            run.kill()
        took = time.monotonic() - began
    assert run.returncode != 0
    said = [line for line in err.splitlines() if "is not there" in line]
    assert said and "HELICS" in said[0] and f"broker at 127.0.0.1:{port}" in said[0], err
    assert "Traceback" not in err
    end = summary(out)
    assert end["status"] == "failed" and "broker" in end["reason"]
    rows = recorded(out)  # every step up to the broker's end, as recorded
    assert len(rows) >= 20 and len(rows) == end["steps"] + 1
    assert float(rows[-1]["time"]) == pytest.approx(end["end_time"], abs=1e-12)
    assert float(rows[-1]["HELICS.ramp"]) == pytest.approx(SLOPE * end["end_time"], rel=1e-12)
    assert took < 30


def _rows(out: Path) -> int:
    try:
        return len(recorded(out))
    except (OSError, StopIteration):
        return 0
