"""Master algorithms: drive every member in lockstep on an exact time grid.

Each base step reads like FMPy's SSP loop: gather inputs from the outputs they are connected
to, step the members that are due, store their outputs, record. Jacobi steps all due members
concurrently on the outputs of the previous communication point; Gauss-Seidel steps them one
after another in topological order, each seeing what its predecessors just produced.
"""

from __future__ import annotations

import asyncio
import statistics
import time as wallclock
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import structlog

from coupler.channels import RunSetup, Value
from coupler.errors import CouplerError, ScenarioError
from coupler.participant import EndRun, Values
from coupler_orchestrator.observer import Column, Observer, RunInfo
from coupler_orchestrator.plan import Algorithm, Converter, Link, Member, Plan

log = structlog.get_logger("coupler.master")
Key = tuple[str, str]


def gauss_seidel_order(members: Sequence[Member], links: Sequence[Link]) -> tuple[Member, ...]:
    """Members in topological order of the non-decoupled links (ties keep scenario order).

    A loop that no decoupled connection breaks is a ScenarioError naming the loop.
    """
    names = [m.name for m in members]
    successors: dict[str, set[str]] = {n: set() for n in names}
    for link in links:
        if not link.decoupled and link.source != link.target:
            successors[link.source].add(link.target)
    indegree = {n: 0 for n in names}
    for targets in successors.values():
        for t in targets:
            indegree[t] += 1
    order: list[str] = []
    ready = [n for n in names if indegree[n] == 0]
    while ready:
        current = ready.pop(0)
        order.append(current)
        for t in sorted(successors[current], key=names.index):
            indegree[t] -= 1
            if indegree[t] == 0:
                ready.append(t)
        ready.sort(key=names.index)
    if len(order) < len(names):
        cycle = _find_cycle({n: successors[n] for n in names if n not in order})
        raise ScenarioError(
            f"Gauss-Seidel cannot order the loop {' -> '.join(cycle)}: mark one connection of "
            f'it decoupled (annotation org.coupler.connection decoupled="true" or OpenMCx '
            f"decoupling), or run with --algorithm jacobi"
        )
    by_name = {m.name: m for m in members}
    return tuple(by_name[n] for n in order)


def _find_cycle(graph: Mapping[str, set[str]]) -> list[str]:
    """A loop among members that topological sorting left over, closed (first == last).

    Every leftover member has a leftover predecessor (else it would have been ordered), but
    not necessarily a leftover successor (it may merely follow a loop), so walk backwards.
    """
    predecessors = {n: sorted(p for p in graph if n in graph[p]) for n in graph}
    node = min(graph)
    path, seen = [node], {node}
    while True:
        node = predecessors[node][0]
        if node in seen:
            loop = path[path.index(node) :][::-1]
            return [*loop, loop[0]]
        path.append(node)
        seen.add(node)


@dataclass
class _Feed:
    """The inputs of one member: (input, source key, converter)."""

    entries: list[tuple[str, Key, Converter | None]] = field(default_factory=list)

    def gather(self, store: Mapping[Key, Value]) -> Values:
        return {
            name: convert(store[key]) if convert else store[key]
            for name, key, convert in self.entries
        }


@dataclass
class RunResult:
    """How a run ended."""

    status: str
    """completed, aborted or failed."""
    reason: str
    """Why it ended so; empty when completed."""
    summary: dict[str, Any]
    """What summary.json holds."""


