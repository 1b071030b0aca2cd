"""``coupler export-fmu``: the exported FMU driven by FMPy, by Coupler itself and by libcosim.

The proxy binary is the one the installed coupler-native wheel ships (built by `make setup`)
and really talks to a real gRPC participant on loopback. FMUs are driven by FMPy
in a process of their own (fmpy_driver.py): a failing FMU cannot take the test session along.
"""

from __future__ import annotations

import asyncio
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import time
import zipfile
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from coupler.channels import Capabilities, Description, Value
from coupler.examples.gain import GainParticipant
from coupler.participant import EndRun, Values
from coupler.security import ServerSecurity
from coupler.server import ParticipantServer
from coupler.testing import Component, Connector, SystemStructure, free_port
from coupler.testing.ssd import FMU
from coupler_dev.devcerts import write_pki
from coupler_orchestrator.tools import export_fmu as export
from coupler_orchestrator.tools.export_fmu import fingerprint, write_fmu

from ..support import Coupler, serving

DRIVER = Path(__file__).parent / "fmpy_driver.py"
OUTPUTS = ["y", "x", "count", "inverted"]  # FMPy records no String or Binary values
STARTS = {"u": 1.1, "gain": 3.0, "offset": 2, "n": 4, "flag": True, "label": "hi"}
Y = 3.0 * 1.1  # the gain participant's y for STARTS
# FMPy steps from n*h to (n+1)*h with h = difference of the two: with h = 0.1 its steps differ
# from 0.1 in the last bits (Coupler's are exactly 0.1), with h = 1/8 they are the same.
STEP = 0.125

GAIN_CONNECTORS = [
    Connector("gain", "parameter", "Real"),
    Connector("offset", "parameter", "Integer"),
    Connector("u", "input", "Real"),
    Connector("n", "input", "Integer"),
    Connector("flag", "input", "Boolean"),
    Connector("label", "input", "String"),
    Connector("y", "output", "Real"),
    Connector("x", "output", "Real"),
    Connector("count", "output", "Integer"),
    Connector("inverted", "output", "Boolean"),
    Connector("echo", "output", "String"),
]


def gain_ssd(path: Path, kind: str, source: str | Path) -> Path:
    """The gain participant alone, as component ``kind`` (an FMU or gRPC) at ``source``."""
    gain = Component("Gain", str(source), type=kind, connectors=GAIN_CONNECTORS)
    return SystemStructure("G", [gain], start_time=0.0, stop_time=1.0).write(path)


BASE_SYSTEM = re.compile(
    r"^(linux-vdso|ld-linux|libc|libm|libdl|libpthread|librt|libstdc\+\+|libgcc_s)[.-]"
)
"""Libraries every Linux the FMU runs on has (glibc, the C++ runtime); all others are bundled."""


def installed_proxy() -> Path:
    """The proxy binary and its libraries, as coupler-native holds them (skipped only when
    coupler-native is not installed; an installed one without them fails)."""
    try:
        return export.proxy_binaries()
    except export.ProxyMissing as exc:
        if importlib.util.find_spec("coupler_native") is None:
            pytest.skip(str(exc))
        raise


@pytest.fixture(scope="session")
def proxy_binaries() -> Path:
    return installed_proxy()


@pytest.fixture(scope="session")
def gain_description() -> Description:
    return asyncio.run(GainParticipant().describe())


@pytest.fixture(scope="session")
def exported(
    proxy_binaries: Path, gain_description: Description, tmp_path_factory: pytest.TempPathFactory
) -> dict[int, Path]:
    """The gain participant exported as FMI 2 and FMI 3 FMUs, its address left to
    COUPLER_PROXY_ADDRESS (the baked-in one is a port nobody listens on)."""
    out = tmp_path_factory.mktemp("exported")
    nobody = f"grpc://127.0.0.1:{free_port()}"
    return {
        fmi: write_fmu(
            gain_description,
            address=nobody,
            out=out / f"Gain{fmi}.fmu",
            fmi_version=fmi,
            call_timeout=5.0,
            binaries=proxy_binaries,
        ).path
        for fmi in (2, 3)
    }


@pytest.fixture
def gain() -> Iterator[ParticipantServer]:
    with serving(GainParticipant()) as server:
        yield server


