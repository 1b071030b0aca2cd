"""``coupler export-fmu``: a co-simulation FMU whose binary drives a running participant.

Any FMI master (FMPy, libcosim/OSP, OMSimulator, Dymola, Simulink, Coupler itself) can then
run a Coupler participant as if it were an FMU. The FMU holds:

- ``modelDescription.xml`` (FMI 2.0 or 3.0) made from the participant's Describe answer: one
  variable per channel (value references 1..N in the description's order) plus the String
  parameter ``coupler_address`` (value reference 0) whose start is the exported address;
- ``binaries/<platform>/CouplerProxy.so``, built once per machine from the C++ sources in
  ``proxy/`` with Debian's gRPC and protobuf (``scripts/install-grpc-dev.sh``) by the FMU
  builder's compiler step and packed by its archive writer (``coupler.fmubuild``), and beside it
  every shared library it needs that is not part of the base system (``$ORIGIN`` run path), so
  the FMU runs where gRPC is not installed;
- ``resources/coupler-proxy.txt``: the address, the call deadline, the description's
  fingerprint and one line per channel, read by the binary at instantiation.

The GUID (FMI 3: instantiation token) is ``{coupler-proxy-<fingerprint>}``; the binary asks the
participant for its description at instantiation and refuses one that changed since the export,
naming what changed. docs/export-fmu.md is the user's guide.
"""

from __future__ import annotations

import ctypes
import hashlib
import inspect
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import structlog
from google.protobuf import descriptor_pb2

from coupler import durations, wire
from coupler.channels import Causality, Channel, Description, ValueType
from coupler.client import RemoteParticipant, parse_address
from coupler.errors import CouplerError
from coupler.fmubuild import compile_library, fmi_headers, write_archive
from coupler.security import ClientSecurity
from coupler.v1 import component_pb2

__all__ = [
    "BASE_SYSTEM",
    "MODEL_IDENTIFIER",
    "ExportError",
    "Exported",
    "NativeLibrary",
    "ToolchainMissing",
    "build_proxy",
    "cache_root",
    "cached_library",
    "export_fmu",
    "fingerprint",
    "toolchain_problem",
    "write_fmu",
]

log = structlog.get_logger("coupler.export")

MODEL_IDENTIFIER = "CouplerProxy"
ADDRESS_VARIABLE = "coupler_address"
SOURCES = Path(__file__).parent / "proxy"
INSTALL_HINT = (
    "install the C++ gRPC tool chain: `bash scripts/install-grpc-dev.sh` (Debian: apt-get "
    "install g++ pkg-config libgrpc++-dev libprotobuf-dev protobuf-compiler-grpc patchelf)"
)

BASE_SYSTEM = re.compile(
    r"^(linux-vdso|ld-linux|libc|libm|libdl|libpthread|librt|libstdc\+\+|libgcc_s)[.-]"
)
"""Libraries every Linux the FMU runs on has (glibc, the C++ runtime); all others are bundled."""
_PLATFORM = {2: "linux64", 3: "x86_64-linux"}


class ExportError(CouplerError):
    """The FMU cannot be exported: no tool chain, a participant that cannot be exported."""


class ToolchainMissing(ExportError):
    """The C++ gRPC tool chain the proxy binary is built with is not installed."""


@dataclass(frozen=True)
class Exported:
    """What ``export_fmu`` wrote."""

    path: Path
    fmi_version: int
    variables: int
    warnings: tuple[str, ...]


# --- the description's fingerprint (proxy_core.cc computes the same) -------------------------


