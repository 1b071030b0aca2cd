"""coupler.testing, as a participant author uses it: a real server on a free port (in this event
loop or in a thread), a real participant process waited for and ended with everything it
started, whichever way the test leaves the block."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time

import pytest

from coupler.client import RemoteParticipant
from coupler.errors import ParticipantUnavailable
from coupler.examples.gain import GainParticipant
from coupler.testing import (
    eventually,
    free_port,
    free_ports,
    process_group,
    served,
    served_in_thread,
    wait_until,
    wait_until_serving,
)

SPAWNS_A_GRANDCHILD = """
import subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
print(child.pid, flush=True)
time.sleep(120)
"""


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie waiting for its parent counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def listening(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) == 0


async def test_served_gives_a_real_server_on_a_free_port_and_stops_it() -> None:
    async with served(GainParticipant()) as server:
        async with RemoteParticipant(server.address) as remote:
            description = await remote.describe()
        assert description == await GainParticipant().describe()
        port = server.port
    assert port != 0 and not listening(port)


def test_served_in_thread_serves_synchronous_code() -> None:
    with served_in_thread(GainParticipant()) as server:
        probe = [sys.executable, "-m", "coupler.health", server.address]
        assert subprocess.run(probe, capture_output=True, check=False).returncode == 0
        port = server.port
    assert not listening(port)


async def test_a_participant_process_is_waited_for_then_ended() -> None:
    port = free_port()
    address = f"grpc://127.0.0.1:{port}"
    command = [sys.executable, "-m", "coupler.examples", "gain", "--port", str(port)]
    with process_group(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) as gain:
        await wait_until_serving(address)
        assert gain.poll() is None
    assert gain.returncode is not None and not listening(port)
    with pytest.raises(ParticipantUnavailable, match=str(port)):
        await wait_until_serving(address, within=0.5)


@pytest.mark.parametrize("leaving", [AssertionError, KeyboardInterrupt, TimeoutError])
def test_a_process_group_ends_with_its_grandchildren_however_the_block_is_left(
    leaving: type[BaseException],
) -> None:
    command = [sys.executable, "-c", SPAWNS_A_GRANDCHILD]
    with (
        pytest.raises(leaving),
        process_group(command, stdout=subprocess.PIPE, text=True, grace=1) as parent,
    ):
        assert parent.stdout is not None
        grandchild = int(parent.stdout.readline())
        assert alive(parent.pid) and alive(grandchild)
        raise leaving("the test fails, is interrupted or times out here")
    assert parent.returncode is not None
    wait_until(lambda: not alive(grandchild), 5, what=f"grandchild {grandchild} to end")
    assert parent.stdout is not None and parent.stdout.closed


def test_a_process_group_ends_with_what_it_started_in_sessions_of_their_own() -> None:
    """As ``coupler fleet`` starts each service: a session of its own, outside the group."""
    command = [
        sys.executable,
        "-c",
        SPAWNS_A_GRANDCHILD.replace("])", "], start_new_session=True)"),
    ]
    with process_group(command, stdout=subprocess.PIPE, text=True, grace=1) as parent:
        assert parent.stdout is not None
        grandchild = int(parent.stdout.readline())
        assert os.getsid(grandchild) == grandchild != os.getsid(parent.pid)
    wait_until(lambda: not alive(grandchild), 5, what=f"grandchild {grandchild} to end")


def test_wait_until_gives_what_the_condition_gave_or_says_what_it_waited_for() -> None:
    started = time.monotonic()
    assert wait_until(lambda: time.monotonic() - started > 0.1 and "late", 5) == "late"
    with pytest.raises(TimeoutError, match="the sky to fall"):
        wait_until(lambda: False, 0.2, what="the sky to fall")


async def test_eventually_retries_until_the_attempt_passes() -> None:
    attempts: list[int] = []

    async def attempt() -> int:
        attempts.append(1)
        assert len(attempts) >= 3
        return len(attempts)

    assert await eventually(attempt) == 3
    with pytest.raises(AssertionError):
        await eventually(attempt_failing, within=0.2)


async def attempt_failing() -> None:
    raise AssertionError("never")


def test_free_port_is_free() -> None:
    port = free_port()
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", port))


def test_free_ports_are_different_and_free() -> None:
    ports = free_ports(8)
    assert len(set(ports)) == 8
    with contextlib.ExitStack() as stack:
        for port in ports:
            stack.enter_context(socket.socket()).bind(("127.0.0.1", port))
