"""The localisation's estimator on the scenario's line (its linking data from the railML file),
fed by the transmission model from a train driven at constant speed: positions, the interval,
its reset at each group, linking errors for lost groups, rejected telegrams, camera frames."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from localisation.estimator import Estimate, Estimator, EstimatorSettings, Odometry, Sighting
from localisation.linking import Linking
from localisation.transmission import BaliseFaults, Telegram, Transmission, parse_telegrams

FRONT, ANTENNA = 41.7, 39.7  # the railway scenario's train: front and antenna at distance 0
H = 1.0


@dataclass
class Run:
    """Per step: the truth, the estimate, the telegrams and the faults."""

    truth: list[float] = field(default_factory=list)
    estimates: list[Estimate] = field(default_factory=list)
    faults: list[str] = field(default_factory=list)


def drive(
    line: Linking,
    *,
    speed: float = 16.0,
    seconds: int = 400,
    odometer_scale: float = 1.0,
    faults: BaliseFaults | None = None,
    settings: EstimatorSettings | None = None,
) -> Run:
    """A train at ``speed`` from distance 0, its odometer reading ``odometer_scale`` times the
    truth, through the balise transmission (with ``faults``) into the estimator, with the
    Jacobi delays of the scenario: the estimate at t + h from inputs at t."""
    estimator = Estimator(
        line,
        settings or EstimatorSettings(start_front_m=FRONT, antenna_to_front_m=FRONT - ANTENNA),
    )
    transmission = Transmission(faults=faults or BaliseFaults(), antenna_offset_m=ANTENNA)
    transmission.start(0.0, 0.0)
    estimator.start(0.0, Odometry(0.0, 0.0))
    balises = sorted((d, b, g.group_id) for g in line.groups for b, d in g.balises)
    run = Run()
    telegrams = ""
    antenna_before = ANTENNA
    for k in range(seconds):
        t = k * H
        distance = speed * t
        antenna = distance + ANTENNA
        passed = ";".join(f"{b}:{g}:{d!r}" for d, b, g in balises if antenna_before < d <= antenna)
        antenna_before = antenna
        odometry = Odometry(distance * odometer_scale, speed * odometer_scale)
        estimate = estimator.step(t, H, odometry, parse_telegrams(telegrams))
        telegrams, injected = transmission.step(t, passed, distance)
        run.truth.append(FRONT + speed * (t + H))
        run.estimates.append(estimate)
        run.faults.append(injected)
    return run


def violations(run: Run) -> list[int]:
    return [
        k
        for k, (truth, e) in enumerate(zip(run.truth, run.estimates, strict=True))
        if not e.min_safe_front_m <= truth <= e.max_safe_front_m
    ]


def test_exact_odometry_tracks_the_truth_and_reads_every_group(line: Linking) -> None:
    run = drive(line, seconds=600)  # 9.6 km
    assert violations(run) == []
    assert max(abs(e.front_m - t) for t, e in zip(run.truth, run.estimates, strict=True)) < 0.01
    read = [e.last_group_id for e in run.estimates]
    passed = [g.group_id for g in line.groups if g.start_m < 16.0 * 598 + ANTENNA]
    assert sorted(set(read) - {0}) == passed[:-1] or sorted(set(read) - {0}) == passed
    assert run.estimates[-1].linking_errors == 0 and run.estimates[-1].rejected_telegrams == 0


def test_interval_grows_five_percent_and_resets_at_each_group(line: Linking) -> None:
    run = drive(line, seconds=300, odometer_scale=1.03)  # a 3 % over-reading odometer
    assert violations(run) == []
    half = [(e.max_safe_front_m - e.min_safe_front_m) / 2 for e in run.estimates]
    since = [e.distance_since_group_m for e in run.estimates]
    for k in range(1, len(run.estimates)):
        if run.estimates[k].last_group_id == run.estimates[k - 1].last_group_id:
            assert since[k] > since[k - 1]  # grows between groups
            accuracy = 1.0 if run.estimates[k].last_group_id else 2.0  # a group's, the start's
            assert half[k] == pytest.approx(accuracy + 5.0 + 0.05 * since[k])
    resets = [k for k in range(1, len(since)) if since[k] < since[k - 1]]
    assert len(resets) >= 5
    assert all(half[k] < half[k - 1] for k in resets)


def test_odometer_worse_than_the_envelope_breaks_integrity(line: Linking) -> None:
    run = drive(line, seconds=600, odometer_scale=1.08)  # 8 % over-reading
    assert violations(run)
    worst = max(run.estimates[k].front_m - run.truth[k] for k in violations(run))
    assert worst > 0  # over-reading: the estimate runs ahead of the truth


def test_a_whole_group_lost_raises_the_linking_error_naming_it(line: Linking) -> None:
    lost = line.groups[5]
    run = drive(line, seconds=600, faults=BaliseFaults(lost_groups=frozenset({lost.group_id})))
    assert any("lost:" in f and f":{lost.group_id}" in f for f in run.faults)
    last = run.estimates[-1]
    assert last.linking_errors == 1 and last.missed_group_id == lost.group_id
    raised = next(k for k, e in enumerate(run.estimates) if e.linking_error)
    # raised once the train is surely past it, before the next group is read
    assert run.truth[raised] - (FRONT - ANTENNA) > lost.end_m
    assert run.estimates[raised].last_group_id == line.groups[4].group_id
    # the interval kept growing over the lost group: wider than any without a loss
    since = max(e.distance_since_group_m for e in run.estimates)
    assert since > line.groups[6].start_m - line.groups[4].start_m - 20
    assert violations(run) == []
    # the next group read clears the flag
    cleared = next(
        k for k in range(raised, len(run.estimates)) if not run.estimates[k].linking_error
    )
    assert run.estimates[cleared].last_group_id == line.groups[6].group_id


def test_one_balise_of_a_group_lost_is_no_linking_error(line: Linking) -> None:
    group = next(g for g in line.groups if len(g.balises) > 1)
    first = group.balises[0][0]
    run = drive(line, seconds=600, faults=BaliseFaults(lost_balises=frozenset({first})))
    assert run.estimates[-1].linking_errors == 0
    assert violations(run) == []


def test_corrupt_telegrams_are_rejected_and_late_groups_lag(line: Linking) -> None:
    corrupt = line.groups[3].balises[0][0]
    run = drive(line, seconds=300, faults=BaliseFaults(corrupt_balises=frozenset({corrupt})))
    assert run.estimates[-1].rejected_telegrams == 1
    late = line.groups[3]
    run = drive(
        line,
        seconds=300,
        faults=BaliseFaults(late_groups=frozenset({late.group_id}), late_delay_s=2.0),
    )
    after = next(k for k, e in enumerate(run.estimates) if e.last_group_id == late.group_id)
    # the reader took the pass for 2 s later: the estimate lags 32 m behind
    assert run.estimates[after].front_m - run.truth[after] == pytest.approx(-32.0, abs=0.5)


def test_camera_frames_read_the_expected_group(line: Linking) -> None:
    estimator = Estimator(line, EstimatorSettings(start_front_m=100.0))
    estimator.start(0.0, Odometry(0.0, 0.0))
    group = line.after(None, 100.0)
    assert group is not None
    places = [d for _, d in group.balises]
    # the odometer says the front is at 100 m + 10 m; the camera sees the group 20 m ahead of
    # a front really at 100 + 12 m
    front = group.start_m - 20.0
    odometry = Odometry(front - 100.0 - 2.0, 10.0)
    frame = [Sighting(1.0, 20.0 + d - places[0]) for d in places]
    e = estimator.step(1.0, 1.0, odometry, frames=[frame])
    assert e.last_group_id == group.group_id
    assert e.front_m == pytest.approx(front + 10.0)
    # a frame that shows fewer balises than the group has reads nothing
    estimator.start(0.0, Odometry(0.0, 0.0))
    e = estimator.step(1.0, 1.0, odometry, frames=[frame[:-1] if len(frame) > 1 else []])
    assert e.last_group_id == 0


def test_telegrams_of_unknown_balises_or_behind_the_reference_are_rejected(
    line: Linking,
) -> None:
    estimator = Estimator(line, EstimatorSettings(start_front_m=FRONT, antenna_to_front_m=2.0))
    estimator.start(0.0, Odometry(0.0, 0.0))
    first, second = line.groups[0], line.groups[1]
    b1, d1 = first.balises[0]
    travel = d1 - ANTENNA
    estimator.step(10.0, 1.0, Odometry(travel, 10.0), [Telegram(b1, first.group_id, 10.0)])
    e = estimator.step(11.0, 1.0, Odometry(travel + 10, 10.0), [Telegram(99999, 1, 10.5)])
    assert e.rejected_telegrams == 1 and e.last_group_id == first.group_id
    b2, d2 = second.balises[0]
    travel2 = d2 - ANTENNA
    estimator.step(20.0, 1.0, Odometry(travel2, 10.0), [Telegram(b2, second.group_id, 20.0)])
    e = estimator.step(21.0, 1.0, Odometry(travel2 + 10, 10.0), [Telegram(b1, first.group_id, 21)])
    assert e.rejected_telegrams == 2 and e.last_group_id == second.group_id