class Master:
    """Executes one plan; observers see every communication point."""

    def __init__(self, plan: Plan, observers: Sequence[Observer] = ()) -> None:
        self.plan = plan
        self.observers = list(observers)
        members = plan.members
        if plan.algorithm is Algorithm.GAUSS_SEIDEL:
            members = gauss_seidel_order(members, plan.links)
        self.members = members
        self.feeds: dict[str, _Feed] = defaultdict(_Feed)
        for link in plan.links:
            self.feeds[link.target].entries.append(
                (link.input, (link.source, link.output), link.convert)
            )
        self.columns = tuple(
            Column(name=f"{m.name}.{c.name}", unit=c.unit, type=str(c.type))
            for m in plan.members
            for c in m.outputs
        )
        self._keys = [(m.name, c.name) for m in plan.members for c in m.outputs]
        self.store: dict[Key, Value] = {}
        self.latency: dict[str, list[float]] = {m.name: [] for m in plan.members}
        self.completed_steps = 0
        self._ended: str | None = None
        """Why a participant asked to end the run, once one did."""

    async def run(self) -> RunResult:
        """Initialize, step to the end, terminate; never raises for a participant's failure."""
        plan, grid = self.plan, self.plan.grid
        wall_start = wallclock.perf_counter()
        status, reason = "completed", ""
        initialized: list[Member] = []  # every member Initialize was sent to
        log.info(
            "run_started",
            run_id=plan.run_id,
            members=len(self.members),
            steps=grid.steps,
            algorithm=str(plan.algorithm),
        )
        try:
            await self._initialize(initialized)
            info = RunInfo(
                run_id=plan.run_id,
                columns=self.columns,
                start_time=grid.start,
                stop_time=grid.stop,
                step_size=grid.step,
                steps=grid.steps,
            )
            for observer in self.observers:
                observer.started(info)
            self._record(grid.start)
            pending: dict[int, list[tuple[str, Values]]] = defaultdict(list)
            held: dict[str, Values] = {}
            for k in range(grid.steps):
                if plan.algorithm is Algorithm.JACOBI:
                    await self._jacobi_step(k, pending)
                else:
                    await self._gauss_seidel_step(k, held)
                self.completed_steps = k + 1
                self._record(grid.time(k + 1))
                if self._ended is not None:
                    status, reason = "terminated", self._ended
                    log.info("run_terminated", run_id=plan.run_id, reason=reason)
                    break
                if plan.realtime_factor:
                    await self._pace(wall_start, grid.time(k + 1) - grid.start)
        except CouplerError as exc:
            status, reason = "failed", str(exc)
            log.error(
                "run_failed",
                run_id=plan.run_id,
                reason=reason,
                time=grid.time(self.completed_steps),
            )
        except Exception as exc:  # a bug or a foreign error: still a clean end and a summary
            status, reason = "failed", f"{type(exc).__name__}: {exc}"
            log.exception("run_failed", run_id=plan.run_id, reason=reason)
        except (asyncio.CancelledError, KeyboardInterrupt):
            status, reason = "aborted", "interrupted by the user"
            log.warning("run_aborted", run_id=plan.run_id, time=grid.time(self.completed_steps))
            raise
        finally:
            await self._terminate(initialized, reason or "run completed")
            wall = wallclock.perf_counter() - wall_start
            summary = self._summary(status, reason, wall)
            for observer in self.observers:
                observer.finished(summary)
            if status == "completed":
                log.info(
                    "run_completed",
                    run_id=plan.run_id,
                    steps=self.completed_steps,
                    wall_time_s=round(wall, 3),
                    realtime_factor=summary["realtime_factor"],
                )
        return RunResult(status=status, reason=reason, summary=summary)

    async def _initialize(self, initialized: list[Member]) -> None:
        grid = self.plan.grid

        async def init(m: Member) -> Values:
            setup = RunSetup(
                run_id=self.plan.run_id,
                start_time=grid.start,
                step_size=grid.step * m.multiple,
                stop_time=grid.stop,
                parameters=m.parameters,
                inputs=m.start_inputs,
                lease=self.plan.lease,
            )
            initialized.append(m)  # Terminated on every path, even if its answer is refused
            return await m.participant.initialize(setup)

        results = await asyncio.gather(*(init(m) for m in self.members), return_exceptions=True)
        for m, result in zip(self.members, results, strict=True):
            if isinstance(result, BaseException):
                raise result
            self._store(m.name, result)
        initialized.sort(key=self.members.index)

    async def _step(self, m: Member, k: int) -> Values:
        grid = self.plan.grid
        inputs = self.feeds[m.name].gather(self.store) if m.name in self.feeds else {}
        started = wallclock.perf_counter()
        try:
            outputs = await m.participant.do_step(grid.time(k), grid.step * m.multiple, inputs)
        except EndRun as end:
            outputs = end.outputs
            if self._ended is None:
                reached = grid.time(k + m.multiple)
                self._ended = f"{m.name} asked to end the run at t={reached:g} s: {end.reason}"
        self.latency[m.name].append(wallclock.perf_counter() - started)
        return outputs

    async def _jacobi_step(self, k: int, pending: dict[int, list[tuple[str, Values]]]) -> None:
        due = [m for m in self.members if k % m.multiple == 0]
        results = await asyncio.gather(*(self._step(m, k) for m in due), return_exceptions=True)
        for m, result in zip(due, results, strict=True):
            if isinstance(result, BaseException):
                raise result
            pending[k + m.multiple].append((m.name, result))
        for name, outputs in pending.pop(k + 1, []):
            self._store(name, outputs)

    async def _gauss_seidel_step(self, k: int, pending: dict[str, Values]) -> None:
        """Members in order; outputs of t_{k+m} are stored in the slot of the base step that
        ends at t_{k+m}, so successors see them then and no row shows a value from later."""
        for m in self.members:
            if k % m.multiple == 0:
                pending[m.name] = await self._step(m, k)
            if (k + 1) % m.multiple == 0 and m.name in pending:
                self._store(m.name, pending.pop(m.name))

    def _store(self, name: str, outputs: Values) -> None:
        for channel, value in outputs.items():
            self.store[(name, channel)] = value

    def _record(self, time: float) -> None:
        if not self.observers:
            return
        missing = [k for k in self._keys if k not in self.store]
        if missing:
            raise ScenarioError(
                "participants did not report outputs they describe: "
                + ", ".join(f"{c}.{o}" for c, o in missing)
            )
        row = [self.store[k] for k in self._keys]
        for observer in self.observers:
            observer.stepped(time, row)

    async def _pace(self, wall_start: float, simulated: float) -> None:
        assert self.plan.realtime_factor
        ahead = simulated / self.plan.realtime_factor - (wallclock.perf_counter() - wall_start)
        if ahead > 0:
            await asyncio.sleep(ahead)

    async def _terminate(self, members: Sequence[Member], reason: str) -> None:
        results = await asyncio.gather(
            *(m.participant.terminate(reason) for m in members), return_exceptions=True
        )
        for m, result in zip(members, results, strict=True):
            if isinstance(result, Exception):
                log.warning("terminate_failed", participant=m.name, error=str(result))

    def _summary(self, status: str, reason: str, wall: float) -> dict[str, Any]:
        grid = self.plan.grid
        simulated = grid.time(self.completed_steps) - grid.start
        return {
            "status": status,
            "reason": reason,
            "run_id": self.plan.run_id,
            "algorithm": str(self.plan.algorithm),
            "start_time": grid.start,
            "stop_time": grid.stop,
            "end_time": grid.time(self.completed_steps),
            "step_size": grid.step,
            "steps": self.completed_steps,
            "steps_planned": grid.steps,
            "wall_time_s": round(wall, 6),
            "realtime_factor": round(simulated / wall, 3) if wall > 0 else None,
            "participants": {
                m.name: {
                    "multiple": m.multiple,
                    "steps": len(self.latency[m.name]),
                    "do_step_latency_ms": _latency(self.latency[m.name]),
                }
                for m in self.plan.members
            },
            "columns": [{"name": c.name, "unit": c.unit, "type": c.type} for c in self.columns],
        }


def _latency(samples: Sequence[float]) -> dict[str, float] | None:
    if not samples:
        return None
    ordered = sorted(samples)

    def pct(q: float) -> float:
        return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]

    return {
        "mean": round(statistics.fmean(ordered) * 1e3, 4),
        "p50": round(pct(0.5) * 1e3, 4),
        "p99": round(pct(0.99) * 1e3, 4),
    }
