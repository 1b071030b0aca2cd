"""Participants on this host over unix sockets, as users start them (docs/orchestrator.md,
"Addresses"):

    python -m coupler.examples gain --socket DIR/gain.sock      (every participant kind)
    coupler run ramp-gain.ssd  (source unix:///DIR/gain.sock, or --address Gain=unix://...)
        -> results.csv, the same bytes as over TCP
    a second server on a live socket: refused, naming the process that holds it
    a socket left by a killed server: replaced
    a participant's step socket (PATH.steps): results.csv the same bytes as over its StepStream
        (--no-step-socket, COUPLER_STEP_SOCKET=0), summary.json naming the transport; a step
        socket that does not open: the StepStream, with a warning
    coupler fleet scenarios/railway/fleet.toml (unix sockets by default) and --tcp
        -> the same results.csv

Each service runs as a subprocess, ``coupler`` as the user's command.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from coupler.testing import free_port

ROOT = Path(__file__).resolve().parents[2]
PY = sys.executable
COUPLER = str(Path(sys.executable).with_name("coupler"))
RAMP_GAIN = ROOT / "examples" / "ramp-gain" / "SystemStructure.ssd"
SERVICES = {
    "coupler.examples": [PY, "-m", "coupler.examples", "gain"],
    "coupler replay": [COUPLER, "replay", "{recording}"],
    "openrails-bridge": [PY, "-m", "openrails_bridge", "--openrails-url", "http://127.0.0.1:9"],
    "balise-fmu": [PY, "-m", "balise_fmu"],
    "mapserver": [PY, "-m", "mapserver", "--http-port", "0"],
    "perception": [PY, "-m", "perception"],
}

pytestmark = pytest.mark.timeout(300)


@pytest.fixture
def folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A short private folder (a socket's path has at most 107 bytes)."""
    made = Path(os.path.realpath("/tmp")) / f"cs-{os.getpid()}-{free_port()}"
    made.mkdir(mode=0o700)
    yield made
    for entry in made.iterdir():
        entry.unlink()
    made.rmdir()


