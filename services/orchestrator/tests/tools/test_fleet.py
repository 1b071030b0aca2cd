"""``coupler fleet`` and the console of ``coupler run`` as a person meets them, with real
processes: a second fleet refused with the busy port and the pid holding it (the first one
untouched), Ctrl-C during and after a run, and what a run waiting for a participant says.

    coupler fleet (process) --starts--> gain participant (process, GAIN_PORT)
         |  run: Source (FMU) -> Gain (gRPC) -> Feed, Feed2 (FMUs)      tests/data/mixed.ssd
         v
    out/<time>-<run id>/results.csv, summary.json (out/latest links to it),
    build/logs/fleet-<time>-<random>/gain.log
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from coupler.errors import ScenarioError
from coupler.health import probe
from coupler.testing import end_group, free_port, wait_until
from coupler_orchestrator.tools.fleet import (
    Fleet,
    FleetError,
    FleetSpec,
    holders_of,
    port_is_free,
)

from ..support import DATA, REPO

FLEET = f"""
[scenario]
ssp = "{DATA / "mixed.ssd"}"
out = "out"

[[service]]
name = "gain"
command = ["python", "-m", "coupler.examples", "gain", "--port", "${{GAIN_PORT:-50051}}"]
health = "grpc://127.0.0.1:${{GAIN_PORT:-50051}}"
"""


class Console:
    """A ``coupler`` process whose stdout and stderr lines are collected as they come."""

    def __init__(self, args: list[str], cwd: Path, env: dict[str, str]) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "coupler_orchestrator", *args],
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its services are ended with it (``stop``)
        )
        self.out: list[str] = []
        self.err: list[str] = []
        assert self.process.stdout is not None and self.process.stderr is not None
        self._readers = [
            threading.Thread(target=self._read, args=(self.process.stdout, self.out), daemon=True),
            threading.Thread(target=self._read, args=(self.process.stderr, self.err), daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    @staticmethod
    def _read(stream: object, lines: list[str]) -> None:
        for line in stream:  # type: ignore[attr-defined]
            lines.append(line.rstrip("\n"))

    def wait_for(self, lines: list[str], pattern: str, timeout: float = 60.0) -> str:
        def found() -> str | None:
            line = next((line for line in list(lines) if re.search(pattern, line)), None)
            ended = self.process.poll() is not None and not any(r.is_alive() for r in self._readers)
            if line is None and ended:
                raise AssertionError(f"ended without {pattern!r}; out={self.out} err={self.err}")
            return line

        return wait_until(found, timeout, what=f"a line matching {pattern!r}; out={self.out}")

    def finish(self, timeout: float = 30.0) -> int:
        code = self.process.wait(timeout)
        for reader in self._readers:
            reader.join(5)
        return code

    def stop(self) -> None:
        end_group(self.process, close=False)
        for reader in self._readers:
            reader.join(5)
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()


@pytest.fixture
def env(fmus: dict[str, Path]) -> dict[str, str]:
    """The environment of the processes: the built FMUs and a free GAIN_PORT."""
    return {**os.environ, "GAIN_PORT": str(free_port())}


@pytest.fixture
def fleet_dir(tmp_path: Path) -> Path:
    (tmp_path / "fleet.toml").write_text(FLEET)
    return tmp_path


@pytest.fixture
def consoles() -> Iterator[list[Console]]:
    started: list[Console] = []
    yield started
    for console in started:
        console.stop()


def coupler(args: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """``coupler ARGS`` run to its end."""
    return subprocess.run(
        [sys.executable, "-m", "coupler_orchestrator", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


def children_of(pid: int) -> list[int]:
    text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    return [int(p) for p in text.split()]


def fleet_of(pid: int) -> int:
    """The process that runs the fleet: ``coupler fleet`` forks once and watches its child
    (``cli.supervisor``), which starts the services and holds the results folder."""
    (child,) = children_of(pid)
    return child


def files_of(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {
        str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_fleet_file_ports_come_from_the_environment(fleet_dir: Path) -> None:
    spec = FleetSpec.load(fleet_dir / "fleet.toml", root=fleet_dir, env={"GAIN_PORT": "4321"})
    (gain,) = spec.services
    assert gain.command[-1] == "4321"
    assert gain.health == "grpc://127.0.0.1:4321"
    assert gain.needed_ports() == (4321,)
    assert gain.port_variables == {4321: "GAIN_PORT"}
    default = FleetSpec.load(fleet_dir / "fleet.toml", root=fleet_dir, env={})
    assert default.services[0].needed_ports() == (50051,)


@pytest.mark.slow
def test_a_second_fleet_is_refused_and_the_first_is_untouched(
    fleet_dir: Path, env: dict[str, str], consoles: list[Console]
) -> None:
    port = int(env["GAIN_PORT"])
    first = Console(["fleet", "fleet.toml", "--tcp"], fleet_dir, env)  # on TCP ports
    consoles.append(first)
    first.wait_for(first.out, r"services stay up; Ctrl-C stops them")
    (gain_pid,) = children_of(fleet_of(first.process.pid))
    (log_folder,) = (fleet_dir / "build" / "logs").iterdir()
    assert (log_folder / "gain.log").exists()
    before = files_of(fleet_dir)
    latest = fleet_dir / "out" / "latest"
    assert json.loads((latest / "summary.json").read_text())["status"] == "completed"

    second = coupler(["fleet", "fleet.toml", "--tcp"], fleet_dir, env)
    assert second.returncode == 1
    assert "Traceback" not in second.stderr
    assert f"port {port} (gain) is in use by pid {gain_pid} (" in second.stderr
    assert "coupler.examples gain" in second.stderr
    assert "move this fleet with GAIN_PORT=<free port>" in second.stderr
    assert "services healthy" not in second.stdout
    assert files_of(fleet_dir) == before  # no log truncated, no summary overwritten
    assert [p.name for p in (fleet_dir / "build" / "logs").iterdir()] == [log_folder.name]

    import asyncio

    asyncio.run(probe(f"grpc://127.0.0.1:{port}", connect_timeout=5))  # the first still serves
    assert [h.pid for h in holders_of(port)] == [gain_pid]

    # Ctrl-C after a completed run stops the services: one sentence, exit 0
    first.process.send_signal(signal.SIGINT)
    assert first.finish() == 0
    assert first.err[-1] == (
        "stopped the services; the run had ended completed at t=1.5 s, results in "
        f"out/{os.readlink(latest)}"
    )
    assert not any("Traceback" in line or line.startswith("{") for line in first.err)
    assert port_is_free(port)


@pytest.mark.slow
def test_results_directory_of_a_running_fleet_is_refused(
    fleet_dir: Path, env: dict[str, str], consoles: list[Console]
) -> None:
    first = Console(["fleet", "fleet.toml"], fleet_dir, env)
    consoles.append(first)
    first.wait_for(first.out, r"services stay up")
    # on a unix socket in a private folder: its TCP port stays free
    line = first.wait_for(first.out, r"^participants on unix sockets in ")
    sockets = Path(line.split()[5])
    assert (sockets / "gain.sock").is_socket()
    assert sockets.stat().st_mode & 0o777 == 0o700
    assert port_is_free(int(env["GAIN_PORT"]))
    moved = {**env, "GAIN_PORT": str(free_port())}  # free ports, same results directory
    second = coupler(["fleet", "fleet.toml"], fleet_dir, moved)
    assert second.returncode == 1
    assert f"is being written by another fleet (pid {fleet_of(first.process.pid)})" in second.stderr
    assert "--out" in second.stderr


@pytest.mark.slow
def test_ctrl_c_during_a_run_says_where_and_when_it_stopped(
    fleet_dir: Path, env: dict[str, str], consoles: list[Console]
) -> None:
    run = Console(["fleet", "fleet.toml", "--exit", "--realtime-factor", "0.25"], fleet_dir, env)
    consoles.append(run)
    csv = fleet_dir / "out" / "latest" / "results.csv"

    def stepping() -> bool:
        assert run.process.poll() is None, run.err
        return csv.exists() and len(csv.read_text().splitlines()) >= 3  # header, t=0, t=0.5

    wait_until(stepping, 60, what="the run's first rows")
    run.process.send_signal(signal.SIGINT)
    assert run.finish() == 130
    rows = len(csv.read_text().splitlines()) - 1
    reached = (rows - 1) * 0.5
    assert run.err[-1] == (
        f"interrupted at t={reached:g} s of 1.5 s; the results so far are in "
        f"out/{os.readlink(csv.parent)} (summary.json: status aborted)"
    )
    assert not any("Traceback" in line or line.startswith("{") for line in run.err)
    summary = json.loads((csv.parent / "summary.json").read_text())
    assert summary["status"] == "aborted"
    assert port_is_free(int(env["GAIN_PORT"]))  # the fleet stopped its service


def test_waiting_for_a_participant_is_said_at_once(
    tmp_path: Path, env: dict[str, str], consoles: list[Console]
) -> None:
    port = env["GAIN_PORT"]  # nothing listens there
    run = Console(
        ["run", str(DATA / "mixed.ssd"), "--out", "out", "--connect-timeout", "60"], tmp_path, env
    )
    consoles.append(run)
    line = run.wait_for(run.err, r"^waiting for ")
    assert line == (
        f"waiting for Gain at grpc://127.0.0.1:{port} "
        "(connection refused: nothing listens on that port yet)"
    )
    assert run.process.poll() is None  # said while it still waits
    run.process.send_signal(signal.SIGINT)
    assert run.finish() == 130
    assert run.err[-1] == "interrupted before the run started; nothing was recorded"


def test_a_participant_not_running_ends_with_how_to_start_it(
    env: dict[str, str], tmp_path: Path
) -> None:
    out = tmp_path / "coupler-hint"
    result = coupler(
        ["run", "examples/ramp-gain/SystemStructure.ssd", "--out", str(out), "--connect-timeout",
         "0.5"],
        REPO,
        env,
    )  # fmt: skip
    assert result.returncode == 1
    lines = result.stderr.splitlines()
    assert lines[0].startswith(f"waiting for Gain at grpc://127.0.0.1:{env['GAIN_PORT']} (")
    assert "is the participant running" in result.stderr
    assert lines[-1] == (
        "hint: start the scenario's services with `.venv/bin/coupler fleet "
        "examples/ramp-gain/fleet.toml` or `make demo-example` (it starts them and runs the "
        "scenario), or start each one yourself"
    )


def test_a_service_without_socket_option_is_named_with_the_way_out(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """``coupler fleet`` adds ``--socket PATH`` to a gRPC service's command; a program that
    does not know the option fails, and the error says how to keep it on TCP."""
    gain = '["python", "-m", "coupler.examples", "gain", "--port", "${GAIN_PORT:-50051}"]'
    knows_no_socket = """["python", "-c", "import sys; sys.exit('no --socket here')"]"""
    assert gain in FLEET
    (tmp_path / "fleet.toml").write_text(FLEET.replace(gain, knows_no_socket))
    done = coupler(["fleet", "fleet.toml", "--exit"], tmp_path, env)
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    assert "service 'gain' exited with code 1 (started with --socket PATH" in done.stderr
    assert "needs socket = false in its [[service]], or run coupler fleet --tcp" in done.stderr
    assert "no --socket here" in done.stderr


def test_the_fleet_file_keeps_services_on_tcp(fleet_dir: Path) -> None:
    """``unix_sockets = false`` under [scenario], ``socket = false`` in a [[service]]: TCP;
    anything but true or false is refused naming the file."""
    path = fleet_dir / "fleet.toml"
    on_socket = Fleet(FleetSpec.load(path, root=fleet_dir), sockets=True)
    assert on_socket.on_socket(on_socket.spec.services[0])
    assert on_socket.ports_of(on_socket.spec.services[0]) == ()  # its gRPC port not needed
    for text in (
        FLEET.replace('out = "out"', 'out = "out"\nunix_sockets = false'),
        FLEET.replace('health = "grpc:', 'socket = false\nhealth = "grpc:'),
    ):
        path.write_text(text)
        fleet = Fleet(FleetSpec.load(path, root=fleet_dir), sockets=True)
        assert not fleet.on_socket(fleet.spec.services[0])
    path.write_text(FLEET.replace('out = "out"', 'out = "out"\nunix_sockets = "no"'))
    with pytest.raises(ScenarioError, match=r"fleet.toml: not a fleet file .*unix_sockets = 'no'"):
        FleetSpec.load(path, root=fleet_dir)


@pytest.mark.slow
def test_fleet_takes_stop_time_params_and_output_variables_like_run(
    fleet_dir: Path, env: dict[str, str]
) -> None:
    """The run of ``coupler fleet`` is shortened, parameterised and its recording chosen on
    the command line, as with ``coupler run``: no copy of the fleet file."""
    args = ["fleet", "fleet.toml", "--exit", "--stop-time", "1.0", "--param", "Gain.gain=6",
            "--output-variables", "Gain.y"]  # fmt: skip
    done = coupler(args, fleet_dir, env)
    assert done.returncode == 0, done.stderr
    rows = (fleet_dir / "out" / "latest" / "results.csv").read_text().splitlines()
    assert rows[0].split(",") == ["time", "Gain.y"]
    times = [float(row.split(",")[0]) for row in rows[1:]]
    assert times[-1] == 1.0  # the SSD's stop time is 1.5
    plain = coupler(["fleet", "fleet.toml", "--exit", "--out", "plain"], fleet_dir, env)
    assert plain.returncode == 0, plain.stderr
    header, *lines = (fleet_dir / "plain" / "results.csv").read_text().splitlines()
    y = header.split(",").index("Gain.y")
    doubled = [float(row.split(",")[1]) for row in rows[1:]]  # the SSD's gain is 3
    assert doubled == [2 * float(line.split(",")[y]) for line in lines[: len(doubled)]]
    assert any(v != 0 for v in doubled)


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (('out = "out"', 'out = "out"\nunix_socket = false'),
         "fleet.toml line 5: unknown key 'unix_socket' in [scenario]; its keys are ssp, out, "
         "args, unix_sockets (docs/fleet.md)"),
        (("health =", "healt ="),
         "fleet.toml line 9: unknown key 'healt' in [[service]]; its keys are name, command, "
         "health, ports, socket (docs/fleet.md)"),
        (("[[service]]", '[url]\nmap = "http://127.0.0.1:8080/"\n\n[[service]]'),
         "fleet.toml line 6: unknown table [url]; a fleet file has [scenario], [[service]] and "
         "[urls] (docs/fleet.md)"),
    ],
)  # fmt: skip
def test_a_key_the_fleet_file_may_not_have_is_refused_with_its_line(
    fleet_dir: Path, change: tuple[str, str], said: str
) -> None:
    path = fleet_dir / "fleet.toml"
    path.write_text(FLEET.replace(*change))
    with pytest.raises(ScenarioError) as refused:
        FleetSpec.load(path, root=fleet_dir)
    assert str(refused.value) == f"{path.parent}/{said}"


async def test_the_results_lock_goes_with_the_fleet(fleet_dir: Path) -> None:
    """``out/.fleet.lock`` is held while a fleet is up (a second fleet is refused) and removed
    when it stops; the next fleet locks afresh."""
    spec = FleetSpec.load(fleet_dir / "fleet.toml", root=fleet_dir)
    spec = FleetSpec(root=fleet_dir, ssp=spec.ssp, out=spec.out)  # no services: the lock alone
    lock = spec.out / ".fleet.lock"
    async with Fleet(spec, logs=fleet_dir / "logs"):
        assert lock.read_text() == f"pid {os.getpid()}\n"
        with pytest.raises(FleetError, match="is being written by another fleet"):
            async with Fleet(spec, logs=fleet_dir / "logs"):
                pass
        assert lock.exists()
    assert not lock.exists()
    async with Fleet(spec, logs=fleet_dir / "logs"):
        assert lock.exists()
    assert sorted(p.name for p in spec.out.iterdir()) == []
