"""SSP loading: the reference scenario in data/ and one test per bad input.

Source --position[km]--> Gain.u[m] --y--> Sub.in --> Sub.Scale.x
Sub.Scale.out --> Sub.out --> Sink.a          (flattened through the nested system)
Source.{flag,count,mode,temp} --transformations--> Sink.*
Source.name --> BusIn.label ~ Bus ~ BusOut.label --> Sink.label   (signal dictionary)
"""

from __future__ import annotations

import shutil
import zipfile
from collections.abc import Sequence
from pathlib import Path

import pytest

from coupler.channels import Causality, ValueType
from coupler.errors import ScenarioError, ValidationError
from coupler.testing import (
    Annotation,
    Binding,
    Component,
    Connection,
    Connector,
    SystemStructure,
    fmu,
    remote,
)
from coupler_orchestrator.ssp import BooleanMappingTransformation, LinearTransformation, load_ssp

DATA = Path(__file__).parent / "data"
ENV = {"SCALE_HOST": "scale"}


def grpc(name: str, *connectors: Connector, source: str = "grpc://localhost:1") -> Component:
    return remote(name, source, *connectors)


def real(name: str, kind: str, unit: str = "") -> Connector:
    return Connector(name, kind, "Real", unit)


def write(
    tmp_path: Path,
    components: Sequence[Component],
    connections: Sequence[tuple[str, str]] = (),
    version: str = "1.0",
) -> Path:
    system = SystemStructure(
        "Root",
        components,
        connections,
        stop_time=None,
        units={"m": {"m": 1}, "s": {"s": 1}},
        version=version,
    )
    return system.write(tmp_path / "scenario.ssd")


@pytest.fixture
def scenario():  # type: ignore[no-untyped-def]
    return load_ssp(DATA / "scenario.ssd", env=ENV)


def test_reference_scenario_components(scenario) -> None:  # type: ignore[no-untyped-def]
    assert scenario.ssp_version == "1.0"
    assert scenario.name == "Reference"
    assert len(scenario.sha256) == 64
    assert [c.name for c in scenario.components] == ["Source", "Gain", "Sub.Scale", "Sink"]
    source = scenario.component("Source")
    assert source.source == "grpc://127.0.0.1:50051"
    assert source.delta_time == 0.05
    assert scenario.component("Sub.Scale").source == "grpc://scale:6000"
    gain = scenario.component("Gain")
    assert gain.source == str((DATA / "resources" / "gain.fmu").resolve())
    assert gain.connector("u").causality is Causality.INPUT
    position = source.connector("position")
    assert (position.type, position.unit, position.kind) == (ValueType.REAL, "km", "output")
    assert source.connector("blob").type is ValueType.BINARY
    assert source.connector("mode").enumeration == "Modes"


def test_parameters_inline_ssv_ssm_prefix_and_units(scenario) -> None:  # type: ignore[no-untyped-def]
    gain = scenario.component("Gain").parameters
    assert gain["k"].value == 6.0  # ssv 3.0 mapped to k through a LinearTransformation x2
    assert gain["label"].value == "gain one"  # inline
    assert gain["offset"].value == pytest.approx(1500.0)  # 1.5 km -> m
    assert gain["offset"].unit == "m"
    assert gain["enabled"].value is True
    # system binding with prefix "Scale." reaches the nested component; Integer widened to Real
    factor = scenario.component("Sub.Scale").parameters["factor"]
    assert (factor.value, factor.type) == (4.0, ValueType.REAL)


def test_connections_flattened_and_annotated(scenario) -> None:  # type: ignore[no-untyped-def]
    pairs = {(c.start, c.end): c for c in scenario.connections}
    assert ("Gain.y", "Sub.Scale.x") in pairs
    assert ("Source.name", "Sink.label") in pairs  # through the signal dictionary
    nested = pairs[("Sub.Scale.out", "Sink.a")]
    assert (nested.decouple_type, nested.decouple_priority, nested.decoupled) == (
        "if_needed",
        3,
        False,
    )
    assert pairs[("Source.blob", "Sink.blob")].decoupled is True
    assert isinstance(
        pairs[("Source.flag", "Sink.flag")].transformation, BooleanMappingTransformation
    )
    assert pairs[("Source.temp", "Sink.temp")].transformation == LinearTransformation(
        factor=2.0, offset=1.0
    )


