"""Lockstep mode against a real mock on a port: start-up, the step reply, driving physics.

    test (aiohttp client) --HTTP--> openrails-mock (lockstep, 200 ms) --> Simulation --> route

The driving profile is checked against the test's own integration of the equation of motion
written from the README (not the mock's code), and against a closed form for braking.
"""

from __future__ import annotations

import math
from typing import Any

import aiohttp

from openrails_mock.config import ConsistOverrides, MockConfig
from openrails_mock.route import StraightRoute

from .support import FakeClock, Serve, body

G = 9.80665

# The test's own train: figures chosen here, given to the mock through its configuration.
FIGURES = {
    "mass_kg": 80_000.0,
    "length_m": 45.0,
    "max_tractive_effort_n": 120_000.0,
    "max_power_w": 600_000.0,
    "davis_a_n": 1_500.0,
    "davis_b_n_per_mps": 20.0,
    "davis_c_n_per_mps2": 5.0,
    "max_service_brake_decel_mps2": 0.9,
    "max_dynamic_brake_force_n": 50_000.0,
    "rotating_mass_fraction": 0.1,
}
STEP_S = 0.2


def config(**changes: Any) -> MockConfig:
    values: dict[str, Any] = {
        "loading_delay_s": 0.0,
        "consist": ConsistOverrides(**FIGURES),
        "step_ms": STEP_S * 1000,
    }
    values.update(changes)
    return MockConfig(**values)


def flat_route() -> StraightRoute:
    return StraightRoute(length_m=10_000.0, section_length_m=500.0)


async def step(session: aiohttp.ClientSession, **controls: float) -> dict[str, Any]:
    async with session.post("/API/CABCONTROLS", json=body(**controls)) as resp:
        assert resp.status == 200, await resp.text()
        reply: dict[str, Any] = await resp.json()
    return reply["trains"]["PLAYER"]


def reference_accel(v: float, throttle: float, brake: float, f: dict[str, float]) -> float:
    """dv/dt from the README's equation, for v >= 0 on flat track, direction forward."""
    m_eff = f["mass_kg"] * (1 + f["rotating_mass_fraction"])
    traction = 0.0
    if throttle > 0:
        traction = throttle * f["max_tractive_effort_n"]
        if v > 0:
            traction = min(traction, throttle * f["max_power_w"] / v)
    resistance = f["davis_a_n"] + f["davis_b_n_per_mps"] * v + f["davis_c_n_per_mps2"] * v * v
    braking = brake * m_eff * f["max_service_brake_decel_mps2"]
    return (traction - resistance - braking) / m_eff


def reference_run(
    v: float, s: float, seconds: float, throttle: float, brake: float, f: dict[str, float]
) -> tuple[float, float]:
    """Explicit Euler with 1 ms steps (ten times finer than the mock's substeps)."""
    h = 0.001
    for _ in range(round(seconds / h)):
        v_new = v + reference_accel(v, throttle, brake, f) * h
        if v_new <= 0.0:
            return 0.0, s + v * h * v / (v - v_new)  # stop where v crosses zero
        s += (v + v_new) / 2 * h
        v = v_new
    return v, s


async def drive_profile(session: aiohttp.ClientSession) -> list[dict[str, Any]]:
    """Full throttle 50 s, throttle 0.35 for 30 s, then full service brake to a stop."""
    replies = [await step(session, THROTTLE=1.0, TRAIN_BRAKE=0.0, DIRECTION=1)]
    replies += [await step(session) for _ in range(249)]
    replies.append(await step(session, THROTTLE=0.35))
    replies += [await step(session) for _ in range(149)]
    replies.append(await step(session, THROTTLE=0.0, TRAIN_BRAKE=1.0))
    while replies[-1]["locomotiveState"]["v"] > 0.0:
        replies.append(await step(session))
        assert len(replies) < 2000, "the train did not stop"
    return replies


