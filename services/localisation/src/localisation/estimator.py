"""The localisation itself: odometry fused with balise readings and the line's linking data into
the train's front-end position with a confidence interval -- an example of the system a user
validates, meant to be replaced by theirs.

Position. The train's front is at ``reference + (odometer now - odometer at the reference)``.
The reference is the last relevant balise group (LRBG): when a balise of the group the linking
data says comes next is read, the front was at that balise's distance (railML) plus
``antenna_to_front`` when the antenna passed it, and the odometer's value then is looked up in
its recent history at the telegram's time stamp. At the start the reference is
``start_front`` (known to ``start_accuracy``).

Confidence interval (min/max safe front end, as ETCS names them): the estimate
+- ``accuracy + odometry_fixed + odometry_factor * d + slip``, where ``accuracy`` is the
reference's (the group's location accuracy), ``d`` the distance measured since the reference
and ``slip`` the wheel/radar disagreement the step has seen while slipping (below). The defaults
are the ETCS odometry envelope, +-(5 m + 5 % d). Each group read resets it.

Odometry. Wheel distance, unless a Doppler radar is fitted and disagrees with the wheel speed
by more than ``slip_threshold``: the wheels slip or slide, so the step's distance is the
radar's and the disagreement widens the interval on both sides until the next group.

Linking. The group after the LRBG is expected while the min safe antenna position has not
passed its last balise by more than its accuracy and the distance a telegram takes to arrive
(``report_latency`` at the current speed). Past that, the group is declared missing: a linking
error (``linking_error`` stands until a group is read in a later step, ``linking_errors``
counts them, ``missed_group_id`` names the last), and the next group is expected; the
reference stays, so the interval keeps growing. A telegram of a balise the line does not have,
of another group than the telegram says, of a group behind the LRBG, or of a group beyond the
expected one whose place is outside the interval is rejected (``rejected_telegrams``); a
telegram of a group beyond the expected one inside the interval declares those in between
missing and becomes the reference.

Camera detections (perception's ``BaliseDetections``) instead of telegrams: a frame that shows
as many balises as the expected group has, spaced as the group's are (within
``spacing_tolerance``), and whose place is inside the interval (widened by
``detection_accuracy``), reads the group: the camera was the nearest detection's distance
before the group's first balise.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from localisation.linking import LinkedGroup, Linking
from localisation.transmission import Telegram


@dataclass(frozen=True, kw_only=True)
class EstimatorSettings:
    """The localisation's parameters (channels of the same names)."""

    start_front_m: float = 0.0
    """Front-end position along the line at the start."""
    start_accuracy_m: float = 2.0
    """How well the start position is known (+-) [m]."""
    antenna_to_front_m: float = 0.0
    """Front end = balise antenna + this [m]."""
    camera_to_front_m: float = 0.0
    """Front end = camera + this [m]."""
    odometry_fixed_m: float = 5.0
    """The odometry error's constant part [m] (ETCS: 5 m)."""
    odometry_factor: float = 0.05
    """The odometry error per metre travelled since the reference (ETCS: 5 %)."""
    slip_threshold_mps: float = 0.5
    """Wheel and radar speeds further apart than this: slip or slide [m/s]."""
    report_latency_s: float = 2.0
    """Longest a telegram takes to arrive after its balise was passed [s]."""
    detection_accuracy_m: float = 2.0
    """How far a camera detection's place may be off [m]."""
    spacing_tolerance_m: float = 1.0
    """How far detections' spacing may differ from the group's [m]."""


@dataclass(frozen=True)
class Odometry:
    """The odometer's outputs at one communication point."""

    distance_m: float
    speed_mps: float
    radar_speed_mps: float = 0.0
    radar_valid: bool = False


@dataclass(frozen=True)
class Sighting:
    """One balise a camera saw: when, and how far ahead of the camera."""

    time_s: float
    distance_ahead_m: float


@dataclass(frozen=True)
class Estimate:
    """The localisation's outputs."""

    front_m: float
    min_safe_front_m: float
    max_safe_front_m: float
    distance_since_group_m: float
    last_group_id: int
    expected_group_id: int
    linking_error: bool
    linking_errors: int
    missed_group_id: int
    rejected_telegrams: int


