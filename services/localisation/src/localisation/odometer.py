"""The onboard odometer as a sensor model: what a wheel sensor (and a Doppler radar) measure of
the train's true motion, with the errors real odometers have.

Truth in, each communication point ``t``: the distance travelled ``D(t)`` (the simulator's
odometer, never decreasing), the speed ``v(t)`` and the acceleration ``a(t)`` (OpenRails: the
mean over its last step), and the simulator's own ``wheelslip`` / ``wheelskid`` flags.

The wheel channel. A wheel of true diameter ``d`` turns ``D / (pi d)`` times; the odometer
counts ``pulses_per_revolution`` pulses a turn and multiplies by the circumference it was told,
``pi d (1 + diameter_error)``: on dry rail the measured distance is ``(1 + diameter_error)``
times the true one, a 1 % diameter error is a 1 % distance error. Measured distance and speed
are whole pulses (quantisation: one pulse is ``pi d / pulses_per_revolution``, 12 mm for a
770 mm wheel and 200 pulses); the first pulse comes after a random fraction of one (seeded).

Slip and slide. The rail gives at most ``adhesion * g`` of force per unit of weight on the axles
that pull (``traction_mass_fraction`` of the train's weight) or brake
(``braked_mass_fraction``). A train accelerating harder than
``adhesion * g * traction_mass_fraction`` needs more than the rail gives: its driven wheels
slip, turning faster than the train moves, and the odometer over-reads by ``slip`` (0.1: the
wheel runs 10 % fast). Braking harder than ``adhesion * g * braked_mass_fraction`` the wheels
slide, turning slower: the odometer under-reads by ``slide`` (1.0: a locked wheel, nothing
counted). The simulator's flags (real OpenRails sets them from its own adhesion model) start
slip or slide whatever the acceleration says. Each episode's amount is drawn once, uniformly
in 0.5..1.5 times the parameter (seeded): no two slips are the same. Slip never happens while
coasting or braking; slide never while pulling.

The Doppler radar (``radar`` on): the true speed times ``1 + radar_bias`` plus Gaussian noise of
``radar_noise`` (seeded); no reading below ``radar_min_speed`` (a Doppler radar sees no motion
at walking pace). Radar does not slip.

Time. Under the Jacobi master an output at ``t + h`` is computed from inputs at ``t``: the
truth over ``[t - h, t]`` is known exactly (``D(t) - D(t - h)``, with the mean acceleration
``a(t)`` of that interval deciding slip), the stretch ``[t, t + h]`` is predicted from
``v(t)`` and ``a(t)``; the next step replaces the prediction by the truth, so predictions never
accumulate. The model is the ``Odometer`` class (plain Python, tested against this physics);
``OdometerParticipant`` in ``localisation.sensors`` serves it.

Source of the nominal envelope: the ETCS odometry accuracy requirement of UNISIG SUBSET-041
(Performance Requirements for Interoperability): distances measured on board within +-(5 m +
5 % of the distance travelled since the last balise group) -- the localisation's default
confidence interval (``localisation.estimator``).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

GRAVITY_MPS2 = 9.80665

SLIP, NONE, SLIDE = 1, 0, -1
"""``Measurement.adhesion_state``: wheels slipping (traction), rolling, sliding (braking)."""


@dataclass(frozen=True, kw_only=True)
class OdometerErrors:
    """Every error of the odometer, in physical units; all default to a perfect odometer on dry
    rail except quantisation, which a pulse counter always has."""

    wheel_diameter_m: float = 0.77
    """True diameter of the measuring wheel (class 642: 770 mm new)."""
    diameter_error: float = 0.0
    """Relative error of the diameter the odometer assumes: +0.01 reads 1 % long."""
    pulses_per_revolution: int = 200
    """Pulses of the wheel sensor per turn."""
    adhesion: float = 0.3
    """Adhesion coefficient the rail gives: dry 0.3, wet 0.1-0.15, leaves 0.03-0.05."""
    traction_mass_fraction: float = 0.67
    """Share of the train's weight on driven axles (class 642: 4 of 6 axles)."""
    braked_mass_fraction: float = 1.0
    """Share of the train's weight on braked axles."""
    slip: float = 0.1
    """Wheel over-speed while slipping, relative (0.1: 10 % fast)."""
    slide: float = 0.1
    """Wheel under-speed while sliding, relative (1.0: locked)."""
    radar: bool = False
    """A Doppler radar is fitted."""
    radar_bias: float = 0.0
    """Relative error of the radar's speed."""
    radar_noise_mps: float = 0.05
    """Standard deviation of the radar's noise [m/s]."""
    radar_min_speed_mps: float = 0.5
    """Below this speed the radar gives no reading [m/s]."""
    seed: int = 0
    """Seed of every random draw (pulse phase, slip amounts, radar noise)."""

    def __post_init__(self) -> None:
        problems = [
            f"{name} must be {rule}"
            for name, ok, rule in (
                ("wheel_diameter", self.wheel_diameter_m > 0, "> 0 m"),
                ("diameter_error", -0.5 < self.diameter_error < 0.5, "within -0.5..0.5"),
                ("pulses_per_revolution", self.pulses_per_revolution >= 1, ">= 1"),
                ("adhesion", self.adhesion > 0, "> 0"),
                ("traction_mass_fraction", 0 < self.traction_mass_fraction <= 1, "in (0, 1]"),
                ("braked_mass_fraction", 0 < self.braked_mass_fraction <= 1, "in (0, 1]"),
                ("slip", self.slip >= 0, ">= 0"),
                ("slide", 0 <= self.slide <= 1, "in 0..1"),
                ("radar_noise", self.radar_noise_mps >= 0, ">= 0 m/s"),
            )
            if not ok
        ]
        if problems:
            raise ValueError("; ".join(problems))

    @property
    def pulse_m(self) -> float:
        """Distance one pulse stands for, as the odometer counts it [m]."""
        return (
            math.pi
            * self.wheel_diameter_m
            * (1 + self.diameter_error)
            / (self.pulses_per_revolution)
        )

    @property
    def slip_acceleration_mps2(self) -> float:
        """Acceleration above which the driven wheels slip [m/s2]."""
        return self.adhesion * GRAVITY_MPS2 * self.traction_mass_fraction

    @property
    def slide_deceleration_mps2(self) -> float:
        """Deceleration above which the braked wheels slide [m/s2]."""
        return self.adhesion * GRAVITY_MPS2 * self.braked_mass_fraction