class CountingGain(GainParticipant):
    """The gain participant, counting the steps it was asked for."""

    steps = 0

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.steps += 1
        return await super().do_step(time, step, inputs)


def address(server: ParticipantServer) -> str:
    return f"grpc://127.0.0.1:{server.port}"


def drive(
    tmp_path: Path,
    runs: list[dict[str, Any]],
    *,
    env: dict[str, str] | None = None,
    timeout: float = 120.0,
) -> tuple[dict[str, Any], str]:
    """Run the FMUs under FMPy in a child process: (its JSON answer, everything it printed).
    FMPy unpacks into the test's folder: it leaves its unpacked FMU behind when a run fails."""
    spec = tmp_path / f"spec-{time.monotonic_ns()}.json"
    spec.write_text(json.dumps({"runs": runs}))
    scratch = tmp_path / "fmpy-temp"
    scratch.mkdir(exist_ok=True)
    done = subprocess.run(
        [sys.executable, str(DRIVER), str(spec)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "TMPDIR": str(scratch), **(env or {})},
        check=False,
    )
    printed = done.stdout + done.stderr
    last = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else "{}"
    try:
        answer = json.loads(last)
    except json.JSONDecodeError:
        answer = {"error": f"no answer (exit {done.returncode})"}
    return answer, printed


def gain_run(fmu: Path, stop: float = 1.0, step: float = STEP) -> dict[str, Any]:
    return {"fmu": str(fmu), "stop": stop, "step": step, "start_values": STARTS, "outputs": OUTPUTS}


def direct_run(coupler: Coupler, tmp_path: Path, source: str, kind: str) -> list[dict[str, str]]:
    """`coupler run` of the gain participant alone, with STARTS, steps of STEP to 1.0."""
    short = kind.rsplit("-", 1)[-1]
    ssd = gain_ssd(tmp_path / f"{short}.ssd", kind, source)
    out = tmp_path / f"results-{short}"
    params = [
        f"--param=Gain.{k}={str(v).lower() if isinstance(v, bool) else v}"
        for k, v in STARTS.items()
    ]
    outcome = coupler("run", ssd, "--step", str(STEP), "--out", out, *params)
    assert outcome.code == 0, outcome.err
    return coupler.results(out)


@pytest.mark.parametrize("fmi", [2, 3])
def test_exported_fmu_under_fmpy_gives_coupler_runs_numbers(
    fmi: int,
    exported: dict[int, Path],
    gain: ParticipantServer,
    coupler: Coupler,
    tmp_path: Path,
) -> None:
    answer, printed = drive(
        tmp_path, [gain_run(exported[fmi])], env={"COUPLER_PROXY_ADDRESS": address(gain)}
    )
    assert "results" in answer, printed
    fmpy = answer["results"][0]
    rows = direct_run(coupler, tmp_path, address(gain), "application/x-coupler-grpc")
    assert [float(r["time"]) for r in rows] == fmpy["time"]
    # bit for bit: the same floats, not merely close ones
    assert [float(r["Gain.y"]) for r in rows] == fmpy["y"]
    assert [float(r["Gain.x"]) for r in rows] == fmpy["x"]
    assert [int(r["Gain.count"]) for r in rows] == fmpy["count"] == [6] * 9
    assert [r["Gain.inverted"] for r in rows] == ["0"] * 9
    assert [r["Gain.echo"] for r in rows] == ["hi"] * 9  # FMPy records no strings
    assert fmpy["inverted"] == [False] * 9


def test_exported_fmus_validate_clean(exported: dict[int, Path]) -> None:
    from fmpy.validation import validate_fmu

    for fmi, fmu in exported.items():
        assert validate_fmu(str(fmu)) == [], fmi
        with zipfile.ZipFile(fmu) as archive:
            md = archive.read("modelDescription.xml").decode()
            platform = "linux64" if fmi == 2 else "x86_64-linux"
            names = archive.namelist()
        assert f"binaries/{platform}/CouplerProxy.so" in names
        assert re.search(r'(guid|instantiationToken)="\{coupler-proxy-[0-9a-f]{16}\}"', md)
        assert 'name="coupler_address"' in md
        assert ('name="blob"' in md) == (fmi == 3)  # FMI 2 has no binary type


