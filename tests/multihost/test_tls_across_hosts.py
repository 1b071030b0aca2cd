"""The railway scenario (and ramp-gain) across hosts: the participants on one, the
orchestrator on another, over grpcs:// with mutual TLS and a bearer token, through a router.
Each host is a network namespace this test creates and removes; every address is from the
benchmarking range 198.18.0.0/15 and exists only inside those namespaces.

    participants (ns P)                router (ns R)                     orchestrator (ns O)
    openrails-mock   127.0.0.1:42150
    openrails-bridge 198.18.0.1:45061 -+
    balise-fmu       198.18.0.1:45062 -+- veth - .0.2 | .0.5 [relay] - veth - 198.18.0.6
    mapserver        198.18.0.1:45071 -+                                      coupler run
    gain (example)   198.18.0.1:45051 -+                                     (FMUs in-process)

1. The reference: the loopback run, every process in ns P on 127.0.0.1, plaintext.
2. The same scenarios from ns O over TLS at 0, 1 and 10 ms round-trip time: results.csv
   byte-identical to the reference; the cost per step is reported (the railway's is mostly
   the OpenRails mock's physics; ramp-gain's one participant shows the link's own cost).
   Latency comes from ``tc netem`` on the router's links where the kernel has it, else from
   a relay in ns R that holds every byte back by half the round trip each way
   (delay_relay.py).
3. The participants' link goes down mid-run (``ip link set ... down``): the run ends
   ``failed`` within the call deadlines, every row recorded so far kept.

Needs root (network namespaces); skipped with the reason otherwise.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from coupler_dev.devcerts import DevPki, write_pki

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
RAILWAY = ROOT / "scenarios" / "railway" / "SystemStructure.ssd"
RAMP_GAIN = ROOT / "examples" / "ramp-gain" / "SystemStructure.ssd"
RAILML = ROOT / "scenarios" / "railway" / "data" / "annaberg-schwarzenberg.railml"
FMUS = ROOT / "build" / "fmus"
ROUTE = ROOT / "build" / "routes" / "annaberg-schwarzenberg"  # make setup exports it
# (scenario, --stop-time, its gRPC participants): 300 railway steps pass the first balises
SCENARIOS = {
    "railway": (RAILWAY, 300.0, ("OpenRails", "TrackBalises", "Map")),
    "ramp-gain": (RAMP_GAIN, 50.0, ("Gain",)),
}
RTTS_MS = (0.0, 1.0, 10.0)
CALL_TIMEOUT = 2.0  # the link-drop run's per-call deadline [s]

# Addresses: P 198.18.0.1/30 -- R 198.18.0.2/30 | R 198.18.0.5/30 -- O 198.18.0.6/30
PARTICIPANTS_IP, RELAY_IP, ORCHESTRATOR_IP = "198.18.0.1", "198.18.0.5", "198.18.0.6"
# fixed ports: the namespaces are private to this test
PORTS = {"BRIDGE": 45061, "BALISE": 45062, "MAP": 45071, "GAIN": 45051}
MOCK_PORT, MAP_HTTP_PORT = 42150, 48080
PREFIX = "cplt"  # namespaces cplt<pid>-p/-r/-o

pytestmark = pytest.mark.timeout(420)


def ip(*args: str) -> str:
    result = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {result.stderr.strip()}")
    return result.stdout


def in_ns(ns: str, *argv: str) -> list[str]:
    return ["ip", "netns", "exec", ns, *argv]


@dataclass(frozen=True)
class Hosts:
    """The three namespaces and the interfaces the test changes."""

    participants: str
    router: str
    orchestrator: str
    participants_link: str
    """The participants' veth (in ns P): down = the participants' host is cut off."""
    router_links: tuple[str, str]
    """The router's two veths (in ns R), where netem delays traffic."""
    netem: bool
    """Whether this kernel has sch_netem (else the delay relay stands in)."""

    @property
    def all(self) -> tuple[str, str, str]:
        return (self.participants, self.router, self.orchestrator)


def _remove_stale() -> None:
    """Namespaces left by an earlier run of this test that was killed (its pid is gone)."""
    for line in ip("netns", "list").splitlines():
        name = line.split()[0] if line.split() else ""
        pid = name[len(PREFIX) :].split("-")[0]
        if name.startswith(PREFIX) and pid.isdigit() and not Path(f"/proc/{pid}").exists():
            _kill_namespace(name)


