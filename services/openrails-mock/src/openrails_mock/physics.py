"""Longitudinal train dynamics: one consist as a point mass moving along a route.

The equation of motion, with ``v`` the signed speed along the route (positive towards increasing
route distance) and ``m_eff = mass * (1 + rotating_mass_fraction)``::

    m_eff * dv/dt = F_active - sign(v) * F_passive

    F_active  = direction * F_t - mass * g * gradient / 1000        (can move the train either way)
    F_t       = min(throttle * F_max, throttle * P_max / |v|)       (tractive effort at the wheel)
    F_passive = A + B |v| + C v^2                                  (Davis running resistance)
              + train_brake * m_eff * max_service_brake_decel       (friction brake)
              + dynamic_brake * max_dynamic_brake_force            (only while moving)

Passive forces only oppose motion: they stop the train, never reverse it. At standstill the
train stays put while ``|F_active| <= A + F_brake`` (static resistance and the friction brake
hold it); otherwise it starts in the direction of ``F_active``.

The integrator is semi-implicit Euler (speed first, then position with the new speed) on
fixed substeps, so equal inputs give bit-identical outputs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

GRAVITY_MPS2 = 9.80665
"""Standard gravity."""

DEFAULT_SUBSTEP_S = 0.01
"""Largest integration substep; a step of dt is split into ceil(dt / substep) equal parts."""


@dataclass(frozen=True, kw_only=True)
class Consist:
    """A train's figures for longitudinal dynamics."""

    name: str
    """What the consist is, for logs and the README."""
    mass_kg: float
    """Total mass of the train, including load."""
    length_m: float
    """Length over buffers/couplers."""
    max_tractive_effort_n: float
    """Tractive effort at full throttle at low speed (adhesion/transmission limit)."""
    max_power_w: float
    """Power at the wheel at full throttle; above P/F_max the effort falls as P/v."""
    davis_a_n: float
    """Davis A: speed-independent running resistance (bearings, rolling)."""
    davis_b_n_per_mps: float
    """Davis B: resistance proportional to speed (flange friction, ...)."""
    davis_c_n_per_mps2: float
    """Davis C: resistance proportional to speed squared (aerodynamic drag)."""
    max_service_brake_decel_mps2: float
    """Deceleration of a full service application of the friction brake alone."""
    max_dynamic_brake_force_n: float
    """Retarding force of the dynamic (hydrodynamic/electric) brake at full application."""
    rotating_mass_fraction: float
    """Rotating masses as a fraction of the mass: m_eff = mass * (1 + fraction)."""
    car_count: int = 1
    """Cars of equal length; the API reports the first and last car's centres."""

    @property
    def effective_mass_kg(self) -> float:
        """The mass that resists acceleration, rotating parts included."""
        return self.mass_kg * (1.0 + self.rotating_mass_fraction)

    def tractive_effort_n(self, throttle: float, speed_mps: float) -> float:
        """Tractive effort at the wheel: min(throttle * F_max, throttle * P_max / |v|)."""
        v = abs(speed_mps)
        if throttle <= 0.0:
            return 0.0
        if v <= 0.0:
            return throttle * self.max_tractive_effort_n
        return min(throttle * self.max_tractive_effort_n, throttle * self.max_power_w / v)

    def running_resistance_n(self, speed_mps: float) -> float:
        """Davis running resistance A + B |v| + C v^2 (a magnitude)."""
        v = abs(speed_mps)
        return self.davis_a_n + self.davis_b_n_per_mps * v + self.davis_c_n_per_mps2 * v * v

    def service_brake_force_n(self, train_brake: float) -> float:
        """Friction brake force for a brake application 0..1 (a magnitude)."""
        return train_brake * self.effective_mass_kg * self.max_service_brake_decel_mps2


DB_CLASS_642 = Consist(
    name="DB class 642 (Siemens Desiro Classic), two-car DMU with passengers",
    mass_kg=75_000.0,
    length_m=41.7,
    max_tractive_effort_n=100_000.0,
    max_power_w=500_000.0,
    davis_a_n=1_200.0,
    davis_b_n_per_mps=15.0,
    davis_c_n_per_mps2=6.0,
    max_service_brake_decel_mps2=1.0,
    max_dynamic_brake_force_n=60_000.0,
    rotating_mass_fraction=0.08,
    car_count=2,
)
"""The Erzgebirge line's regional train: 2 x 275 kW diesel-hydraulic, about 500 kW at the wheel."""

