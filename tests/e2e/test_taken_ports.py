"""Every server Coupler starts refuses a port another process holds, naming the port and the
holder (pid and command line), instead of sharing it (gRPC's SO_REUSEPORT let a second server
start there, and connections split between the two processes).

    port_holder.py (a gRPC server with grpc's default options) holds 127.0.0.1:P
    <service> --port P  ->  exits non-zero: "... 127.0.0.1:P: the port is in use by pid N (...)"

Each service runs as users start it: its command, as a subprocess.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from coupler.testing import SystemStructure, fmu

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).parent
PY = sys.executable
COUPLER = str(Path(sys.executable).with_name("coupler"))
SOURCE_FMU = ROOT / "build" / "fmus" / "Source2.fmu"
SSD = SystemStructure("Ramp", [fmu("Source", SOURCE_FMU, outputs=["ramp"])], stop_time=1)
SERVICES = {
    "coupler.examples": [PY, "-m", "coupler.examples", "gain", "--port", "{port}"],
    "coupler.examples --health-port": [
        *(PY, "-m", "coupler.examples", "gain", "--port", "0", "--health-port", "{port}"),
    ],
    "coupler replay": [COUPLER, "replay", "{recording}", "--port", "{port}"],
    "openrails-bridge": [
        *(
            PY,
            "-m",
            "openrails_bridge",
            "--port",
            "{port}",
            "--openrails-url",
            "http://127.0.0.1:9",
        ),
    ],
    "balise-fmu": [PY, "-m", "balise_fmu", "--port", "{port}"],
    "mapserver (gRPC)": [PY, "-m", "mapserver", "--grpc-port", "{port}", "--http-port", "0"],
    "mapserver (web)": [PY, "-m", "mapserver", "--grpc-port", "0", "--http-port", "{port}"],
    "openrails-mock": [PY, "-m", "openrails_mock", "--port", "{port}"],
    "coupler run --monitor": [
        COUPLER,
        "run",
        "{ssd}",
        "--out",
        "{out}",
        "--step",
        "0.1",
        "--monitor",
        "{port}",
    ],
}


@dataclass(frozen=True)
class Holder:
    pid: int
    port: int


@pytest.fixture(scope="module")
def holder() -> Iterator[Holder]:
    """A process holding a port the way every gRPC server does by default."""
    process = subprocess.Popen(
        [PY, str(HERE / "port_holder.py")], stdout=subprocess.PIPE, text=True
    )
    try:
        assert process.stdout is not None
        yield Holder(process.pid, int(process.stdout.readline()))
    finally:
        process.kill()
        process.wait(10)
        if process.stdout is not None:
            process.stdout.close()


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording of an FMU's outputs, made by ``coupler run --record``."""
    folder = tmp_path_factory.mktemp("recorded")
    SSD.write(folder / "ramp.ssd")
    subprocess.run(
        [
            COUPLER,
            "run",
            folder / "ramp.ssd",
            "--out",
            folder / "out",
            "--step",
            "0.1",
            "--record",
            "Source",
        ],
        check=True,
        capture_output=True,
    )
    return folder / "out" / "recordings" / "Source.crec"


def refusal(command: list[str], port: int) -> str:
    """What ``command`` says when it exits; fails the test when it keeps serving."""
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{command[1:4]} started on port {port}, which another process holds")
    assert done.returncode != 0, done.stdout
    assert "Traceback" not in done.stderr, done.stderr
    return done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("service", SERVICES)
def test_a_taken_port_is_refused_naming_its_holder(
    service: str, holder: Holder, recording: Path, tmp_path: Path
) -> None:
    SSD.write(tmp_path / "ramp.ssd")
    values = {
        "port": str(holder.port),
        "recording": str(recording),
        "ssd": str(tmp_path / "ramp.ssd"),
        "out": str(tmp_path / "out"),
    }
    command = [part.format(**values) for part in SERVICES[service]]
    said = refusal(command, holder.port)
    assert f"127.0.0.1:{holder.port}: the port is in use by pid {holder.pid} (" in said, said
    assert "port_holder.py" in said, said


def test_a_second_gain_example_is_refused_naming_the_first() -> None:
    """The attack as it was seen: the same service started twice on one port."""
    first = subprocess.Popen(
        [PY, "-m", "coupler.examples", "gain", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert first.stdout is not None
        port = int(first.stdout.readline().rsplit(":", 1)[1])
        said = refusal([PY, "-m", "coupler.examples", "gain", "--port", str(port)], port)
        assert f"the port is in use by pid {first.pid} (" in said, said
        assert "-m coupler.examples gain --port 0)" in said, said
    finally:
        first.terminate()
        first.wait(10)
        if first.stdout is not None:
            first.stdout.close()