def _kill_namespace(ns: str) -> None:
    """SIGKILL every process left in ``ns`` (ours), then delete it."""
    with contextlib.suppress(RuntimeError):
        for pid in ip("netns", "pids", ns).split():
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(pid), signal.SIGKILL)
    with contextlib.suppress(RuntimeError):
        ip("netns", "delete", ns)


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    if os.geteuid() != 0:
        pytest.skip("creating network namespaces needs root (run `make test` as root)")
    if shutil.which("ip") is None:
        pytest.skip("iproute2's `ip` is not installed")
    for fmu in ("Driver2.fmu", "TrackBalises.fmu"):
        if not (FMUS / fmu).exists():
            pytest.fail(f"{FMUS / fmu} is missing: run 'make setup' (make test does)")
    _remove_stale()
    tag = f"{PREFIX}{os.getpid()}"
    names = Hosts(
        participants=f"{tag}-p",
        router=f"{tag}-r",
        orchestrator=f"{tag}-o",
        participants_link=f"c{os.getpid()}p",
        router_links=(f"c{os.getpid()}rp", f"c{os.getpid()}ro"),
        netem=False,
    )
    created: list[str] = []
    try:
        for ns in names.all:
            try:
                ip("netns", "add", ns)
            except RuntimeError as exc:
                pytest.skip(f"cannot create network namespaces here: {exc}")
            created.append(ns)
            ip("-n", ns, "link", "set", "lo", "up")
        p, r, o = names.all
        rp, ro = names.router_links
        # each end created in its namespace: nothing appears in the machine's own
        ip("link", "add", names.participants_link, "netns", p, "type", "veth",
           "peer", "name", rp, "netns", r)  # fmt: skip
        ip("link", "add", f"c{os.getpid()}o", "netns", o, "type", "veth",
           "peer", "name", ro, "netns", r)  # fmt: skip
        for ns, dev, address in (
            (p, names.participants_link, f"{PARTICIPANTS_IP}/30"),
            (r, rp, "198.18.0.2/30"),
            (r, ro, f"{RELAY_IP}/30"),
            (o, f"c{os.getpid()}o", f"{ORCHESTRATOR_IP}/30"),
        ):
            ip("-n", ns, "addr", "add", address, "dev", dev)
            ip("-n", ns, "link", "set", dev, "up")
        ip("-n", p, "route", "add", "198.18.0.4/30", "via", "198.18.0.2")
        ip("-n", o, "route", "add", "198.18.0.0/30", "via", RELAY_IP)
        subprocess.run(in_ns(r, "sysctl", "-qw", "net.ipv4.ip_forward=1"), check=True)
        netem = shutil.which("tc") is not None and (
            subprocess.run(
                ["tc", "-n", r, "qdisc", "add", "dev", rp, "root", "netem", "delay", "0ms"],
                capture_output=True,
                check=False,
            ).returncode
            == 0
        )
        yield dataclasses.replace(names, netem=netem)
    finally:
        for ns in created:
            _kill_namespace(ns)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> DevPki:
    return write_pki(tmp_path_factory.mktemp("pki"), names=(PARTICIPANTS_IP, RELAY_IP))


# --- processes in namespaces --------------------------------------------------------------


