"""Section ``frameworks``: each framework adapter against the framework's own loop, steps/s and
their ratio measured in one run (docs/frameworks.md).

- mosaik: a mosaik World stepping a local source -> the example gain participant (its own
  process, gRPC) through ``coupler_mosaik:CouplerSimulator`` -> a local sink, against the same
  World with the gain as mosaik's own simulator (benchmarks/mosaik_gain.py, its own process,
  mosaik's TCP API): what the adapter costs a mosaik user per step.
- HELICS: a broker on loopback and the ramp federate (benchmarks/helics_federate.py) exchanging
  a value each step with an echo federate (HELICS alone), against the same ramp federate
  exchanging it with a Coupler run (``coupler-helics`` as a process, the HELICS.ramp ->
  Gain.u, Gain.y -> HELICS.y loop with the example gain participant): steps/s of the ramp
  federate, from executing mode to its last grant.
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sections.common import (
    ROOT,
    STEP,
    Row,
    Sizes,
    address_of,
    free_ports,
    gains,
    interleaved,
    processes,
    serving,
    write_ssd,
)
from sections.peers import mosaik_rate, quiet

BENCHMARKS = ROOT / "benchmarks"


def _coupler_world(address: str, steps: int) -> float:
    import mosaik

    sys.path.insert(0, str(BENCHMARKS))
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


def _helics(role: str, port: int, steps: int) -> list[str]:
    script = str(BENCHMARKS / "helics_federate.py")
    return [sys.executable, script, role, str(port), str(steps), str(STEP)]


def _ramp(port: int, steps: int) -> subprocess.Popen[str]:
    return subprocess.Popen(
        _helics("ramp", port, steps), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )


def helics_alone(steps: int) -> float:
    """Steps/s of the ramp federate exchanging a value with the echo federate."""
    from coupler_helics.broker import command

    [port] = free_ports(1)
    with processes([command(port, 2), _helics("echo", port, steps)]):
        ramp = _ramp(port, steps)
        said, _ = ramp.communicate(timeout=600)
    return float(said.split()[-1])  # its last line (HELICS may warn before it)


HELICS_TOML = """name = "HELICS"
federate = "coupler"
broker = "127.0.0.1:{port}"
[[publication]]
channel = "y"
key = "coupler/y"
start = 0.0
[[subscription]]
channel = "ramp"
key = "ramp"
start = 0.0
"""


def _loop_ssd(folder: Path, helics: int, gain: int) -> Path:
    def component(name: str, port: int, *kinds: tuple[str, str]) -> str:
        connectors = "".join(
            f'<ssd:Connector name="{n}" kind="{k}"><ssc:Real/></ssd:Connector>' for n, k in kinds
        )
        return (
            f'<ssd:Component name="{name}" type="application/x-coupler-grpc" '
            f'source="{address_of(port)}"><ssd:Connectors>{connectors}</ssd:Connectors>'
            "</ssd:Component>"
        )

    return write_ssd(
        folder / "helics-gain.ssd",
        [component("HELICS", helics, ("y", "input"), ("ramp", "output")),
         component("Gain", gain, ("u", "input"), ("y", "output"))],
        ['<ssd:Connection startElement="HELICS" startConnector="ramp" endElement="Gain" '
         'endConnector="u"/>',
         '<ssd:Connection startElement="Gain" startConnector="y" endElement="HELICS" '
         'endConnector="y"/>'],
    )  # fmt: skip


async def helics_through_coupler(work: Path, steps: int) -> float:
    """Steps/s of the ramp federate exchanging a value with a Coupler run (the gain
    participant behind the HELICS participant)."""
    from coupler_helics.broker import command
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.runner import run_scenario

    port, helics, gain = free_ports(3)
    config = work / "helics.toml"
    config.write_text(HELICS_TOML.format(port=port))
    serve = [sys.executable, "-m", "coupler_helics", str(config), "--port", str(helics)]
    with processes([command(port, 2), serve, *gains([gain])]):
        await serving([helics, gain])
        ramp = _ramp(port, steps)
        try:
            options = RunOptions(
                stop_time=steps * STEP, step_size=STEP, run_id=f"bench-helics-{time.time_ns()}"
            )
            outcome = await run_scenario(
                _loop_ssd(work, helics, gain), options, out_dir=work / "helics-run", replace=True
            )
            if outcome.end.status != "completed":
                raise RuntimeError(f"HELICS loop: {outcome.end.status}: {outcome.end.reason}")
            said, _ = await asyncio.to_thread(ramp.communicate, timeout=600)
        finally:
            if ramp.poll() is None:
                ramp.kill()
                ramp.wait()
    return float(said.split()[-1])  # its last line (HELICS may warn before it)


async def frameworks(
    sizes: Sizes, log: Callable[[str], None], work: Path, rows: list[Row], extra: dict[str, Any]
) -> None:
    try:
        import helics  # noqa: F401  (coupler-helics brings it)
        import mosaik  # noqa: F401  (the bench group brings it)
        from loguru import logger
    except ImportError as exc:
        log(f"frameworks rows skipped: {exc}")
        extra.setdefault("skipped", []).append(f"frameworks: {exc}")
        return
    logger.remove()
    log("mosaik World: CouplerSimulator -> gain participant against mosaik's own simulator")
    [port] = free_ports(1)
    with processes(gains([port])):
        await serving([port])
        address = address_of(port)

        async def adapter() -> float:
            with quiet():
                return await asyncio.to_thread(_coupler_world, address, sizes.remote_steps)

        async def own() -> float | None:
            return await asyncio.to_thread(mosaik_rate, sizes.remote_steps)

        coupler, reference = await interleaved(sizes.repeats, adapter, own)
    assert coupler is not None
    rows.append(
        Row("mosaik World, CouplerSimulator x1 (gRPC)", coupler,
            "mosaik World, own simulator x1 (TCP)", reference)
    )  # fmt: skip
    log("HELICS: a federate and a Coupler run against two federates alone")

    async def coupler_side() -> float:
        return await helics_through_coupler(work, sizes.remote_steps)

    async def federates() -> float:
        return await asyncio.to_thread(helics_alone, sizes.remote_steps)

    through, alone = await interleaved(sizes.repeats, coupler_side, federates)
    assert through is not None
    rows.append(
        Row("HELICS federate <-> Coupler run", through, "HELICS federates alone", alone,
            note="the ramp federate's steps/s")
    )  # fmt: skip
