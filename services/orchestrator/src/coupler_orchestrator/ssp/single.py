"""One FMU alone as a scenario: what ``coupler run X.fmu`` runs (like ``fmpy simulate``).

The FMU is the only component, named after its model; its DefaultExperiment gives start and
stop time and the step: ``stepSize``, else FMI 3's ``fixedInternalStepSize``, else a step that
divides the run into 500 to 1000 steps (FMPy's rule); a missing stop time is start + 1 s, as in
FMPy. Every output is recorded. The CLI's ``--start-time``, ``--stop-time`` and ``--step``
override all of it.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

from coupler.errors import ScenarioError

from .model import FMU_TYPE, Component, Scenario, frozen_mapping


def scenario_of_fmu(path: str | Path) -> Scenario:
    """The scenario of one FMU; ScenarioError when it is not a readable co-simulation FMU."""
    import fmpy  # the orchestrator depends on coupler[fmu]

    fmu = Path(path).resolve()
    if not fmu.is_file():
        raise ScenarioError(f"{path}: no such file; give the path of an .fmu")
    try:
        md = fmpy.read_model_description(str(fmu), validate=False)
    except Exception as exc:  # FMPy raises plain exceptions for any broken FMU
        raise ScenarioError(f"{fmu.name}: not a readable FMU: {exc}") from exc
    experiment = md.defaultExperiment
    start = _number(getattr(experiment, "startTime", None)) or 0.0
    stop = _number(getattr(experiment, "stopTime", None))
    stop = start + 1.0 if stop is None else stop
    step = _number(getattr(experiment, "stepSize", None))
    if step is None and md.coSimulation is not None:
        step = _number(getattr(md.coSimulation, "fixedInternalStepSize", None))
    if step is None and math.isfinite(stop - start) and stop > start:
        step = auto_interval(stop - start)
    return Scenario(
        source=fmu,
        sha256=hashlib.sha256(fmu.read_bytes()).hexdigest(),
        ssp_version="",
        name=md.modelName,
        components=(
            Component(
                name=md.modelName,
                type=FMU_TYPE,
                source=str(fmu),
                connectors=(),
                file=fmu.name,
            ),
        ),
        connections=(),
        units=frozen_mapping(),
        enumerations=frozen_mapping(),
        signal_dictionaries=frozen_mapping(),
        start_time=start,
        stop_time=stop,
        step_size=step,
        step_type=None,
        task=None,
        results=None,
        warnings=(),
        resource_dir=fmu.parent,
    )


def _number(text: object) -> float | None:
    if text is None or text == "":
        return None
    try:
        return float(str(text))
    except ValueError:
        return None


def auto_interval(span: float) -> float:
    """A round step dividing ``span`` into 500 to 1000 steps (FMPy's ``auto_interval``)."""
    step = 10.0 ** (round(math.log10(span)) - 3)
    samples = span / step
    if samples >= 2500:
        step *= 5
    elif samples >= 2000:
        step *= 4
    elif samples >= 1000:
        step *= 2
    return step