def test_experiment_openmcx_task_results_and_warnings(scenario) -> None:  # type: ignore[no-untyped-def]
    assert (scenario.start_time, scenario.stop_time) == (0.0, 10.0)
    assert (scenario.step_size, scenario.step_type) == (0.01, "sequential")
    assert scenario.results.output_directory == "out"
    assert scenario.results.backends[0].type == "csv"
    assert scenario.signal_dictionaries["Bus"].entries["speed"].unit == "m/s"
    text = "\n".join(scenario.warnings)
    assert "inter_extrapolation" not in text  # OpenMCx's inter/extrapolation is applied
    assert "root system connector 'ext_in'" in text
    assert "OpenMCx resultLevel 'coupling' is not supported" in text
    assert "results backend 'csv'" not in text  # csv is what Coupler writes


def test_ssp_archive(tmp_path: Path) -> None:
    archive = tmp_path / "scenario.ssp"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.write(DATA / "scenario.ssd", "SystemStructure.ssd")
        for name in ("params.ssv", "mapping.ssm", "signals.ssb", "resources/gain.fmu"):
            zf.write(DATA / name, name)
    work = tmp_path / "work"
    scenario = load_ssp(archive, env=ENV, workdir=work)
    assert scenario.resource_dir == work.resolve()
    assert scenario.component("Gain").source == str(work.resolve() / "resources" / "gain.fmu")
    assert scenario.source == archive.resolve()


def test_the_ssd_builder_of_coupler_testing_writes_what_it_is_given(tmp_path: Path) -> None:
    """coupler.testing.SystemStructure: a schema-valid SSD that loads as it was built."""
    bound = {"gain": 2.5, "count": 3, "on": True, "label": "x"}
    timeout = Annotation("org.coupler.component", "Component", {"callTimeout": "4"})
    decoupled = Annotation("org.coupler.connection", "Connection", {"decoupled": "true"})
    system = SystemStructure(
        "Built",
        components=[
            fmu(
                "Plant",
                "x.fmu",
                real("y", "output", "m"),
                inputs=["u"],
                parameters=bound,
                annotations=[timeout],
            ),
            remote("Control", "grpc://${C_HOST}:9", inputs=["y"], outputs=["u"]),
        ],
        connections=[
            ("Plant.y", "Control.y"),
            Connection("Control.u", "Plant.u", annotations=[decoupled]),
        ],
        start_time=0.5,
        stop_time=3,
        units={"m": {"m": 1}, "km": {"m": 1, "factor": 1000}},
    )
    (tmp_path / "x.fmu").touch()
    scenario = load_ssp(system.write(tmp_path / "b.ssd"), env={"C_HOST": "h"})
    assert (scenario.name, scenario.start_time, scenario.stop_time) == ("Built", 0.5, 3.0)
    assert scenario.units["km"].base_unit.factor == 1000.0
    plant, control = scenario.components
    assert plant.type == "application/x-fmu-sharedlibrary"
    assert [(c.name, c.kind, c.type, c.unit) for c in plant.connectors] == [
        ("y", "output", ValueType.REAL, "m"),
        ("u", "input", None, None),
    ]
    assert {n: p.value for n, p in plant.parameters.items()} == bound
    assert (plant.settings.call_timeout, control.settings.call_timeout) == (4.0, None)
    assert (control.type, control.source) == ("application/x-coupler-grpc", "grpc://h:9")
    assert [(c.start, c.end, c.decoupled) for c in scenario.connections] == [
        ("Plant.y", "Control.y", False),
        ("Control.u", "Plant.u", True),
    ]


def test_ssp2_loads_with_structural_checks(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        [grpc("A", real("y", "output")), grpc("B", real("u", "input"))],
        [("A.y", "B.u")],
        version="2.0",
    )
    scenario = load_ssp(path)
    assert scenario.ssp_version == "2.0"
    assert any("no XML schema for SSP version '2.0'" in w for w in scenario.warnings)


def test_env_expansion_and_undefined_variable(tmp_path: Path) -> None:
    path = write(tmp_path, [grpc("A", real("y", "output"), source="grpc://${A_HOST}:${A_PORT:-9}")])
    assert load_ssp(path, env={"A_HOST": "h"}).component("A").source == "grpc://h:9"
    with pytest.raises(ValidationError) as info:
        load_ssp(path, env={})
    assert "scenario.ssd line 8: component 'A': environment variable 'A_HOST'" in str(info.value)


