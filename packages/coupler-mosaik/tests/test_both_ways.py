"""Coupler and mosaik both ways, each against the other framework's own run of the same setup.

    mosaik World:  CSV (mosaik-csv) --value--> Gain (CouplerSimulator -> the example gain
                   participant over gRPC) --y, x--> CSVWriter (mosaik-csv)
    coupler run:   Source2 (FMU, ramp = 0.5 t) --ramp--> Gain (the same participant)

    coupler run:   CSV (MosaikParticipant, mosaik-csv in process) --value--> MGain
                   (MosaikParticipant, coupler_mosaik.examples.Gain over mosaik's TCP)
    mosaik World:  CSV --value--> Gain (coupler_mosaik.examples, its own process) --> CSVWriter

Both under Gauss-Seidel (mosaik's data flow: a successor sees its predecessor's value of the
same tick; docs/frameworks.md); every recorded value must be equal to the last bit.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path
from typing import Any

import pytest

from coupler.examples.gain import GainParticipant
from coupler.testing import (
    Connector,
    SystemStructure,
    fmu,
    recorded,
    remote,
    run_coupler,
    served_in_thread,
    summary,
)

ROOT = Path(__file__).resolve().parents[3]
SOURCE_FMU = ROOT / "build" / "fmus" / "Source2.fmu"
SLOPE, GAIN, STEPS = 0.5, 4.0, 30
START = "2024-01-01 00:00:00"


def ramp_csv(path: Path) -> Path:
    """mosaik-csv's file of a ramp: SLOPE * t at t = 0, 1, ..., STEPS + 1 s (as Source2)."""
    rows = [f"2024-01-01 00:{k // 60:02d}:{k % 60:02d},{SLOPE * k!r}" for k in range(STEPS + 2)]
    path.write_text("Ramp\nDate,value\n" + "\n".join(rows) + "\n")
    return path


def mosaik_world(config: dict[str, Any]) -> Any:
    import mosaik

    return mosaik.World(config, time_resolution=1.0, debug=False)


def written(path: Path) -> list[dict[str, str]]:
    """What mosaik-csv's CSVWriter wrote: one dict per tick."""
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


def gain_world(world: Any, address: str, data: Path, out: Path) -> dict[str, str]:
    """CSV -> the participant at ``address`` (CouplerSimulator) -> CSVWriter, run; the
    participant's units as ``channels()`` tells them."""
    source = world.start("CSV", sim_start=START, datafile=str(data)).Ramp()
    simulator = world.start("Coupler", address=address, step_size=1)
    gain = simulator.Gain(gain=GAIN)
    writer = world.start("Writer", start_date=START, output_file=str(out))
    sink = writer.CSVWriter(buff_size=1000)
    world.connect(source, gain, ("value", "u"))
    world.connect(gain, sink, "y", "x")
    units = {c["name"]: c["unit"] for c in simulator.channels()}
    world.run(until=STEPS + 1, print_progress=False)
    return units


@pytest.mark.slow
def test_mosaik_world_drives_a_coupler_participant_as_coupler_run_does(tmp_path: Path) -> None:
    if not SOURCE_FMU.exists():
        pytest.fail(f"{SOURCE_FMU} is missing: run 'make setup' (make test does)")
    data = ramp_csv(tmp_path / "ramp.csv")
    with served_in_thread(GainParticipant()) as server:
        with mosaik_world(
            {
                "CSV": {"python": "mosaik_csv:CSV"},
                "Coupler": {"python": "coupler_mosaik:CouplerSimulator"},
                "Writer": {"python": "mosaik_csv_writer:CSVWriter"},
            }
        ) as world:
            units = gain_world(world, server.address, data, tmp_path / "mosaik.csv")
        out = tmp_path / "mosaik.csv"

        ssd = SystemStructure(
            "RampGain",
            [
                fmu("Source", SOURCE_FMU, outputs=["ramp"], parameters={"slope": SLOPE}),
                remote(
                    "Gain",
                    server.address,
                    Connector("u", "input", "Real"),
                    outputs=["y", "x"],
                    parameters={"gain": GAIN},
                ),
            ],
            [("Source.ramp", "Gain.u")],
            stop_time=STEPS,
        ).write(tmp_path / "ramp-gain.ssd")
        done = run_coupler(
            "run", ssd, "--step", "1", "--algorithm", "gauss-seidel", "--no-progress",
            "--out", tmp_path / "run",
        )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert units["y"] == "m/s" and units["x"] == "m"
    coupler = recorded(tmp_path / "run")
    mosaik = written(out)
    assert len(coupler) == len(mosaik) == STEPS + 1
    for k, (row, theirs) in enumerate(zip(coupler, mosaik, strict=True)):
        assert float(row["time"]) == k
        assert float(theirs["Coupler-0.Gain-y"]) == float(row["Gain.y"]) == GAIN * SLOPE * k
        assert float(theirs["Coupler-0.Gain-x"]) == float(row["Gain.x"])