async def test_driving_profile_matches_independent_integration(serve: Serve) -> None:
    async with serve(config(), route=flat_route()) as session:
        replies = await drive_profile(session)

    states = [r["locomotiveState"] for r in replies]
    v_accel, s_accel = reference_run(0.0, 0.0, 50.0, 1.0, 0.0, FIGURES)
    v_cruise, s_cruise = reference_run(v_accel, s_accel, 30.0, 0.35, 0.0, FIGURES)
    v_stop, s_stop = reference_run(v_cruise, s_cruise, 600.0, 0.0, 1.0, FIGURES)
    assert v_stop == 0.0

    # Tolerances: the mock integrates with semi-implicit Euler on 10 ms substeps, the reference
    # with 1 ms Euler (trapezoidal position). Semi-implicit Euler runs the position ahead by
    # about h/2 * v (0.13 m at 25 m/s) and its first-order speed error stays below 0.01 m/s
    # here; observed: 0.002 m/s and 0.27 m. The bounds are about twice that, and far below
    # what a wrong force law gives (dropping Davis C moves the cruise speed by over 1 m/s).
    assert math.isclose(states[249]["v"], v_accel, abs_tol=0.02)
    assert math.isclose(states[249]["distance"], s_accel, abs_tol=0.5)
    assert math.isclose(states[399]["v"], v_cruise, abs_tol=0.02)
    assert math.isclose(states[399]["distance"], s_cruise, abs_tol=0.5)
    assert states[-1]["v"] == 0.0
    stopping_distance = states[-1]["distance"] - states[399]["distance"]
    assert math.isclose(stopping_distance, s_stop - s_cruise, abs_tol=0.5)
    assert v_accel > 20.0 and stopping_distance > 200.0  # a real profile, not a crawl


async def test_braking_distance_matches_closed_form(serve: Serve) -> None:
    """Without Davis B: m dv/dt = -(F0 + C v^2) gives s = m/(2C) ln(1 + C v0^2 / F0)."""
    figures = FIGURES | {"davis_b_n_per_mps": 0.0}
    async with serve(config(consist=ConsistOverrides(**figures)), route=flat_route()) as session:
        state = await step(session, THROTTLE=1.0)
        for _ in range(199):
            state = await step(session)
        v0 = state["locomotiveState"]["v"]
        start = state["locomotiveState"]["distance"]
        state = await step(session, THROTTLE=0.0, TRAIN_BRAKE=1.0)
        while state["locomotiveState"]["v"] > 0.0:
            state = await step(session)
    m_eff = figures["mass_kg"] * (1 + figures["rotating_mass_fraction"])
    f0 = m_eff * figures["max_service_brake_decel_mps2"] + figures["davis_a_n"]
    c = figures["davis_c_n_per_mps2"]
    expected = m_eff / (2 * c) * math.log(1 + c * v0 * v0 / f0)
    # Semi-implicit Euler on 10 ms substeps: within v0 * h (about 0.3 m) of the exact value.
    assert math.isclose(state["locomotiveState"]["distance"] - start, expected, abs_tol=0.5)


async def test_two_runs_are_identical(serve: Serve) -> None:
    runs = []
    for _ in range(2):
        async with serve(config(), route=flat_route()) as session:
            replies = await drive_profile(session)
            async with session.get("/API/TIME") as resp:
                replies.append({"time": await resp.json()})
        runs.append(replies)
    assert runs[0] == runs[1]


async def test_step_reply_has_openrails_shape_and_track_mapping(serve: Serve) -> None:
    route = StraightRoute(length_m=3000.0, section_length_m=500.0, heading_deg=90.0)
    async with serve(config(start_distance_m=520.0), route=route) as session:
        train = await step(session)
    # Front at 520 m: section 1 (node 2), 20 m in. Rear at 475 m: section 0 (node 1).
    assert train["trackLocation"] == {
        "trackNodeIndex": 2,
        "trackNodeLength": 500.0,
        "trackNodeOffset": 20.0,
        "trackVectorSectionIndex": 0,
        "movementDirection": "Forward",
    }
    assert train["rearTrackLocation"]["trackNodeIndex"] == 1
    assert math.isclose(train["rearTrackLocation"]["trackNodeOffset"], 475.0)
    assert math.isclose(train["rotation"], math.pi / 2)
    # two cars of 22.5 m: the lead locomotive's centre is 11.25 m behind the front, due east
    assert train["location"] == {"tileX": -5354, "tileZ": 14849, "x": 508.75, "y": 0.0, "z": 0.0}
    assert train["trainLength"] == {"length": 45.0}
    assert train["locomotiveState"]["v"] == 0.0  # no throttle: standstill stays standstill


async def test_ready_answers_425_until_loaded(serve: Serve) -> None:
    clock = FakeClock()
    async with serve(config(loading_delay_s=5.0), route=flat_route(), clock=clock) as session:
        async with session.get("/API/READY") as resp:
            assert resp.status == 425
        async with session.post("/API/CABCONTROLS", json=body(THROTTLE=0.5)) as resp:
            assert resp.status == 425
            assert "READY" in (await resp.json())["error"]
        clock.now += 5.0
        async with session.get("/API/READY") as resp:
            assert resp.status == 200
            assert await resp.read() == b""
        assert (await step(session, THROTTLE=0.5))["locomotiveState"]["v"] > 0.0