def fleet_file(path: Path, *, bind: str, tls: DevPki | None) -> Path:
    """The railway participants as a fleet file, bound to ``bind``, with TLS when given."""
    security: list[str] = []
    scheme = "grpc"
    if tls is not None:
        scheme = "grpcs"
        security = [
            "--tls-cert", str(tls.server_cert), "--tls-key", str(tls.server_key),
            "--tls-client-ca", str(tls.ca), "--token-file", str(tls.token),
        ]  # fmt: skip
    services = {
        "netns-openrails-mock": (
            ["python", "-m", "openrails_mock", "--host", "127.0.0.1", "--port", str(MOCK_PORT),
             "--mode", "lockstep", "--route", str(ROUTE), "--path", "PATHS/ocp_ABU-ocp_SZB.pat"],
            f"http://127.0.0.1:{MOCK_PORT}/API/READY",
        ),
        "netns-openrails-bridge": (
            ["python", "-m", "openrails_bridge", "--host", bind, "--port", str(PORTS["BRIDGE"]),
             "--openrails-url", f"http://127.0.0.1:{MOCK_PORT}", *security],
            f"{scheme}://{bind}:{PORTS['BRIDGE']}",
        ),
        "netns-balise-fmu": (
            ["python", "-m", "balise_fmu", "--host", bind, "--port", str(PORTS["BALISE"]),
             "--name", "TrackBalises", "--fmu", str(FMUS / "TrackBalises.fmu"), *security],
            f"{scheme}://{bind}:{PORTS['BALISE']}",
        ),
        "netns-gain": (
            ["python", "-m", "coupler.examples", "gain", "--host", bind,
             "--port", str(PORTS["GAIN"]), *security],
            f"{scheme}://{bind}:{PORTS['GAIN']}",
        ),
        "netns-mapserver": (
            ["python", "-m", "mapserver", "--grpc-host", bind, "--grpc-port", str(PORTS["MAP"]),
             "--http-host", "127.0.0.1", "--http-port", str(MAP_HTTP_PORT),
             "--railml", str(RAILML), *security],
            f"{scheme}://{bind}:{PORTS['MAP']}",
        ),
    }  # fmt: skip
    lines = ["[scenario]", f"ssp = {json.dumps(str(RAILWAY))}", ""]
    for name, (command, health) in services.items():
        lines += [
            "[[service]]",
            f"name = {json.dumps(name)}",
            f"command = {json.dumps(command)}",
            f"health = {json.dumps(health)}",
            "",
        ]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def client_env(tls: DevPki | None) -> dict[str, str]:
    """The client side's TLS files (the participants' host needs them for its health checks)."""
    if tls is None:
        return {}
    return {
        "COUPLER_TLS_CA": str(tls.ca),
        "COUPLER_TLS_CERT": str(tls.client_cert),
        "COUPLER_TLS_KEY": str(tls.client_key),
    }


def wait_ready(process: subprocess.Popen[bytes], what: str, log: Path, timeout: float) -> None:
    """Until ``process`` prints ``ready``; fails with its log when it exits or times out."""
    assert process.stdout is not None
    fd, said = process.stdout.fileno(), b""
    deadline = time.monotonic() + timeout
    while b"ready\n" not in said and time.monotonic() < deadline:
        if select.select([fd], [], [], 0.5)[0]:
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            said += chunk
    if b"ready\n" not in said:
        pytest.fail(f"{what} did not become ready:\n{log.read_text(errors='replace')[-3000:]}")


@contextlib.contextmanager
def started(argv: list[str], what: str, log: Path, env: dict[str, str]) -> Iterator[None]:
    """A process that prints ``ready``; SIGTERM (then SIGKILL) on the way out."""
    with log.open("w") as errors:
        process = subprocess.Popen(
            argv,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=errors,
            env={**os.environ, **env},
            start_new_session=True,
        )
    try:
        wait_ready(process, what, log, timeout=90)
        yield
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        if process.stdout is not None:
            process.stdout.close()


@contextlib.contextmanager
def participants(hosts: Hosts, work: Path, *, bind: str, tls: DevPki | None) -> Iterator[None]:
    """Fresh railway participants in ns P (OpenRails, and so the mock, has no reset)."""
    fleet = fleet_file(work / "fleet.toml", bind=bind, tls=tls)
    host = [sys.executable, str(HERE / "netns_host.py"), str(fleet), str(ROOT)]
    with started(
        in_ns(hosts.participants, *host), "the participants' host", work / "host.log",
        client_env(tls),
    ):  # fmt: skip
        yield


@contextlib.contextmanager
def delay(hosts: Hosts, rtt_ms: float, work: Path) -> Iterator[str]:
    """``rtt_ms`` of round-trip time between O and P; yields the address O must use for P."""
    rp, ro = hosts.router_links
    if rtt_ms == 0:
        yield PARTICIPANTS_IP
    elif hosts.netem:
        for dev in (rp, ro):
            netem = ["tc", "-n", hosts.router, "qdisc", "replace", "dev", dev, "root", "netem"]
            subprocess.run([*netem, "delay", f"{rtt_ms / 2}ms"], check=True)
        try:
            yield PARTICIPANTS_IP
        finally:
            for dev in (rp, ro):
                netem = ["tc", "-n", hosts.router, "qdisc", "replace", "dev", dev, "root", "netem"]
                subprocess.run([*netem, "delay", "0ms"], check=True)
    else:
        routes = [f"{RELAY_IP}:{p}={PARTICIPANTS_IP}:{p}" for p in PORTS.values()]
        relay = [sys.executable, str(HERE / "delay_relay.py"), "--one-way-ms", str(rtt_ms / 2)]
        with started(
            in_ns(hosts.router, *relay, *routes), "the delay relay", work / "relay.log", {}
        ):
            yield RELAY_IP


