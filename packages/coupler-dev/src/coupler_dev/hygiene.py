"""The suite's hygiene, a pytest plugin: nothing a test starts or makes outlives it (issue 32;
docs/testing.md).

Around each test (setup, call and teardown) it notes what runs and lies on the machine, and
after the teardown it fails the test, naming what the test left behind:

- a **process** of this session still running: one descended from pytest, or one whose
  environment carries this session's ``COUPLER_TEST_SESSION`` token (every process the suite
  starts inherits it, so one whose parent has ended is found too). It is named with its command
  line, its parent and the test its ``PYTEST_CURRENT_TEST`` says it was started by.
- a **listening TCP socket** held by pytest itself (an in-process server not stopped) or by
  such a process.
- an **entry of the session's temp folder**: the session gets a ``TMPDIR`` of its own (pytest's
  ``tmp_path`` folders stay where pytest keeps them), so whatever a test or the code it runs
  makes with ``tempfile`` and does not remove is seen.

What is left is then ended (SIGTERM, then SIGKILL) or removed, so that the next test starts
clean. Processes of other sessions on the machine are never counted nor touched.

What a fixture wider than a test (class, module, package, session) starts while it is set up
belongs to that fixture, not to the test that first asked for it: it is checked when the fixture
is torn down. At the session's end a last sweep ends whatever of the session still runs.

A test whose leftover is a known bug of the product is marked, naming the bug and what it
leaves (the leftover is still removed, and listed at the end of the run):

    @pytest.mark.known_leak(temp="coupler-fmu-*", reason="issue #25 item 4: ...")

Registered by the workspace's pytest options (``-p coupler_dev.hygiene``); ``-p
no:coupler_dev.hygiene`` runs a session without it.
"""

from __future__ import annotations

import contextlib
import fnmatch
import os
import secrets
import shutil
import signal
import tempfile
import time
from collections.abc import Generator, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from coupler_dev.leftovers import (
    ProcessInfo,
    environment_value,
    listening_sockets,
    process_ids,
    read_process,
    socket_inodes,
)

__all__ = ["SESSION_VARIABLE", "Hygiene"]

SESSION_VARIABLE = "COUPLER_TEST_SESSION"
"""The environment variable whose tokens (one per pytest session, nested sessions appended)
mark the processes a session started."""

SETTLE_S = 3.0
"""How long a process or socket found after the teardown is given to finish going (a server
closes its socket on a thread of its own; a killed process ends a moment later)."""

SHARED_HELPERS = (
    # Python's multiprocessing starts these once per interpreter; they end with pytest.
    "from multiprocessing.resource_tracker import main",
    "from multiprocessing.forkserver import main",
)

SHARED_TEMP = (
    # uv's lock files (one per uv cache it used): uv keeps them in TMPDIR by design.
    "uv-*.lock",
)


def shared_temp(name: str) -> bool:
    """Whether a temp entry is a tool's, kept on purpose (``SHARED_TEMP``)."""
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in SHARED_TEMP)


MARKER = (
    "known_leak(temp=GLOBS, process=GLOBS, port=GLOBS, reason=TEXT): the test leaves what the "
    "globs (one or a tuple) match behind because of a known bug named in reason "
    "(coupler_dev.hygiene removes it and lists it at the end of the run instead of failing "
    "the test)"
)


@dataclass(frozen=True)
class Census:
    """What was on the machine at one moment: cheap to take, compared later."""

    pids: frozenset[int]
    sockets: dict[int, str]
    entries: frozenset[str]


@dataclass(frozen=True)
class Leftover:
    """One thing left behind, described for a person."""

    kind: str  # "process", "port", "temp"
    name: str  # what a known_leak glob is matched against
    text: str
    pid: int = 0  # a process's


@dataclass
class Holding:
    """What a fixture wider than a test started or made while it was set up."""

    fixture: str
    pids: set[int] = field(default_factory=set)
    sockets: dict[int, str] = field(default_factory=dict)
    entries: set[str] = field(default_factory=set)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", MARKER)
    if Path("/proc/self/stat").exists():  # Linux; elsewhere the suite runs unchecked
        config.pluginmanager.register(Hygiene(config), "coupler-hygiene")


