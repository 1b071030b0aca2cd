"""The documentation's shell blocks run as written, so a command in the docs is a command that
works.

Every fenced block labelled ``sh`` in README.md, docs/*.md and the READMEs of scenarios,
services, packages and examples runs here, in a fresh ``bash`` with ``set -euo pipefail``,
unless the line before it says why it cannot::

    <!-- docs-test: skip (needs a Docker engine) -->

A block of another language becomes a file the page's shell blocks use when the line before it
names the file (the page tells the reader to save it under that name)::

    <!-- docs-test: file controller.py -->

A block that takes long (a whole scenario run, a campaign) runs with the slow tests (``make
test-slow``, which CI runs; docs/testing.md) when the line before it says why::

    <!-- docs-test: slow (runs the railway scenario for 60 simulated seconds) -->

How a block runs:

- in a sandbox: a temporary folder with the repository's top-level entries linked in (the
  workspace ``.venv`` included) and a ``build/`` of its own holding a copy of ``build/fmus``
  and ``build/routes`` (the railway's OpenRails route), so what a block writes (results, logs,
  certificates, FMUs) stays out of the checkout; the page's files (above) are written there
  before each of its shell blocks runs;
- with PATH as a new user has it after ``make setup``: no virtual environment, no uv on it, so
  every command must name ``.venv/bin/...`` or a make target;
- with the well-known ports (2150, 8080, 50051, 50061, 50062, 50063-50066, 50071, 50080, 50082,
  50443) replaced by free ones in the block's text, the page's files and the variables the SSDs
  and fleet files read (MOCK_PORT, GAIN_PORT, ...): blocks may start servers without colliding with a demo, another test or
  another block, and the docs keep showing the ports a person uses;
- with a deadline; the processes it started (found by a marker in their environment) must be
  gone when it ends — a block that starts a server stops it (``kill %1``) — and are killed
  either way.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

from coupler.testing import free_port

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted(
    [
        ROOT / "README.md",
        *(ROOT / "docs").glob("*.md"),
        *ROOT.glob("scenarios/*/README.md"),
        *ROOT.glob("services/*/README.md"),
        *ROOT.glob("packages/*/README.md"),
        *ROOT.glob("examples/*/README.md"),
    ]
)
PORT_VARIABLES = {
    2150: "MOCK_PORT",
    8080: "MAP_HTTP_PORT",
    8090: "MONITOR_PORT",
    50051: "GAIN_PORT",
    50080: "",
    50082: "CONTROLLER_PORT",
    50061: "BRIDGE_PORT",
    50062: "BALISE_PORT",
    50063: "PERCEPTION_PORT",
    50064: "LOCALISATION_PORT",
    50065: "ODOMETER_PORT",
    50066: "TRANSMISSION_PORT",
    50071: "MAP_PORT",
    50443: "",
}
"""Well-known ports of the docs and the environment variable that moves each (SSDs, fleets)."""
SKIP = re.compile(r"^\s*<!--\s*docs-test:\s*skip\s*\((?P<reason>[^)]+)\)\s*-->\s*$")
FILE = re.compile(r"^\s*<!--\s*docs-test:\s*file\s+(?P<name>[\w.-]+)\s*-->\s*$")
SLOW = re.compile(r"^\s*<!--\s*docs-test:\s*slow\s*\((?P<reason>[^)]+)\)\s*-->\s*$")
FENCE = re.compile(r"^(?P<indent>\s*)```(?P<lang>[\w-]*)\s*$")
COMMAND_START = re.compile(r"^\s*(\.venv/bin/|python3? |make |coupler |uv |docker |npm )")
BARE_UV = re.compile(r"(?<![\w/.-])uv run\b")
"""A reader sent to ``uv run`` (Dockerfile internals such as ``uv sync`` in an image are fine)."""
LEFTOVER_GRACE_S = 10.0
BLOCK_TIMEOUT_S = 300.0
KEPT_OUT = {".git", "build", "results", "test-artifacts", ".pytest_cache"}


@dataclass(frozen=True)
class Block:
    """One fenced block of a document."""

    doc: Path
    line: int
    """Line of the opening fence (1-based)."""
    lang: str
    text: str
    skip: str | None
    """The reason given in the skip marker, None when the block runs."""
    file: str | None = None
    """The name the file marker gives the block: written into the sandbox for the page's
    shell blocks."""
    slow: str | None = None
    """The reason given in the slow marker: the block runs with the slow tests."""

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def blocks_of(doc: Path) -> list[Block]:
    lines = doc.read_text(encoding="utf-8").splitlines()
    found = []
    i = 0
    while i < len(lines):
        fence = FENCE.match(lines[i])
        if not fence:
            i += 1
            continue
        indent, start = len(fence["indent"]), i
        body = []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            kept = not indent or lines[i][:indent].isspace()  # "".isspace() is False
            body.append(lines[i][indent:] if kept else lines[i].lstrip())
            i += 1
        before = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        marker, file, slow = SKIP.match(before), FILE.match(before), SLOW.match(before)
        found.append(
            Block(
                doc=doc,
                line=start + 1,
                lang=fence["lang"],
                text="\n".join(body) + "\n",
                skip=marker["reason"].strip() if marker else None,
                file=file["name"] if file else None,
                slow=slow["reason"].strip() if slow else None,
            )
        )
        i += 1
    return found


ALL_BLOCKS = [block for doc in DOCS for block in blocks_of(doc)]
RUNNABLE = [b for b in ALL_BLOCKS if b.lang == "sh" and b.skip is None]
FILES = [b for b in ALL_BLOCKS if b.file is not None]


def test_the_docs_follow_the_convention() -> None:
    """Shell blocks are labelled ``sh`` (so they run or say why not), no doc sends a reader to
    a bare ``uv`` (it is not on PATH after ``make setup``), and a skip marker gives a reason
    and stands before a shell block."""
    problems = []
    for block in ALL_BLOCKS:
        if block.lang in {"bash", "shell", "console", "zsh"}:
            problems.append(f"{block.where}: label the block ```sh (it then runs in this test)")
        if block.lang == "" and any(COMMAND_START.match(line) for line in block.text.splitlines()):
            problems.append(f"{block.where}: commands in an unlabelled block; label it ```sh")
        if block.skip is not None and block.lang != "sh":
            problems.append(f"{block.where}: a docs-test skip marker before a non-sh block")
        if block.slow is not None and block.lang != "sh":
            problems.append(f"{block.where}: a docs-test slow marker before a non-sh block")
        if block.file is not None and block.lang == "sh":
            problems.append(f"{block.where}: a docs-test file marker before a shell block")
    named: dict[str, Block] = {}
    for block in FILES:
        if (first := named.setdefault(str(block.file), block)) is not block:
            problems.append(f"{block.where}: file {block.file} is also {first.where}'s")
    for doc in DOCS:
        for number, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            if BARE_UV.search(line):
                problems.append(
                    f"{doc.relative_to(ROOT)}:{number}: a bare `uv` command; write .venv/bin/... "
                    f"or a make target"
                )
            if "docs-test" in line and "skip" in line and not SKIP.match(line):
                problems.append(
                    f"{doc.relative_to(ROOT)}:{number}: write <!-- docs-test: skip (REASON) -->"
                )
            if "docs-test" in line and "file" in line and not FILE.match(line):
                problems.append(
                    f"{doc.relative_to(ROOT)}:{number}: write <!-- docs-test: file NAME -->"
                )
            if "docs-test" in line and "slow" in line and not SLOW.match(line):
                problems.append(
                    f"{doc.relative_to(ROOT)}:{number}: write <!-- docs-test: slow (REASON) -->"
                )
    assert not problems, "\n".join(problems)
    assert len(RUNNABLE) >= 8, "the docs lost their runnable examples"


@pytest.fixture(scope="module")
def sandbox(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder that looks like the checkout after ``make setup``, writes kept apart."""
    home = tmp_path_factory.mktemp("docs-sandbox")
    for entry in ROOT.iterdir():
        if entry.name not in KEPT_OUT:
            (home / entry.name).symlink_to(entry)
    fmus = ROOT / "build" / "fmus"
    if not (fmus / "TrackBalises.fmu").exists():
        pytest.fail(f"{fmus} lacks the FMUs: run `make setup` (make test does)")
    shutil.copytree(fmus, home / "build" / "fmus")
    routes = ROOT / "build" / "routes"
    if not (routes / "annaberg-schwarzenberg").is_dir():
        pytest.fail(f"{routes} lacks the railway's route: run `make setup` (make test does)")
    shutil.copytree(routes, home / "build" / "routes")
    return home