def fingerprint(description: Description) -> str:
    """FNV-1a 64 (hex) of the sorted lines ``name|causality|type|unit`` of every channel, the
    enums as their protobuf numbers: what the binary compares at instantiation."""
    response = wire.description_to_pb(description)
    lines = sorted(f"{c.name}|{c.causality}|{c.type}|{c.unit}" for c in response.channels)
    value = 0xCBF29CE484222325
    for byte in "\n".join(lines).encode():
        value = ((value ^ byte) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return f"{value:016x}"


# --- the proxy binary -------------------------------------------------------------------------


def toolchain_problem(
    tools: Sequence[str] = ("g++", "pkg-config", "protoc", "grpc_cpp_plugin", "patchelf", "ldd"),
    packages: Sequence[str] = ("grpc++", "protobuf"),
) -> str | None:
    """What is missing to build against C++ gRPC (``tools`` on PATH, ``packages`` known to
    pkg-config); None when nothing is."""
    missing = [tool for tool in tools if shutil.which(tool) is None]
    if missing:
        return f"{', '.join(missing)} not found"
    probe = subprocess.run(["pkg-config", "--exists", *packages], capture_output=True, check=False)
    if probe.returncode != 0:
        return f"pkg-config finds no {'/'.join(packages)} (libgrpc++-dev)"
    return None


def cache_root() -> Path:
    """Where built binaries are kept: ``$COUPLER_CACHE``, else ``~/.cache/coupler``."""
    if explicit := os.environ.get("COUPLER_CACHE"):
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "coupler"


def cached_library(
    source: Path,
    *,
    compiler: str,
    flags: Sequence[str],
    libraries: Sequence[str] = (),
    versions: Sequence[Sequence[str]],
    prefix: str,
    what: str,
    log_to_stderr: bool = True,
) -> Path:
    """A shared library of one source file, built on first use under ``cache_root()`` and
    kept under a key of the source, the flags and what the ``versions`` commands print (the
    compiler's and the libraries' versions); FmuBuildError when the compiler fails."""
    key = hashlib.sha256(source.read_bytes())
    key.update("\0".join([compiler, *flags, *libraries]).encode())
    for command in versions:
        key.update(subprocess.run(command, capture_output=True, check=False).stdout)
    library = cache_root() / f"{prefix}-{key.hexdigest()[:16]}.so"
    if library.is_file():
        return library
    if log_to_stderr:
        print(f"building {what} (once per machine)", file=sys.stderr)
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent, prefix=".build-") as scratch:
        built = Path(scratch) / library.name
        compile_library(compiler, [*flags, str(source), *libraries, "-o", str(built)], what=what)
        built.replace(library)  # whole or not at all
    return library


class NativeLibrary:
    """A shared library built by ``build`` and loaded on the first call; the call then gives
    it, or None when it cannot be had — said once: quietly (logged) without its tool chain
    (``ToolchainMissing``), as a warning on stderr when the build fails (a bug)."""

    def __init__(
        self, build: Callable[[], Path], declare: Callable[[ctypes.CDLL], None], what: str
    ) -> None:
        self._build = build
        self._declare = declare
        """Sets the functions' argument and result types."""
        self.what = what
        self._loaded: ctypes.CDLL | None = None
        self.problem: str | None = None

    def __call__(self) -> ctypes.CDLL | None:
        if self._loaded is not None or self.problem is not None:
            return self._loaded
        try:
            lib = ctypes.CDLL(str(self._build()))
        except ToolchainMissing as exc:
            self.problem = str(exc)
            log.info("native_library_unavailable", library=self.what, reason=self.problem)
            return None
        except (CouplerError, OSError) as exc:
            self.problem = str(exc)
            print(f"warning: {self.what} unavailable: {exc}", file=sys.stderr)
            return None
        self._declare(lib)
        self._loaded = lib
        return lib


def _protocol_descriptor() -> bytes:
    """The protocol as compiled into the Python package, for protoc (--descriptor_set_in): the
    binary speaks exactly the protocol of the Coupler that exported it."""
    files = descriptor_pb2.FileDescriptorSet()
    component_pb2.DESCRIPTOR.CopyToProto(files.file.add())
    return files.SerializeToString()


def _run(command: Sequence[str], what: str, cwd: Path | None = None) -> str:
    done = subprocess.run(list(command), capture_output=True, text=True, check=False, cwd=cwd)
    if done.returncode != 0:
        raise ExportError(f"{what} failed ({' '.join(command[:3])} ...):\n{done.stderr[-4000:]}")
    return done.stdout


def _bundled_libraries(binary: Path) -> list[Path]:
    """The shared libraries ``binary`` loads that are not part of the base system."""
    found = []
    for line in _run(["ldd", str(binary)], "ldd").splitlines():
        name, arrow, rest = line.strip().partition(" => ")
        if not arrow or BASE_SYSTEM.match(name):
            continue
        path = rest.split(" (")[0].strip()
        if path == "not found":
            raise ToolchainMissing(
                f"{binary.name} needs {name}, which is not installed; {INSTALL_HINT}"
            )
        found.append(Path(path))
    return found


