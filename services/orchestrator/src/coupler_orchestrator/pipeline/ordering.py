"""Stage 5: the order members step in, computed once.

Jacobi steps every member concurrently: scenario order, for determinism of everything that is
not concurrent (initialization order of results, logs). Gauss-Seidel steps them one after
another in topological order of the non-decoupled links, ties kept in scenario order; ``checks``
has already refused every loop such links would form.
"""

from __future__ import annotations

from collections.abc import Sequence

from coupler_orchestrator.model import Algorithm, Link


def execution_order(
    names: Sequence[str], links: Sequence[Link], algorithm: Algorithm
) -> tuple[str, ...]:
    """``names`` in the order the algorithm steps them."""
    if algorithm is Algorithm.JACOBI:
        return tuple(names)
    rank = {name: i for i, name in enumerate(names)}
    successors: dict[str, set[str]] = {n: set() for n in names}
    indegree = dict.fromkeys(names, 0)
    for link in links:
        if link.decoupled or link.source == link.target or link.target in successors[link.source]:
            continue
        successors[link.source].add(link.target)
        indegree[link.target] += 1
    ready = sorted((n for n in names if indegree[n] == 0), key=rank.__getitem__)
    order: list[str] = []
    while ready:
        current = ready.pop(0)
        order.append(current)
        for target in successors[current]:
            indegree[target] -= 1
            if indegree[target] == 0:
                ready.append(target)
        ready.sort(key=rank.__getitem__)
    if len(order) != len(names):
        raise AssertionError("checks let a Gauss-Seidel loop through")  # a bug, not an input
    return tuple(order)
