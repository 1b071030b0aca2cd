"""The generic FMU host: TrackBalises.fmu served over gRPC gives what FMPy gives standalone.

RemoteParticipant --gRPC--> ParticipantServer(FmuParticipant(TrackBalises.fmu))
fmpy.simulate_fmu(TrackBalises.fmu, input=position signal)     (the reference)
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import fmpy
import numpy as np
import pytest

from coupler.channels import Causality, RunSetup, ValueType
from coupler.client import RemoteParticipant
from coupler.fmu import FmuParticipant
from coupler.testing import served

NUMERIC = (
    "last_balise_id",
    "last_group_id",
    "last_balise_distance",
    "balises_passed",
    "latitude",
    "longitude",
)
TIMES = np.arange(0.0, 20.0, 1.0)
POSITIONS = np.array(
    [
        0,
        60,
        99,
        104,
        250,
        599,
        601,
        1150,
        1260,
        1500,
        1499,
        1200,
        1100,
        640,
        100,
        95,
        1785,
        1785,
        0,
        10,
    ],
    dtype=np.float64,
)


@pytest.fixture(params=[2, 3])
async def remote(
    fmus: dict[int, Path], request: pytest.FixtureRequest
) -> AsyncIterator[tuple[Path, RemoteParticipant]]:
    fmu = fmus[request.param]
    async with served(FmuParticipant(fmu, name="Balises")) as server:
        client = RemoteParticipant(server.address, name="Balises")
        await client.open()
        try:
            yield fmu, client
        finally:
            await client.close()


async def test_channels_come_from_the_model_description(
    remote: tuple[Path, RemoteParticipant],
) -> None:
    _, client = remote
    description = await client.describe()
    channels = {c.name: c for c in description.channels}
    assert description.name == "Balises"
    assert (channels["position"].causality, channels["position"].type) == (
        Causality.INPUT,
        ValueType.REAL,
    )
    assert channels["position"].unit == "m" and channels["position"].start == 0.0
    assert channels["antenna_offset"].causality is Causality.PARAMETER
    assert channels["antenna_offset"].start == 0.0
    assert {n: (channels[n].type, channels[n].unit) for n in NUMERIC} == {
        "last_balise_id": (ValueType.INTEGER, ""),
        "last_group_id": (ValueType.INTEGER, ""),
        "last_balise_distance": (ValueType.REAL, "m"),
        "balises_passed": (ValueType.INTEGER, ""),
        "latitude": (ValueType.REAL, "deg"),
        "longitude": (ValueType.REAL, "deg"),
    }
    assert channels["passed_in_step"].type is ValueType.STRING
    assert all(channels[n].causality is Causality.OUTPUT for n in (*NUMERIC, "passed_in_step"))


async def test_served_fmu_gives_the_same_outputs_as_fmpy(
    remote: tuple[Path, RemoteParticipant], drive: Callable
) -> None:
    fmu, client = remote
    h = 1.0
    stop = float(TIMES[-1] + h)
    outputs = [
        await client.initialize(
            RunSetup(
                run_id="same-as-fmpy",
                start_time=0.0,
                step_size=h,
                stop_time=stop,
                parameters={"antenna_offset": 3.0},
                inputs={"position": float(POSITIONS[0])},
            )
        )
    ]
    for t, position in zip(TIMES, POSITIONS, strict=True):
        outputs.append(await client.do_step(float(t), h, {"position": float(position)}))
    await client.terminate("done")

    signal_ = np.array(
        list(zip(TIMES, POSITIONS, strict=True)),
        dtype=[("time", np.float64), ("position", np.float64)],
    )
    reference = await asyncio.to_thread(
        fmpy.simulate_fmu,
        str(fmu),
        stop_time=stop,
        output_interval=h,
        input=signal_,
        start_values={"antenna_offset": 3.0},
        output=list(NUMERIC),
    )
    assert len(reference) == len(outputs)
    for name in NUMERIC:
        assert [o[name] for o in outputs] == reference[name].tolist(), name
    assert outputs[-1]["balises_passed"] > 10

    # passed_in_step: FMPy's simulate_fmu records no strings, so the low-level driver is the
    # reference (the same positions, one per step)
    rows = drive(fmu, [float(POSITIONS[0]), *POSITIONS.tolist()], antenna_offset=3.0)
    assert [o["passed_in_step"] for o in outputs] == [r["passed_in_step"] for r in rows]


@pytest.mark.slow
async def test_service_command_serves_an_fmu(fmus: dict[int, Path]) -> None:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "balise_fmu",
        "--fmu",
        str(fmus[3]),
        "--port",
        "0",
        "--name",
        "Balises",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env={**os.environ, "BALISE_FMU_LOG_JSON": "true"},
    )
    try:
        assert process.stdout is not None
        line = (await asyncio.wait_for(process.stdout.readline(), 30)).decode()
        assert "balise-fmu serving" in line, line
        address = line.rsplit(" at ", 1)[1].strip()
        async with RemoteParticipant(address) as client:
            description = await client.describe()
            assert description.name == "Balises"
            assert description.channel("passed_in_step") is not None
        process.send_signal(signal.SIGTERM)
        assert await asyncio.wait_for(process.wait(), 30) == 0
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()


async def test_service_command_names_a_missing_fmu(tmp_path: Path) -> None:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "balise_fmu",
        "--fmu",
        str(tmp_path / "nope.fmu"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    _, err = await asyncio.wait_for(process.communicate(), 30)
    assert process.returncode == 1
    assert "nope.fmu" in err.decode() and "balise_fmu.build" in err.decode()


def test_default_fmu_is_built_when_missing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import balise_fmu.__main__ as entry
    from balise_fmu.config import BaliseFmuSettings

    default = tmp_path / "fmus" / "TrackBalises.fmu"
    monkeypatch.setattr(entry, "DEFAULT_FMU", default)
    test_line = Path(__file__).resolve().parents[3] / "packages/railway/tests/data/test-line.railml"
    settings = BaliseFmuSettings(railml=test_line)
    assert entry.resolve_fmu(settings) == default
    assert fmpy.read_model_description(str(default)).modelName == "TrackBalises"
    with pytest.raises(FileNotFoundError, match=r"nope\.fmu"):
        entry.resolve_fmu(BaliseFmuSettings(fmu=tmp_path / "nope.fmu"))