def orchestrator(
    ns: str, scenario: str, out: Path, *, tls: DevPki | None, extra: tuple[str, ...] = ()
) -> list[str]:
    """``coupler run`` of ``scenario`` (a SCENARIOS key) in the namespace ``ns``."""
    ssd, stop_time, _ = SCENARIOS[scenario]
    argv = [
        sys.executable, "-m", "coupler_orchestrator", "run", str(ssd), "--out", str(out),
        "--no-progress", "--stop-time", str(stop_time), "--connect-timeout", "30", *extra,
    ]  # fmt: skip
    if tls is not None:
        argv += [
            "--tls-ca", str(tls.ca), "--tls-cert", str(tls.client_cert),
            "--tls-key", str(tls.client_key), "--token-file", str(tls.token),
        ]  # fmt: skip
    return in_ns(ns, *argv)


def scenario_env(host: str, tls: bool) -> dict[str, str]:
    """The SSD's address variables (docs/deployment.md): scheme, host and port per participant."""
    env = {"COUPLER_FMU_DIR": str(FMUS)}
    for name, port in PORTS.items():
        env |= {
            f"{name}_SCHEME": "grpcs" if tls else "grpc",
            f"{name}_HOST": host,
            f"{name}_PORT": str(port),
        }
    return env


def run(argv: list[str], env: dict[str, str], out: Path) -> dict[str, Any]:
    """``argv`` to completion; its summary (status completed, else the test fails)."""
    done = subprocess.run(
        argv, cwd=ROOT, env={**os.environ, **env}, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, f"coupler run failed:\n{done.stdout}\n{done.stderr[-3000:]}"
    summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed", summary["reason"]
    return summary


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


# --- the tests ----------------------------------------------------------------------------


Runs = dict[str, tuple[Path, dict[str, Any]]]
"""scenario -> (results.csv, summary)"""


def run_all(ns: str, work: Path, *, host: str, tls: DevPki | None) -> Runs:
    """Every scenario of SCENARIOS once, from ``ns``, the participants reached at ``host``."""
    runs = {}
    for scenario in SCENARIOS:
        out = work / scenario
        summary = run(
            orchestrator(ns, scenario, out, tls=tls), scenario_env(host, tls=bool(tls)), out
        )
        runs[scenario] = (out / "results.csv", summary)
    return runs


@pytest.fixture(scope="module")
def reference(hosts: Hosts, tmp_path_factory: pytest.TempPathFactory) -> Runs:
    """The loopback runs: participants and orchestrator on one host, 127.0.0.1, plaintext."""
    work = tmp_path_factory.mktemp("loopback")
    with participants(hosts, work, bind="127.0.0.1", tls=None):
        return run_all(hosts.participants, work, host="127.0.0.1", tls=None)


def per_step_ms(summary: dict[str, Any]) -> float:
    return 1000 * float(summary["wall_time_s"]) / int(summary["steps"])


def step_latency(scenario: str, summary: dict[str, Any]) -> str:
    """Median DoStep latency of the scenario's gRPC participants."""
    p50 = {
        n: summary["participants"][n]["do_step_latency_ms"]["p50"] for n in SCENARIOS[scenario][2]
    }
    return " ".join(f"{name} {ms:.2f}" for name, ms in p50.items())


@pytest.mark.slow
def test_tls_across_hosts_gives_the_loopback_results(
    hosts: Hosts, pki: DevPki, reference: Runs, tmp_path: Path, report: Any
) -> None:
    railway_rows = rows(reference["railway"][0])
    assert len(railway_rows) == int(SCENARIOS["railway"][1]) + 1
    assert int(railway_rows[-1]["TrackBalises.balises_passed"]) > 0, "no balise in the run"
    measured: dict[float, Runs] = {}
    for rtt in RTTS_MS:
        work = tmp_path / f"rtt-{rtt:g}"
        work.mkdir()
        with (
            participants(hosts, work, bind=PARTICIPANTS_IP, tls=pki),
            delay(hosts, rtt, work) as address,
        ):
            measured[rtt] = run_all(hosts.orchestrator, work, host=address, tls=pki)
        for scenario, (results, summary) in measured[rtt].items():
            assert results.read_bytes() == reference[scenario][0].read_bytes(), (
                f"{scenario} over TLS at {rtt:g} ms RTT differs from the loopback run ({results})"
            )
            # at least a round trip per step (Jacobi steps the participants concurrently)
            assert per_step_ms(summary) >= rtt

    method = "tc netem on the router" if hosts.netem else "a delay relay on the router (no netem)"
    table = [
        f"grpcs:// + mutual TLS + token across a router; added latency: {method}",
        f"{'scenario':<10} {'link':<26} {'RTT ms':>6} {'ms/step':>8} {'vs 0 ms':>8}  DoStep p50 ms",
    ]
    for scenario in SCENARIOS:
        loopback = reference[scenario][1]
        table.append(
            f"{scenario:<10} {'loopback, plaintext':<26} {'-':>6} "
            f"{per_step_ms(loopback):8.2f} {'':>8}  {step_latency(scenario, loopback)}"
        )
        zero = per_step_ms(measured[0.0][scenario][1])
        for rtt, runs in measured.items():
            summary = runs[scenario][1]
            cost = per_step_ms(summary)
            table.append(
                f"{scenario:<10} {'TLS, other host':<26} {rtt:6g} {cost:8.2f} {cost - zero:+8.2f}"
                f"  {step_latency(scenario, summary)}"
            )
    steps = ", ".join(f"{s}: {reference[s][1]['steps']} steps" for s in SCENARIOS)
    table.append(f"results.csv of every run byte-identical to its loopback run ({steps})")
    report.publish("multihost-rtt.txt", "\n".join(table))


@pytest.mark.slow
def test_link_down_mid_run_fails_within_the_deadline(
    hosts: Hosts, pki: DevPki, tmp_path: Path, report: Any
) -> None:
    out = tmp_path / "results"
    paced = ("--realtime-factor", "60", "--call-timeout", str(CALL_TIMEOUT))
    with participants(hosts, tmp_path, bind=PARTICIPANTS_IP, tls=pki):
        argv = orchestrator(hosts.orchestrator, "railway", out, tls=pki, extra=paced)
        env = {**os.environ, **scenario_env(PARTICIPANTS_IP, tls=True)}
        with (tmp_path / "run.log").open("w") as log:
            process = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=log, stderr=log)
        try:
            deadline = time.monotonic() + 60
            while not (out / "results.csv").exists() or len(rows(out / "results.csv")) < 30:
                assert process.poll() is None, (tmp_path / "run.log").read_text()
                assert time.monotonic() < deadline, "the run did not get going"
                time.sleep(0.05)
            ip("-n", hosts.participants, "link", "set", hosts.participants_link, "down")
            cut = time.monotonic()
            code = process.wait(timeout=60)
            ended_after = time.monotonic() - cut
        finally:
            with contextlib.suppress(RuntimeError):
                ip("-n", hosts.participants, "link", "set", hosts.participants_link, "up")
            if process.poll() is None:
                process.kill()
                process.wait()
    summary = json.loads((out / "summary.json").read_text())
    recorded = rows(out / "results.csv")
    assert code == 1, (tmp_path / "run.log").read_text()
    assert summary["status"] == "failed"
    assert "DEADLINE_EXCEEDED" in summary["reason"], summary["reason"]
    # every completed step is kept: the initial row plus one per step
    assert len(recorded) == summary["steps"] + 1 >= 30
    assert [float(r["time"]) for r in recorded] == [float(k) for k in range(len(recorded))]
    # the step's deadline, then Terminate's and the stream's close, each bounded by it
    assert ended_after <= 3 * CALL_TIMEOUT + 5
    report.publish(
        "multihost-link-down.txt",
        f"link down after {len(recorded) - 1} steps: run {summary['status']} "
        f"{ended_after:.1f} s later (call deadline {CALL_TIMEOUT:g} s); {len(recorded)} rows "
        f"kept; reason: {summary['reason']}",
    )
