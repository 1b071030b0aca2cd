"""An adapter-based participant served for real: the SDK's adapter pattern end to end.

RemoteParticipant --gRPC--> ParticipantServer(AdapterParticipant(CounterAdapter, TOML map))
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from coupler.adapter import Adapter, AdapterConfig, AdapterParticipant
from coupler.channels import RunSetup, Value
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError, ScenarioError
from coupler.testing import served

MAPPING = """
name = "Cart"

[[channel]]
name = "push"
causality = "input"
type = "Real"
unit = "km/h"
field = "force"
scale = 3.6
start = 3.6

[[channel]]
name = "speed_kmh"
causality = "output"
type = "Real"
unit = "km/h"
field = "state.v"
scale = 3.6

[[channel]]
name = "steps"
causality = "output"
type = "Integer"
field = "state.steps"

[[channel]]
name = "mass"
causality = "parameter"
type = "Real"
field = "mass_kg"
start = 2.0
"""


class CartAdapter(Adapter):
    """A cart whose speed grows by force/mass per second; speaks SI field names."""

    def __init__(self) -> None:
        self.connected = False
        self.mass = 0.0
        self.force = 0.0
        self.v = 0.0
        self.steps = 0

    async def connect(self) -> None:
        self.connected = True

    async def start(self, setup: RunSetup, parameters: Mapping[str, Value]) -> None:
        self.mass = float(parameters["mass_kg"])
        self.v, self.steps = 0.0, 0

    async def get_state(self) -> Mapping[str, Any]:
        return {"state": {"v": self.v, "steps": self.steps}}

    async def apply_inputs(self, inputs: Mapping[str, Value]) -> None:
        self.force = float(inputs["force"])

    async def advance(self, time: float, step: float) -> None:
        self.v += self.force / self.mass * step
        self.steps += 1

    async def shutdown(self) -> None:
        self.connected = False


async def test_adapter_participant_maps_channels_to_fields(tmp_path: Path) -> None:
    path = tmp_path / "cart.toml"
    path.write_text(MAPPING)
    adapter = CartAdapter()
    async with served(AdapterParticipant(adapter, AdapterConfig.load(path))) as server:
        assert adapter.connected
        async with RemoteParticipant(server.address) as remote:
            description = await remote.describe()
            assert [c.name for c in description.channels] == ["push", "speed_kmh", "steps", "mass"]
            assert description.channels[0].start == 3.6  # in channel units: no scale applied
            await remote.initialize(
                RunSetup(run_id="a", start_time=0, step_size=1, parameters={"mass": 4.0})
            )
            # push 7.2 "km/h" units -> force field 2.0; v += 2/4 per second -> 1.8 km/h per step
            out = await remote.do_step(0.0, 1.0, {"push": 7.2})
            assert out == {"speed_kmh": pytest.approx(1.8), "steps": 1}
            out = await remote.do_step(1.0, 1.0, {})
            assert out == {"speed_kmh": pytest.approx(3.6), "steps": 2}
            await remote.terminate()
    assert not adapter.connected


async def test_missing_state_field_names_channel_and_fix(tmp_path: Path) -> None:
    path = tmp_path / "cart.toml"
    path.write_text(MAPPING.replace("state.steps", "state.count"))
    participant = AdapterParticipant(CartAdapter(), AdapterConfig.load(path))
    with pytest.raises(
        ParticipantError, match=r"field 'state\.count' has no 'count'.*channel 'steps'"
    ):
        await participant.initialize(RunSetup(run_id="a", start_time=0, step_size=1))


def test_bad_mapping_file_is_named(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('name = "X"\n[[channel]]\nname = "a"\ncausality = "sideways"\n')
    with pytest.raises(
        ScenarioError, match=r"bad.toml: invalid channel mapping: channel.0.causality"
    ):
        AdapterConfig.load(path)


async def test_binary_start_written_as_text_is_its_bytes(tmp_path: Path) -> None:
    """A Binary input's start in the TOML map is text (TOML has no bytes): its UTF-8 bytes, so
    ``start = ""`` is an empty message and the input need not be connected."""
    path = tmp_path / "cart.toml"
    path.write_text(
        MAPPING
        + '\n[[channel]]\nname = "frame"\ncausality = "input"\ntype = "Binary"\n'
        + 'field = "frame"\nstart = ""\n'
    )
    adapter = CartAdapter()
    seen: list[Mapping[str, Value]] = []
    apply_inputs = adapter.apply_inputs

    async def record(inputs: Mapping[str, Value]) -> None:
        seen.append(dict(inputs))
        await apply_inputs(inputs)

    adapter.apply_inputs = record  # type: ignore[method-assign]
    async with (
        served(AdapterParticipant(adapter, AdapterConfig.load(path))) as server,
        RemoteParticipant(server.address) as remote,
    ):
        description = await remote.describe()
        assert description.channel("frame").start == b""
        await remote.initialize(RunSetup(run_id="a", start_time=0, step_size=1))
        await remote.terminate()
    assert seen[0]["frame"] == b""
