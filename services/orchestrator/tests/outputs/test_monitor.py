"""The live monitor (``coupler run --monitor``) with a real run: FMUs in-process and the example
gain participant over gRPC (tests/data/mixed.ssd), paced so the page sees it move.

    run_scenario --events--> MonitorState <--frames-- aiohttp /api/events (SSE) --> Chromium
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from coupler.server import ParticipantServer
from coupler.testing import eventually
from coupler_dev.browser import CHROMIUM, NO_CHROMIUM, chromium
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.outputs.monitor import (
    Decimated,
    MonitorError,
    MonitorServer,
    MonitorState,
    parse_address,
)
from coupler_orchestrator.runner import run_scenario

from ..support import DATA, REPO, Coupler

ARTIFACT = REPO / "test-artifacts" / "monitor.png"
MEMBERS = ["Source", "Gain", "Feed", "Feed2"]


async def frames(url: str, count: int, query: str = "") -> list[dict[str, Any]]:
    """The first ``count`` frames of the monitor's event stream."""
    found: list[dict[str, Any]] = []
    async with aiohttp.ClientSession() as session, session.get(f"{url}api/events{query}") as reply:
        async for line in reply.content:
            if line.startswith(b"data: "):
                found.append(json.loads(line[6:]))
                if len(found) == count:
                    return found
    return found


def run(stop: float, rtf: float | None, monitor: MonitorServer, out: Path) -> Any:
    options = RunOptions(stop_time=stop, step_size=0.1, realtime_factor=rtf)
    return run_scenario(DATA / "mixed.ssd", options, out_dir=out, observers=[monitor.state])


