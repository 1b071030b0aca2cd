"""Transformations, unit conversion, .ssv/.ssm parameters and signal dictionaries at run time.

The loader's unit tests (tests/ssp/) check the parsing; these check the values the
participants actually receive, through what they output into results.csv.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ..support import DATA, Coupler, Stepper, serving

pytestmark = pytest.mark.usefixtures("fmus")


def test_conversions_reach_the_participants(coupler: Coupler, tmp_path: Path) -> None:
    """Gauss-Seidel (so no delays), h = 0.5, 0 .. 1.5 s:

    Source (slope, offset from .ssv/.ssm) --ramp [degC]--> Feed.real_in [K]
    Source --ramp, LinearTransformation 3x+1--> Feed2.real_in
    Source --counter, IntegerMapping 1->10 2->20--> Feed.int_in
    Feed --bool_out, BooleanMapping true<->false--> Feed2.bool_in
    Source --counter--> BusIn.rate ~ signal dictionary Bus ~ BusOut.rate --> Integ.u
    """
    outcome = coupler(
        "run", DATA / "conversions.ssd", "--out", tmp_path, "--algorithm", "gauss-seidel"
    )
    assert outcome.code == 0, outcome.err
    # .ssv rate 0.25 -> .ssm LinearTransformation x2 -> slope 0.5; 0.001 km -> offset 1.0 m
    assert coupler.column(tmp_path, "Source.ramp") == [1.0, 1.25, 1.5, 1.75]
    # degC -> K, then the FMU's gain 2
    assert coupler.column(tmp_path, "Feed.real_out")[1:] == [
        2.0 * (ramp + 273.15) for ramp in (1.25, 1.5, 1.75)
    ]
    # 3 * ramp + 1, then gain 2
    assert coupler.column(tmp_path, "Feed2.real_out")[1:] == [9.5, 11.0, 12.5]
    # counter 1, 2, 3 mapped (3 has no entry and passes unchanged)
    assert coupler.column(tmp_path, "Feed.int_out")[1:] == [10, 20, 3]
    # Feed.bool_out is 1 (not bool_in = false); mapped to 0; Feed2.bool_out = not 0
    assert coupler.column(tmp_path, "Feed.bool_out") == [1, 1, 1, 1]
    assert coupler.column(tmp_path, "Feed2.bool_out")[1:] == [1, 1, 1]
    # Integer counter through the dictionary, widened to Real: x += 0.5 * counter
    assert coupler.column(tmp_path, "Integ.x") == [0.0, 0.5, 1.5, 3.0]


ENUMS = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="Enums"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">
  <ssd:System name="Enums">
    <ssd:Elements>
      <ssd:Component name="A" type="application/x-coupler-grpc" source="grpc://127.0.0.1:${A_PORT}">
        <ssd:Connectors>
          <ssd:Connector name="phase" kind="output">
            <ssc:Enumeration name="Modes"/></ssd:Connector>
          <ssd:Connector name="aspect" kind="input">
            <ssc:Enumeration name="Aspects"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="a">
                <ssv:Parameters>
                  <ssv:Parameter name="aspect">
                    <ssv:Enumeration name="Aspects" value="Red"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="B" type="application/x-coupler-grpc" source="grpc://127.0.0.1:${B_PORT}">
        <ssd:Connectors>
          <ssd:Connector name="aspect" kind="input">
            <ssc:Enumeration name="Aspects"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="A" startConnector="phase" endElement="B" endConnector="aspect">
        <ssc:EnumerationMappingTransformation>
          <ssc:MapEntry source="Stop" target="Red"/>
          <ssc:MapEntry source="Go" target="Green"/>
        </ssc:EnumerationMappingTransformation>
      </ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:Enumerations>
    <ssc:Enumeration name="Modes">
      <ssc:Item name="Stop" value="0"/><ssc:Item name="Go" value="1"/></ssc:Enumeration>
    <ssc:Enumeration name="Aspects">
      <ssc:Item name="Green" value="5"/><ssc:Item name="Red" value="7"/></ssc:Enumeration>
  </ssd:Enumerations>
  <ssd:DefaultExperiment startTime="0" stopTime="1.5"/>
</ssd:SystemStructureDescription>
"""


def test_enumeration_mapping_over_grpc(
    coupler: Coupler, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two gRPC participants with Enumeration channels, Jacobi, h = 0.5:

        A --phase (Modes: Stop 0, Go 1), EnumerationMapping Stop->Red Go->Green--> B.aspect
        (Aspects: Green 5, Red 7); A.aspect bound to Red in the SSD (a start value)

    B.shown(t_{k+1}) = map(A.phase(t_k)), A.phase(t_k) = k mod 2.
    """
    with serving(Stepper()) as a, serving(Stepper()) as b:
        monkeypatch.setenv("A_PORT", str(a.port))
        monkeypatch.setenv("B_PORT", str(b.port))
        ssd = tmp_path / "enums.ssd"
        ssd.write_text(ENUMS)
        outcome = coupler("run", ssd, "--out", tmp_path / "out", "--step", "0.5")
    assert outcome.code == 0, outcome.err
    assert coupler.column(tmp_path / "out", "A.phase") == [0, 1, 0, 1]
    assert coupler.column(tmp_path / "out", "A.shown") == [7, 7, 7, 7]
    assert coupler.column(tmp_path / "out", "B.shown") == [0, 7, 5, 7]
