"""summary.json tells each member's own step cost apart from the latency the master sees.

    Source (FMU) --ramp--> Slow  (gRPC, unix socket: its step socket; 25 ms a step, 15 of
                 |                them waiting for an outside program, ``waiting()``)
                 \\-ramp--> Quick (gRPC, unix socket: its step socket; no work)

On the native step socket the master sends both requests, then receives Slow's answer and
Quick's, one after the other: Quick's latency holds Slow's time. Each answer says what the step
cost the participant itself (``DoStepResponse.step_seconds``, ``waited_seconds``): summary.json
``step_cost_ms`` and ``waited_ms``, which tell them apart.
"""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path

import pytest

from coupler.costs import waiting
from coupler.examples.gain import GainParticipant
from coupler.participant import Values
from coupler.testing import SystemStructure, fmu, remote
from coupler_orchestrator.master import native_step_channel

from ..support import Coupler, require_native, serving

pytestmark = pytest.mark.usefixtures("fmus")


class Slow(GainParticipant):
    """10 ms of its own work and 15 ms waiting for an outside program, every step."""

    async def do_step(self, time: float, step: float, inputs: Mapping[str, object]) -> Values:
        await asyncio.sleep(0.010)
        with waiting():
            await asyncio.sleep(0.015)
        return await super().do_step(time, step, inputs)  # type: ignore[arg-type]


@pytest.mark.slow
def test_summary_tells_each_members_own_step_cost_apart(tmp_path: Path) -> None:
    require_native(native_step_channel.library)
    folder = Path(tempfile.mkdtemp(prefix="costs-", dir="/tmp"))  # a socket's path: 107 bytes
    system = SystemStructure(
        "Costs",
        components=[
            fmu("Source", "${COUPLER_FMU_DIR}/Source2.fmu", outputs=["ramp"]),
            remote("Slow", f"unix://{folder / 'slow.sock'}", inputs=["u"], outputs=["y"]),
            remote("Quick", f"unix://{folder / 'quick.sock'}", inputs=["u"], outputs=["y"]),
        ],
        connections=[("Source.ramp", "Slow.u"), ("Source.ramp", "Quick.u")],
        stop_time=2,
    )
    try:
        with (
            serving(Slow("Slow"), unix_socket=folder / "slow.sock"),
            serving(GainParticipant("Quick"), unix_socket=folder / "quick.sock"),
        ):
            out = tmp_path / "out"
            outcome = Coupler.process(
                "run", system.write(tmp_path / "costs.ssd"), "--out", out, "--step", "0.1"
            )
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    assert outcome.code == 0, outcome.err
    members = Coupler.summary(out)["participants"]
    slow, quick, source = members["Slow"], members["Quick"], members["Source"]
    assert slow["step_path"]["path"] == quick["step_path"]["path"] == "native step socket"
    # the master waited for Slow before it received Quick's answer: both latencies hold it
    assert quick["do_step_latency_ms"]["p50"] >= 25 and slow["do_step_latency_ms"]["p50"] >= 25
    # each one's own figure tells them apart
    assert slow["step_cost_ms"]["p50"] >= 25
    assert quick["step_cost_ms"]["p50"] < slow["step_cost_ms"]["p50"] / 5
    assert 15 <= slow["waited_ms"]["p50"] < slow["step_cost_ms"]["p50"]
    assert quick["waited_ms"] is None  # it waits for nothing: it says none
    assert slow["step_cost_ms"]["p50"] <= slow["do_step_latency_ms"]["p50"]
    # an in-process FMU's step is computed by the master: its cost is its latency
    assert source["step_cost_ms"] == source["do_step_latency_ms"]
