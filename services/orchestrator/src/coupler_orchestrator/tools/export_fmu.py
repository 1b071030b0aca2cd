"""``coupler export-fmu``: a co-simulation FMU whose binary drives a running participant.

Any FMI master (FMPy, libcosim/OSP, OMSimulator, Dymola, Simulink, Coupler itself) can then
run a Coupler participant as if it were an FMU. The FMU holds:

- ``modelDescription.xml`` (FMI 2.0 or 3.0) made from the participant's Describe answer: one
  variable per channel (value references 1..N in the description's order) plus the String
  parameter ``coupler_address`` (value reference 0) whose start is the exported address;
- ``binaries/<platform>/CouplerProxy.so`` and beside it every shared library it needs that is
  not part of the base system (``$ORIGIN`` run path), so the FMU runs where gRPC is not
  installed: the folder ``coupler_native.PROXY``, compiled from ``csrc/proxy/`` when the
  coupler-native wheel was built and copied here as it is (no compiler at export time);
- ``resources/coupler-proxy.txt``: the address, the call deadline, the message limits (from the
  participant's declared maxima, else Coupler's default; not gRPC's 4 MiB default), the
  description's fingerprint and one line per channel, read by the binary at instantiation.

The GUID (FMI 3: instantiation token) is ``{coupler-proxy-<fingerprint>}``; the binary asks the
participant for its description at instantiation and refuses one that changed since the export,
naming what changed. docs/export-fmu.md is the user's guide.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from coupler import durations, wire
from coupler.channels import Causality, Channel, Description, ValueType
from coupler.client import RemoteParticipant, parse_address
from coupler.errors import CouplerError
from coupler.security import ClientSecurity
from coupler.values import MAX_MESSAGE_BYTES
from coupler_orchestrator import native
from coupler_tools.fmubuild import write_archive

__all__ = [
    "MODEL_IDENTIFIER",
    "ExportError",
    "Exported",
    "ProxyMissing",
    "export_fmu",
    "fingerprint",
    "proxy_binaries",
    "write_fmu",
]

MODEL_IDENTIFIER = "CouplerProxy"
ADDRESS_VARIABLE = "coupler_address"
_PLATFORM = {2: "linux64", 3: "x86_64-linux"}


class ExportError(CouplerError):
    """The FMU cannot be exported: no proxy binaries, a participant that cannot be exported."""


class ProxyMissing(ExportError):
    """coupler-native, which holds the proxy FMU's binaries, is not installed."""


@dataclass(frozen=True)
class Exported:
    """What ``export_fmu`` wrote."""

    path: Path
    fmi_version: int
    variables: int
    warnings: tuple[str, ...]


# --- the description's fingerprint (proxy_core.cc computes the same) -------------------------