def test_two_exported_fmus_in_one_process_and_a_second_run(
    exported: dict[int, Path], gain: ParticipantServer, tmp_path: Path
) -> None:
    """FMI 2 and FMI 3 proxies in one process (one protocol library loaded), each run twice:
    the participant is free again after each run (Terminate sent at fmi*Terminate)."""
    runs = [gain_run(exported[2]), gain_run(exported[3]), gain_run(exported[2])]
    answer, printed = drive(tmp_path, runs, env={"COUPLER_PROXY_ADDRESS": address(gain)})
    assert "results" in answer, printed
    assert answer["results"][0]["x"] == answer["results"][1]["x"] == answer["results"][2]["x"]


def test_exported_fmu_inside_an_ssd_runs_like_the_participant(
    exported: dict[int, Path],
    gain: ParticipantServer,
    coupler: Coupler,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Coupler runs the proxy FMU (FMI 3, with the binary channel) in-process: an FMU that
    itself calls a gRPC participant. results.csv is byte-identical to Coupler driving the
    participant directly."""
    monkeypatch.setenv("COUPLER_PROXY_ADDRESS", address(gain))
    direct = direct_run(coupler, tmp_path, address(gain), "application/x-coupler-grpc")
    proxied = direct_run(coupler, tmp_path, str(exported[3]), "application/x-fmu-sharedlibrary")
    assert proxied == direct
    assert (tmp_path / "results-grpc" / "results.csv").read_bytes() == (
        tmp_path / "results-sharedlibrary" / "results.csv"
    ).read_bytes()


def test_exported_from_the_command_line_with_the_address_baked_in(
    gain: ParticipantServer, coupler: Coupler, tmp_path: Path, proxy_binaries: Path
) -> None:
    out = tmp_path / "Gain.fmu"
    # a bare HOST:PORT is baked in as grpc://HOST:PORT
    outcome = coupler("export-fmu", f"127.0.0.1:{gain.port}", "--out", out, "--fmi", "2")
    assert outcome.code == 0, outcome.err
    assert f"exported {out}: FMI 2.0 co-simulation, 13 variables" in outcome.out
    assert "binary channel 'blob' is left out" in outcome.err
    answer, printed = drive(tmp_path, [gain_run(out)])
    assert "results" in answer, printed
    assert answer["results"][0]["y"][-1] == Y


def test_export_needs_no_compiler_and_copies_the_installed_binaries(
    gain: ParticipantServer, tmp_path: Path, proxy_binaries: Path
) -> None:
    """`coupler export-fmu` as a user runs it, with nothing on PATH but the environment's own
    commands (no g++, pkg-config or protoc): the FMU's binaries are coupler-native's, byte
    for byte."""
    scripts = Path(sys.executable).parent
    out = tmp_path / "Gain.fmu"
    done = subprocess.run(
        [scripts / "coupler", "export-fmu", address(gain), "--out", out, "--fmi", "3"],
        capture_output=True,
        text=True,
        env={"PATH": str(scripts), "HOME": str(tmp_path)},
        check=False,
    )
    assert done.returncode == 0, done.stderr
    with zipfile.ZipFile(out) as fmu:
        copied = {
            Path(name).name: fmu.read(name)
            for name in fmu.namelist()
            if name.startswith("binaries/x86_64-linux/")
        }
    assert copied == {path.name: path.read_bytes() for path in proxy_binaries.iterdir()}
    assert not (tmp_path / ".cache").exists()  # nothing built or cached on the way


def test_a_changed_participant_is_refused_at_instantiation(
    gain_description: Description,
    gain: ParticipantServer,
    proxy_binaries: Path,
    tmp_path: Path,
) -> None:
    """Exported when `y` was in km/h and `x` did not exist: the participant answers
    otherwise, and the FMU says what changed."""
    then = replace(
        gain_description,
        channels=tuple(
            replace(c, unit="km/h") if c.name == "y" else c
            for c in gain_description.channels
            if c.name != "x"
        ),
    )
    printed = refused_at_instantiation(then, gain_description, gain, proxy_binaries, tmp_path)
    who = f"participant 'Gain' at {address(gain)}"
    assert f"{who} is not the one this FMU was exported from" in printed
    assert "'y' changed unit 'km/h' -> 'm/s'" in printed
    assert "'x' is new" in printed
    assert "export the FMU again" in printed


def refused_at_instantiation(
    then: Description,
    now: Description,
    gain: ParticipantServer,
    proxy_binaries: Path,
    tmp_path: Path,
) -> str:
    """An FMU exported from ``then`` (a description of the gain participant that is not its
    description ``now``) driven against it: refused at instantiation; what the driver printed."""
    assert fingerprint(then) != fingerprint(now)
    fmu = write_fmu(
        then, address=address(gain), out=tmp_path / "Old.fmu", binaries=proxy_binaries
    ).path
    answer, printed = drive(tmp_path, [gain_run(fmu)])
    assert "instantiate" in answer.get("error", ""), printed
    return printed


def test_a_changed_maximum_is_refused_at_instantiation(
    gain_description: Description,
    gain: ParticipantServer,
    proxy_binaries: Path,
    tmp_path: Path,
) -> None:
    """Exported when `blob` declared its largest value (1000 bytes): the participant now
    declares none, and the FMU says so; the fingerprint of a description that declares
    nothing is what it was before declarations existed."""
    then = replace(
        gain_description,
        channels=tuple(
            replace(c, max_bytes=1000) if c.name == "blob" else c for c in gain_description.channels
        ),
    )
    printed = refused_at_instantiation(then, gain_description, gain, proxy_binaries, tmp_path)
    assert "is not the one this FMU was exported from" in printed
    assert "'blob' changed its largest value 1000 -> 0 bytes (max_bytes)" in printed


def test_the_fmus_limits_come_from_the_declarations(
    gain_description: Description, proxy_binaries: Path, tmp_path: Path
) -> None:
    """The proxy receives what the outputs declare together and sends what the inputs and
    parameters accept (plus framing); an undeclared side keeps Coupler's default. FMI 3's
    Binary variables carry the maximum as ``maxSize``."""
    declared = replace(
        gain_description,
        channels=tuple(
            replace(c, max_bytes={"blob_out": 2_000_000, "echo": 100}.get(c.name, 0))
            for c in gain_description.channels
        ),
    )
    fmu = write_fmu(
        declared,
        address="grpc://127.0.0.1:1",
        out=tmp_path / "Declared.fmu",
        fmi_version=3,
        binaries=proxy_binaries,
    ).path
    with zipfile.ZipFile(fmu) as archive:
        resources = archive.read("resources/coupler-proxy.txt").decode()
        model = archive.read("modelDescription.xml").decode()
    framing = 8 * 2**20
    assert f"\nmax_receive\t{2_000_100 + framing}\n" in resources
    assert f"\nmax_send\t{64 * 2**20 + framing}\n" in resources  # label and blob: undeclared
    assert re.search(r'<Binary name="blob_out"[^>]* maxSize="2000000"', model), model
    assert not re.search(r'<Binary name="blob"[^>]* maxSize', model)


@pytest.mark.slow
def test_a_participant_that_is_down_is_an_error_naming_its_address(
    exported: dict[int, Path], tmp_path: Path
) -> None:
    down = f"grpc://127.0.0.1:{free_port()}"
    started = time.monotonic()
    answer, printed = drive(
        tmp_path, [gain_run(exported[2])], env={"COUPLER_PROXY_ADDRESS": down}, timeout=60
    )
    took = time.monotonic() - started
    assert "instantiate" in answer.get("error", ""), printed
    assert f"participant 'Gain' at {down}: Describe failed [" in printed
    assert took < 30  # the exported call deadline (5 s), not a hang


def test_the_address_parameter_moves_the_fmu_to_another_participant(
    exported: dict[int, Path], gain: ParticipantServer, tmp_path: Path
) -> None:
    other_participant = CountingGain()
    with serving(other_participant) as other:
        run = gain_run(exported[3])
        run["start_values"] = {**STARTS, "coupler_address": address(other)}
        answer, printed = drive(tmp_path, [run], env={"COUPLER_PROXY_ADDRESS": address(gain)})
    assert "results" in answer, printed
    assert other_participant.steps == 8
    bad = gain_run(exported[2])
    bad["start_values"] = {**STARTS, "coupler_address": "http://example"}
    answer, printed = drive(tmp_path, [bad], env={"COUPLER_PROXY_ADDRESS": address(gain)})
    assert "coupler_address 'http://example' is not grpc://HOST:PORT" in printed, printed


def test_the_fmu_carries_every_library_it_needs(proxy_binaries: Path) -> None:
    """Everything the binary loads that is not glibc or the C++ runtime resolves inside the
    FMU's own folder, with an empty environment (no LD_LIBRARY_PATH)."""
    done = subprocess.run(
        ["ldd", str(proxy_binaries / "CouplerProxy.so")],
        capture_output=True,
        text=True,
        env={},
        check=True,
    )
    loaded = [line.split() for line in done.stdout.splitlines() if "=>" in line]
    assert not [line for line in loaded if "not" in line], done.stdout
    outside = [
        words[0]
        for words in loaded
        if not BASE_SYSTEM.match(words[0]) and not words[2].startswith(str(proxy_binaries))
    ]
    assert outside == [], done.stdout
    assert any(words[0].startswith("libgrpc++") for words in loaded)


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("unshare") is None, reason="needs root")
def test_the_fmu_runs_where_grpc_is_not_installed(
    exported: dict[int, Path], gain: ParticipantServer, tmp_path: Path
) -> None:
    """The system's gRPC and protobuf libraries hidden (bind-mounted over with /dev/null in a
    mount namespace of the FMPy process): the FMU still runs, on its own libraries."""
    system = [
        p
        for p in Path("/usr/lib/x86_64-linux-gnu").glob("lib*.so*")
        if re.match(r"lib(grpc|gpr|protobuf|upb|absl|cares|re2|address_sorting)", p.name)
        and not p.is_symlink()
    ]
    assert system, "the system has no gRPC libraries to hide"
    spec = tmp_path / "hidden.json"
    spec.write_text(json.dumps({"runs": [gain_run(exported[2])]}))
    mounts = " && ".join(f"mount --bind /dev/null {p}" for p in system)
    done = subprocess.run(
        [
            "unshare",
            "--mount",
            "--propagation",
            "private",
            "sh",
            "-c",
            f"{mounts} && exec {sys.executable} {DRIVER} {spec}",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        env={**os.environ, "COUPLER_PROXY_ADDRESS": address(gain)},
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1])["results"][0]["y"][-1] == Y


