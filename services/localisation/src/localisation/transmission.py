"""The balise transmission: what the train's balise reader delivers of the balises its antenna
passed (TrackBalises' ground truth), with the faults of the air gap.

In, each communication point ``t``: TrackBalises' ``passed_in_step`` (every balise crossed,
``id:group:distance;...``) and the train's true distance travelled ``D(t)``. Out: telegrams,
``balise_id:group_id:time;...``, one per balise delivered in the step, ``time`` being when the
antenna passed the balise's centre (the reader's time stamp, found in the recent history of
``D + antenna_offset``, linear between communication points); and ``faults``, what was done to
which balise in the step, ``kind:balise_id:group_id;...`` -- ground truth for the scorer.

A telegram says which balise it is; where that balise lies is the line's linking data (railML),
so the telegram carries no distance.

Faults, each decided once per balise or group from ``seed`` and its id alone (the same balises
fail in every run with the same seed, whatever the timing):

- ``lost``: the balise gives nothing. Per balise with ``loss_probability`` or listed in
  ``lost_balises``; every balise of a group with ``group_loss_probability`` or listed in
  ``lost_groups`` (a whole group lost).
- ``late``: every telegram of the group arrives ``late_delay_s`` after the pass, and its time
  stamp is late by as much: the reader took the pass for later than it was, so a localisation
  that trusts it places the train behind the truth by the distance travelled in the delay.
  Per group with ``late_probability`` or listed in ``late_groups``.
- ``corrupt``: the telegram arrives with its balise and group ids replaced by random ones
  (0..16383, the range of ETCS' NID_BG) -- a corruption the telegram's own check did not catch.
  Per telegram with ``corrupt_probability`` or listed in ``corrupt_balises``.

A lost balise is never also late or corrupt; a corrupt telegram of a late group comes late.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

LOST, LATE, CORRUPT = "lost", "late", "corrupt"
MAX_ID = 16383
"""Largest id a corrupt telegram gets (NID_BG has 14 bits)."""


@dataclass(frozen=True, kw_only=True)
class BaliseFaults:
    """What goes wrong between the balises and the reader; nothing by default."""

    loss_probability: float = 0.0
    """Chance that one balise gives nothing."""
    lost_balises: frozenset[int] = frozenset()
    group_loss_probability: float = 0.0
    """Chance that every balise of a group gives nothing."""
    lost_groups: frozenset[int] = frozenset()
    late_probability: float = 0.0
    """Chance that a group's telegrams come late."""
    late_groups: frozenset[int] = frozenset()
    late_delay_s: float = 1.0
    """How late a late group's telegrams (and their time stamps) are [s]."""
    corrupt_probability: float = 0.0
    """Chance that one telegram is corrupt."""
    corrupt_balises: frozenset[int] = frozenset()
    seed: int = 0

    def __post_init__(self) -> None:
        for name in (
            "loss_probability",
            "group_loss_probability",
            "late_probability",
            "corrupt_probability",
        ):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be within 0..1, got {value}")
        if not self.late_delay_s >= 0.0:
            raise ValueError(f"late_delay must be >= 0 s, got {self.late_delay_s}")

    def _draw(self, kind: str, ident: int) -> float:
        return random.Random(f"{self.seed}:{kind}:{ident}").random()

    def lost(self, balise: int, group: int) -> bool:
        return (
            balise in self.lost_balises
            or group in self.lost_groups
            or self._draw("balise-loss", balise) < self.loss_probability
            or self._draw("group-loss", group) < self.group_loss_probability
        )

    def late(self, group: int) -> bool:
        return group in self.late_groups or self._draw("late", group) < self.late_probability

    def corrupt(self, balise: int) -> tuple[int, int] | None:
        """The ids a corrupt telegram of ``balise`` carries; None when it is intact."""
        if balise not in self.corrupt_balises and not (
            self._draw("corrupt", balise) < self.corrupt_probability
        ):
            return None
        garble = random.Random(f"{self.seed}:garble:{balise}")
        return garble.randint(0, MAX_ID), garble.randint(0, MAX_ID)


@dataclass(frozen=True)
class Pass:
    """A balise TrackBalises saw passed."""

    balise_id: int
    group_id: int
    distance_m: float


