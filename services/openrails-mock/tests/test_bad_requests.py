"""Every request the mock cannot take gets 400 with a JSON error, and changes nothing.

test --bad POST--> openrails-mock --> 400 {"error": ...}; then the same valid step as a
fresh mock must give the same reply
"""

from __future__ import annotations

from typing import Any

import pytest

from openrails_mock.config import MockConfig
from openrails_mock.route import StraightRoute

from .support import FakeClock, Serve

GOOD = {"LocomotiveName": "PLAYER", "TypeName": "THROTTLE", "ControlIndex": 1, "Value": 1.0}


def lockstep(*controls: dict[str, Any], **extra: Any) -> dict[str, Any]:
    return {"Controls": list(controls), "Commands": [], "SwitchCommands": {}} | extra


LOCKSTEP_BAD: dict[str, bytes | dict[str, Any] | list[Any]] = {
    "invalid JSON": b'{"Controls": [',
    "not JSON at all": b"throttle=1",
    "plain list (stock form)": [{"TypeName": "THROTTLE", "ControlIndex": 1, "Value": 0.5}],
    "no Controls": {"Commands": [], "SwitchCommands": {}},
    "Controls not a list": {"Controls": {"THROTTLE": 1}},
    "unknown TypeName": lockstep(GOOD, GOOD | {"TypeName": "HORN"}),
    "lower-case TypeName": lockstep(GOOD | {"TypeName": "throttle"}),
    "unknown locomotive": lockstep(GOOD | {"LocomotiveName": "AI-42"}),
    "throttle above 1": lockstep(GOOD | {"Value": 1.5}),
    "brake below 0": lockstep(GOOD, GOOD | {"TypeName": "TRAIN_BRAKE", "Value": -0.1}),
    "direction between positions": lockstep(GOOD | {"TypeName": "DIRECTION", "Value": 0.5}),
    "Value a string": lockstep(GOOD | {"Value": "0.5"}),
    "Value a boolean": lockstep(GOOD | {"Value": True}),
    "Value missing": lockstep({"LocomotiveName": "PLAYER", "TypeName": "THROTTLE"}),
    "ControlIndex not an integer": lockstep(GOOD | {"ControlIndex": 1.5}),
    "control not an object": lockstep(GOOD, "THROTTLE"),  # type: ignore[arg-type]
    "step over 500 ms": lockstep(GOOD, StepMs=501),
    "step of zero": lockstep(GOOD, StepMs=0),
    "unsupported Commands": lockstep(GOOD) | {"Commands": [{"Command": "Horn"}]},
    "unsupported SwitchCommands": lockstep(GOOD) | {"SwitchCommands": {"12": 1}},
}

STOCK_BAD: dict[str, bytes | dict[str, Any] | list[Any]] = {
    "invalid JSON": b"[{",
    "lockstep form": lockstep(GOOD),
    "unknown TypeName": [GOOD, {"TypeName": "PANTOGRAPH", "Value": 1}],
    "value out of range": [{"TypeName": "THROTTLE", "Value": 2}],
    "Value not a number": [{"TypeName": "THROTTLE", "Value": None}],
}


def _kwargs(payload: bytes | dict[str, Any] | list[Any]) -> dict[str, Any]:
    return {"data": payload} if isinstance(payload, bytes) else {"json": payload}


def config(mode: str) -> MockConfig:
    return MockConfig(mode=mode, loading_delay_s=0.0)  # type: ignore[arg-type]


@pytest.mark.parametrize("case", list(LOCKSTEP_BAD))
async def test_lockstep_bad_request_gets_400_and_changes_nothing(serve: Serve, case: str) -> None:
    route = StraightRoute(length_m=5000.0)
    async with (
        serve(config("lockstep"), route=route) as fresh,
        fresh.post("/API/CABCONTROLS", json=lockstep(GOOD)) as resp,
    ):
        expected = await resp.json()
    async with serve(config("lockstep"), route=route) as session:
        async with session.post("/API/CABCONTROLS", **_kwargs(LOCKSTEP_BAD[case])) as resp:
            assert resp.status == 400
            assert resp.content_type == "application/json"
            error = (await resp.json())["error"]
            assert isinstance(error, str) and error
        async with session.get("/API/TIME") as resp:
            assert await resp.json() == 8 * 3600.0  # no step taken
        async with session.get("/API/CABCONTROLS") as resp:
            assert all(c["RangeFraction"] in (0.0, 1.0) for c in await resp.json())
        async with session.post("/API/CABCONTROLS", json=lockstep(GOOD)) as resp:
            assert await resp.json() == expected


@pytest.mark.parametrize("case", list(STOCK_BAD))
async def test_stock_bad_request_gets_400_and_changes_nothing(serve: Serve, case: str) -> None:
    clock = FakeClock()
    async with serve(config("stock"), route=StraightRoute(length_m=5000.0), clock=clock) as session:
        async with session.post("/API/CABCONTROLS", **_kwargs(STOCK_BAD[case])) as resp:
            assert resp.status == 400
            assert (await resp.json())["error"]
        async with session.get("/API/CABCONTROLS") as resp:
            fractions = {c["TypeName"]: c["RangeFraction"] for c in await resp.json()}
        assert fractions["THROTTLE"] == 0.0 and fractions["DIRECTION"] == 1.0


async def test_error_names_the_culprit(serve: Serve) -> None:
    async with serve(config("lockstep"), route=StraightRoute(length_m=5000.0)) as session:
        bad = lockstep(GOOD | {"TypeName": "TRAIN_BRAKE", "Value": 3})
        async with session.post("/API/CABCONTROLS", json=bad) as resp:
            error = (await resp.json())["error"]
    assert "TRAIN_BRAKE" in error and "3" in error and "[0, 1]" in error
