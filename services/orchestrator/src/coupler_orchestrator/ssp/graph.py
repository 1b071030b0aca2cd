"""The connection graph: raw SSD connections between component, system and signal-dictionary
connectors, flattened into component-to-component connections.

Each raw connection is oriented by the roles of its ends as seen from the system that declares
it (an output of an element is a source, a system's own input connector is a source inside the
system, ...); where neither end has a role the order of the file applies. Flattening follows
the oriented edges from every component connector through system connectors and dictionary
entries to the component connectors they reach.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

from .documents import checkpoint
from .model import Component, Connection, InterExtrapolation, Transformation


@dataclass(frozen=True)
class Node:
    """One end of a raw connection."""

    key: tuple[str, ...]
    """("comp", *component path, connector), ("sys", *system path, connector) or
    ("dict", *system path, dictionary name, entry)."""
    role: str | None
    """"source", "sink" or None, seen from the declaring system."""
    label: str


@dataclass(frozen=True, kw_only=True)
class Edge:
    """What a raw connection carries besides its ends."""

    transformation: Transformation | None
    suppress_unit_conversion: bool
    decoupled: bool
    decouple_type: str | None
    decouple_priority: int | None
    inter_extrapolation: InterExtrapolation | None
    file: str
    line: int
    label: str


@dataclass
class Graph:
    """Oriented raw connections."""

    out: dict[tuple[str, ...], list[tuple[tuple[str, ...], Edge]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    into: dict[tuple[str, ...], int] = field(default_factory=lambda: defaultdict(int))
    labels: dict[tuple[str, ...], str] = field(default_factory=dict)

    def add(self, a: Node, b: Node, edge: Edge) -> None:
        """Add the connection a - b, oriented by the ends' roles."""
        backwards = a.role == "sink" or b.role == "source"
        forwards = a.role == "source" or b.role == "sink"
        if backwards and not forwards:
            a, b = b, a
        self.labels[a.key] = a.label
        self.labels[b.key] = b.label
        self.out[a.key].append((b.key, edge))
        self.into[b.key] += 1

    def flatten(
        self,
        components: dict[tuple[str, ...], Component],
        warnings: list[str],
        problems: list[str],
    ) -> list[Connection]:
        """Component-to-component connections, in file order of their first leg."""
        result: list[tuple[int, Connection]] = []
        reached: set[tuple[str, ...]] = set()
        for start in list(self.out):
            if start[0] != "comp":
                continue
            checkpoint()
            for end, legs in self._walk(start, [], set(), warnings):
                reached.update(k for k in (start, end))
                connection = self._connection(start, end, legs, problems)
                if connection is not None:
                    result.append((connection.line, connection))
        for node in list(self.out):
            if node[0] != "comp" and self.into.get(node, 0) == 0:
                what = (
                    "root system connector" if node[0] == "sys" and len(node) == 2 else "connector"
                )
                for target, edge in self.out[node]:
                    warnings.append(
                        f"{edge.file} line {edge.line}: connection {edge.label}: nothing drives "
                        f"{what} '{self.labels[node]}', so '{self.labels[target]}' is not "
                        "connected by it; ignored"
                    )
        result.sort(key=lambda item: item[0])
        return [c for _, c in result]

    def _walk(
        self,
        node: tuple[str, ...],
        legs: list[Edge],
        seen: set[tuple[str, ...]],
        warnings: list[str],
    ) -> list[tuple[tuple[str, ...], list[Edge]]]:
        found = []
        for target, edge in self.out.get(node, []):
            path = [*legs, edge]
            if target[0] == "comp":
                found.append((target, path))
            elif target in seen:
                continue
            elif not self.out.get(target):
                what = (
                    "the root system's connector"
                    if target[0] == "sys" and len(target) == 2
                    else "connector"
                )
                warnings.append(
                    f"{edge.file} line {edge.line}: connection {edge.label} ends at {what} "
                    f"'{self.labels[target]}', which leads to no component; "
                    "not interpretable, ignored"
                )
            else:
                found.extend(self._walk(target, path, seen | {target}, warnings))
        return found

    def _connection(
        self,
        start: tuple[str, ...],
        end: tuple[str, ...],
        legs: list[Edge],
        problems: list[str],
    ) -> Connection | None:
        first = legs[0]
        transformations = [e.transformation for e in legs if e.transformation is not None]
        if len(transformations) > 1:
            lines = ", ".join(f"line {e.line}" for e in legs if e.transformation is not None)
            problems.append(
                f"{first.file} line {first.line}: connection {self.labels[start]} -> "
                f"{self.labels[end]} passes through nested systems with a transformation on more "
                f"than one leg ({lines}); keep one transformation on the path"
            )
            return None
        decouple = next((e for e in legs if e.decouple_type is not None), None)
        filtered = next((e for e in legs if e.inter_extrapolation is not None), None)
        return Connection(
            start_element=".".join(start[1:-1]),
            start_connector=start[-1],
            end_element=".".join(end[1:-1]),
            end_connector=end[-1],
            transformation=transformations[0] if transformations else None,
            suppress_unit_conversion=any(e.suppress_unit_conversion for e in legs),
            decoupled=any(e.decoupled for e in legs),
            decouple_type=decouple.decouple_type if decouple else None,
            decouple_priority=decouple.decouple_priority if decouple else None,
            inter_extrapolation=filtered.inter_extrapolation if filtered else None,
            file=first.file,
            line=first.line,
        )
