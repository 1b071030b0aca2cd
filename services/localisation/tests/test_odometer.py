"""The odometer model against its physics (localisation.odometer's docstring): diameter error,
slip and slide only above adhesion, quantisation, the radar, the seed."""

from __future__ import annotations

import math

import pytest

from localisation.odometer import NONE, SLIDE, SLIP, Measurement, Odometer, OdometerErrors

H = 1.0


def drive(errors: OdometerErrors, profile: list[tuple[float, float]]) -> list[Measurement]:
    """Run a true motion through the odometer: per step (speed at its start, acceleration over
    it), the simulator's distance integrated exactly; the measurement at each step's end."""
    odometer = Odometer(errors)
    odometer.start(0.0)
    distance, out = 0.0, []
    speed_before = 0.0
    for speed, accel in profile:
        # the simulator's inputs at t: distance and speed reached, mean acceleration of the
        # step that led there
        out.append(odometer.step(H, distance_m=distance, speed_mps=speed, acceleration_mps2=accel))
        distance += speed * H + 0.5 * accel * H * H
        speed_before = speed
    assert speed_before >= 0
    return out


def cruise(v: float, steps: int) -> list[tuple[float, float]]:
    return [(v, 0.0)] * steps


def test_one_percent_diameter_error_is_one_percent_distance_error_on_dry_rail() -> None:
    measured = drive(OdometerErrors(diameter_error=0.01), cruise(16.0, 600))[-1]
    assert measured.true_distance_m == pytest.approx(16.0 * 600)
    pulse = OdometerErrors(diameter_error=0.01).pulse_m
    assert measured.distance_m == pytest.approx(1.01 * measured.true_distance_m, abs=pulse)
    exact = drive(OdometerErrors(), cruise(16.0, 600))[-1]
    assert exact.distance_m == pytest.approx(exact.true_distance_m, abs=OdometerErrors().pulse_m)


def test_readings_are_whole_pulses() -> None:
    errors = OdometerErrors(pulses_per_revolution=10)  # a coarse sensor: 24 cm a pulse
    for m in drive(errors, cruise(1.234, 20)):
        pulses = m.distance_m / errors.pulse_m
        assert pulses == pytest.approx(round(pulses), abs=1e-9)
        assert abs(m.distance_m - m.true_distance_m) <= errors.pulse_m


def test_slip_only_under_traction_above_adhesion() -> None:
    wet = OdometerErrors(adhesion=0.1, slip=0.2, seed=3)  # slips above 0.657 m/s2
    assert wet.slip_acceleration_mps2 == pytest.approx(0.1 * 9.80665 * 0.67)
    below = drive(wet, [(i * 0.6, 0.6) for i in range(20)])
    assert {m.adhesion_state for m in below} == {NONE}
    assert below[-1].distance_m == pytest.approx(below[-1].true_distance_m, abs=wet.pulse_m)
    above = drive(wet, [(i * 0.8, 0.8) for i in range(20)])
    assert {m.adhesion_state for m in above} == {SLIP}
    over = above[-1].distance_m / above[-1].true_distance_m - 1
    assert 0.2 * 0.5 <= over <= 0.2 * 1.5  # one episode, its amount drawn in 0.5..1.5 x slip
    # the same deceleration brakes without sliding: slide needs more than adhesion * g * 1.0
    braking = drive(wet, [(16.0 - i * 0.8, -0.8) for i in range(20)])
    assert {m.adhesion_state for m in braking} == {NONE}
    # dry rail: nothing a train can do slips
    dry = drive(OdometerErrors(slip=0.2), [(i * 1.2, 1.2) for i in range(10)])
    assert {m.adhesion_state for m in dry} == {NONE}


def test_slide_under_braking_above_adhesion_under_reads() -> None:
    leaves = OdometerErrors(adhesion=0.04, slide=0.5, seed=1)  # slides above 0.39 m/s2
    profile = cruise(16.0, 10) + [(16.0 - i * 0.5, -0.5) for i in range(30)]
    out = drive(leaves, profile)
    assert {m.adhesion_state for m in out[:10]} == {NONE}
    assert {m.adhesion_state for m in out[11:]} == {SLIDE}
    braking_true = out[-1].true_distance_m - out[10].true_distance_m
    braking_measured = out[-1].distance_m - out[10].distance_m
    assert braking_measured < braking_true * (1 - 0.5 * 0.5) + leaves.pulse_m


def test_simulator_flags_start_slip_and_slide_whatever_the_acceleration() -> None:
    odometer = Odometer(OdometerErrors(slip=0.1))
    odometer.start(0.0)
    m = odometer.step(H, distance_m=0.0, speed_mps=5.0, acceleration_mps2=0.1, wheelslip=True)
    assert m.adhesion_state == SLIP
    m = odometer.step(H, distance_m=5.0, speed_mps=5.0, acceleration_mps2=-0.1, wheelskid=True)
    assert m.adhesion_state == SLIDE
    # a slip flag while braking is no slip: slip needs traction
    m = odometer.step(H, distance_m=10.0, speed_mps=5.0, acceleration_mps2=-0.1, wheelslip=True)
    assert m.adhesion_state == NONE


def test_radar_does_not_slip_and_is_silent_when_slow() -> None:
    errors = OdometerErrors(adhesion=0.05, slip=0.3, radar=True, radar_noise_mps=0.0)
    out = drive(errors, [(0.1, 0.0)] + [(i * 0.5, 0.5) for i in range(1, 20)])
    assert not out[0].radar_valid and out[0].radar_speed_mps == 0.0
    last = out[-1]
    assert last.adhesion_state == SLIP and last.radar_valid
    assert last.radar_speed_mps == pytest.approx(19 * 0.5 + 0.5)  # the true speed at t + h
    assert last.speed_mps > last.radar_speed_mps * 1.1  # the wheel runs fast


def test_same_seed_same_measurements_other_seed_other_ones() -> None:
    errors = OdometerErrors(adhesion=0.1, slip=0.2, radar=True, seed=7)
    profile = [(i * 0.8, 0.8) for i in range(10)] + cruise(8.0, 10)
    assert drive(errors, profile) == drive(errors, profile)
    other = drive(OdometerErrors(adhesion=0.1, slip=0.2, radar=True, seed=8), profile)
    assert other != drive(errors, profile)


def test_a_braking_train_is_predicted_to_stop_not_reverse() -> None:
    odometer = Odometer(OdometerErrors())
    odometer.start(0.0)
    m = odometer.step(H, distance_m=100.0, speed_mps=0.2, acceleration_mps2=-0.5)
    assert m.true_distance_m == pytest.approx(100.0 + 0.2**2 / 1.0)


@pytest.mark.parametrize(
    ("field", "value"), [("adhesion", 0.0), ("slide", 1.5), ("pulses_per_revolution", 0)]
)
def test_impossible_errors_are_refused_by_name(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        OdometerErrors(**{field: value})  # type: ignore[arg-type]


def test_pulse_length_of_a_class_642_wheel() -> None:
    assert OdometerErrors().pulse_m == pytest.approx(math.pi * 0.77 / 200)