@dataclass(frozen=True)
class Measurement:
    """What the odometer gives at one communication point."""

    distance_m: float
    """Measured distance travelled: whole pulses."""
    speed_mps: float
    """Wheel speed: pulses counted over the step."""
    radar_speed_mps: float
    """Radar speed; 0 when ``radar_valid`` is false."""
    radar_valid: bool
    adhesion_state: int
    """SLIP, NONE or SLIDE over the step (ground truth, for the scorer and the map)."""
    true_distance_m: float
    """The distance the measurement stands for (truth, predicted over the last step)."""


class Odometer:
    """The sensor model; ``start`` once, then ``step`` per communication point."""

    def __init__(self, errors: OdometerErrors) -> None:
        self.errors = errors
        self._random = random.Random(errors.seed)
        self._phase = self._random.random()
        self._true = 0.0  # D(t) of the last input
        self._wheel = 0.0  # the wheel's distance (with diameter error and slip) at D(t)
        self._pulses = 0
        self._state = NONE
        self._episode = 1.0

    def start(self, distance_m: float) -> Measurement:
        """The run begins with the train having travelled ``distance_m`` (truth)."""
        self._true, self._wheel, self._pulses = distance_m, 0.0, 0
        return Measurement(0.0, 0.0, 0.0, False, NONE, distance_m)

    def step(
        self,
        step_s: float,
        *,
        distance_m: float,
        speed_mps: float,
        acceleration_mps2: float,
        wheelslip: bool = False,
        wheelskid: bool = False,
    ) -> Measurement:
        """Inputs at ``t`` (truth), the measurement at ``t + step_s`` (module docstring)."""
        state = self._adhesion_state(acceleration_mps2, wheelslip, wheelskid)
        travelled = max(0.0, distance_m - self._true)
        self._wheel += self._wheel_distance(travelled, state)
        self._true = distance_m
        ahead = _predicted_travel(abs(speed_mps), acceleration_mps2, step_s)
        wheel = self._wheel + self._wheel_distance(ahead, state)
        pulses = math.floor(wheel / self._true_pulse_m() + self._phase)
        counted = pulses - self._pulses
        self._pulses = pulses
        pulse = self.errors.pulse_m
        true_speed = max(0.0, abs(speed_mps) + acceleration_mps2 * step_s)
        radar, valid = self._radar(true_speed)
        return Measurement(
            distance_m=pulses * pulse,
            speed_mps=counted * pulse / step_s,
            radar_speed_mps=radar,
            radar_valid=valid,
            adhesion_state=state,
            true_distance_m=distance_m + ahead,
        )

    def _true_pulse_m(self) -> float:
        """True distance the wheel rolls per pulse (the true circumference's share)."""
        return math.pi * self.errors.wheel_diameter_m / self.errors.pulses_per_revolution

    def _adhesion_state(self, acceleration: float, wheelslip: bool, wheelskid: bool) -> int:
        e = self.errors
        if acceleration > 0 and (wheelslip or acceleration > e.slip_acceleration_mps2):
            state = SLIP
        elif acceleration < 0 and (wheelskid or -acceleration > e.slide_deceleration_mps2):
            state = SLIDE
        else:
            state = NONE
        if state != NONE and state != self._state:
            self._episode = self._random.uniform(0.5, 1.5)
        self._state = state
        return state

    def _wheel_distance(self, true_m: float, state: int) -> float:
        """How far the wheel's circumference rolls while the train moves ``true_m``."""
        if state == SLIP:
            return true_m * (1 + self.errors.slip * self._episode)
        if state == SLIDE:
            return true_m * max(0.0, 1 - self.errors.slide * self._episode)
        return true_m

    def _radar(self, true_speed: float) -> tuple[float, bool]:
        e = self.errors
        if not e.radar:
            return 0.0, False
        noise = self._random.gauss(0.0, e.radar_noise_mps) if e.radar_noise_mps > 0 else 0.0
        if true_speed < e.radar_min_speed_mps:
            return 0.0, False
        return max(0.0, true_speed * (1 + e.radar_bias) + noise), True


def _predicted_travel(speed: float, acceleration: float, step_s: float) -> float:
    """Distance covered in ``step_s`` from ``speed`` at constant ``acceleration``; a braking
    train stops and stays."""
    if acceleration < 0 and speed + acceleration * step_s < 0:
        return speed * speed / (-2 * acceleration)
    return max(0.0, speed * step_s + 0.5 * acceleration * step_s * step_s)