async def test_uphill_start_with_weak_throttle_stays_put_then_rolls_back(serve: Serve) -> None:
    # 25 per mille uphill: gravity 80 t * g * 0.025 = 19.6 kN.
    route = StraightRoute(length_m=5000.0, gradient_per_mille=25.0)
    async with serve(config(start_distance_m=2000.0), route=route) as session:
        # 15 kN traction: less than gravity, and the friction brake holds: no movement.
        held = await step(session, THROTTLE=0.125, TRAIN_BRAKE=0.5)
        assert held["locomotiveState"]["v"] == 0.0
        # Release the brake: gravity (19.6 kN) beats traction (15 kN) + A (1.5 kN): rolls back.
        rolled = await step(session, TRAIN_BRAKE=0.0)
        for _ in range(20):
            rolled = await step(session)
        assert rolled["locomotiveState"]["v"] < 0.0
        assert rolled["trackLocation"]["movementDirection"] == "Forward"  # still faces uphill
        assert rolled["locomotiveState"]["distance"] > 0.0  # the odometer counts both ways
        # Braking stops the rollback but never drives the train uphill.
        for _ in range(100):
            braked = await step(session, TRAIN_BRAKE=1.0)
            assert braked["locomotiveState"]["v"] <= 0.0
        assert braked["locomotiveState"]["v"] == 0.0


async def test_reverse_drives_backwards(serve: Serve) -> None:
    async with serve(config(start_distance_m=5000.0), route=flat_route()) as session:
        state = await step(session, DIRECTION=-1, THROTTLE=0.5)
        for _ in range(10):
            state = await step(session)
    assert state["locomotiveState"]["v"] < 0.0
    assert state["locomotiveState"]["a"] < 0.0
    assert state["trackLocation"]["trackNodeOffset"] < 500.0  # moved back from node 11's start


async def test_dynamic_brake_slows_the_train(serve: Serve) -> None:
    async with serve(config(), route=flat_route()) as session:
        state = await step(session, THROTTLE=1.0)
        for _ in range(100):
            state = await step(session)
        v0 = state["locomotiveState"]["v"]
        state = await step(session, THROTTLE=0.0, DYNAMIC_BRAKE=1.0)
    m_eff = FIGURES["mass_kg"] * (1 + FIGURES["rotating_mass_fraction"])
    expected = (
        -(
            FIGURES["max_dynamic_brake_force_n"]
            + FIGURES["davis_a_n"]
            + FIGURES["davis_b_n_per_mps"] * v0
            + FIGURES["davis_c_n_per_mps2"] * v0 * v0
        )
        / m_eff
    )
    assert math.isclose(state["locomotiveState"]["a"], expected, rel_tol=0.01)


async def test_get_endpoints(serve: Serve) -> None:
    route = StraightRoute(length_m=10_000.0, origin_lat_deg=50.0, origin_lon_deg=13.0)
    async with serve(config(start_time_s=3600.0), route=route) as session:
        await step(session, THROTTLE=0.5)
        async with session.get("/API/TIME") as resp:
            assert math.isclose(await resp.json(), 3600.2)
        async with session.get("/API/MAP") as resp:
            position = await resp.json()
        assert set(position) == {"LatLon", "DirectionDeg"}
        assert math.isclose(position["LatLon"]["Lat"], 50.0, abs_tol=0.01)
        assert math.isclose(position["LatLon"]["Lon"], 13.0, abs_tol=0.01)
        assert position["DirectionDeg"] == 225.0
        async with session.get("/API/CABCONTROLS") as resp:
            controls = {c["TypeName"]: c for c in await resp.json()}
        assert controls["THROTTLE"] == {
            "TypeName": "THROTTLE",
            "MinValue": 0.0,
            "MaxValue": 1.0,
            "RangeFraction": 0.5,
        }
        assert set(controls) == {
            "THROTTLE",
            "TRAIN_BRAKE",
            "DYNAMIC_BRAKE",
            "DIRECTION",
            "REGULATOR",
        }
        async with session.get("/API/TRAININFO") as resp:
            assert await resp.json() == {"ControlMode": "EXPLORER"}
        async with session.get("/API/TRAINDRIVINGDISPLAY") as resp:
            rows = await resp.json()
        assert all(set(r) == {"FirstCol", "LastCol", "SymbolCol", "KeyPressed"} for r in rows)
        short = {r["FirstCol"]: r["LastCol"] for r in rows}
        assert short["TIME"] == "01:00:00" and short["THRO"] == "50%"
        assert short["SPED"].endswith(" km/h")
        async with session.get("/API/TRAINDRIVINGDISPLAY?normalText=true") as resp:
            long = {r["FirstCol"]: r["LastCol"] for r in await resp.json()}
        assert long["Direction"] == "Forward" and "Gradient" in long
        # Paths are case-sensitive, as in OpenRails.
        async with session.get("/api/TIME") as resp:
            assert resp.status == 404
        async with session.get("/API/time") as resp:
            assert resp.status == 404