@pytest.mark.parametrize(
    "source",
    ["grpc://${SECRET}:9", "grpc://${HOME}@127.0.0.1:9", "grpc://${PASSWORD:-x}.example:9"],
)
def test_only_address_variables_expand_and_values_are_never_shown(
    tmp_path: Path, source: str
) -> None:
    """An SSD cannot read an arbitrary environment variable into an address (and print it)."""
    path = write(tmp_path, [grpc("A", real("y", "output"), source=source)])
    secrets = {"SECRET": "s3cr3t-value", "HOME": "/root", "PASSWORD": "hunter2"}
    with pytest.raises(ValidationError) as info:
        load_ssp(path, env=secrets)
    message = str(info.value)
    assert "only names ending in _HOST, _PORT, _ADDRESS, _SCHEME, _DIR" in message
    assert not any(value in message for value in secrets.values())


def test_user_information_in_a_source_is_refused(tmp_path: Path) -> None:
    path = write(tmp_path, [grpc("A", real("y", "output"), source="grpc://user:pw@${A_HOST}:9")])
    with pytest.raises(ValidationError, match="carries user information"):
        load_ssp(path, env={"A_HOST": "h"})


@pytest.mark.parametrize("source", ["grpc://127.0.0.1:9/../x", "grpc://127.0.0.1:9?x"])
def test_a_source_with_a_path_or_query_is_refused(tmp_path: Path, source: str) -> None:
    path = write(tmp_path, [grpc("A", real("y", "output"), source=source)])
    with pytest.raises(ValidationError, match=r"is not of the form grpc://HOST:PORT"):
        load_ssp(path)


def test_an_unpacked_ssp_folder_loads(tmp_path: Path) -> None:
    folder = tmp_path / "unpacked"
    for name in ("params.ssv", "mapping.ssm", "signals.ssb", "resources/gain.fmu"):
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(DATA / name, folder / name)
    shutil.copy(DATA / "scenario.ssd", folder / "SystemStructure.ssd")
    scenario = load_ssp(folder, env=ENV)
    assert scenario.resource_dir == folder.resolve()
    assert scenario.component("Gain").source == str(folder.resolve() / "resources" / "gain.fmu")
    with pytest.raises(ScenarioError, match=r"must hold an unpacked SSP with SystemStructure\.ssd"):
        load_ssp(folder / "resources")


def test_an_unknown_mapping_source_is_an_error(tmp_path: Path) -> None:
    """An .ssm entry that maps a parameter the set does not have is refused, not ignored."""
    (tmp_path / "p.ssv").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"'
        ' version="1.0" name="p"><ssv:Parameters>'
        '<ssv:Parameter name="gain"><ssv:Real value="2"/></ssv:Parameter>'
        "</ssv:Parameters></ssv:ParameterSet>\n"
    )
    (tmp_path / "p.ssm").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<ssm:ParameterMapping version="1.0"'
        ' xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping">\n'
        '  <ssm:MappingEntry source="gian" target="k"/>\n</ssm:ParameterMapping>\n'
    )
    component = remote("A", "grpc://h:1", bindings=[Binding("p.ssv", mapping="p.ssm")])
    with pytest.raises(ValidationError) as info:
        load_ssp(write(tmp_path, [component]))
    assert "p.ssm line 3: parameter mapping source 'gian' names no parameter" in str(info.value)
    assert "gain" in str(info.value)


def test_malformed_xml(tmp_path: Path) -> None:
    path = tmp_path / "bad.ssd"
    path.write_text('<?xml version="1.0"?>\n<a>\n  <b>\n</a>\n')
    with pytest.raises(ScenarioError, match=r"bad\.ssd line 4: malformed XML"):
        load_ssp(path)


def test_doctype_refused(tmp_path: Path) -> None:
    path = tmp_path / "x.ssd"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE a [<!ENTITY e "boom">]>\n<a>&e;</a>\n')
    with pytest.raises(ScenarioError, match="DOCTYPE declaration is not allowed"):
        load_ssp(path)


def test_schema_violation(tmp_path: Path) -> None:
    path = write(tmp_path, [fmu("A", "x.fmu")])
    path.write_text(path.read_text().replace('source="x.fmu"', 'source="x.fmu" bogus="1"'))
    with pytest.raises(ValidationError) as info:
        load_ssp(path)
    assert "scenario.ssd line 8: schema violation" in str(info.value)
    assert "bogus" in str(info.value)


def test_unknown_component_type(tmp_path: Path) -> None:
    path = write(tmp_path, [Component("A", "x", type="application/x-other")])
    with pytest.raises(ValidationError) as info:
        load_ssp(path)
    message = str(info.value)
    assert "component 'A' has type 'application/x-other'" in message
    assert "application/x-fmu-sharedlibrary or application/x-coupler-grpc" in message


