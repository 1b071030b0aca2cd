"""OpenRails answering what the bridge cannot use: UNAVAILABLE naming the URL and the field,
never a Python error; a huge answer refused after the first MiB.

    RemoteParticipant --gRPC--> bridge --HTTP--> tiny OpenRails: a step reply of the wrong
                                                 shape, nested 100 000 deep, or 400 MB

The tiny server answers the GETs like OpenRails; only POST /API/CABCONTROLS (or GET
/API/CABCONTROLS, at start-up) answers badly. A real simulator cannot be made to misbehave
on purpose, so this one stands in for it.
"""

from __future__ import annotations

import asyncio
import json
import math
from typing import Any

import pytest
from aiohttp import web

from coupler.channels import RunSetup
from coupler.errors import ParticipantError, ParticipantUnavailable

from .support import (
    GOOD_TRAIN,
    HUGE,
    MIB,
    RANGES,
    Bridge,
    Firehose,
    Handler,
    serve_app,
    step_reply,
    tiny_openrails,
)


def answering(payload: Any) -> Handler:
    async def handler(request: web.Request) -> web.Response:
        if isinstance(payload, bytes):
            return web.Response(body=payload, content_type="application/json")
        return web.json_response(payload)

    return handler


async def step_error(bridge: Bridge, app: web.Application, **settings: Any) -> tuple[str, str]:
    """The DoStep error against ``app``: (message, OpenRails URL)."""
    async with serve_app(app) as url, bridge(url, **settings) as remote:
        await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
        with pytest.raises(ParticipantError) as caught:
            await remote.do_step(0.0, 0.2, {"throttle": 0.5})
        assert caught.value.status == "UNAVAILABLE"
        return str(caught.value), url


BAD_STEPS = {
    "a string for a number": (
        step_reply(locomotiveState__v="fast"),
        "trains.PLAYER.locomotiveState.v: Input should be a valid number (got 'fast')",
    ),
    "a NaN speed (Python's JSON reads it)": (
        step_reply(locomotiveState__v=math.nan),
        "trains.PLAYER.locomotiveState.v: Input should be a finite number (got nan)",
    ),
    "an infinite distance": (
        step_reply(locomotiveState__distance=math.inf),
        "trains.PLAYER.locomotiveState.distance: Input should be a finite number (got inf)",
    ),
    "a number for a bool": (
        step_reply(locomotiveState__wheelslip=0),
        "trains.PLAYER.locomotiveState.wheelslip: Input should be a valid boolean (got 0)",
    ),
    "the old movementDirection number": (
        step_reply(trackLocation__movementDirection=1),
        "trains.PLAYER.trackLocation.movementDirection: Input should be 'Forward' or "
        "'Backward' (got 1)",
    ),
    "a missing key": (
        step_reply(trackLocation=KeyError),
        "trains.PLAYER.trackLocation: Field required",
    ),
    "a missing nested key": (
        step_reply(locomotiveState__distance=KeyError),
        "trains.PLAYER.locomotiveState.distance: Field required",
    ),
    "trains not an object": ({"trains": [1, 2]}, "trains: Input should be an object (got [1, 2])"),
    "deep nesting": (
        b'{"trains": ' + b"[" * 100_000 + b"]" * 100_000 + b"}",
        "the body: Invalid JSON: recursion limit exceeded",
    ),
    "not JSON": (b"<html>Server Error</html>", "the body: Invalid JSON: expected value"),
    "no player train": (
        {"trains": {"AI-1": GOOD_TRAIN}, "CameraSensors": {}},
        "answered without train 'PLAYER' (trains: ['AI-1'])",
    ),
}


@pytest.mark.parametrize("case", BAD_STEPS)
async def test_bad_step_reply_names_url_and_field(case: str, bridge: Bridge) -> None:
    payload, expected = BAD_STEPS[case]
    message, url = await step_error(bridge, tiny_openrails(step=answering(payload)))
    assert f"OpenRails at {url}/API/CABCONTROLS answered" in message
    assert expected in message
    assert "Traceback" not in message and len(message) < 1000


async def test_a_good_reply_of_the_tiny_server_passes(bridge: Bridge) -> None:
    """The same server with a well-formed reply: the failures above are the replies' fault."""
    async with serve_app(tiny_openrails()) as url, bridge(url) as remote:
        await remote.initialize(RunSetup(run_id="t", start_time=0.0, step_size=0.2))
        outputs = await remote.do_step(0.0, 0.2, {"throttle": 0.5})
    assert outputs["speed"] == 1.5 and outputs["distance"] == 12.0 and outputs["track_node"] == 1


@pytest.mark.parametrize("declare_length", [False, True], ids=["chunked", "content-length"])
async def test_huge_reply_is_refused_after_the_cap(declare_length: bool, bridge: Bridge) -> None:
    firehose = Firehose(declare_length=declare_length)
    message, url = await step_error(bridge, tiny_openrails(step=firehose.handle))
    await asyncio.wait_for(firehose.finished.wait(), 10.0)
    size = f"{HUGE} bytes, more than" if declare_length else "more than"
    assert (
        f"OpenRails at {url}/API/CABCONTROLS answered POST with {size} the 1048576 bytes the "
        f"bridge reads (OPENRAILS_BRIDGE_MAX_BODY_BYTES); refused "
    ) in message
    assert message.count("refused unread" if declare_length else "refused after 1") == 1
    # the bridge hung up at the cap: what got out is the cap plus what the sockets buffer
    assert firehose.sent < 64 * MIB, f"{firehose.sent / MIB:.0f} MiB sent before the refusal"


async def test_max_body_bytes_is_configurable(bridge: Bridge) -> None:
    reply = json.dumps(step_reply()).encode()
    padded = reply[:-1] + b', "padding": "' + b"x" * 4096 + b'"}'
    message, _ = await step_error(
        bridge, tiny_openrails(step=answering(padded)), max_body_bytes=4096
    )
    assert f"with {len(padded)} bytes, more than the 4096 bytes" in message
    assert "refused unread" in message


async def test_bad_control_list_keeps_health_not_serving(bridge: Bridge) -> None:
    """GET /API/CABCONTROLS of the wrong shape at start-up: NOT_SERVING, the reason names the
    field; the participant still answers health."""
    controls = [dict(RANGES[0], MinValue="0")]
    async with serve_app(tiny_openrails(controls=controls)) as url:
        with pytest.raises(ParticipantUnavailable) as caught:
            async with bridge(url, connect_timeout=0.5):
                pass
    assert "health is NOT_SERVING: OpenRails at " in str(caught.value)
    assert (
        f"{url}/API/CABCONTROLS answered 200 with a body the bridge cannot use: "
        "[0].MinValue: Input should be a valid number (got '0')"
    ) in str(caught.value)


async def test_the_bridge_answers_after_a_bad_reply(bridge: Bridge) -> None:
    """One bad reply fails that step only: the next run works against a good server."""
    calls = 0

    async def sometimes_bad(request: web.Request) -> web.Response:
        nonlocal calls
        calls += 1
        return web.json_response(step_reply(rotation="x") if calls == 1 else step_reply())

    async with serve_app(tiny_openrails(step=sometimes_bad)) as url, bridge(url) as remote:
        await remote.initialize(RunSetup(run_id="a", start_time=0.0, step_size=0.2))
        with pytest.raises(ParticipantError):
            await remote.do_step(0.0, 0.2, {})
        await remote.terminate()
        await remote.initialize(RunSetup(run_id="b", start_time=0.0, step_size=0.2))
        outputs = await remote.do_step(0.0, 0.2, {})
    assert outputs["speed"] == 1.5