def test_export_errors_are_sentences(
    coupler: Coupler, tmp_path: Path, proxy_binaries: Path, gain: ParticipantServer
) -> None:
    down = f"grpc://127.0.0.1:{free_port()}"
    outcome = coupler("export-fmu", down, "--out", tmp_path / "x.fmu", "--timeout", "1")
    assert outcome.code == 1
    assert down in outcome.err and "Traceback" not in outcome.err
    outcome = coupler("export-fmu", address(gain), "--out", tmp_path / "x.zip")
    assert outcome.code == 1
    assert "must end in .fmu" in outcome.err
    assert not (tmp_path / "x.fmu").exists()


def test_a_deadline_without_a_ceiling_is_refused_by_the_fmu(
    gain_description: Description,
    gain: ParticipantServer,
    proxy_binaries: Path,
    tmp_path: Path,
) -> None:
    """The longest deadline (24 h) runs: the binary caps its lease (four deadlines) at the
    participants' ceiling. A hand-edited coupler-proxy.txt whose timeout has no ceiling (its
    lease would lock the participant for good) is refused at instantiation, naming the value
    and the bound."""
    fmu = write_fmu(
        gain_description,
        address=address(gain),
        out=tmp_path / "Gain.fmu",
        call_timeout=86_400.0,
        binaries=proxy_binaries,
    ).path
    answer, printed = drive(tmp_path, [gain_run(fmu)])
    assert "results" in answer, printed
    edited = tmp_path / "Edited.fmu"
    with zipfile.ZipFile(fmu) as original, zipfile.ZipFile(edited, "w") as copy:
        for item in original.infolist():
            data = original.read(item)
            if item.filename == "resources/coupler-proxy.txt":
                data = data.replace(b"timeout\t86400.0", b"timeout\t1e300")
            copy.writestr(item, data)
    answer, printed = drive(tmp_path, [gain_run(edited)])
    assert "instantiate" in answer.get("error", ""), printed
    assert "coupler-proxy.txt: timeout 1e+300 must be a number of seconds > 0 and <= 86400" in (
        printed
    )