class Hygiene:
    """The plugin object: one per pytest session."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.pid = os.getpid()
        self.token = secrets.token_hex(8)
        self.root: Path | None = None
        self.saved_environment: dict[str, str | None] = {}
        self.saved_tempdir: str | None = None
        self.before: Census | None = None
        self.holdings: dict[Any, Holding] = {}
        self.reported_sockets: set[int] = set()
        self.found: list[str] = []  # what failed, for the summary at the end
        self.allowed: list[str] = []  # known leaks (marked), for the summary
        self.spent = 0.0  # looking: the census before and after each test
        self.waited = 0.0  # giving leftovers time to go, ending and removing them
        self.tests = 0
        self.started = time.monotonic()

    # -- the session: its marker and its temp folder ----------------------------------------

    @pytest.hookimpl(tryfirst=True)
    def pytest_sessionstart(self, session: pytest.Session) -> None:
        system_temp = tempfile.gettempdir()
        self.root = Path(tempfile.mkdtemp(prefix="coupler-suite-", dir=system_temp))
        tokens = os.environ.get(SESSION_VARIABLE, "").split()
        self._set_environment(
            {
                SESSION_VARIABLE: " ".join([*tokens, self.token]),
                "TMPDIR": str(self.root),
                # pytest's own tmp_path folders stay in the system's temp folder, kept as usual
                "PYTEST_DEBUG_TEMPROOT": os.environ.get("PYTEST_DEBUG_TEMPROOT", system_temp),
            }
        )
        self.saved_tempdir, tempfile.tempdir = tempfile.tempdir, str(self.root)
        self.started = time.monotonic()

    def _set_environment(self, values: dict[str, str]) -> None:
        for name, value in values.items():
            self.saved_environment.setdefault(name, os.environ.get(name))
            os.environ[name] = value

    def pytest_unconfigure(self, config: pytest.Config) -> None:
        for name, value in self.saved_environment.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        tempfile.tempdir = self.saved_tempdir
        if self.root is not None:
            shutil.rmtree(self.root, ignore_errors=True)

    # -- around each test -------------------------------------------------------------------

    @pytest.hookimpl(wrapper=True, tryfirst=True)
    def pytest_runtest_setup(self, item: pytest.Item) -> Generator[None, None, None]:
        began = time.perf_counter()
        self.before = self._census()
        self.spent += time.perf_counter() - began
        return (yield)

    @pytest.hookimpl(wrapper=True, tryfirst=True)
    def pytest_runtest_teardown(
        self, item: pytest.Item, nextitem: pytest.Item | None
    ) -> Generator[None, None, None]:
        try:
            result = yield
        except BaseException:
            report = self._after(item)
            if report:  # the teardown failed already: its error stays the one shown
                item.add_report_section("teardown", "left behind", report)
            raise
        report = self._after(item)
        if report:
            pytest.fail(report, pytrace=False)
        return result

    def _after(self, item: pytest.Item) -> str:
        """What ``item`` left behind, ended and removed; the text of its failure ('' if
        nothing, or only marked known leaks)."""
        began = time.perf_counter()
        try:
            if self.before is None:
                return ""
            self.tests += 1
            left = self._leftovers(self.before)
            self.before = None
            if not left:
                self._unused_markers(item, [])
                return ""
            self._clean(left)
            failing = self._allow_known(item, left)
            if not failing:
                return ""
            self.found += [f"{item.nodeid}:", *(f"  {leftover.text}" for leftover in failing)]
            return describe(failing)
        finally:
            self.spent += time.perf_counter() - began

    def _census(self) -> Census:
        entries = frozenset(os.listdir(self.root)) if self.root is not None else frozenset()
        return Census(frozenset(process_ids()), listening_sockets(), entries)

    def _leftovers(self, before: Census) -> list[Leftover]:
        """What is new since ``before`` and this session's; what runs is given ``SETTLE_S`` to
        go before it counts."""
        first = deadline = time.monotonic() + SETTLE_S
        while True:
            processes = self._new_processes(before)
            sockets = self._held(self._new_sockets(before), processes)
            if not (processes or sockets) or time.monotonic() > deadline:
                break
            first = min(first, time.monotonic())
            time.sleep(0.05)
        self.waited += max(time.monotonic() - first, 0.0)
        self.reported_sockets.update(sockets)
        left = [process_leftover(info) for info in processes.values()]
        left += [port_leftover(address, holder) for address, holder in sockets.values()]
        left += self._new_entries(before)
        return left

    def _new_processes(self, before: Census) -> dict[int, ProcessInfo]:
        return self._claim(process_ids() - before.pids)

    def _new_sockets(self, before: Census) -> dict[int, str]:
        owned = {inode for holding in self.holdings.values() for inode in holding.sockets}
        return {
            inode: address
            for inode, address in listening_sockets().items()
            if inode not in before.sockets and inode not in owned
        }

    def _new_entries(self, before: Census) -> list[Leftover]:
        if self.root is None:
            return []
        owned = {entry for holding in self.holdings.values() for entry in holding.entries}
        new = set(os.listdir(self.root)) - before.entries - owned
        return [temp_leftover(self.root / name) for name in sorted(new) if not shared_temp(name)]

    def _held(
        self, sockets: dict[int, str], processes: dict[int, ProcessInfo]
    ) -> dict[int, tuple[str, str]]:
        """Those of ``sockets`` that pytest itself or one of ``processes`` holds: inode ->
        (address, who holds it)."""
        if not sockets:
            return {}
        holders = {inode: "held by pytest itself" for inode in socket_inodes(self.pid)}
        for pid in processes:
            holders.update({inode: f"held by process {pid}" for inode in socket_inodes(pid)})
        return {
            inode: (address, holders[inode])
            for inode, address in sockets.items()
            if inode in holders
        }

    # -- whose a process is ------------------------------------------------------------------

    def _claim(self, pids: Iterable[int]) -> dict[int, ProcessInfo]:
        """Those of ``pids`` that run, are this session's and no wider fixture's."""
        owned = {pid for holding in self.holdings.values() for pid in holding.pids}
        verdicts: dict[int, str] = {}
        claimed: dict[int, ProcessInfo] = {}
        for pid in pids:
            info = read_process(pid)
            if info is None or not info.running or pid == self.pid:
                continue
            lineage = self._lineage(pid, owned, verdicts)
            if lineage == "owned" or any(helper in info.command for helper in SHARED_HELPERS):
                continue
            if lineage == "ours" or self._marked(info):
                claimed[pid] = info
        return claimed

    def _lineage(self, pid: int, owned: set[int], verdicts: dict[int, str]) -> str:
        """``ours`` when ``pid`` descends from pytest, ``owned`` when from a process a wider
        fixture holds, else ``""``."""
        chain: list[int] = []
        current, verdict = pid, ""
        while current > 1:
            if current in owned:
                verdict = "owned"
                break
            if current == self.pid:
                verdict = "ours"
                break
            if current in verdicts:
                verdict = verdicts[current]
                break
            chain.append(current)
            info = read_process(current)
            if info is None:
                break
            current = info.ppid
        for link in chain:
            verdicts[link] = verdict
        return verdict

    def _marked(self, info: ProcessInfo) -> bool:
        tokens = environment_value(info.environment(), SESSION_VARIABLE) or ""
        return self.token in tokens.split()

    # -- ending and removing what was left -----------------------------------------------------

    def _clean(self, left: list[Leftover]) -> None:
        began = time.perf_counter()
        end_processes([leftover.pid for leftover in left if leftover.kind == "process"])
        for leftover in left:
            if leftover.kind == "temp" and self.root is not None:
                remove(self.root / leftover.name)
        self.waited += time.perf_counter() - began

    def _allow_known(self, item: pytest.Item, left: list[Leftover]) -> list[Leftover]:
        """``left`` less what a ``known_leak`` marker of ``item`` allows (noted for the
        summary)."""
        failing: list[Leftover] = []
        matched: list[pytest.Mark] = []
        for leftover in left:
            mark = known_leak(item, leftover)
            if mark is None:
                failing.append(leftover)
                continue
            matched.append(mark)
            reason = mark.kwargs.get("reason", "")
            self.allowed.append(f"{item.nodeid}: {leftover.text} ({reason})")
        self._unused_markers(item, matched)
        return failing

    def _unused_markers(self, item: pytest.Item, matched: list[pytest.Mark]) -> None:
        for mark in item.iter_markers("known_leak"):
            if all(mark is not used for used in matched):
                self.allowed.append(
                    f"{item.nodeid}: left nothing its known_leak marker allows "
                    f"({mark.kwargs.get('reason', '')}): the marker can go"
                )

    # -- fixtures wider than a test -------------------------------------------------------------

    @pytest.hookimpl(wrapper=True)
    def pytest_fixture_setup(
        self, fixturedef: pytest.FixtureDef[Any], request: pytest.FixtureRequest
    ) -> Generator[None, object, object]:
        if fixturedef.scope == "function":
            return (yield)
        began = time.perf_counter()
        before = self._census()
        self.spent += time.perf_counter() - began
        try:
            return (yield)
        finally:
            began = time.perf_counter()
            holding = Holding(f"fixture {fixturedef.argname!r} ({fixturedef.scope} scope)")
            processes = self._new_processes(before)
            holding.pids = set(processes)
            held = self._held(self._new_sockets(before), processes)
            holding.sockets = {inode: address for inode, (address, _) in held.items()}
            if self.root is not None:
                holding.entries = {
                    name
                    for name in set(os.listdir(self.root)) - before.entries
                    if not shared_temp(name)
                }
            self.holdings[fixturedef] = holding
            self.spent += time.perf_counter() - began

    def pytest_fixture_post_finalizer(
        self, fixturedef: pytest.FixtureDef[Any], request: pytest.FixtureRequest
    ) -> None:
        holding = self.holdings.pop(fixturedef, None)
        if holding is None:
            return
        began = time.perf_counter()
        left = self._still_held(holding)
        if left:
            self._clean(left)
            self.found += [f"{holding.fixture}:", *(f"  {leftover.text}" for leftover in left)]
        self.spent += time.perf_counter() - began
        if left:
            pytest.fail(f"{holding.fixture}: {describe(left)}", pytrace=False)

    def _still_held(self, holding: Holding) -> list[Leftover]:
        first = deadline = time.monotonic() + SETTLE_S
        while True:
            pids = descendants(holding.pids)
            running = {pid: info for pid in pids if (info := read_process(pid)) and info.running}
            listening = listening_sockets()
            sockets = self._held(
                {inode: a for inode, a in holding.sockets.items() if inode in listening}, running
            )
            if not (running or sockets) or time.monotonic() > deadline:
                break
            first = min(first, time.monotonic())
            time.sleep(0.05)
        self.waited += max(time.monotonic() - first, 0.0)
        left = [process_leftover(info) for info in running.values()]
        left += [port_leftover(address, holder) for address, holder in sockets.values()]
        if self.root is not None:
            left += [
                temp_leftover(self.root / name)
                for name in sorted(holding.entries)
                if os.path.lexists(self.root / name)
            ]
        return left

    # -- the end of the session -------------------------------------------------------------------

    @pytest.hookimpl(trylast=True)
    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        """The last sweep, after every fixture was torn down (also after Ctrl-C)."""
        began = time.perf_counter()
        left = [process_leftover(info) for info in self._claim(process_ids()).values()]
        mine = socket_inodes(self.pid) - self.reported_sockets
        left += [
            port_leftover(address, "held by pytest itself")
            for inode, address in listening_sockets().items()
            if inode in mine
        ]
        if self.root is not None:
            left += [
                temp_leftover(self.root / name)
                for name in sorted(os.listdir(self.root))
                if not shared_temp(name)
            ]
        if left:
            self._clean(left)
            self.found += ["at the end of the session:", *(f"  {x.text}" for x in left)]
            if session.exitstatus == pytest.ExitCode.OK:
                session.exitstatus = pytest.ExitCode.TESTS_FAILED
        self.spent += time.perf_counter() - began

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if self.found:
            terminalreporter.section("left behind (coupler_dev.hygiene)", red=True)
            for line in self.found:
                terminalreporter.write_line(line)
        if self.allowed:
            terminalreporter.section("known leaks (known_leak markers)", yellow=True)
            for line in self.allowed:
                terminalreporter.write_line(line)
        wall = max(time.monotonic() - self.started, 1e-9)
        looked = self.spent - self.waited
        terminalreporter.write_line(
            f"hygiene: {self.tests} tests checked in {looked:.2f} s "
            f"({100 * looked / wall:.2f} % of the session's {wall:.0f} s)"
            + (f"; {self.waited:.1f} s more went on leftovers" if self.waited >= 0.05 else "")
        )


def describe(left: list[Leftover]) -> str:
    kinds = {leftover.kind for leftover in left}
    done = [
        *(["the processes were ended"] if "process" in kinds else []),
        *(["the temp entries removed"] if "temp" in kinds else []),
    ]
    return "\n".join(
        [
            "left behind (own what a test starts: coupler.testing.process_group, served, "
            "a fixture; docs/testing.md):",
            *(f"  {leftover.text}" for leftover in left),
            *([f"({', '.join(done)} by coupler_dev.hygiene)"] if done else []),
        ]
    )


def process_leftover(info: ProcessInfo) -> Leftover:
    started = environment_value(info.environment(), "PYTEST_CURRENT_TEST")
    parent = read_process(info.ppid)
    origin = f"parent {info.ppid}" + (f" `{parent.command}`" if parent and info.ppid > 1 else "")
    if started:
        origin += f", started during {started}"
    text = f"process {info.pid} `{info.command}` ({origin})"
    return Leftover("process", info.command, text, pid=info.pid)


def port_leftover(address: str, holder: str) -> Leftover:
    return Leftover("port", address, f"port {address} listening, {holder}")


def temp_leftover(path: Path) -> Leftover:
    kind = "folder" if path.is_dir() and not path.is_symlink() else "file"
    return Leftover("temp", path.name, f"temp {kind} {path}")


def known_leak(item: pytest.Item, leftover: Leftover) -> pytest.Mark | None:
    """The ``known_leak`` marker of ``item`` whose glob matches ``leftover``, if any."""
    for mark in item.iter_markers("known_leak"):
        patterns = mark.kwargs.get(leftover.kind, ())
        patterns = (patterns,) if isinstance(patterns, str) else tuple(patterns)
        if any(fnmatch.fnmatchcase(leftover.name, pattern) for pattern in patterns):
            return mark
    return None


def descendants(pids: Iterable[int]) -> set[int]:
    """``pids`` and every process below them (children as the kernel lists them)."""
    found: set[int] = set()
    todo = list(pids)
    while todo:
        pid = todo.pop()
        if pid in found:
            continue
        found.add(pid)
        with contextlib.suppress(OSError):
            for task in os.listdir(f"/proc/{pid}/task"):
                children = Path(f"/proc/{pid}/task/{task}/children").read_text().split()
                todo += [int(child) for child in children]
    return found


def end_processes(pids: list[int], *, grace: float = 2.0) -> None:
    """SIGTERM, up to ``grace`` seconds, SIGKILL for those still running; those that are this
    process's children are reaped."""
    for number in (signal.SIGTERM, signal.SIGKILL):
        for pid in [pid for pid in pids if alive(pid)]:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, number)
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and any(alive(pid) for pid in pids):
            time.sleep(0.05)
    for pid in pids:
        with contextlib.suppress(ChildProcessError, OSError):
            os.waitpid(pid, os.WNOHANG)


def alive(pid: int) -> bool:
    info = read_process(pid)
    return info is not None and info.running


def remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()