class Estimator:
    """See the module docstring; ``start`` once per run, then ``step``."""

    def __init__(self, linking: Linking, settings: EstimatorSettings) -> None:
        self.linking = linking
        self.settings = settings
        self._history: deque[tuple[float, float]] = deque(maxlen=256)

    def start(self, time_s: float, odometry: Odometry) -> Estimate:
        s = self.settings
        self._time, self._wheel, self._fused, self._speed = time_s, odometry.distance_m, 0.0, 0.0
        self._history.clear()
        self._history.append((time_s, 0.0))
        self._ref_front, self._ref_odo, self._ref_accuracy = (
            s.start_front_m,
            0.0,
            s.start_accuracy_m,
        )
        self._slip = 0.0
        self._lrbg: LinkedGroup | None = None
        self._expected = self.linking.after(None, s.start_front_m - s.antenna_to_front_m)
        self._error_at: float | None = None
        self._errors, self._missed, self._rejected = 0, 0, 0
        return self._estimate(0.0)

    def step(
        self,
        time_s: float,
        step_s: float,
        odometry: Odometry,
        telegrams: Sequence[Telegram] = (),
        frames: Sequence[Sequence[Sighting]] = (),
    ) -> Estimate:
        """Inputs at ``time_s``; the estimate at ``time_s + step_s``."""
        self._odometry(time_s, odometry)
        for telegram in sorted(telegrams, key=lambda t: t.time_s):
            self._telegram(time_s, telegram)
        for frame in frames:
            self._frame(time_s, frame)
        self._check_linking(time_s)
        return self._estimate(step_s)

    # --- odometry -----------------------------------------------------------------------------

    def _odometry(self, time_s: float, o: Odometry) -> None:
        dt = time_s - self._time
        wheel = o.distance_m - self._wheel
        travelled, self._speed = wheel, o.speed_mps
        if o.radar_valid and dt > 0:
            self._speed = o.radar_speed_mps
            if abs(o.speed_mps - o.radar_speed_mps) > self.settings.slip_threshold_mps:
                travelled = o.radar_speed_mps * dt
                self._slip += abs(wheel - travelled)
        self._time, self._wheel = time_s, o.distance_m
        self._fused += travelled
        self._history.append((time_s, self._fused))

    def _odometer_at(self, time_s: float) -> float:
        """The fused odometer at ``time_s``, linear in its history (clamped to its ends)."""
        times = [t for t, _ in self._history]
        i = bisect.bisect_left(times, time_s)
        if i == 0:
            return self._history[0][1]
        if i >= len(times):
            return self._history[-1][1]
        (t0, d0), (t1, d1) = self._history[i - 1], self._history[i]
        return d0 + (d1 - d0) * (time_s - t0) / (t1 - t0) if t1 > t0 else d1

    def _half_width(self, since_m: float) -> float:
        s = self.settings
        return (
            self._ref_accuracy + s.odometry_fixed_m + s.odometry_factor * abs(since_m) + self._slip
        )

    def _front_at(self, odometer_m: float) -> tuple[float, float]:
        """Estimated front end and the interval's half width at an odometer value."""
        since = odometer_m - self._ref_odo
        return self._ref_front + since, self._half_width(since)

    # --- balise readings ----------------------------------------------------------------------

    def _telegram(self, now_s: float, t: Telegram) -> None:
        found = self.linking.balise(t.balise_id)
        if found is None or found[0].group_id != t.group_id:
            self._rejected += 1
            return
        group, balise_m = found
        if self._lrbg is not None and group.start_m <= self._lrbg.start_m:
            if group is not self._lrbg:
                self._rejected += 1  # a group behind the reference: late, or a repeat
            return
        odometer = self._odometer_at(t.time_s)
        front, half = self._front_at(odometer)
        antenna = front - self.settings.antenna_to_front_m
        inside = abs(balise_m - antenna) <= half + group.accuracy_m
        if group is not self._expected and not inside:
            self._rejected += 1
            return
        self._read(now_s, group, balise_m + self.settings.antenna_to_front_m, odometer)

    def _frame(self, now_s: float, sightings: Sequence[Sighting]) -> None:
        group, s = self._expected, self.settings
        if group is None or not sightings or len(sightings) != len(group.balises):
            return
        seen = sorted(sightings, key=lambda d: d.distance_ahead_m)
        places = sorted(d for _, d in group.balises)
        if any(
            abs((a.distance_ahead_m - seen[0].distance_ahead_m) - (b - places[0]))
            > s.spacing_tolerance_m
            for a, b in zip(seen, places, strict=True)
        ):
            return
        odometer = self._odometer_at(seen[0].time_s)
        front, half = self._front_at(odometer)
        camera_front = places[0] - seen[0].distance_ahead_m + s.camera_to_front_m
        if abs(camera_front - front) > half + group.accuracy_m + s.detection_accuracy_m:
            return
        self._read(now_s, group, camera_front, odometer, extra_m=s.detection_accuracy_m)

    def _read(
        self,
        now_s: float,
        group: LinkedGroup,
        front_m: float,
        odometer_m: float,
        extra_m: float = 0.0,
    ) -> None:
        """``group`` was read with the front at ``front_m`` when the odometer said
        ``odometer_m``: it becomes the reference; groups skipped on the way are missing."""
        if self._expected is not None and group is not self._expected:
            for skipped in self.linking.between(self._expected, group):
                self._declare_missing(now_s, skipped)
        self._ref_front, self._ref_odo = front_m, odometer_m
        self._ref_accuracy = group.accuracy_m + extra_m
        self._slip = 0.0
        self._lrbg = group
        self._expected = self.linking.after(group, front_m)
        if self._error_at is not None and self._error_at < now_s:
            self._error_at = None

    def _check_linking(self, now_s: float) -> None:
        s = self.settings
        while self._expected is not None:
            front, half = self._front_at(self._fused)
            min_antenna = front - half - s.antenna_to_front_m
            window_end = (
                self._expected.end_m
                + self._expected.accuracy_m
                + abs(self._speed) * s.report_latency_s
            )
            if min_antenna <= window_end:
                return
            missing = self._expected
            self._declare_missing(now_s, missing)
            self._expected = self.linking.after(missing, front)

    def _declare_missing(self, now_s: float, group: LinkedGroup) -> None:
        self._errors += 1
        self._missed = group.group_id
        self._error_at = now_s

    # --- outputs ------------------------------------------------------------------------------

    def _estimate(self, ahead_s: float) -> Estimate:
        odometer = self._fused + self._speed * ahead_s
        front, half = self._front_at(odometer)
        return Estimate(
            front_m=front,
            min_safe_front_m=front - half,
            max_safe_front_m=front + half,
            distance_since_group_m=odometer - self._ref_odo,
            last_group_id=self._lrbg.group_id if self._lrbg else 0,
            expected_group_id=self._expected.group_id if self._expected else 0,
            linking_error=self._error_at is not None,
            linking_errors=self._errors,
            missed_group_id=self._missed,
            rejected_telegrams=self._rejected,
        )