def test_values_up_to_couplers_message_limit_pass_the_fmu(
    exported: dict[int, Path], gain: ParticipantServer, tmp_path: Path
) -> None:
    """A 6 MB String, over gRPC's 4 MiB default, goes into the participant (the label input)
    and back out of it (its echo output) through the FMU: the proxy's channel has Coupler's
    message limit, which the export writes into coupler-proxy.txt. Without that line the same
    FMU refuses the answer (gRPC's default), so the line is what lets the value through."""
    label = "frame " * 1_000_000
    run = gain_run(exported[2]) | {"start_values": {**STARTS, "label": label}}
    env = {"COUPLER_PROXY_ADDRESS": address(gain)}
    answer, printed = drive(tmp_path, [run], env=env)
    assert "results" in answer, printed
    assert answer["results"][0]["y"][-1] == Y
    without = tmp_path / "Without.fmu"
    with zipfile.ZipFile(exported[2]) as original, zipfile.ZipFile(without, "w") as copy:
        for item in original.infolist():
            data = original.read(item)
            if item.filename == "resources/coupler-proxy.txt":
                assert b"\nmax_receive\t" in data and b"\nmax_send\t" in data
                data = re.sub(rb"\nmax_(receive|send)\t[0-9]+", b"", data)
            copy.writestr(item, data)
    answer, printed = drive(tmp_path, [run | {"fmu": str(without)}], env=env)
    assert "error" in answer, printed
    assert "RESOURCE_EXHAUSTED" in printed


