"""OpenMCx's evaluation order: components ordered by their connections, algebraic loops cut as
OpenMCx cuts them (its ``core/SubModel.c``, ``libs/tarjan``), so that a scenario written for
OpenMCx steps and initializes its components in the same order.

Every connection that is not decoupled from the start (``Always``) makes its target depend on
its source (OpenMCx takes every output of every component to depend on every input). The
strongly connected components come out of Tarjan's algorithm in the order OpenMCx's emits them:
depth first from each component in scenario order, the components a component depends on
before it. In every loop the bundle of connections from one component to another with the
highest priority is cut: a bundle from a component with a higher trigger sequence to one with a
lower first, else the highest ``IfNeeded`` priority (0 when none is given, and every connection
is ``IfNeeded`` unless it says otherwise); a bundle holding a ``Never`` connection is never cut;
ties go to the first pair found (the loop's components in the order they leave Tarjan's stack).
Cutting repeats until no loop is left.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

NEVER_CUT = -1
FIRST = sys.maxsize


@dataclass(frozen=True, kw_only=True)
class Edge:
    """One connection as the ordering sees it."""

    key: str
    """Identifies the connection (its driven input, ``Component.connector``)."""
    source: str
    target: str
    decouple: str
    """``always``, ``never`` or ``if_needed``."""
    priority: int = 0


class Uncuttable(Exception):
    """A loop none of whose connections may be cut."""

    def __init__(self, loop: Sequence[str]) -> None:
        super().__init__(" -> ".join([*loop, loop[0]]))
        self.loop = tuple(loop)


def groups(names: Sequence[str], edges: Sequence[Edge], cut: frozenset[str]) -> list[list[str]]:
    """Tarjan's strongly connected components of the components ``names``, in OpenMCx's order;
    each group's components in the order they leave the stack."""
    depends: dict[str, list[str]] = {n: [] for n in names}
    rank = {n: i for i, n in enumerate(names)}
    for edge in edges:
        active = edge.key not in cut and edge.decouple != "always"
        known = edge.target in depends and edge.source in rank
        if active and known and edge.source not in depends[edge.target]:
            depends[edge.target].append(edge.source)
    for sources in depends.values():
        sources.sort(key=rank.__getitem__)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    result: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in depends[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                group.append(w)
                if w == v:
                    break
            result.append(group)

    for name in names:
        if name not in index:
            connect(name)
    return result


def is_loop(group: list[str], edges: Sequence[Edge], cut: frozenset[str]) -> bool:
    if len(group) > 1:
        return True
    (only,) = group
    return any(
        e.source == only == e.target and e.key not in cut and e.decouple != "always" for e in edges
    )


def cut_loops(
    names: Sequence[str], edges: Sequence[Edge], sequence: Mapping[str, int]
) -> frozenset[str]:
    """The connections OpenMCx cuts (decouples) to break every loop, by key; ``sequence`` is
    each component's trigger sequence. Uncuttable names a loop nothing may be cut in."""
    cut = frozenset(e.key for e in edges if e.decouple == "always")
    while True:
        loops = [g for g in groups(names, edges, cut) if is_loop(g, edges, cut)]
        if not loops:
            return cut
        for group in loops:
            cut |= _cut_one(group, edges, cut, sequence)


def _cut_one(
    group: list[str], edges: Sequence[Edge], cut: frozenset[str], sequence: Mapping[str, int]
) -> frozenset[str]:
    best: tuple[str, str] | None = None
    best_priority = NEVER_CUT
    for a in group:
        for b in group:
            bundle = [e for e in edges if e.source == a and e.target == b]
            priority = NEVER_CUT
            for edge in bundle:
                if edge.key in cut:
                    continue
                if sequence.get(a, -1) > sequence.get(b, -1):
                    priority = FIRST
                    break
                if edge.decouple == "if_needed":
                    priority = max(priority, edge.priority)
                elif edge.decouple == "never":
                    priority = NEVER_CUT
                    break
            if priority > best_priority:
                best, best_priority = (a, b), priority
            if best_priority == FIRST:
                break
        if best_priority == FIRST:
            break
    if best is None:
        raise Uncuttable(group[::-1])
    return frozenset(e.key for e in edges if (e.source, e.target) == best)


def evaluation_order(
    names: Sequence[str], edges: Sequence[Edge], cut: frozenset[str]
) -> tuple[str, ...]:
    """The components in the order OpenMCx evaluates them, the ``cut`` connections left out."""
    return tuple(name for group in groups(names, edges, cut) for name in group)