PRESETS: dict[str, Consist] = {"br642": DB_CLASS_642}
"""Consists selectable by name in the configuration."""


@dataclass(frozen=True, kw_only=True)
class Controls:
    """The driver's controls, each already validated."""

    throttle: float = 0.0
    """Throttle 0..1."""
    train_brake: float = 0.0
    """Friction (service) brake 0..1."""
    dynamic_brake: float = 0.0
    """Dynamic brake 0..1."""
    direction: int = 1
    """Reverser: 1 forward, 0 neutral, -1 reverse."""


@dataclass(frozen=True, kw_only=True)
class TrainState:
    """Where the train is and how it moves, after a step."""

    position_m: float
    """Route distance of the train's front (the end towards increasing route distance)."""
    speed_mps: float
    """Signed speed along the route: positive towards increasing route distance."""
    acceleration_mps2: float
    """Mean acceleration over the last step, signed like the speed."""
    odometer_m: float
    """Distance travelled, whatever the direction; never decreases."""


class TrainDynamics:
    """Integrates one consist along a route segment [min_position_m, max_position_m].

    ``gradient`` gives the gradient in per mille (positive uphill towards increasing distance)
    at a route distance; it is evaluated at the train's middle. Reaching either end of the
    segment stops the train there (a buffer stop), as the mock models no other track.
    """

    def __init__(
        self,
        consist: Consist,
        gradient: Callable[[float], float],
        *,
        position_m: float,
        min_position_m: float,
        max_position_m: float,
        substep_s: float = DEFAULT_SUBSTEP_S,
    ) -> None:
        if not min_position_m <= position_m <= max_position_m:
            raise ValueError(
                f"start position {position_m} m is outside the route [{min_position_m}, "
                f"{max_position_m}] m for a {consist.length_m} m train"
            )
        self.consist = consist
        self._gradient = gradient
        self._min = min_position_m
        self._max = max_position_m
        self._substep = substep_s
        self.state = TrainState(
            position_m=position_m, speed_mps=0.0, acceleration_mps2=0.0, odometer_m=0.0
        )

    def set_limits(self, min_position_m: float, max_position_m: float) -> None:
        """New ends of the segment (the track beyond the train changed); the train keeps its
        place."""
        self._min = min(min_position_m, self.state.position_m)
        self._max = max(max_position_m, self.state.position_m)

    def step(self, dt_s: float, controls: Controls) -> TrainState:
        """Advance by dt_s seconds with constant controls; returns (and keeps) the new state."""
        if dt_s <= 0.0:
            raise ValueError(f"step must be positive, got {dt_s} s")
        n = max(1, math.ceil(dt_s / self._substep - 1e-9))
        h = dt_s / n
        s, v, odo = self.state.position_m, self.state.speed_mps, self.state.odometer_m
        v0 = v
        for _ in range(n):
            s, v, odo = self._substep_once(s, v, odo, h, controls)
        self.state = TrainState(
            position_m=s, speed_mps=v, acceleration_mps2=(v - v0) / dt_s, odometer_m=odo
        )
        return self.state

    def _substep_once(
        self, s: float, v: float, odo: float, h: float, c: Controls
    ) -> tuple[float, float, float]:
        k = self.consist
        m_eff = k.effective_mass_kg
        grade_force = k.mass_kg * GRAVITY_MPS2 * self._gradient(s - k.length_m / 2.0) / 1000.0
        active = c.direction * k.tractive_effort_n(c.throttle, v) - grade_force
        brake = k.service_brake_force_n(c.train_brake)
        if v == 0.0:
            holding = k.davis_a_n + brake
            if abs(active) <= holding:
                return s, 0.0, odo
            a = (active - math.copysign(holding, active)) / m_eff
            v_new = a * h
        else:
            passive = (
                k.running_resistance_n(v) + brake + c.dynamic_brake * k.max_dynamic_brake_force_n
            )
            v_new = v + (active - math.copysign(passive, v)) / m_eff * h
            if v_new * v < 0.0:
                v_new = 0.0  # passive forces stop the train; they never reverse it
        s_new = s + v_new * h
        if s_new >= self._max:
            s_new, v_new = self._max, 0.0
        elif s_new <= self._min:
            s_new, v_new = self._min, 0.0
        return s_new, v_new, odo + abs(s_new - s)