def test_libcosim_runs_the_exported_fmu(
    exported: dict[int, Path], gain: ParticipantServer, tmp_path: Path
) -> None:
    """libcosim (OSP's C++ master) steps the exported FMU: the participant's numbers."""
    pytest.importorskip("libcosimpy")
    script = f"""
import json
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave
log_output_level(CosimLogLevel.ERROR)
ex = CosimExecution.from_step_size(step_size=125_000_000)
i = ex.add_local_slave(CosimLocalSlave(fmu_path={str(exported[2])!r}, instance_name="Gain"))
m = CosimManipulator.create_override()
ex.add_manipulator(m)
o = CosimObserver.create_last_value()
ex.add_observer(o)
m.slave_real_values(i, [4], [1.1])
ex.step(8)
print(json.dumps(o.last_real_values(i, [8, 9])))
"""
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "COUPLER_PROXY_ADDRESS": address(gain)},
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    y, x = json.loads(done.stdout.strip().splitlines()[-1])
    expected_x = 0.0
    for _ in range(8):  # the participant's explicit Euler, h = 1/8
        expected_x += 1.1 * STEP
    assert (y, x) == (2.0 * 1.1, expected_x)  # gain's start value 2.0


def test_mutual_tls_and_a_token_through_the_orchestrators_variables(
    tmp_path: Path, coupler: Coupler, proxy_binaries: Path
) -> None:
    """A grpcs:// participant requiring a client certificate and a token: exported with the
    command line's TLS options, run with COUPLER_TLS_* and COUPLER_TOKEN_FILE; without the
    token the FMU's error names the address and UNAUTHENTICATED."""
    pki = write_pki(tmp_path / "pki")
    security = ServerSecurity(
        cert=pki.server_cert, key=pki.server_key, client_ca=pki.ca, token_file=pki.token
    )
    with serving(GainParticipant(), security) as server:
        secure = f"grpcs://127.0.0.1:{server.port}"
        tls = ["--tls-ca", pki.ca, "--tls-cert", pki.client_cert, "--tls-key", pki.client_key]
        out = tmp_path / "Secure.fmu"
        outcome = coupler("export-fmu", secure, "--out", out, *tls, "--token-file", pki.token)
        assert outcome.code == 0, outcome.err
        env = {
            "COUPLER_TLS_CA": str(pki.ca),
            "COUPLER_TLS_CERT": str(pki.client_cert),
            "COUPLER_TLS_KEY": str(pki.client_key),
        }
        answer, printed = drive(tmp_path, [gain_run(out)], env=env)
        assert "UNAUTHENTICATED" in printed and secure in printed, printed
        env["COUPLER_TOKEN_FILE"] = str(pki.token)
        answer, printed = drive(tmp_path, [gain_run(out)], env=env)
    assert "results" in answer, printed
    assert answer["results"][0]["y"][-1] == Y


