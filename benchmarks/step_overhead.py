"""Step overhead of the protocol, measured in one run: unary DoStep vs the StepStream session,
and an FMU in-process vs the same FMU behind the generic gRPC host.

    .venv/bin/python benchmarks/step_overhead.py [--steps N]

Prints mean microseconds per step and the ratios. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from pathlib import Path

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.examples.gain import GainParticipant
from coupler.fmu import FmuParticipant
from coupler.logs import configure_logging
from coupler.participant import Participant
from coupler.server import ParticipantServer

ROOT = Path(__file__).resolve().parents[1]
FMU = ROOT / "build" / "fmus" / "Integrator2.fmu"


async def per_step(participant: Participant, steps: int, inputs: dict[str, float]) -> float:
    """Mean seconds per do_step over ``steps`` steps (after 50 warm-up steps)."""
    await participant.initialize(RunSetup(run_id="bench", start_time=0.0, step_size=0.01))
    for k in range(50):
        await participant.do_step(k * 0.01, 0.01, inputs)
    started = time.perf_counter()
    for k in range(steps):
        await participant.do_step((k + 50) * 0.01, 0.01, inputs)
    elapsed = time.perf_counter() - started
    await participant.terminate()
    return elapsed / steps


async def remote(
    participant: Participant, steps: int, inputs: dict[str, float], *, streaming: bool
) -> float:
    server = ParticipantServer(participant)
    await server.start()
    try:
        async with RemoteParticipant(server.address, streaming=streaming) as client:
            return await per_step(client, steps, inputs)
    finally:
        await server.stop(grace=0.1)


async def main(steps: int) -> None:
    rows: list[tuple[str, float]] = []
    gain_inputs = {"u": 1.0}
    rows.append(("gain, in-process", await per_step(GainParticipant(), steps, gain_inputs)))
    rows.append(
        (
            "gain, gRPC unary DoStep",
            await remote(GainParticipant(), steps, gain_inputs, streaming=False),
        )
    )
    rows.append(
        (
            "gain, gRPC StepStream",
            await remote(GainParticipant(), steps, gain_inputs, streaming=True),
        )
    )
    if FMU.exists():
        local = FmuParticipant(FMU)
        rows.append(("Integrator FMU, in-process", await per_step(local, steps, gain_inputs)))
        await local.close()
        rows.append(
            (
                "Integrator FMU, gRPC host StepStream",
                await remote(FmuParticipant(FMU), steps, gain_inputs, streaming=True),
            )
        )
    width = max(len(name) for name, _ in rows)
    print(f"{'participant':<{width}}  us/step  (mean of {steps} steps)")
    for name, seconds in rows:
        print(f"{name:<{width}}  {seconds * 1e6:7.1f}")
    by = dict(rows)
    print(
        f"\nunary / stream ratio:        "
        f"{by['gain, gRPC unary DoStep'] / by['gain, gRPC StepStream']:.2f}"
    )
    if FMU.exists():
        print(
            f"FMU over gRPC / in-process:  "
            f"{by['Integrator FMU, gRPC host StepStream'] / by['Integrator FMU, in-process']:.2f}"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    configure_logging("WARNING")
    asyncio.run(main(parser.parse_args().steps))