@pytest.mark.slow
@pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)
async def test_the_page_charts_a_picked_channel_and_each_participants_latency(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    async with MonitorServer("127.0.0.1:0") as monitor:
        # 8 s of wall time: long enough for a browser that starts slowly on a busy machine to
        # see the chart move
        running = asyncio.create_task(run(8.0, 1.0, monitor, tmp_path))
        async with chromium() as browser:
            page = await browser.new_page(viewport={"width": 1200, "height": 900})
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            await page.goto(monitor.url)
            await page.wait_for_function("window.monitor.channels.length > 0")
            await page.check("#channels input[value='Gain.y']")
            gain = "window.monitor.values['Gain.y']"
            await page.wait_for_function(f"{gain} && {gain}.data[0].length > 3")
            first = await page.evaluate("window.monitor.values['Gain.y'].data[0].length")
            await page.wait_for_function(
                f"window.monitor.values['Gain.y'].data[0].length > {first + 3}"
            )  # the chart moves
            status = await page.text_content("#status")
            latency = await page.evaluate(
                "Array.from(document.querySelectorAll('#latency-table tbody tr'))"
                ".map((row) => row.cells[0].textContent)"
            )
            series = await page.evaluate(
                "window.monitor.latency.series.slice(1).map((s) => s.label)"
            )
            ARTIFACT.parent.mkdir(exist_ok=True)
            await page.screenshot(path=str(ARTIFACT), full_page=True)
            outcome = await running
            await page.wait_for_function(
                "document.getElementById('status').textContent === 'completed'"
            )
            drawn = await page.evaluate("window.monitor.values['Gain.y'].data[0].length")
    assert status == "running"
    assert latency == MEMBERS and series == MEMBERS
    assert outcome.end.status == "completed"
    assert drawn == 81  # every point of t = 0 .. 8 s, h = 0.1 s
    assert errors == []
    assert ARTIFACT.stat().st_size > 20_000


async def test_a_late_joiner_gets_the_history(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    async with MonitorServer("0") as monitor:
        outcome = await run(3.0, None, monitor, tmp_path)
        _state, frame = await frames(monitor.url, 2, "?channels=Gain.y,Feed.real_out,Nope.x")
    assert outcome.end.status == "completed"
    assert frame["header"]["status"] == "completed"
    assert frame["header"]["progress"] == pytest.approx(1.0)
    assert frame["layout"]["members"] == MEMBERS
    assert {"name": "Gain.y", "unit": "m/s"} in frame["layout"]["channels"]
    values = frame["values"]
    assert values["t"] == [k / 10 for k in range(31)]  # the grid as written: 0.3, not 0.30...04
    assert set(values["series"]) == {"Gain.y", "Feed.real_out"}
    assert frame["unknown_channels"] == ["Nope.x"]  # for the page to say so
    assert set(frame["latency"]["series"]) == set(MEMBERS)
    assert values["series"]["Gain.y"] == Coupler.column(tmp_path, "Gain.y")


@pytest.mark.slow
@pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)
async def test_the_page_shows_times_on_the_grid_and_says_which_picked_channels_are_not_there(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    """``t = 2.3 / 2.3 s`` as the user wrote the grid (it showed ``2.30000 / 2.30000``), and a
    ``?channels=`` name the run does not have is named on the page (it was ignored silently)."""
    async with MonitorServer("127.0.0.1:0") as monitor:
        outcome = await run(2.3, None, monitor, tmp_path)
        async with chromium() as browser:
            page = await browser.new_page()
            await page.goto(f"{monitor.url}?channels=Gain.y,Nope.x")
            await page.wait_for_function("window.monitor.values['Gain.y'] !== undefined")
            shown = {i: await page.text_content(f"#{i}") for i in ("time", "stop", "notice")}
    assert outcome.end.status == "completed"
    assert (shown["time"], shown["stop"]) == ("2.3", "2.3")
    assert shown["notice"] == (
        "?channels= in this page's address names Nope.x: no channel of this run that can be "
        "charted; pick from the list on the left."
    )


async def test_the_first_paint_waits_for_no_history(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    """However busy the run keeps its process, a page paints the run's state from the page
    itself, and every stream starts with that small state; the history comes second."""
    async with MonitorServer("0") as monitor:
        outcome = await run(3.0, None, monitor, tmp_path)
        first, second = await frames(monitor.url, 2, "?channels=Gain.y")
        async with aiohttp.ClientSession() as session, session.get(monitor.url) as reply:
            page = await reply.text()
    assert outcome.end.status == "completed"
    assert set(first) == {"header", "layout"}  # no history in the first frame
    assert first["header"]["status"] == "completed"
    assert {"name": "Gain.y", "unit": "m/s"} in first["layout"]["channels"]
    assert len(second["values"]["t"]) == 31 and len(second["values"]["series"]["Gain.y"]) == 31
    inlined = page.split('<script id="state" type="application/json">', 1)[1].split("</script>")[0]
    assert json.loads(inlined) == {
        "header": json.loads(inlined)["header"],
        "layout": first["layout"],
    }
    assert json.loads(inlined)["header"]["status"] == "completed"


async def test_a_browser_that_never_reads_does_not_slow_the_run(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    """A stream nobody reads: its frames stay in the socket (the kernel's buffers, then the
    server's write times out and drops it); the run goes on at full speed and completes."""
    async with MonitorServer("0") as monitor:
        _reader, writer = await asyncio.open_connection("127.0.0.1", monitor.port)
        writer.write(b"GET /api/events?channels=Gain.y,Feed.real_out HTTP/1.1\r\nHost: x\r\n\r\n")
        await writer.drain()  # and never read a byte
        outcome = await asyncio.wait_for(run(200.0, None, monitor, tmp_path), 120)
        writer.close()
    assert outcome.end.status == "completed" and outcome.end.steps == 2000
    assert len(monitor.state.values.times) <= monitor.state.points  # bounded history


def test_history_stays_bounded_and_spread_over_the_run() -> None:
    series = Decimated(points=100)
    for k in range(1_000_000):
        series.offer(k * 0.01, (k,))
    assert len(series.times) < 100
    assert series.times[0] == 0.0 and series.times[-1] > 9000  # the whole run, evenly
    steps = {round(b - a, 6) for a, b in zip(series.times, series.times[1:], strict=False)}
    assert len(steps) == 1
    later_times, _ = series.after(5000.0)
    assert all(t > 5000.0 for t in later_times)


def test_state_before_the_run_says_what_it_waits_for() -> None:
    state = MonitorState()
    state.waiting("Gain", "grpc://127.0.0.1:1", "connection refused")
    frame, _cursor = state.frame(None, [])
    assert frame["header"] == {
        "status": "waiting",
        "reason": "",
        "waiting_for": {"Gain": "grpc://127.0.0.1:1 (connection refused)"},
    }
    assert frame["layout"] == {"members": [], "channels": [], "frames": []}


@pytest.mark.parametrize("text", ["host:port", "70000", ""])
def test_bad_monitor_addresses_are_refused(text: str) -> None:
    with pytest.raises(MonitorError, match="not \\[HOST:\\]PORT"):
        parse_address(text)


async def test_a_taken_port_is_refused_with_the_fix() -> None:
    async with MonitorServer("127.0.0.1:0") as first:
        with pytest.raises(
            MonitorError, match=rf"port is in use by pid {os.getpid()} .*--monitor 0 takes any"
        ):
            async with MonitorServer(f"127.0.0.1:{first.port}"):
                pass


def test_the_cli_prints_the_monitor_url(
    fmus: dict[str, Path], gain_server: ParticipantServer, coupler: Coupler, tmp_path: Path
) -> None:
    outcome = coupler(
        "run", str(DATA / "mixed.ssd"), "--out", str(tmp_path), "--monitor", "0", "--no-progress"
    )
    assert outcome.code == 0, outcome
    assert "monitor: http://127.0.0.1:" in outcome.out


async def test_at_most_16_pages_stream_at_once_and_the_17th_is_told_why() -> None:
    """Every stream costs the run's process memory and time (issue #25: 200 streams, +56 MB,
    the run 23 % slower), so the monitor serves 16 at once: the 17th is answered 503 with a
    sentence, and a page gets its stream again once another has closed."""
    async with MonitorServer("127.0.0.1:0") as monitor, aiohttp.ClientSession() as session:
        url = f"{monitor.url}api/events"
        streams = [await session.get(url) for _ in range(16)]
        for reply in streams:
            assert reply.status == 200
            assert (await reply.content.readline()).startswith(b"data: ")
        refused = await session.get(url)
        assert refused.status == 503
        assert (await refused.text()).startswith(
            "the monitor serves at most 16 live pages at once and 16 are open; close one"
        )
        streams.pop().close()

        async def served() -> aiohttp.ClientResponse:  # once the server has seen it gone
            reply = await session.get(url)  # (at its next write to it, 0.25 s at most)
            if reply.status != 200:
                reply.close()
                raise AssertionError(f"answered {reply.status}")
            return reply

        again = await eventually(served, within=5.0)
        for reply in [*streams, again]:
            reply.close()


def test_the_end_of_the_run_is_said_when_it_ends_not_after_the_monitor_lingers(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    """``--monitor-linger 600``: ``completed:`` and the results' paths come when the run ends,
    then the page stays up (they came only after the 600 s)."""
    command = [str(Path(sys.executable).with_name("coupler")), "run", str(DATA / "mixed.ssd"),
               "--out", str(tmp_path), "--monitor", "127.0.0.1:0", "--monitor-linger", "600",
               "--no-progress"]  # fmt: skip
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as p:
        try:
            assert p.stdout is not None
            said = [p.stdout.readline()]
            while said[-1] and " stays up " not in said[-1]:
                said.append(p.stdout.readline())
        finally:
            p.terminate()
            p.wait(timeout=30)
    assert said[0].startswith("monitor: http://127.0.0.1:")
    assert said[1].startswith("completed: "), said
    assert said[2:] == [
        f"results: {tmp_path / 'results.csv'}\n",
        f"summary: {tmp_path / 'summary.json'}\n",
        f"{said[0].rstrip()} stays up 600 s\n",
    ]


def test_an_ipv6_monitor_url_is_written_with_brackets(
    fmus: dict[str, Path], gain_server: ParticipantServer, tmp_path: Path
) -> None:
    """``coupler run --monitor [::1]:0`` prints a URL a browser opens (it printed
    http://::1:PORT/, which none does)."""
    outcome = Coupler.process(
        "run", DATA / "mixed.ssd", "--out", tmp_path, "--monitor", "[::1]:0", "--no-progress"
    )
    assert outcome.code == 0, outcome.err
    assert "monitor: http://[::1]:" in outcome.out, outcome.out
