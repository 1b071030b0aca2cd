"""What does not fit between mosaik and Coupler is refused, naming the culprit and the fix; the
tick grid is exact."""

from __future__ import annotations

from pathlib import Path

import pytest

from coupler.channels import RunSetup
from coupler.errors import ParticipantError, ScenarioError
from coupler.examples.gain import GainParticipant
from coupler.testing import served_in_thread
from coupler_mosaik import CouplerSimulator, MosaikConfig, MosaikParticipant, Ticks


def csv_participant(tmp_path: Path, attr: str = "value") -> MosaikParticipant:
    data = tmp_path / "ramp.csv"
    rows = [f"2024-01-01 00:00:{k:02d},{0.5 * k}" for k in range(10)]
    data.write_text("Ramp\nDate,value\n" + "\n".join(rows) + "\n")
    return MosaikParticipant(
        MosaikConfig.model_validate(
            {
                "name": "CSV",
                "simulator": {
                    "python": "mosaik_csv:CSV",
                    "params": {"sim_start": "2024-01-01 00:00:00", "datafile": str(data)},
                },
                "model": {"name": "Ramp"},
                "channel": [{"name": "value", "attr": attr, "causality": "output"}],
            }
        ),
        source="csv.toml",
    )


def test_ticks_are_the_exact_decimals() -> None:
    ticks = Ticks(0.0, 0.1)
    assert ticks.time(3) == 0.3 and ticks.span(3) == 0.3  # not 0.30000000000000004
    assert ticks.tick(0.3) == 3 and ticks.ticks(0.7) == 7
    with pytest.raises(ValueError, match=r"0\.25 s is not a whole number of mosaik ticks of 0\.1"):
        ticks.ticks(0.25)


async def test_a_next_step_between_communication_points_is_refused(tmp_path: Path) -> None:
    participant = csv_participant(tmp_path)
    try:
        setup = RunSetup(run_id="r", start_time=0.0, step_size=2.0, stop_time=8.0)
        assert await participant.initialize(setup) == {"value": 0.0}
        with pytest.raises(ParticipantError, match=r"next step at tick 1 \(t = 1\.0 s\), between"):
            await participant.do_step(0.0, 2.0, {})
    finally:
        await participant.close()


async def test_a_step_that_is_not_whole_ticks_is_refused(tmp_path: Path) -> None:
    participant = csv_participant(tmp_path)
    setup = RunSetup(run_id="r", start_time=0.0, step_size=0.5, stop_time=8.0)
    with pytest.raises(ScenarioError, match=r"step size of 0\.5 s is not a whole number"):
        await participant.initialize(setup)
    await participant.close()


async def test_an_attribute_the_model_lacks_is_named(tmp_path: Path) -> None:
    participant = csv_participant(tmp_path, attr="power")
    setup = RunSetup(run_id="r", start_time=0.0, step_size=1.0)
    with pytest.raises(ScenarioError, match=r"csv.toml: channel 'value': model 'Ramp' has no "
                       r"attribute 'power' \(its attrs: value\)"):  # fmt: skip
        await participant.initialize(setup)
    await participant.close()


def test_a_config_without_a_starter_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "sim.toml"
    path.write_text('name = "X"\n[simulator]\n[model]\nname = "M"\n'
                    '[[channel]]\nname = "a"\ncausality = "output"\n')  # fmt: skip
    with pytest.raises(ScenarioError, match=r"sim.toml: invalid mosaik participant: simulator: "
                       r"Value error, give exactly one of python"):  # fmt: skip
        MosaikParticipant.from_file(path)


def test_the_simulator_refuses_what_a_participant_cannot_be() -> None:
    with served_in_thread(GainParticipant()) as server:
        simulator = CouplerSimulator()
        meta = simulator.init("Gain-0", 1.0, address=server.address)
        try:
            assert meta["models"]["Gain"]["params"] == ["gain", "x0", "offset"]
            assert "u" in meta["models"]["Gain"]["attrs"] and "y" in meta["models"]["Gain"]["attrs"]
            with pytest.raises(ValueError, match="one entity"):
                simulator.create(2, "Gain")
            with pytest.raises(ValueError, match="has no parameter 'k'"):
                simulator.create(1, "Gain", k=1)
            [entity] = simulator.create(1, "Gain", gain=3.0)
            two = {"u": {"A.a": 1.0, "B.b": 2.0}}
            with pytest.raises(ValueError, match=r"input 'u' of Gain is connected to \['A.a', "
                               r"'B.b'\]: a Coupler input takes one source"):  # fmt: skip
                simulator.step(0, {entity["eid"]: two}, 10)
            assert simulator.step(0, {entity["eid"]: {"u": {"A.a": 2}}}, 10) == 1
            assert simulator.get_data({entity["eid"]: ["y"]}) == {entity["eid"]: {"y": 6.0}}
        finally:
            simulator.finalize()