def started(command: list[str]) -> subprocess.Popen[str]:
    """A participant process, once it says where it serves (its first line)."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None
    line = process.stdout.readline()
    assert "unix:///" in line, (line, process.stderr.read() if process.poll() is not None else "")
    return process


def ended(process: subprocess.Popen[str], sig: int = signal.SIGTERM) -> None:
    process.send_signal(sig)
    process.wait(20)
    for stream in (process.stdout, process.stderr):
        if stream is not None:
            stream.close()


def coupler(*args: str | Path, env: dict[str, str] | None = None) -> str:
    done = subprocess.run(
        [COUPLER, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=240,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    return done.stdout


@pytest.mark.slow
def test_coupler_run_reaches_a_participant_on_its_unix_socket(folder: Path, tmp_path: Path) -> None:
    """The ramp-gain example with its Gain on a socket (the SSD's source, or ``--address``)
    and on TCP: the same bytes in results.csv, over the native step channel and grpc.aio."""
    socket = folder / "gain.sock"
    port = free_port()
    on_socket = started([PY, "-m", "coupler.examples", "gain", "--socket", str(socket)])
    on_tcp = subprocess.Popen(
        [PY, "-m", "coupler.examples", "gain", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert on_tcp.stdout is not None and "grpc://" in on_tcp.stdout.readline()
    try:
        ssd = tmp_path / "unix.ssd"
        text = RAMP_GAIN.read_text()
        source = "${GAIN_SCHEME:-grpc}://${GAIN_HOST:-127.0.0.1}:${GAIN_PORT:-50051}"
        assert source in text
        fmus = str(ROOT / "build" / "fmus")
        ssd.write_text(text.replace(source, f"unix://{socket}").replace("../../build/fmus", fmus))
        coupler("run", RAMP_GAIN, "--out", tmp_path / "tcp", env={"GAIN_PORT": str(port)})
        coupler("run", ssd, "--out", tmp_path / "unix")
        coupler(
            "run", RAMP_GAIN, "--out", tmp_path / "moved", "--address", f"Gain=unix://{socket}",
            "--no-native-steps", env={"GAIN_PORT": "9"},
        )  # fmt: skip
    finally:
        ended(on_socket)
        ended(on_tcp)
    tcp = (tmp_path / "tcp" / "results.csv").read_bytes()
    assert len(tcp.splitlines()) > 10
    assert (tmp_path / "unix" / "results.csv").read_bytes() == tcp
    assert (tmp_path / "moved" / "results.csv").read_bytes() == tcp
    assert not socket.exists()  # the server removed its socket on the way out


def test_coupler_run_steps_a_participant_over_its_step_socket(folder: Path, tmp_path: Path) -> None:
    """Ramp FMU -> Gain on a unix socket: stepped over its step socket by default, over its
    StepStream when told; the same bytes either way. A step socket that does not open (its
    file gone) leaves the member on its StepStream, said on stderr and in summary.json."""
    pytest.importorskip("coupler_native._step_streams", reason="the native step channel")
    socket = folder / "gain.sock"
    steps = folder / "gain.sock.steps"
    gain = started([PY, "-m", "coupler.examples", "gain", "--socket", str(socket)])
    outputs = {}
    try:
        assert steps.exists() and (steps.stat().st_mode & 0o777) == 0o600
        address = ["--address", f"Gain=unix://{socket}"]
        runs = {
            "socket": ([], {}),
            "stream": (["--no-step-socket"], {}),
            "environment": ([], {"COUPLER_STEP_SOCKET": "0"}),
        }
        for name, (flags, env) in runs.items():
            coupler("run", RAMP_GAIN, "--out", tmp_path / name, *address, *flags, env=env)
        steps.unlink()  # the participant offers it, but it cannot be opened
        outputs["gone"] = subprocess.run(
            [COUPLER, "run", RAMP_GAIN, "--out", tmp_path / "gone", *address],
            capture_output=True, text=True, timeout=240, cwd=ROOT,
        )  # fmt: skip
    finally:
        ended(gain)
    assert outputs["gone"].returncode == 0, outputs["gone"].stderr
    assert "step_socket_unavailable" in outputs["gone"].stderr
    assert str(steps) in outputs["gone"].stderr
    results = (tmp_path / "socket" / "results.csv").read_bytes()
    assert len(results.splitlines()) > 10
    paths = {}
    for name in ("socket", "stream", "environment", "gone"):
        assert (tmp_path / name / "results.csv").read_bytes() == results, name
        summary = json.loads((tmp_path / name / "summary.json").read_text())
        paths[name] = summary["participants"]["Gain"]["step_path"]
    assert paths["socket"] == {
        "path": "native step socket",
        "reason": f"its step socket {steps}, without gRPC",
    }
    stream = {"path": "native step channel", "reason": "its StepStream over C++ gRPC"}
    assert paths["stream"] == paths["environment"] == stream
    assert paths["gone"]["path"] == "native step channel"
    assert "did not open (cannot connect to the step socket" in paths["gone"]["reason"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("recorded")
    subprocess.run(
        [COUPLER, "run", ROOT / "build" / "fmus" / "Source2.fmu", "--out", folder / "out",
         "--stop-time", "0.5", "--step", "0.1", "--record", "Source"],
        check=True, capture_output=True,
    )  # fmt: skip
    return folder / "out" / "recordings" / "Source.crec"


@pytest.mark.slow
@pytest.mark.parametrize("service", SERVICES)
def test_a_live_socket_is_refused_naming_its_holder(
    service: str, folder: Path, recording: Path
) -> None:
    """Every participant kind's ``--socket``: gRPC would silently take the path of a live
    server (it removes the file before binding); Coupler refuses it."""
    socket = folder / "taken.sock"
    holder = started([PY, "-m", "coupler.examples", "gain", "--socket", str(socket)])
    try:
        command = [p.format(recording=recording) for p in SERVICES[service]]
        done = subprocess.run(
            [*command, "--socket", str(socket)], capture_output=True, text=True, timeout=60
        )
    finally:
        ended(holder)
    assert done.returncode != 0, done.stdout
    assert "Traceback" not in done.stderr, done.stderr
    assert f"unix socket {socket}: the socket is in use by pid {holder.pid} (" in done.stderr
    assert "coupler.examples gain --socket" in done.stderr


def test_a_stale_socket_is_replaced(folder: Path) -> None:
    """A server killed without a word leaves its socket file; the next one serves there."""
    socket = folder / "gain.sock"
    first = started([PY, "-m", "coupler.examples", "gain", "--socket", str(socket)])
    ended(first, signal.SIGKILL)
    assert socket.exists()
    second = started([PY, "-m", "coupler.examples", "gain", "--socket", str(socket)])
    try:
        health = subprocess.run(
            [PY, "-m", "coupler.health", f"unix://{socket}"], capture_output=True, text=True
        )
        assert health.returncode == 0, health.stderr
    finally:
        ended(second)


def test_a_socket_path_that_cannot_be_one_is_refused(folder: Path) -> None:
    for path, said in [
        (folder / "file.txt", "a file that is not a socket is there; remove it"),
        (folder / ("x" * 120), "the path is longer than 107 bytes; choose a shorter one"),
        (folder / "missing" / "gain.sock", f"folder {folder / 'missing'} does not exist"),
    ]:
        if path.name == "file.txt":
            path.write_text("mine")
        done = subprocess.run(
            [PY, "-m", "coupler.examples", "gain", "--socket", str(path)],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
        assert said in done.stderr, done.stderr
    assert (folder / "file.txt").read_text() == "mine"  # never removed


@pytest.mark.slow
def test_the_railway_fleet_records_the_same_bytes_on_unix_sockets_and_on_tcp(
    tmp_path: Path,
) -> None:
    """``coupler fleet`` with the railway's fleet file (its services verbatim; 120 s of the
    run, unpaced): on unix sockets (the default) and with ``--tcp``, the same results.csv."""
    fleet = tmp_path / "fleet.toml"
    text = (ROOT / "scenarios" / "railway" / "fleet.toml").read_text()
    fleet.write_text(re.sub(r"(?m)^args = .*$", 'args = ["--stop-time", "120"]', text))
    ports = {
        name: str(free_port())
        for name in ("MOCK_PORT", "BRIDGE_PORT", "BALISE_PORT", "MAP_PORT", "MAP_HTTP_PORT")
    }
    said = {}
    for way in ("unix", "tcp"):
        options = ["--tcp"] if way == "tcp" else []
        said[way] = coupler(
            "fleet", fleet, "--exit", "--out", tmp_path / way, "--realtime-factor", "0",
            *options, env=ports,
        )  # fmt: skip
    [sockets] = re.findall(r"participants on unix sockets in (\S+) ", said["unix"])
    assert not Path(sockets).exists()  # removed with the fleet
    assert "unix sockets" not in said["tcp"]
    logs = {way: Path(re.findall(r"\(logs in (\S+)\)", said[way])[0]) for way in said}
    bridge = {way: (ROOT / logs[way] / "openrails-bridge.log").read_text() for way in said}
    assert f"listening at unix://{sockets}/openrails-bridge.sock" in bridge["unix"]
    assert f"listening at grpc://127.0.0.1:{ports['BRIDGE_PORT']}" in bridge["tcp"]
    unix = (tmp_path / "unix" / "results.csv").read_bytes()
    assert len(unix.splitlines()) == 122  # the header, t = 0 .. 120
    if importlib.util.find_spec("coupler_native._step_streams") is not None:
        paths = {
            way: json.loads((tmp_path / way / "summary.json").read_text())["participants"]
            for way in said
        }  # the bridge and the map are stepped over their step sockets on unix sockets only
        for name in ("OpenRails", "Map"):
            assert paths["unix"][name]["step_path"]["path"] == "native step socket", name
            assert paths["tcp"][name]["step_path"]["path"] == "native step channel", name
    assert unix == (tmp_path / "tcp" / "results.csv").read_bytes()