@pytest.mark.slow
def test_coupler_run_drives_mosaik_simulators_as_mosaik_does(tmp_path: Path) -> None:
    data = ramp_csv(tmp_path / "ramp.csv")
    csv_toml = tmp_path / "csv.toml"
    csv_toml.write_text(
        f"""name = "CSV"
[simulator]
python = "mosaik_csv:CSV"
params = {{ sim_start = "{START}", datafile = "{data}" }}
[model]
name = "Ramp"
[[channel]]
name = "value"
causality = "output"
unit = "m/s"
"""
    )
    gain_toml = tmp_path / "gain.toml"
    gain_toml.write_text(
        """name = "MGain"
[simulator]
cmd = "%(python)s -m coupler_mosaik.examples %(addr)s"
[model]
name = "Gain"
[[channel]]
name = "gain"
causality = "parameter"
[[channel]]
name = "u"
causality = "input"
unit = "m/s"
start = 0.0
[[channel]]
name = "y"
causality = "output"
unit = "m/s"
[[channel]]
name = "x"
causality = "output"
unit = "m"
"""
    )
    from coupler_mosaik import MosaikParticipant

    with (
        served_in_thread(MosaikParticipant.from_file(csv_toml)) as source,
        served_in_thread(MosaikParticipant.from_file(gain_toml)) as gain,
    ):
        ssd = SystemStructure(
            "CsvGain",
            [
                remote("CSV", source.address, outputs=["value"]),
                remote(
                    "MGain",
                    gain.address,
                    inputs=["u"],
                    outputs=["y", "x"],
                    parameters={"gain": GAIN},
                ),
            ],
            [("CSV.value", "MGain.u")],
            stop_time=STEPS,
        ).write(tmp_path / "csv-gain.ssd")
        done = run_coupler(
            "run", ssd, "--step", "1", "--algorithm", "gauss-seidel", "--no-progress",
            "--out", tmp_path / "run",
        )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert summary(tmp_path / "run")["status"] == "completed"

    out = tmp_path / "mosaik.csv"
    with mosaik_world(
        {
            "CSV": {"python": "mosaik_csv:CSV"},
            "Gain": {"cmd": f"{sys.executable} -m coupler_mosaik.examples %(addr)s"},
            "Writer": {"python": "mosaik_csv_writer:CSVWriter"},
        }
    ) as world:
        ramp = world.start("CSV", sim_start=START, datafile=str(data)).Ramp()
        entity = world.start("Gain").Gain(gain=GAIN)
        writer = world.start("Writer", start_date=START, output_file=str(out))
        sink = writer.CSVWriter(buff_size=1000)
        world.connect(ramp, entity, ("value", "u"))
        world.connect(entity, sink, "y", "x")
        world.run(until=STEPS + 1, print_progress=False)

    coupler = recorded(tmp_path / "run")
    mosaik = written(out)
    assert len(coupler) == len(mosaik) == STEPS + 1
    for k, (row, theirs) in enumerate(zip(coupler, mosaik, strict=True)):
        assert float(row["CSV.value"]) == SLOPE * k
        assert float(theirs["Gain-0.Gain-0-y"]) == float(row["MGain.y"]) == GAIN * SLOPE * k
        assert float(theirs["Gain-0.Gain-0-x"]) == float(row["MGain.x"])