def fingerprint(description: Description) -> str:
    """FNV-1a 64 (hex) of the sorted lines ``name|causality|type|unit`` of every channel (with
    ``|max_bytes`` appended where it declares one), the enums as their protobuf numbers: what
    the binary compares at instantiation."""
    response = wire.description_to_pb(description)
    lines = sorted(
        f"{c.name}|{c.causality}|{c.type}|{c.unit}" + (f"|{c.max_bytes}" if c.max_bytes else "")
        for c in response.channels
    )
    value = 0xCBF29CE484222325
    for byte in "\n".join(lines).encode():
        value = ((value ^ byte) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return f"{value:016x}"


# --- the proxy binary -------------------------------------------------------------------------


def proxy_binaries() -> Path:
    """The folder of the proxy FMU's binaries (``CouplerProxy.so`` and the libraries it loads),
    as the installed coupler-native package holds it; ProxyMissing without it."""
    folder, why = native.proxy_binaries()
    if folder is None:
        raise ProxyMissing(why)
    return folder


# --- the model description ---------------------------------------------------------------------


def _start_text(channel: Channel) -> str:
    value = channel.start
    if channel.type is ValueType.REAL:
        number = float(value) if isinstance(value, (int, float)) else 0.0
        return repr(number) if math.isfinite(number) else "0.0"
    if channel.type in (ValueType.INTEGER, ValueType.ENUMERATION):
        return str(int(value)) if isinstance(value, (int, float)) else "0"
    if channel.type is ValueType.BOOLEAN:
        return "true" if value is True else "false"
    if channel.type is ValueType.BINARY:
        return bytes(value).hex() if isinstance(value, (bytes, bytearray)) else ""
    return str(value) if value is not None else ""


def _escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace("\t", "\\t").replace("\n", "\\n")


_FMI2_TYPE = {
    ValueType.REAL: "Real",
    ValueType.INTEGER: "Integer",
    ValueType.ENUMERATION: "Integer",
    ValueType.BOOLEAN: "Boolean",
    ValueType.STRING: "String",
}
_FMI3_TYPE = {
    ValueType.REAL: "Float64",
    ValueType.INTEGER: "Int32",
    ValueType.ENUMERATION: "Int32",
    ValueType.BOOLEAN: "Boolean",
    ValueType.STRING: "String",
    ValueType.BINARY: "Binary",
}
# the proxy's names for its value kinds (proxy_core.cc, Kind): FMI 2's, and Binary
_KIND = {**_FMI2_TYPE, ValueType.BINARY: "Binary"}


def _model_description(
    description: Description,
    exported: Sequence[tuple[int, Channel]],
    *,
    address: str,
    fmi_version: int,
    guid: str,
) -> bytes:
    caps = description.capabilities
    root = ElementTree.Element("fmiModelDescription")
    root.set("fmiVersion", "2.0" if fmi_version == 2 else "3.0")
    root.set("modelName", description.name or "participant")
    root.set("guid" if fmi_version == 2 else "instantiationToken", guid)
    root.set(
        "description",
        f"Coupler participant '{description.name}' at {address}, reached over gRPC "
        f"(exported by coupler export-fmu)",
    )
    root.set("generationTool", "coupler export-fmu")
    if fmi_version == 2:
        root.set("variableNamingConvention", "flat")
        root.set("numberOfEventIndicators", "0")
    cosim = ElementTree.SubElement(root, "CoSimulation")
    cosim.set("modelIdentifier", MODEL_IDENTIFIER)
    cosim.set("canHandleVariableCommunicationStepSize", str(caps.variable_step_size).lower())
    if fmi_version == 2:
        cosim.set("canNotUseMemoryManagementFunctions", "true")
    elif caps.fixed_step_size > 0:
        cosim.set("fixedInternalStepSize", repr(caps.fixed_step_size))
    units = sorted({c.unit for _, c in exported if c.unit})
    if units:
        definitions = ElementTree.SubElement(root, "UnitDefinitions")
        for unit in units:
            ElementTree.SubElement(definitions, "Unit", name=unit)
    categories = ElementTree.SubElement(root, "LogCategories")
    for name, text in (
        ("logStatusError", "failed calls to the participant"),
        ("logAll", "connections and the participant ending the run"),
    ):
        ElementTree.SubElement(categories, "Category", name=name, description=text)
    if caps.fixed_step_size > 0:
        ElementTree.SubElement(root, "DefaultExperiment", stepSize=repr(caps.fixed_step_size))
    variables = ElementTree.SubElement(root, "ModelVariables")
    _variable(
        variables,
        fmi_version,
        0,
        Channel(
            name=ADDRESS_VARIABLE,
            causality=Causality.PARAMETER,
            type=ValueType.STRING,
            start=address,
            description="where the participant is: grpc://HOST:PORT or grpcs://HOST:PORT "
            "(environment: COUPLER_PROXY_ADDRESS)",
        ),
    )
    for vr, channel in exported:
        _variable(variables, fmi_version, vr, channel)
    if fmi_version == 3:
        ElementTree.SubElement(
            variables,
            "Float64",
            name="time",
            valueReference=str(len(exported) + 1),
            causality="independent",
            variability="continuous",
            description="simulation time",
        )
    _model_structure(ElementTree.SubElement(root, "ModelStructure"), exported, fmi_version)
    ElementTree.indent(root)
    return ElementTree.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def _model_structure(
    structure: ElementTree.Element, exported: Sequence[tuple[int, Channel]], fmi_version: int
) -> None:
    """The outputs, and the initial unknowns (the same), by index (FMI 2) or reference (3)."""
    outputs = [
        (index, vr)
        for index, (vr, c) in enumerate(exported, start=2)
        if c.causality is Causality.OUTPUT
    ]
    if fmi_version == 2:
        if outputs:
            listed = ElementTree.SubElement(structure, "Outputs")
            for index, _ in outputs:
                ElementTree.SubElement(listed, "Unknown", index=str(index))
            initial = ElementTree.SubElement(structure, "InitialUnknowns")
            for index, _ in outputs:
                ElementTree.SubElement(initial, "Unknown", index=str(index))
    else:
        for _, vr in outputs:
            ElementTree.SubElement(structure, "Output", valueReference=str(vr))
        for _, vr in outputs:
            ElementTree.SubElement(structure, "InitialUnknown", valueReference=str(vr))


def _variable(parent: ElementTree.Element, fmi_version: int, vr: int, channel: Channel) -> None:
    causality = str(channel.causality)
    discrete = channel.type is not ValueType.REAL
    variability = (
        "fixed"
        if channel.causality is Causality.PARAMETER
        else "discrete"
        if discrete
        else "continuous"
    )
    attributes = {"name": channel.name, "valueReference": str(vr), "causality": causality}
    attributes["variability"] = variability
    if channel.description:
        attributes["description"] = channel.description
    start = channel.causality is not Causality.OUTPUT
    if fmi_version == 2:
        variable = ElementTree.SubElement(parent, "ScalarVariable", attributes)
        typed = ElementTree.SubElement(variable, _FMI2_TYPE[channel.type])
        if channel.unit and channel.type is ValueType.REAL:
            typed.set("unit", channel.unit)
        if start:
            typed.set("start", _start_text(channel))
        return
    if channel.unit and channel.type is ValueType.REAL:
        attributes["unit"] = channel.unit
    if channel.type is ValueType.BINARY and channel.max_bytes > 0:
        attributes["maxSize"] = str(channel.max_bytes)
    variable = ElementTree.SubElement(parent, _FMI3_TYPE[channel.type], attributes)
    if start:
        if channel.type in (ValueType.STRING, ValueType.BINARY):
            ElementTree.SubElement(variable, "Start", value=_start_text(channel))
        else:
            variable.set("start", _start_text(channel))


def _resources(
    description: Description,
    exported: Sequence[tuple[int, Channel]],
    *,
    address: str,
    call_timeout: float,
) -> str:
    served = wire.served_limits(description, MAX_MESSAGE_BYTES)  # the proxy receives what
    receive, send = wire.MessageLimits(received=served.sent, sent=served.received).transport
    lines = [
        "# read by the FMU's binary at instantiation; written by coupler export-fmu",
        f"name\t{_escape(description.name)}",
        f"address\t{address}",
        f"fingerprint\t{fingerprint(description)}",
        f"timeout\t{call_timeout!r}",
        f"step_size\t{description.capabilities.fixed_step_size!r}",
        f"time_vr\t{len(exported) + 1}",
        f"max_receive\t{receive}",
        f"max_send\t{send}",
    ]
    shown = {c.name for _, c in exported}
    codes = {c.name: c for c in wire.description_to_pb(description).channels}
    by_name = {c.name: vr for vr, c in exported}
    for channel in description.channels:
        pb_channel = codes[channel.name]
        kind = _KIND[channel.type] if channel.name in shown else "-"
        lines.append(
            "\t".join(
                (
                    "channel",
                    str(by_name.get(channel.name, 0)),
                    _escape(channel.name),
                    str(pb_channel.type),
                    str(pb_channel.causality),
                    _escape(channel.unit),
                    kind,
                    _escape(_start_text(channel)),
                    str(channel.max_bytes),
                    # whether the participant declared a start: a parameter without one is
                    # sent only when the FMI master sets it (its FMU start is no value of its)
                    "1" if channel.start is not None else "0",
                )
            )
        )
    return "\n".join(lines) + "\n"


def write_fmu(
    description: Description,
    *,
    address: str,
    out: Path,
    fmi_version: int = 2,
    call_timeout: float = 30.0,
    binaries: Path | None = None,
) -> Exported:
    """Write the FMU for ``description`` (the participant at ``address``) to ``out``."""
    if fmi_version not in _PLATFORM:
        raise ExportError(f"--fmi {fmi_version}: write 2 or 3")
    if why := durations.problem(call_timeout, durations.MAX_TIMEOUT):
        raise ExportError(f"--call-timeout {why}")
    warnings = []
    exported: list[tuple[int, Channel]] = []
    for channel in description.channels:
        if channel.name == ADDRESS_VARIABLE:
            raise ExportError(
                f"participant '{description.name}' has a channel named '{ADDRESS_VARIABLE}', "
                f"the name the FMU's address parameter takes; rename the channel"
            )
        if any(ch in channel.name for ch in "\t\n\\"):
            raise ExportError(
                f"channel {channel.name!r}: tabs, newlines and backslashes in a "
                f"channel name cannot be exported"
            )
        if channel.type is ValueType.BINARY and fmi_version == 2:
            kept = (
                "the participant's output is not readable"
                if channel.causality is Causality.OUTPUT
                else "the participant keeps its start value"
            )
            warnings.append(
                f"binary channel '{channel.name}' is left out: FMI 2.0 has no binary type "
                f"(export with --fmi 3 for it); {kept}"
            )
            continue
        exported.append((len(exported) + 1, channel))
    guid = "{coupler-proxy-" + fingerprint(description) + "}"
    out = Path(out)
    if out.suffix != ".fmu":
        raise ExportError(f"--out {out}: the file name must end in .fmu")
    binaries = binaries or proxy_binaries()
    platform = _PLATFORM[fmi_version]
    members: dict[str, Path | bytes] = {
        "modelDescription.xml": _model_description(
            description, exported, address=address, fmi_version=fmi_version, guid=guid
        ),
        "resources/coupler-proxy.txt": _resources(
            description, exported, address=address, call_timeout=call_timeout
        ).encode(),
    }
    for library in sorted(binaries.iterdir()):
        members[f"binaries/{platform}/{library.name}"] = library
    write_archive(out, members)
    return Exported(
        path=out, fmi_version=fmi_version, variables=len(exported) + 1, warnings=tuple(warnings)
    )


async def export_fmu(
    address: str,
    out: Path,
    *,
    fmi_version: int = 2,
    call_timeout: float = 30.0,
    connect_timeout: float = 10.0,
    security: ClientSecurity | None = None,
) -> Exported:
    """Ask the participant at ``address`` for its description and write its FMU to ``out``."""
    if fmi_version not in _PLATFORM:
        raise ExportError(f"--fmi {fmi_version}: write 2 or 3")
    parse_address(address)  # a clear error for anything that is not an address
    if Path(out).suffix != ".fmu":
        raise ExportError(f"--out {out}: the file name must end in .fmu")
    if "://" not in address:
        address = f"grpc://{address}"  # what the binary reads: always with its scheme
    binaries = proxy_binaries()  # before connecting: a missing package is the likelier problem
    participant = RemoteParticipant(
        address, connect_timeout=connect_timeout, call_timeout=call_timeout, security=security
    )
    try:
        description = await participant.describe()
    finally:
        await participant.close()
    return write_fmu(
        description,
        address=address,
        out=out,
        fmi_version=fmi_version,
        call_timeout=call_timeout,
        binaries=binaries,
    )
