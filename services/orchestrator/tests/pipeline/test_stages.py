"""The pipeline's middle stages on the reference SSD: checks, wiring and ordering.

Participants here mirror the SSD's connectors (their declared types and units are the SSD's),
so the stages can be exercised without the network; the same stages run against real FMUs and
gRPC participants in test_correctness.py, test_conversions.py and test_scenarios.py.

Source --position[km]--> Gain.u[m] --y--> Sub.Scale.x ... --> Sink.a
Source.{flag,count,mode,temp} --transformations--> Sink.*
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import pytest

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.errors import ValidationError
from coupler.participant import Participant, Values
from coupler_orchestrator import ssp
from coupler_orchestrator.model import Algorithm, Candidate, Roster
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.pipeline.checks import check
from coupler_orchestrator.pipeline.ordering import execution_order
from coupler_orchestrator.pipeline.semantics import COUPLER
from coupler_orchestrator.pipeline.wiring import converter, wire
from coupler_orchestrator.ssp.units import affine, from_symbol

DATA = Path(__file__).parents[1] / "ssp" / "data"


class Mirror(Participant):
    """Declares what its component's SSD connectors and parameter bindings say (inputs start at
    a value)."""

    def __init__(self, component: ssp.Component) -> None:
        self.component = component

    async def describe(self) -> Description:
        channels = []
        for c in self.component.connectors:
            kind = c.type or ValueType.REAL
            start: Value | None = None
            if c.causality is Causality.INPUT:
                start = {ValueType.BOOLEAN: False, ValueType.STRING: "", ValueType.BINARY: b""}.get(
                    kind, 0 if kind is not ValueType.REAL else 0.0
                )
            channels.append(
                Channel(
                    name=c.name,
                    causality=c.causality or Causality.INPUT,
                    type=kind,
                    unit=c.unit or "",
                    start=start,
                )
            )
        declared = {c.name for c in self.component.connectors}
        for name, value in self.component.parameters.items():  # bound but not a connector
            if name not in declared:
                channels.append(Channel(name=name, causality=Causality.PARAMETER, type=value.type))
        return Description(name=self.component.name, channels=tuple(channels))

    async def initialize(self, setup: RunSetup) -> Values:
        return {}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return {}

    async def terminate(self, reason: str = "") -> None:
        pass


async def roster_of(scenario: ssp.Scenario) -> Roster:
    candidates = {}
    for component in scenario.components:
        mirror = Mirror(component)
        candidates[component.name] = Candidate(
            component=component, participant=mirror, description=await mirror.describe()
        )
    return Roster(candidates=candidates)


@pytest.fixture
def scenario() -> ssp.Scenario:
    return ssp.load_ssp(DATA / "scenario.ssd", env={"SCALE_HOST": "scale"})


OPTIONS = RunOptions(stop_time=1.0, step_size=0.05, algorithm=Algorithm.JACOBI)


async def test_converters_widen_convert_and_transform(scenario: ssp.Scenario) -> None:
    checked = check(scenario, await roster_of(scenario), OPTIONS, COUPLER)
    by = {(r.connection.start, r.connection.end): r for r in checked.routes}
    position = converter(by[("Source.position", "Gain.u")])
    assert position is not None and position(1.5) == pytest.approx(1500.0)  # km -> m
    temp = converter(by[("Source.temp", "Sink.temp")])  # degC -> K, then 2x + 1
    assert temp is not None and temp(20.0) == pytest.approx(587.3)
    flag = converter(by[("Source.flag", "Sink.flag")])
    assert flag is not None and flag(True) is False
    count = converter(by[("Source.count", "Sink.count")])
    assert count is not None and (count(2), count(3)) == (20, 3)
    mode = converter(by[("Source.mode", "Sink.mode")])
    assert mode is not None and mode(1) == 5  # Go -> Green
    assert converter(by[("Source.name", "Sink.label")]) is None  # nothing to do: no converter
    links = wire(checked)
    assert len(links) == len(checked.routes)
    assert "Source.blob -> Sink.blob" in {link.label for link in links}


async def test_problems_of_the_wiring_are_listed_together(tmp_path: Path) -> None:
    text = (DATA / "scenario.ssd").read_text()
    # an output driven by another connection, a second driver of Sink.a, a String into a Real
    anchor = '<ssd:Connection startConnector="ext_in" endElement="Sink" endConnector="extra">'
    assert anchor in text
    text = text.replace(
        anchor,
        '<ssd:Connection startElement="Source" startConnector="position" '
        'endElement="Sink" endConnector="a"/>'
        '<ssd:Connection startElement="Source" startConnector="name" '
        'endElement="Gain" endConnector="u"/>' + anchor,
    )
    path = tmp_path / "bad.ssd"
    path.write_text(text)
    for name in ("params.ssv", "mapping.ssm", "signals.ssb", "resources/gain.fmu"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes((DATA / name).read_bytes())
    scenario = ssp.load_ssp(path, env={"SCALE_HOST": "scale"})
    with pytest.raises(ValidationError) as info:
        check(scenario, await roster_of(scenario), OPTIONS, COUPLER)
    problems = "\n".join(info.value.problems)
    assert (  # the connections' lines: one of them in the nested system
        "bad.ssd line 79: input 'Sink.a' is driven by 2 connections (line 79 from "
        "'Sub.Scale.out', line 147 from 'Source.position'); an input takes exactly one driver"
    ) in problems
    assert (
        "bad.ssd line 106: input 'Gain.u' is driven by 2 connections (line 106 from "
        "'Source.position', line 147 from 'Source.name')"
    ) in problems
    assert "connector 'Gain.u' expects Real, but 'Source.name' is String" in problems


async def test_gauss_seidel_order_follows_the_links(scenario: ssp.Scenario) -> None:
    options = RunOptions(stop_time=1.0, step_size=0.05, algorithm=Algorithm.GAUSS_SEIDEL)
    checked = check(scenario, await roster_of(scenario), options, COUPLER)
    order = execution_order([m.name for m in checked.members], wire(checked), checked.algorithm)
    assert order.index("Source") < order.index("Gain") < order.index("Sub.Scale")
    assert order.index("Sub.Scale") < order.index("Sink")


@pytest.mark.parametrize(
    ("source", "target", "value", "expected"),
    [
        ("km/h", "m/s", 36.0, 10.0),
        ("degC", "K", 20.0, 293.15),
        ("degF", "degC", 212.0, 100.0),
        ("deg", "rad", 180.0, 3.141592653589793),
        ("m.s-1", "km/h", 10.0, 36.0),  # Modelica unit syntax
        ("kWh", "J", 1.0, 3.6e6),
    ],
)
def test_unit_symbols_convert(source: str, target: str, value: float, expected: float) -> None:
    a, b = from_symbol(source), from_symbol(target)
    assert a is not None and b is not None
    conversion = affine(a, b)
    assert conversion is not None and conversion(value) == pytest.approx(expected)


def test_unknown_symbols_are_none() -> None:
    assert from_symbol("parsecs per fortnite") is None
    assert from_symbol("EUR") is None
