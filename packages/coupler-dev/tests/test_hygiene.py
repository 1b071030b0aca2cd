"""coupler_dev.hygiene, the suite's check that nothing outlives its test, as the suite meets it:
pytest run as a subprocess on a small test file that forgets a process, a port or a temp folder
fails, naming what was left, and nothing of it survives the run.

    this test --process_group--> pytest -p coupler_dev.hygiene leaky/test_x.py
                                     '--> the leaky test --> sleep 300 (forgotten)
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import threading
import uuid
from pathlib import Path

import pytest

from coupler.testing import process_group, wait_until
from coupler_dev.engine import Engine
from coupler_dev.hygiene import SESSION_VARIABLE

INI = """\
[pytest]
addopts = -p coupler_dev.hygiene -p no:cacheprovider
asyncio_default_fixture_loop_scope = function
"""


def pytest_on(folder: Path, source: str, *args: str) -> tuple[int, str]:
    """pytest run on ``source`` as test_x.py in ``folder``: its exit code and output."""
    folder.mkdir(exist_ok=True)
    (folder / "pytest.ini").write_text(INI)
    (folder / "test_x.py").write_text(textwrap.dedent(source))
    command = [sys.executable, "-m", "pytest", "-q", "test_x.py", *args]
    options = {"cwd": folder, "stdout": subprocess.PIPE, "stderr": subprocess.STDOUT, "text": True}
    with process_group(command, **options) as pytest_run:
        out, _ = pytest_run.communicate(timeout=90)
    return pytest_run.returncode, out


def running_with(tag: str) -> list[str]:
    """The command lines of this machine's processes that contain ``tag``."""
    found = []
    for name in filter(str.isdigit, os.listdir("/proc")):
        try:
            command = Path(f"/proc/{name}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            state = Path(f"/proc/{name}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if tag in command and state != "Z":
            found.append(command)
    return found


SLEEPER = "import time; time.sleep(300)  # {tag}"


@pytest.mark.slow
@pytest.mark.parametrize(
    "how",
    [
        "subprocess.Popen([sys.executable, '-c', SLEEPER])",
        # the case: its parent has ended, so it is nobody's child (parent 1) but its
        # environment still carries the session's token and the test's name
        "subprocess.run([sys.executable, '-c', "
        'f\'import subprocess, sys; subprocess.Popen([sys.executable, "-c", {SLEEPER!r}], '
        "start_new_session=True)'], check=True)",
    ],
    ids=["child", "orphan"],
)
def test_a_forgotten_process_fails_its_test_named_and_is_ended(tmp_path: Path, how: str) -> None:
    tag = f"forgotten-{uuid.uuid4().hex}"
    code, out = pytest_on(
        tmp_path,
        f"""
        import subprocess, sys
        SLEEPER = {SLEEPER.format(tag=tag)!r}

        def test_forgets():
            {how}

        def test_next():
            pass
        """,
    )
    assert code == 1, out
    assert "2 passed, 1 error" in out
    assert "ERROR at teardown of test_forgets" in out
    # at the test's error and in the list at the end of the run (and, where pytest runs on CI,
    # once more in the short summary, which then shows whole messages)
    line, *again = [
        line for line in out.splitlines() if line.startswith("  process ") and tag in line
    ]
    assert again and set(again) == {line}, out
    left_behind = out.split("left behind (coupler_dev.hygiene)", 1)[1]
    assert line in left_behind.split("short test summary info", 1)[0]
    assert f"-c {SLEEPER.format(tag=tag)}`" in line  # the command line that started it
    assert "started during test_x.py::test_forgets (call)" in line
    assert "the processes were ended" in out
    assert running_with(tag) == []


@pytest.mark.slow
def test_a_forgotten_server_port_fails_its_test_named(tmp_path: Path) -> None:
    code, out = pytest_on(
        tmp_path,
        """
        import socket
        KEPT = []

        def test_forgets():
            server = socket.socket()
            server.bind(("127.0.0.1", 0))
            server.listen()
            KEPT.append(server)
            print("PORT", server.getsockname()[1])

        def test_next():
            pass
        """,
        "-s",
    )
    assert code == 1, out
    (port,) = re.findall(r"^PORT (\d+)", out, re.MULTILINE)
    assert "ERROR at teardown of test_forgets" in out
    assert f"  port 127.0.0.1:{port} listening, held by pytest itself" in out
    assert "2 passed, 1 error" in out  # reported once, by the test that opened it


def test_a_forgotten_temp_folder_fails_its_test_named_and_is_removed(tmp_path: Path) -> None:
    code, out = pytest_on(
        tmp_path,
        """
        import tempfile

        def test_forgets(tmp_path):
            (tmp_path / "kept.txt").write_text("pytest's own tmp_path is not a leftover")
            print("MADE", tempfile.mkdtemp(prefix="coupler-fmu-"))

        def test_next():
            pass
        """,
        "-s",
    )
    assert code == 1, out
    (made,) = re.findall(r"^MADE (\S+)", out, re.MULTILINE)
    assert f"  temp folder {made}\n" in out
    assert "ERROR at teardown of test_forgets" in out
    assert "2 passed, 1 error" in out
    assert not Path(made).exists()
    assert not Path(made).parent.exists()  # the session's temp folder ends with it


ENGINE = Engine.find()


@pytest.mark.skipif(ENGINE is None, reason="no container engine runs on this machine")
def test_a_forgotten_network_and_volume_fail_their_test_named(tmp_path: Path) -> None:
    """With an engine running, what a test leaves in it is named (never removed: the engine is
    the machine's); what the test removes again is not."""
    tag = f"coupler-hygiene-{uuid.uuid4().hex[:8]}"
    try:
        code, out = pytest_on(
            tmp_path,
            f"""
            import subprocess

            def docker(*args):
                subprocess.run(["docker", *args], check=True, capture_output=True)

            def test_forgets():
                docker("network", "create", "{tag}-net")
                docker("volume", "create", "{tag}-vol")

            def test_cleans_up():
                docker("network", "create", "{tag}-tidy")
                docker("network", "rm", "{tag}-tidy")
            """,
        )
        assert code == 1, out
        assert re.search(rf"^  network {tag}-net \(driver bridge\)$", out, re.MULTILINE), out
        assert re.search(rf"^  volume {tag}-vol \(at \S+\)$", out, re.MULTILINE), out
        assert "ERROR at teardown of test_forgets" in out
        assert "the engine's objects left as they are" in out
        assert "2 passed, 1 error" in out
        assert f"{tag}-tidy" not in out
    finally:
        for kind in ("network", "volume"):
            subprocess.run(["docker", kind, "rm", f"{tag}-{kind[:3]}"], capture_output=True)


@pytest.mark.slow
def test_what_a_test_owns_passes_and_wider_fixtures_are_checked_when_torn_down(
    tmp_path: Path,
) -> None:
    tag = f"owned-{uuid.uuid4().hex}"
    code, out = pytest_on(
        tmp_path,
        f"""
        import subprocess, sys, tempfile, pytest
        from coupler.examples.gain import GainParticipant
        from coupler.testing import process_group, served_in_thread
        SLEEPER = "import time; time.sleep(300)  # {tag}"

        @pytest.fixture(scope="module")
        def shared():  # a module's process, ended by its fixture
            with process_group([sys.executable, "-c", SLEEPER]) as process:
                yield process

        @pytest.fixture(scope="module")
        def careless():  # a module's process its fixture forgets
            yield subprocess.Popen([sys.executable, "-c", SLEEPER])

        def test_owns_a_process_group_a_server_and_a_temp_folder():
            with process_group([sys.executable, "-c", SLEEPER]), tempfile.TemporaryDirectory():
                with served_in_thread(GainParticipant()):
                    pass

        def test_uses_the_module_process(shared):
            assert shared.poll() is None

        def test_uses_it_too(shared):
            assert shared.poll() is None

        def test_uses_the_careless_fixture(careless):
            assert careless.poll() is None

        @pytest.mark.known_leak(temp="coupler-fmu-*", reason="issue #25 item 4 (demo)")
        def test_a_known_leak():
            tempfile.mkdtemp(prefix="coupler-fmu-")
        """,
    )
    assert code == 1, out
    assert "5 passed, 1 error" in out
    errors = re.findall(r"^_+ ERROR at teardown of (\S+) _+$", out, re.MULTILINE)
    assert errors == ["test_a_known_leak"]  # the careless module fixture ends after it
    assert "fixture 'careless' (module scope): left behind" in out
    assert "known leaks (known_leak markers)" in out
    assert "test_x.py::test_a_known_leak: temp folder" in out
    assert "(issue #25 item 4 (demo))" in out
    assert running_with(tag) == []


def test_processes_of_another_session_are_neither_counted_nor_ended(tmp_path: Path) -> None:
    """A process that starts on the machine during the test, neither below this pytest nor
    carrying its session's token (another engineer's), is left alone."""
    tag = f"foreign-{uuid.uuid4().hex}"
    started, seen = tmp_path / "started", tmp_path / "seen"
    foreign_env = {k: v for k, v in os.environ.items() if k != SESSION_VARIABLE}
    foreign: list[subprocess.Popen[bytes]] = []

    def start_foreign() -> None:  # while the inner test waits
        wait_until(started.exists, 60, what="the inner test to start")
        foreign.append(
            subprocess.Popen(
                [sys.executable, "-c", SLEEPER.format(tag=tag)],
                env=foreign_env,
                start_new_session=True,
            )
        )
        seen.write_text(str(foreign[0].pid))

    helper = threading.Thread(target=start_foreign, daemon=True)
    helper.start()
    try:
        code, out = pytest_on(
            tmp_path / "inner",
            f"""
            import time
            from pathlib import Path

            def test_waits_for_a_foreign_process():
                Path({str(started)!r}).touch()
                while not Path({str(seen)!r}).exists():
                    time.sleep(0.05)
            """,
        )
        helper.join(10)
        assert code == 0, out
        assert "1 passed" in out
        assert foreign and foreign[0].poll() is None  # still running: not the inner's to end
    finally:
        for process in foreign:
            process.kill()
            process.wait()