class HangingGain(GainParticipant):
    """The gain participant, never answering the step that starts at t >= 0.25 s."""

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        if time >= 0.25:
            await asyncio.sleep(3600)
        return await super().do_step(time, step, inputs)


class UnaryGain(GainParticipant):
    """The gain participant, declaring that it does not stream its steps."""

    async def describe(self) -> Description:
        described = await super().describe()
        return replace(described, capabilities=Capabilities(streaming=False))


@pytest.mark.slow
def test_a_step_that_outlives_the_deadline_is_an_error_not_a_hang(
    exported: dict[int, Path], tmp_path: Path
) -> None:
    """Steps travel over one StepStream: its deadline per step is kept by the proxy's watchdog
    (the exported call timeout, 5 s here)."""
    with serving(HangingGain()) as hanging:
        started = time.monotonic()
        answer, printed = drive(
            tmp_path, [gain_run(exported[2])], env={"COUPLER_PROXY_ADDRESS": address(hanging)}
        )
        took = time.monotonic() - started
    assert "fmi2DoStep failed" in answer.get("error", ""), printed
    who = f"participant 'Gain' at {address(hanging)}"
    assert f"{who}: StepStream failed [DEADLINE_EXCEEDED]" in printed
    assert took < 30


def test_a_participant_that_does_not_stream_gets_dostep_calls(
    exported: dict[int, Path], coupler: Coupler, tmp_path: Path
) -> None:
    with serving(UnaryGain()) as unary:
        answer, printed = drive(
            tmp_path, [gain_run(exported[3])], env={"COUPLER_PROXY_ADDRESS": address(unary)}
        )
        rows = direct_run(coupler, tmp_path, address(unary), "application/x-coupler-grpc")
    assert "results" in answer, printed
    assert answer["results"][0]["x"] == [float(r["Gain.x"]) for r in rows]


def test_a_participant_on_a_unix_socket(
    exported: dict[int, Path], tmp_path: Path, coupler: Coupler
) -> None:
    """Same host, no TCP: ``unix:///PATH`` as the address."""
    with serving(GainParticipant(), unix_socket=tmp_path / "gain.sock") as local:
        assert local.address.startswith("unix:///")
        answer, printed = drive(
            tmp_path, [gain_run(exported[2])], env={"COUPLER_PROXY_ADDRESS": local.address}
        )
    assert "results" in answer, printed
    assert answer["results"][0]["y"][-1] == Y


class EndingGain(GainParticipant):
    """The gain participant, ending the run after the step that reaches t = 0.5 s."""

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        outputs = await super().do_step(time, step, inputs)
        if time + step >= 0.5:
            raise EndRun("the tank is empty", outputs)
        return outputs


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_participant_ending_the_run_ends_it_through_the_fmu(
    fmi: int,
    exported: dict[int, Path],
    coupler: Coupler,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """DoStepResponse.terminate becomes FMI 3's terminateSimulation or FMI 2's Discard with
    fmi2Terminated: Coupler, running the FMU, ends the run `terminated` at 0.5 s."""
    with serving(EndingGain()) as ending:
        monkeypatch.setenv("COUPLER_PROXY_ADDRESS", address(ending))
        ssd = gain_ssd(tmp_path / "ending.ssd", FMU, exported[fmi])
        outcome = coupler("run", ssd, "--step", str(STEP), "--out", tmp_path / "out")
    assert outcome.code == 0, outcome.err
    summary = coupler.summary(tmp_path / "out")
    assert summary["status"] == "terminated", summary
    assert float(coupler.results(tmp_path / "out")[-1]["time"]) == 0.5


@pytest.mark.usefixtures("without_coupler_native")
def test_export_without_coupler_native_says_what_to_install(
    gain: ParticipantServer, coupler: Coupler, tmp_path: Path
) -> None:
    outcome = coupler("export-fmu", address(gain), "--out", tmp_path / "Gain.fmu")
    assert outcome.code == 1
    assert "coupler-native package, which is not installed" in outcome.err, outcome.err
    assert "Traceback" not in outcome.err
    assert not (tmp_path / "Gain.fmu").exists()