@dataclass(frozen=True)
class Telegram:
    """What the reader delivers of one balise."""

    balise_id: int
    group_id: int
    time_s: float
    """When the antenna passed the balise's centre, by the reader's clock."""

    def text(self) -> str:
        return f"{self.balise_id}:{self.group_id}:{self.time_s:.6f}"


def parse_passes(text: str) -> list[Pass]:
    """TrackBalises' ``passed_in_step``; ValueError naming a malformed entry."""
    passes = []
    for entry in filter(None, (part.strip() for part in text.split(";"))):
        try:
            balise, group, distance = entry.split(":")
            passes.append(Pass(int(balise), int(group), float(distance)))
        except ValueError as exc:
            raise ValueError(f"passed_in_step entry {entry!r} is not id:group:distance") from exc
    return passes


def parse_telegrams(text: str) -> list[Telegram]:
    """Telegrams as ``Transmission`` writes them; ValueError naming a malformed entry."""
    telegrams = []
    for entry in filter(None, (part.strip() for part in text.split(";"))):
        try:
            balise, group, time_s = entry.split(":")
            telegrams.append(Telegram(int(balise), int(group), float(time_s)))
        except ValueError as exc:
            raise ValueError(f"telegram {entry!r} is not balise_id:group_id:time") from exc
    return telegrams


def join(items: Iterable[str]) -> str:
    return ";".join(items)


@dataclass
class Transmission:
    """The reader between TrackBalises and the localisation; see the module docstring."""

    faults: BaliseFaults = field(default_factory=BaliseFaults)
    antenna_offset_m: float = 0.0
    """Antenna relative to the distance travelled (TrackBalises' ``antenna_offset``)."""
    history_s: float = 30.0
    """How far back pass times are looked for [s]."""

    def __post_init__(self) -> None:
        self._antenna: deque[tuple[float, float]] = deque()
        self._queue: list[tuple[float, Telegram]] = []

    def start(self, time_s: float, distance_m: float) -> None:
        self._antenna.clear()
        self._queue.clear()
        self._antenna.append((time_s, distance_m + self.antenna_offset_m))

    def step(self, time_s: float, passed: str, distance_m: float) -> tuple[str, str]:
        """Inputs at ``time_s``; returns (telegrams, faults) delivered in this step."""
        self._remember(time_s, distance_m + self.antenna_offset_m)
        done: list[str] = []
        for p in parse_passes(passed):
            if self.faults.lost(p.balise_id, p.group_id):
                done.append(f"{LOST}:{p.balise_id}:{p.group_id}")
                continue
            at = self._pass_time(p.distance_m)
            balise, group = p.balise_id, p.group_id
            garbled = self.faults.corrupt(p.balise_id)
            if garbled is not None:
                done.append(f"{CORRUPT}:{p.balise_id}:{p.group_id}")
                balise, group = garbled
            delay = 0.0
            if self.faults.late(p.group_id):
                done.append(f"{LATE}:{p.balise_id}:{p.group_id}")
                delay = self.faults.late_delay_s
            self._queue.append((time_s + delay, Telegram(balise, group, at + delay)))
        due = [t for when, t in self._queue if when <= time_s + 1e-9]
        self._queue = [(when, t) for when, t in self._queue if when > time_s + 1e-9]
        due.sort(key=lambda t: t.time_s)
        return join(t.text() for t in due), join(done)

    def _remember(self, time_s: float, antenna_m: float) -> None:
        self._antenna.append((time_s, antenna_m))
        while len(self._antenna) > 2 and self._antenna[1][0] < time_s - self.history_s:
            self._antenna.popleft()

    def _pass_time(self, balise_m: float) -> float:
        """When the antenna was over ``balise_m``: the last crossing in the history, linear
        between its samples; the oldest sample's time when it is older than the history."""
        samples = list(self._antenna)
        for (t0, a0), (t1, a1) in zip(reversed(samples[:-1]), reversed(samples[1:]), strict=True):
            if min(a0, a1) < balise_m <= max(a0, a1) or (a0 == a1 == balise_m):
                if a1 == a0:
                    return t1
                return t0 + (balise_m - a0) / (a1 - a0) * (t1 - t0)
        return samples[0][0] if samples else math.nan
