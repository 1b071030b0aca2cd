"""The peers Coupler is measured against: a hand-written FMPy FMU2Slave loop, libcosim
(libcosimpy, C++) and mosaik 3 with one remote simulator over its TCP API.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sections.common import FMUS, ROOT, STEP


def fmpy_slave(path: Path, name: str) -> tuple[Any, Any]:
    """An FMI 2 FMU initialized at t = 0 by FMPy's FMU2Slave, and its model description."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    description = read_model_description(path)
    slave = FMU2Slave(
        guid=description.guid,
        unzipDirectory=extract(path),
        modelIdentifier=description.coSimulation.modelIdentifier,
        instanceName=name,
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, description


def free_slave(slave: Any) -> None:
    """End an FMPy slave and remove the folder ``fmpy.extract`` unpacked its FMU into."""
    try:
        slave.terminate()
        slave.freeInstance()
    finally:
        shutil.rmtree(slave.unzipDirectory, ignore_errors=True)


def fmpy_loop(n: int, steps: int) -> float:
    """Steps/s of a hand-written FMPy loop: Source2 -> Feedthrough2 x n, every output read."""
    slaves = []
    for k, name in enumerate(["Source2"] + ["Feedthrough2"] * n):
        slave, description = fmpy_slave(FMUS / f"{name}.fmu", f"{name}{k}")
        outputs = [v for v in description.modelVariables if v.causality == "output"]
        by_type: dict[str, list[int]] = {}
        for variable in outputs:
            by_type.setdefault(variable.type, []).append(variable.valueReference)
        ramp = next(v.valueReference for v in outputs if v.name in ("ramp", "real_out"))
        slaves.append((slave, by_type, ramp))
    real_in = 3  # Feedthrough2's real_in
    getters = {"Real": "getReal", "Integer": "getInteger", "Boolean": "getBoolean"}
    t = 0.0
    started = time.perf_counter()
    for k in range(steps):
        t = k * STEP
        values = []
        for slave, by_type, ramp in slaves:
            for kind, refs in by_type.items():
                if kind == "String":
                    slave.getString(refs)
                else:
                    getattr(slave, getters[kind])(refs)
            values.append(slave.getReal([ramp])[0])
        for (slave, _, _), value in zip(slaves[1:], values, strict=False):
            slave.setReal([real_in], [value])
        for slave, _, _ in slaves:
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=STEP)
    rate = steps / (time.perf_counter() - started)
    for slave, _, _ in slaves:
        free_slave(slave)
    return rate


def libcosim_loop(n: int, steps: int) -> float | None:
    """Steps/s of libcosim (C++) on the same chain, last values of every slave observed."""
    try:
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimSlave import CosimLocalSlave
    except ImportError:
        return None
    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_step_size(step_size=int(STEP * 1e9))
    indices = []
    for k, name in enumerate(["Source2"] + ["Feedthrough2"] * n):
        slave = CosimLocalSlave(fmu_path=str(FMUS / f"{name}.fmu"), instance_name=f"{name}{k}")
        indices.append(execution.add_local_slave(slave))
    ramp, real_out, real_in = 5, 8, 3
    for k in range(1, len(indices)):
        output = ramp if k == 1 else real_out
        execution.connect_real_variables(indices[k - 1], output, indices[k], real_in)
    execution.add_observer(CosimObserver.create_last_value())
    execution.step(10)
    started = time.perf_counter()
    execution.step(steps)
    return steps / (time.perf_counter() - started)


def mosaik_rate(steps: int) -> float | None:
    """Steps/s of mosaik 3: a local source -> the gain simulator (its own process, TCP) -> a
    local sink, time-based, one step per time unit."""
    try:
        import mosaik  # noqa: F401  (installed? the bench group brings it)
        from loguru import logger
    except ImportError:
        return None
    logger.remove()
    script = ROOT / "benchmarks" / "mosaik_gain.py"
    sys.path.insert(0, str(script.parent))
    config = {
        "Local": {"python": "mosaik_gain:Simulator"},
        "Local2": {"python": "mosaik_gain:Simulator"},
        "Remote": {"cmd": f"{sys.executable} {script} %(addr)s"},
    }
    with quiet():  # mosaik's banner and its simulators' log lines
        return _mosaik_world(config, steps)


def _mosaik_world(config: dict[str, Any], steps: int) -> float:
    import mosaik

    world = mosaik.World(config, debug=False)
    source = world.start("Local").Source()
    gain = world.start("Remote").Gain()
    sink = world.start("Local2").Sink()
    world.connect(source, gain, ("value", "u"))
    world.connect(gain, sink, "y")
    started = time.perf_counter()
    world.run(until=steps, print_progress=False)
    return steps / (time.perf_counter() - started)


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """stdout and stderr of this process and its children to /dev/null (file descriptors)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)
