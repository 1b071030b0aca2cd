"""One FMU alone under ``coupler run`` equals ``fmpy.simulate_fmu`` to the last bit.

    FMU (alone, parameters and input start values bound in the SSD)

FMPy's co-simulation loop steps from t_n to start + (n+1) * interval with the step size
t_{n+1} - t_n; Coupler's master from t_k = start + k*h with the step size h itself (exact steps,
docs/orchestrator.md). On a grid whose differences are exact (a dyadic step) the two are the
same doubles, so every recorded value must be identical; on other grids Coupler's step sizes
are the configured ones while FMPy's carry the rounding of the difference.
Integrator1, Integrator2 and Integrator3 are one model behind the FMI 1.0, 2.0 and 3.0 wrappers.
The FMI 1.0 binary's failures must also reach Coupler as errors through FMPy's binding.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import fmpy
import pytest

from coupler.channels import Causality, RunSetup
from coupler.errors import ParticipantError
from coupler.fmu import FmuParticipant
from coupler.testing import Component, SystemStructure

from .support import Coupler

CASES = {
    "Source2": {"slope": 0.7, "offset": 0.1, "amplitude": 1.5, "freq": 0.3},
    "Source3": {"slope": -1.3, "offset": 2.0, "amplitude": 0.25, "freq": 1.7},
    "Integrator1": {"x0": 0.75, "u": -0.4},
    "Integrator2": {"x0": 1.25, "u": 0.3},
    "Integrator3": {"x0": -0.5, "u": 0.7},
}


@pytest.mark.parametrize("fmu", sorted(CASES))
def test_fmu_alone_equals_fmpy(
    fmu: str, fmus: dict[str, Path], coupler: Coupler, tmp_path: Path
) -> None:
    start, stop, step = 0.25, 4.0, 0.125
    values = CASES[fmu]
    alone = Component(fmu, str(fmus[fmu]), parameters=values)
    ssd = SystemStructure("Alone", [alone], start_time=start, stop_time=stop).write(
        tmp_path / "alone.ssd"
    )
    out = tmp_path / "out"
    outcome = coupler("run", ssd, "--out", out, "--step", step)
    assert outcome.code == 0, outcome.err

    reference = fmpy.simulate_fmu(
        str(fmus[fmu]),
        start_time=start,
        stop_time=stop,
        output_interval=step,
        start_values=values,
        fmi_type="CoSimulation",
    )
    rows = coupler.results(out)
    assert len(rows) == len(reference) == 31
    outputs = [name for name in rows[0] if name != "time"]
    assert outputs, "the FMU has outputs"
    for row, expected in zip(rows, reference, strict=True):
        assert float(row["time"]) == float(expected["time"])
        for column in outputs:
            assert float(row[column]) == float(expected[column.split(".", 1)[1]]), (
                column,
                row["time"],
            )


async def test_fmi1_parameter_is_a_parameter_channel(fmus: dict[str, Path]) -> None:
    """FMI 1.0 has no causality="parameter": x0 is causality="internal" variability="parameter"."""
    participant = FmuParticipant(fmus["Integrator1"])
    try:
        description = await participant.describe()
    finally:
        await participant.close()
    causalities = {c.name: c.causality for c in description.channels}
    assert causalities == {
        "x0": Causality.PARAMETER,
        "u": Causality.INPUT,
        "x": Causality.OUTPUT,
    }
    assert description.implementation.startswith("FMI 1.0 FMU Integrator")


async def test_fmi1_failing_step_is_a_participant_error(fmus: dict[str, Path]) -> None:
    """fmiDoStep's fmiError is an error, not a crash (FMPy 0.3.32 reads it as a char pointer)."""
    participant = FmuParticipant(fmus["Integrator1"])
    setup = RunSetup(run_id="fmi1", start_time=0.0, step_size=0.5, parameters={"x0": 2.0})
    try:
        assert await participant.initialize(setup) == {"x": 2.0}
        assert await participant.do_step(0.0, 0.5, {"u": 1.5}) == {"x": 2.75}
        with pytest.raises(ParticipantError) as caught:
            await participant.do_step(0.5, 0.0, {})
        assert (caught.value.call, caught.value.status) == ("fmiDoStep", "fmiError")
    finally:
        await participant.close()


async def test_fmi1_guid_mismatch_is_a_participant_error(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """The binary checks the guid; FMPy does not notice fmiInstantiateSlave returning NULL."""
    tampered = tmp_path / "Integrator1.fmu"
    with (
        zipfile.ZipFile(fmus["Integrator1"]) as source,
        zipfile.ZipFile(tampered, "w") as target,
    ):
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'guid="{', b'guid="{0', 1)
            target.writestr(item, data)
    participant = FmuParticipant(tampered)
    try:
        with pytest.raises(ParticipantError) as caught:
            await participant.initialize(RunSetup(run_id="fmi1", start_time=0.0, step_size=0.5))
        assert caught.value.call == "fmiInstantiateSlave"
    finally:
        await participant.close()


async def test_strings_take_the_prepared_calls_both_ways(fmus: dict[str, Path]) -> None:
    """An FMI 2.0 FMU with String inputs and outputs steps through the prepared calls (not
    FMPy's); text survives both ways, UTF-8 intact. (FMI 3.0 Binary still takes FMPy's.)"""
    participant = FmuParticipant(fmus["Feedthrough2"])
    setup = RunSetup(run_id="strings", start_time=0.0, step_size=0.5)
    try:
        await participant.initialize(setup)
        assert participant._calls is not None
        for k, text in enumerate(["grüße, Zürich", "", "x" * 300]):
            outputs = await participant.do_step(k * 0.5, 0.5, {"string_in": text, "real_in": k})
            assert outputs["string_out"] == text
            assert outputs["real_out"] == 2.0 * k  # gain 2
    finally:
        await participant.close()