def test_missing_fmu(tmp_path: Path) -> None:
    path = write(tmp_path, [fmu("A", "resources/missing.fmu")])
    with pytest.raises(ValidationError, match=r"FMU file 'resources/missing\.fmu' does not exist"):
        load_ssp(path)


def test_a_component_that_cannot_load_is_one_problem_not_one_per_connection(
    tmp_path: Path,
) -> None:
    path = write(
        tmp_path,
        [
            fmu("A", "resources/missing.fmu", real("y", "output"), real("u", "input")),
            grpc("B", real("u", "input"), real("y", "output")),
        ],
        [("A.y", "B.u"), ("B.y", "A.u")],
    )
    with pytest.raises(ValidationError) as info:
        load_ssp(path)
    assert len(info.value.problems) == 1, info.value.problems
    assert str(info.value).startswith(
        "scenario.ssd line 8: component 'A': FMU file 'resources/missing.fmu' does not exist"
    )


def test_unknown_connector(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        [grpc("Integrator", real("y", "output")), grpc("Gain", real("real_in2", "input"))],
        [("Integrator.y", "Gain.real_in")],
    )
    with pytest.raises(ValidationError) as info:
        load_ssp(path)
    assert (
        "scenario.ssd line 20: connection Integrator.y -> Gain.real_in: component 'Gain' "
        "declares no connector 'real_in' (its connectors: real_in2); did you mean 'real_in2'?"
    ) in str(info.value)


def _zip(path: Path, entries: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in entries.items():
            zf.writestr(name, data)
    return path


def test_zip_slip_refused(tmp_path: Path) -> None:
    ssd = (DATA / "scenario.ssd").read_bytes()
    archive = _zip(tmp_path / "evil.ssp", {"SystemStructure.ssd": ssd, "../escape.txt": b"x"})
    with pytest.raises(ScenarioError, match=r"entry '\.\./escape\.txt'.*zip-slip"):
        load_ssp(archive, workdir=tmp_path / "work")
    assert not (tmp_path / "escape.txt").exists()


def test_zip_bomb_refused(tmp_path: Path) -> None:
    archive = _zip(tmp_path / "bomb.ssp", {"SystemStructure.ssd": b"0" * 2_000_000})
    with pytest.raises(ScenarioError, match="zip bomb"):
        load_ssp(archive, workdir=tmp_path / "work", max_archive_bytes=1_000_000)


def test_a_forged_archive_is_a_scenario_error(tmp_path: Path) -> None:
    """A zip whose size headers lie: the project's own error, never zipfile's traceback."""
    archive = _zip(tmp_path / "forged.ssp", {"SystemStructure.ssd": b"<a/>" * 1000})
    data = bytearray(archive.read_bytes())
    local = data.find(b"PK\x03\x04")
    data[local + 18 : local + 22] = (5).to_bytes(4, "little")  # compressed size
    central = data.find(b"PK\x01\x02")
    data[central + 20 : central + 24] = (5).to_bytes(4, "little")
    archive.write_bytes(bytes(data))
    with pytest.raises(ScenarioError, match="not a readable zip archive"):
        load_ssp(archive, workdir=tmp_path / "work")


def test_a_unit_defined_twice_is_refused_naming_both_lines(tmp_path: Path) -> None:
    """Two ``ssc:Unit name="km"`` kept the last one silently (a factor of 1 instead of 1000,
    say); now the SSD is refused naming both lines."""
    folder = tmp_path / "data"
    shutil.copytree(DATA, folder)
    ssd = folder / "scenario.ssd"
    text = ssd.read_text().replace(
        '<ssc:Unit name="K">',
        '<ssc:Unit name="km"><ssc:BaseUnit m="1"/></ssc:Unit>\n<ssc:Unit name="K">',
    )
    ssd.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_ssp(ssd, env=ENV)
    assert "scenario.ssd line 173: unit 'km' is defined twice (first on line 172)" in str(
        info.value
    )


def test_a_parameter_given_twice_is_refused_naming_both_lines(tmp_path: Path) -> None:
    folder = tmp_path / "data"
    shutil.copytree(DATA, folder)
    ssv = folder / "params.ssv"
    text = ssv.read_text().replace(
        '<ssv:Parameter name="enabled">',
        '<ssv:Parameter name="gain_factor"><ssv:Real value="4.0"/></ssv:Parameter>\n'
        '    <ssv:Parameter name="enabled">',
    )
    ssv.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_ssp(folder / "scenario.ssd", env=ENV)
    assert (
        "params.ssv line 8: parameter 'gain_factor' is given twice in this parameter set "
        "(first on line 6)"
    ) in str(info.value)
