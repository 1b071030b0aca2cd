"""The bridge as its own process: OpenRails down at start, and a 400 MB answer.

    python -m coupler.health --gRPC--> python -m openrails_bridge --HTTP--> nothing, then the mock
    RemoteParticipant --gRPC--> python -m openrails_bridge --HTTP--> tiny OpenRails: 400 MB

What a person sees: a process that keeps running and says why it is not ready, never a
traceback; and a process whose memory does not grow with what OpenRails sends.
"""

from __future__ import annotations

import asyncio
import os
import re
import signal
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError

from .support import HUGE, MIB, Firehose, Mock, serve_app, tiny_openrails

pytestmark = pytest.mark.timeout(120)
RSS_LIMIT_MIB = 200
"""Peak RSS the bridge may reach while refusing a 400 MB answer (it idles at about 70 MiB)."""


class BridgeProcess:
    """``python -m openrails_bridge`` on a free port, its address read from its first line."""

    def __init__(self, process: asyncio.subprocess.Process, address: str) -> None:
        self.process = process
        self.address = address

    def peak_rss_mib(self) -> float:
        status = Path(f"/proc/{self.process.pid}/status").read_text()
        match = re.search(r"VmHWM:\s+(\d+) kB", status)
        assert match, status
        return int(match.group(1)) / 1024

    async def stop(self) -> tuple[int, str]:
        """SIGTERM; the exit code and everything it wrote to stderr."""
        if self.process.returncode is None:
            self.process.send_signal(signal.SIGTERM)
        _, err = await asyncio.wait_for(self.process.communicate(), 20.0)
        assert self.process.returncode is not None
        return self.process.returncode, err.decode()


async def start_bridge(openrails_url: str, *options: str) -> BridgeProcess:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "openrails_bridge",
        "--port",
        "0",
        "--openrails-url",
        openrails_url,
        *options,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env={**os.environ, "OPENRAILS_BRIDGE_LOG_JSON": "true"},
    )
    assert process.stdout is not None
    line = (await asyncio.wait_for(process.stdout.readline(), 30.0)).decode()
    match = re.search(r"listening at (grpc://\S+)", line)
    assert match, f"unexpected first line: {line!r}"
    return BridgeProcess(process, match.group(1))


@pytest.fixture
async def processes() -> AsyncIterator[list[BridgeProcess]]:
    started: list[BridgeProcess] = []
    yield started
    for bridge in started:
        if bridge.process.returncode is None:
            bridge.process.kill()
            await bridge.process.wait()


async def health(address: str) -> tuple[int, str]:
    """``python -m coupler.health ADDRESS``: exit code and stderr, as a container probe."""
    probe = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "coupler.health",
        address,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    _, err = await asyncio.wait_for(probe.communicate(), 30.0)
    assert probe.returncode is not None
    return probe.returncode, err.decode()


async def test_openrails_down_at_start_then_up(
    mock: Mock, closed_port: int, processes: list[BridgeProcess]
) -> None:
    url = f"http://127.0.0.1:{closed_port}"
    bridge = await start_bridge(url)
    processes.append(bridge)
    code, said = await health(bridge.address)
    assert code == 1
    assert f"health is NOT_SERVING: cannot reach OpenRails at {url}/API/READY" in said
    async with mock(port=closed_port):
        for _ in range(50):  # the watcher backs off to 1 s between looks
            code, said = await health(bridge.address)
            if code == 0:
                break
            await asyncio.sleep(0.2)
        assert code == 0, said
        async with RemoteParticipant(bridge.address, name="OpenRails") as remote:
            await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
            moving = await remote.do_step(0.0, 0.2, {"throttle": 1.0})
    assert moving["speed"] > 0.0
    exit_code, stderr = await bridge.stop()
    assert exit_code == 0
    assert "Traceback" not in stderr
    assert '"event": "participant_not_serving"' in stderr and url in stderr


async def test_a_huge_answer_leaves_memory_alone(processes: list[BridgeProcess]) -> None:
    firehose = Firehose(declare_length=False)
    async with serve_app(tiny_openrails(step=firehose.handle)) as url:
        bridge = await start_bridge(url)
        processes.append(bridge)
        before = bridge.peak_rss_mib()
        async with RemoteParticipant(bridge.address, name="OpenRails") as remote:
            await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
            with pytest.raises(ParticipantError) as caught:
                await remote.do_step(0.0, 0.2, {"throttle": 0.5})
            after = bridge.peak_rss_mib()
        await asyncio.wait_for(firehose.finished.wait(), 10.0)
    exit_code, stderr = await bridge.stop()
    print(
        f"peak RSS {before:.0f} -> {after:.0f} MiB; {firehose.sent / MIB:.0f} of "
        f"{HUGE / MIB:.0f} MiB sent before the refusal"
    )
    assert after < RSS_LIMIT_MIB and after - before < 50
    assert "more than the 1048576 bytes the bridge reads" in str(caught.value)
    assert exit_code == 0 and "Traceback" not in stderr
