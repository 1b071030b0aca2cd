"""`make bench`'s section ``frameworks``: each framework adapter against the framework's own
loop, steps/s and their ratio measured in one run.

- mosaik: a mosaik World stepping a local source -> the example gain participant (its own
  process, gRPC) through ``coupler_mosaik:CouplerSimulator`` -> a local sink, against the same
  World with the gain as mosaik's own simulator (benchmarks/mosaik_gain.py, its own process,
  mosaik's TCP API): what the adapter costs a mosaik user per step.

Not measured yet: the HELICS participant against a HELICS federate's own loop.
"""

from __future__ import annotations

import asyncio
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def _coupler_world(address: str, steps: int) -> float:
    import mosaik

    script = Path(__file__).with_name("mosaik_gain.py")
    sys.path.insert(0, str(script.parent))
    config = {
        "Local": {"python": "mosaik_gain:Simulator"},
        "Local2": {"python": "mosaik_gain:Simulator"},
        "Coupler": {"python": "coupler_mosaik:CouplerSimulator"},
    }
    world = mosaik.World(config, debug=False)
    source = world.start("Local").Source()
    gain = world.start("Coupler", address=address, model="Gain").Gain()
    sink = world.start("Local2").Sink()
    world.connect(source, gain, ("value", "u"))
    world.connect(gain, sink, "y")
    started = time.perf_counter()
    world.run(until=steps, print_progress=False)
    rate = steps / (time.perf_counter() - started)
    world.shutdown()
    return rate


async def frameworks(
    sizes: Any, log: Callable[[str], None], work: Path, rows: list[Any], extra: dict[str, Any]
) -> None:
    import suite

    try:
        import mosaik  # noqa: F401  (the bench group brings it)
        from loguru import logger
    except ImportError:
        log("mosaik is not installed: no frameworks rows")
        return
    logger.remove()
    log("mosaik World: CouplerSimulator -> gain participant against mosaik's own simulator")
    [port] = suite.free_ports(1)
    with suite.processes(suite.gains([port])):
        await suite.serving([port])
        address = suite.address_of(port)

        async def adapter() -> float:
            with suite._quiet():
                return await asyncio.to_thread(_coupler_world, address, sizes.remote_steps)

        async def own() -> float | None:
            return await asyncio.to_thread(suite.mosaik_rate, sizes.remote_steps)

        coupler, reference = await suite.interleaved(sizes.repeats, adapter, own)
    assert coupler is not None
    rows.append(
        suite.Row(
            "mosaik World, CouplerSimulator x1 (gRPC)",
            coupler,
            "mosaik World, own simulator x1 (TCP)",
            reference,
        )
    )
