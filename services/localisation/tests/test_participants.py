"""The three participants of the service on real gRPC servers (port 0), driven by the client
the orchestrator uses, and the command line as a user starts it.

    RemoteParticipant --gRPC--> Odometer | BaliseTransmission | Localisation (adapter SDK)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError
from coupler.testing import process_group, served, wait_until_serving
from localisation.sensors import OdometerParticipant, TransmissionParticipant
from localisation.unit import participant

from .support import SCENARIO_LINE


def setup(**parameters: object) -> RunSetup:
    return RunSetup(run_id="t", start_time=0.0, step_size=1.0, parameters=parameters)  # type: ignore[arg-type]


async def test_odometer_over_grpc_reads_one_percent_long() -> None:
    async with served(OdometerParticipant()) as server, RemoteParticipant(server.address) as odo:
        description = await odo.describe()
        assert description.channel("distance_measured").unit == "m"
        first = await odo.initialize(setup(diameter_error=0.01, front_offset=41.7))
        assert first["true_front"] == 41.7 and first["distance_measured"] == 0.0
        out = {}
        for k in range(100):
            inputs = {"distance": 10.0 * k, "speed": 10.0, "acceleration": 0.0}
            out = await odo.do_step(float(k), 1.0, inputs)
        assert out["true_front"] == pytest.approx(41.7 + 1000.0)
        assert out["distance_measured"] == pytest.approx(1010.0, abs=0.02)
        assert out["adhesion_state"] == 0 and out["radar_valid"] is False
        await odo.terminate()


async def test_bad_odometer_parameter_is_refused_by_name() -> None:
    async with served(OdometerParticipant()) as server, RemoteParticipant(server.address) as odo:
        with pytest.raises(ParticipantError, match="adhesion must be > 0"):
            await odo.initialize(setup(adhesion=0.0))


async def test_transmission_over_grpc_loses_the_listed_group() -> None:
    async with (
        served(TransmissionParticipant()) as server,
        RemoteParticipant(server.address) as tx,
    ):
        await tx.initialize(setup(antenna_offset=39.7, lost_groups="101"))
        await tx.do_step(0.0, 1.0, {"distance": 50.0})
        out = await tx.do_step(1.0, 1.0, {"distance": 100.0, "passed_in_step": "1000:100:120.0"})
        assert out["telegrams"].startswith("1000:100:") and out["faults"] == ""
        out = await tx.do_step(
            2.0, 1.0, {"distance": 300.0, "passed_in_step": "1010:101:320.0;1011:101:323.0"}
        )
        assert out == {"telegrams": "", "faults": "lost:1010:101;lost:1011:101"}
        await tx.terminate()
        with pytest.raises(ParticipantError, match="lost_groups 'x' is not a list"):
            await tx.initialize(setup(lost_groups="x"))


async def test_localisation_adapter_over_grpc() -> None:
    async with (
        served(participant(SCENARIO_LINE)) as server,
        RemoteParticipant(server.address) as loc,
    ):
        description = await loc.describe()
        assert description.name == "Localisation"
        assert description.channel("detections").start == b""
        first = await loc.initialize(
            setup(start_front=41.7, antenna_to_front=2.0, location_accuracy=1.0)
        )
        assert first["estimated_front"] == pytest.approx(41.7)
        assert first["max_safe_front"] - first["min_safe_front"] == pytest.approx(2 * (2 + 5))
        assert first["expected_group_id"] == 100
        # at 10 m/s the antenna (39.7 m + travelled) passes balise 1000 (120 m) at 8.03 s
        inputs = {"odometer_distance": 80.0, "odometer_speed": 10.0, "telegrams": ""}
        await loc.do_step(8.0, 1.0, inputs)
        out = await loc.do_step(9.0, 1.0, {"odometer_distance": 90.0, "telegrams": "1000:100:8.03"})
        assert out["last_group_id"] == 100 and out["expected_group_id"] == 101
        # the front was at 122 m at 8.03 s (odometer 80.3); at 10 s: 9.7 m + 10 m further
        assert out["estimated_front"] == pytest.approx(122.0 + 9.7 + 10.0)
        with pytest.raises(ParticipantError, match=r"channel 'telegrams'.*not balise_id"):
            await loc.do_step(10.0, 1.0, {"telegrams": "garbage"})


def test_command_line_serves_each_role_and_names_a_bad_railml(tmp_path: Path) -> None:
    import asyncio

    from coupler.testing import free_port

    port = free_port()
    command = [sys.executable, "-m", "localisation", "--role", "odometer", "--port", str(port)]
    with process_group(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE):
        asyncio.run(wait_until_serving(f"grpc://127.0.0.1:{port}"))
    missing = tmp_path / "none.railml"
    done = subprocess.run(
        [sys.executable, "-m", "localisation", "--railml", str(missing), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert (
        done.stderr.strip()
        == f"localisation: --railml {missing}: no such file (the line to localise on)"
    )
