"""The line's linking data, from its railML file: which balise groups come in which order, where
each of their balises lies, and how accurately that is known.

railML 2 holds the balises and groups with their positions along the line; ETCS linking
(packet 5) holds the same for the groups a train is to expect: their distances from each other
and a location accuracy (Q_LOCACC). This module makes the second from the first: every group of
the line is linked, in order of distance, each with the same ``accuracy_m``.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, replace
from pathlib import Path

from coupler_railway import load_infrastructure


@dataclass(frozen=True)
class LinkedGroup:
    """One balise group the train is to expect."""

    group_id: int
    balises: tuple[tuple[int, float], ...]
    """(balise id, distance along the line [m]) in the group's order."""
    accuracy_m: float
    """How far the true location may be from the given one (Q_LOCACC)."""

    @property
    def start_m(self) -> float:
        return min(d for _, d in self.balises)

    @property
    def end_m(self) -> float:
        return max(d for _, d in self.balises)


class Linking:
    """Linked groups in order of distance along the line."""

    def __init__(self, groups: tuple[LinkedGroup, ...]) -> None:
        self.groups = tuple(sorted(groups, key=lambda g: g.start_m))
        self._starts = [g.start_m for g in self.groups]
        self._index = {g.group_id: i for i, g in enumerate(self.groups)}
        self._balises = {b: (g, d) for g in self.groups for b, d in g.balises}

    @classmethod
    def from_railml(cls, path: str | Path, *, accuracy_m: float = 1.0) -> Linking:
        """Every group of the line in ``path``; RailMLError for a bad file."""
        infrastructure = load_infrastructure(Path(path))
        where = {b.id: (b.code, b.distance_m) for b in infrastructure.balises}
        return cls(
            tuple(
                LinkedGroup(g.code, tuple(where[b] for b in g.balise_ids), accuracy_m)
                for g in infrastructure.groups
            )
        )

    def with_accuracy(self, accuracy_m: float) -> Linking:
        """The same groups, each with location accuracy ``accuracy_m``."""
        return Linking(tuple(replace(g, accuracy_m=accuracy_m) for g in self.groups))

    def balise(self, balise_id: int) -> tuple[LinkedGroup, float] | None:
        """The group of a balise and its distance; None for a balise the line does not have."""
        return self._balises.get(balise_id)

    def group(self, group_id: int) -> LinkedGroup | None:
        return self.groups[self._index[group_id]] if group_id in self._index else None

    def after(self, group: LinkedGroup | None, position_m: float) -> LinkedGroup | None:
        """The group that follows ``group`` (None: the first beyond ``position_m``)."""
        if group is not None:
            following = self._index[group.group_id] + 1
        else:
            following = bisect.bisect_right(self._starts, position_m)
        return self.groups[following] if following < len(self.groups) else None

    def between(self, first: LinkedGroup, last: LinkedGroup) -> list[LinkedGroup]:
        """The groups from ``first`` up to, not including, ``last``."""
        return list(self.groups[self._index[first.group_id] : self._index[last.group_id]])