def user_environment(marker: str, ports: dict[int, int]) -> dict[str, str]:
    """The environment a person has after ``make setup``: no virtual environment active."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("VIRTUAL_ENV", "PYTEST_", "COUPLER_", "UV_"))
        and k not in PORT_VARIABLES.values()
    }
    env["PATH"] = os.pathsep.join(
        p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p
    )
    env["COUPLER_DOCS_TEST"] = marker
    for well_known, port in ports.items():
        if PORT_VARIABLES[well_known]:
            env[PORT_VARIABLES[well_known]] = str(port)
    return env


def processes_with(marker: str) -> dict[int, str]:
    """pid -> command line of every process whose environment carries ``marker``."""
    needle = f"COUPLER_DOCS_TEST={marker}".encode()
    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            if needle in Path(f"/proc/{entry}/environ").read_bytes().split(b"\0"):
                command = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ")
                found[int(entry)] = command.decode(errors="replace").strip()
        except OSError:
            continue
    return found


def kill_all(pids: dict[int, str]) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            continue


def remap(text: str, ports: dict[int, int]) -> str:
    pattern = re.compile(r"(?<![\d.])(" + "|".join(map(str, ports)) + r")(?![\d])")
    return pattern.sub(lambda m: str(ports[int(m.group(1))]), text)


@pytest.mark.timeout(BLOCK_TIMEOUT_S + 60)
@pytest.mark.parametrize(
    "block",
    [pytest.param(b, id=b.where, marks=[pytest.mark.slow] if b.slow else []) for b in RUNNABLE],
)
def test_shell_block_runs(block: Block, sandbox: Path) -> None:
    ports = {well_known: free_port() for well_known in PORT_VARIABLES}
    marker = uuid.uuid4().hex
    script = "set -euo pipefail\n" + remap(block.text, ports)
    for file in FILES:
        if file.doc == block.doc:
            (sandbox / str(file.file)).write_text(remap(file.text, ports), encoding="utf-8")
    log = sandbox / f"block-{marker}.log"
    with log.open("w") as output:  # a file, not a pipe: a leftover server must not block us
        process = subprocess.Popen(
            ["bash", "-c", script],
            cwd=sandbox,
            env=user_environment(marker, ports),
            stdin=subprocess.DEVNULL,
            stdout=output,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        try:
            process.wait(timeout=BLOCK_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
            kill_all(processes_with(marker))
            pytest.fail(f"{block.where}: still running after {BLOCK_TIMEOUT_S:g} s\n{log.read_text()}")
    deadline = time.monotonic() + LEFTOVER_GRACE_S
    while (left := processes_with(marker)) and time.monotonic() < deadline:
        time.sleep(0.1)
    kill_all(left)
    assert process.returncode == 0, (
        f"{block.where} failed (exit {process.returncode}):\n{script}\n--- output ---\n"
        f"{log.read_text()}"
    )
    assert not left, (
        f"{block.where} left processes running (stop what the block starts, e.g. kill %1): "
        + "; ".join(f"pid {pid}: {command}" for pid, command in left.items())
    )