def build_proxy(*, cache: Path | None = None, log: bool = True) -> Path:
    """A folder holding CouplerProxy.so and every library it needs (RUNPATH ``$ORIGIN``),
    built on first use and cached (``$COUPLER_CACHE``, else ``~/.cache/coupler``) under a key
    of the sources, the protocol and the compiler."""
    if problem := toolchain_problem():
        raise ToolchainMissing(f"cannot build the proxy binary: {problem}; {INSTALL_HINT}")
    sources = sorted(SOURCES.glob("*.cc")) + sorted(SOURCES.glob("*.h"))
    protocol = _protocol_descriptor()
    key = hashlib.sha256()
    for path in sources:
        key.update(path.name.encode() + b"\0" + path.read_bytes())
    key.update(protocol)
    key.update(inspect.getsource(build_proxy).encode())  # how it is built
    key.update(_run(["g++", "--version"], "g++ --version").encode())
    key.update(_run(["pkg-config", "--modversion", "grpc++", "protobuf"], "pkg-config").encode())
    folder = (cache or cache_root()) / f"proxy-{key.hexdigest()[:16]}"
    if (folder / f"{MODEL_IDENTIFIER}.so").is_file():
        return folder
    if log:
        print("building the proxy binary (once per machine, about a minute)", file=sys.stderr)
    folder.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder.parent, prefix=".build-") as scratch:
        work = Path(scratch)
        (work / "gen").mkdir()
        (work / "component.pb").write_bytes(protocol)
        _run(
            [
                "protoc",
                "--descriptor_set_in=component.pb",
                "--cpp_out=gen",
                "--grpc_out=gen",
                f"--plugin=protoc-gen-grpc={shutil.which('grpc_cpp_plugin')}",
                component_pb2.DESCRIPTOR.name,
            ],
            "protoc",
            cwd=work,
        )
        generated = sorted((work / "gen").rglob("*.cc"))
        bin_dir = work / "bin"
        bin_dir.mkdir()
        flags = _run(["pkg-config", "--cflags", "--libs", "grpc++", "protobuf"], "pkg-config")
        common = ["-shared", "-fPIC", "-O2", "-std=c++17", "-Wall", "-Wextra"]
        includes = [f"-I{work / 'gen'}", f"-I{fmi_headers()}", f"-I{SOURCES}"]
        # The protocol (generated code) and the gRPC client in one library with a versioned
        # soname: a process loading several exported FMUs loads it once, as protobuf requires
        # (a .proto registered twice in one process is fatal).
        core = f"libcoupler-proxy-{key.hexdigest()[:12]}.so"
        compile_library(
            "g++",
            [
                *common,
                *includes,
                str(SOURCES / "proxy_core.cc"),
                *map(str, generated),
                *flags.split(),
                f"-Wl,-soname,{core}",
                "-Wl,-rpath,$ORIGIN",
                "-o",
                str(bin_dir / core),
            ],
            what="the proxy's gRPC client",
        )
        out = bin_dir / f"{MODEL_IDENTIFIER}.so"
        compile_library(
            "g++",
            [
                *common,
                "-fvisibility=hidden",
                *includes,
                str(SOURCES / "fmi2_proxy.cc"),
                str(SOURCES / "fmi3_proxy.cc"),
                str(bin_dir / core),
                *flags.split(),
                "-Wl,-rpath,$ORIGIN",
                "-o",
                str(out),
            ],
            what="the proxy binary",
        )
        for library in _bundled_libraries(out):
            copy = bin_dir / library.name
            if copy.exists():
                continue
            shutil.copy2(library, copy)
            copy.chmod(0o755)
            _run(["patchelf", "--set-rpath", "$ORIGIN", str(copy)], "patchelf")
        # the cache entry appears whole or not at all
        try:
            (work / "bin").rename(folder)
        except OSError:
            if not (folder / f"{MODEL_IDENTIFIER}.so").is_file():
                raise
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
    structure = ElementTree.SubElement(root, "ModelStructure")
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
    ElementTree.indent(root)
    return ElementTree.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


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
    lines = [
        "# read by the FMU's binary at instantiation; written by coupler export-fmu",
        f"name\t{_escape(description.name)}",
        f"address\t{address}",
        f"fingerprint\t{fingerprint(description)}",
        f"timeout\t{call_timeout!r}",
        f"step_size\t{description.capabilities.fixed_step_size!r}",
        f"time_vr\t{len(exported) + 1}",
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
    binaries = binaries or build_proxy()
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
    binaries = build_proxy()  # before connecting: the tool chain is the likelier problem
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
