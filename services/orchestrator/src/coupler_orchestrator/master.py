"""Stage 7: the master algorithm — drive every member in lockstep on an exact time grid.

Each base step reads like FMPy's SSP loop: gather inputs from the outputs they are connected
to, step the members that are due, store their outputs, record. Jacobi steps all due members
concurrently on the outputs of the previous communication point; Gauss-Seidel steps them one
after another in the plan's order, each seeing what its predecessors just produced.
t_k = t_0 + k*h; each member steps from t_k by exactly its configured step (its deltaTime,
else h), never by a difference of two communication points.
"""

from __future__ import annotations

import asyncio
import time as wallclock
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import structlog

from coupler.channels import RunSetup, Value
from coupler.errors import CouplerError, ParticipantError
from coupler.participant import EndRun, Values
from coupler_orchestrator.checks import Member
from coupler_orchestrator.observer import Column, Observer, RunEnd, RunInfo
from coupler_orchestrator.options import Algorithm
from coupler_orchestrator.plan import Plan
from coupler_orchestrator.wiring import Converter

log = structlog.get_logger("coupler.master")
Key = tuple[str, str]


@dataclass
class _Feed:
    """The inputs of one member: (input, source key, converter)."""

    entries: list[tuple[str, Key, Converter | None]] = field(default_factory=list)

    def gather(self, store: Mapping[Key, Value]) -> Values:
        return {
            name: convert(store[key]) if convert else store[key]
            for name, key, convert in self.entries
        }


class Master:
    """Executes one plan; observers see every communication point."""

    def __init__(self, plan: Plan, observers: Sequence[Observer] = ()) -> None:
        self.plan = plan
        self.observers = list(observers)
        self.feeds: dict[str, _Feed] = defaultdict(_Feed)
        for link in plan.links:
            self.feeds[link.target].entries.append(
                (link.input, (link.source, link.output), link.convert)
            )
        self.info = RunInfo(
            run_id=plan.run_id,
            algorithm=str(plan.algorithm),
            members=tuple(m.name for m in plan.members),
            multiples=tuple(m.multiple for m in plan.members),
            columns=tuple(
                Column(
                    name=f"{m.name}.{c.name}",
                    unit=c.unit,
                    type=str(c.type),
                    message_type=c.message_type,
                )
                for m in plan.members
                for c in m.outputs
            ),
            start_time=plan.grid.start,
            stop_time=plan.grid.stop,
            step_size=plan.grid.step,
            steps=plan.grid.steps,
        )
        self._keys = [(m.name, c.name) for m in plan.members for c in m.outputs]
        self._slot = {m.name: i for i, m in enumerate(plan.members)}
        self._timing: list[float | None] = [None] * len(plan.members)
        self.store: dict[Key, Value] = {}
        self.completed_steps = 0
        self._ended: str | None = None
        """Why a participant asked to end the run, once one did."""

    async def run(self) -> RunEnd:
        """Initialize, step to the end, terminate; never raises for a participant's failure
        (the run ends ``failed``); re-raises an interruption after ending the run ``aborted``."""
        plan, grid = self.plan, self.plan.grid
        wall_start = wallclock.perf_counter()
        status, reason = "completed", ""
        initialized: list[Member] = []  # every member Initialize was sent to
        log.info(
            "run_started",
            run_id=plan.run_id,
            members=len(plan.members),
            steps=grid.steps,
            algorithm=str(plan.algorithm),
        )
        try:
            for observer in self.observers:
                observer.started(self.info)
            await self._initialize(initialized)
            self._record(grid.start)
            pending: dict[int, list[tuple[Member, Values]]] = defaultdict(list)
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
                    break
                if plan.realtime_factor:
                    await self._pace(wall_start, grid.time(k + 1) - grid.start)
        except CouplerError as exc:
            status, reason = "failed", f"{exc} (the run had reached t={self._time_reached():g} s)"
            log.error("run_failed", run_id=plan.run_id, reason=reason)
        except Exception as exc:  # a bug or a foreign error: still a clean end and a summary
            status, reason = "failed", f"{type(exc).__name__}: {exc}"
            log.exception("run_failed", run_id=plan.run_id, reason=reason)
        except (asyncio.CancelledError, KeyboardInterrupt):
            status, reason = "aborted", "interrupted by the user"
            log.info("run_aborted", run_id=plan.run_id, time=self._time_reached())
            raise
        finally:
            await self._terminate(initialized, reason or "run completed")
            end = RunEnd(
                status=status,
                reason=reason,
                steps=self.completed_steps,
                end_time=self._time_reached(),
                wall_time=wallclock.perf_counter() - wall_start,
            )
            self._finish(end)
        return end

    def _time_reached(self) -> float:
        return self.plan.grid.time(self.completed_steps)

    def _finish(self, end: RunEnd) -> None:
        """Tell every observer, even if one of them fails (its failure is logged)."""
        for observer in self.observers:
            try:
                observer.finished(end)
            except Exception as exc:
                log.error("observer_failed", observer=type(observer).__name__, error=str(exc))
        log.info(
            f"run_{end.status}",
            run_id=self.plan.run_id,
            steps=end.steps,
            wall_time_s=round(end.wall_time, 3),
            reason=end.reason or None,
        )

    async def _initialize(self, initialized: list[Member]) -> None:
        grid = self.plan.grid

        async def init(m: Member) -> Values:
            setup = RunSetup(
                run_id=self.plan.run_id,
                start_time=grid.start,
                step_size=m.step,
                stop_time=grid.stop,
                parameters=m.parameters,
                inputs=m.start_inputs,
                lease=self.plan.lease,
            )
            initialized.append(m)  # Terminated on every path, even if its answer is refused
            return await m.participant.initialize(setup)

        members = self.plan.order
        results = await asyncio.gather(*(init(m) for m in members), return_exceptions=True)
        for m, result in zip(members, results, strict=True):
            if isinstance(result, BaseException):
                raise result
            self._store(m, result, "Initialize", grid.start)

    async def _step(self, m: Member, k: int) -> Values:
        grid = self.plan.grid
        inputs = self.feeds[m.name].gather(self.store) if m.name in self.feeds else {}
        started = wallclock.perf_counter()
        try:
            outputs = await m.participant.do_step(grid.time(k), m.step, inputs)
        except EndRun as end:
            outputs = end.outputs
            if self._ended is None:
                reached = grid.time(k + m.multiple)
                self._ended = f"{m.name} asked to end the run at t={reached:g} s: {end.reason}"
        self._timing[self._slot[m.name]] = wallclock.perf_counter() - started
        return outputs

    async def _jacobi_step(self, k: int, pending: dict[int, list[tuple[Member, Values]]]) -> None:
        due = [m for m in self.plan.order if k % m.multiple == 0]
        results = await asyncio.gather(*(self._step(m, k) for m in due), return_exceptions=True)
        for m, result in zip(due, results, strict=True):
            if isinstance(result, BaseException):
                raise result
            pending[k + m.multiple].append((m, result))
        for m, outputs in pending.pop(k + 1, []):
            self._store(m, outputs, "DoStep", self.plan.grid.time(k + 1))

    async def _gauss_seidel_step(self, k: int, held: dict[str, Values]) -> None:
        """Members in order; outputs of t_{k+m} are stored in the slot of the base step that
        ends at t_{k+m}, so successors see them then and no row shows a value from later."""
        for m in self.plan.order:
            if k % m.multiple == 0:
                held[m.name] = await self._step(m, k)
            if (k + 1) % m.multiple == 0 and m.name in held:
                self._store(m, held.pop(m.name), "DoStep", self.plan.grid.time(k + 1))

    def _store(self, m: Member, outputs: Values, call: str, time: float) -> None:
        """Keep a member's outputs; every output it describes must be there, and no other."""
        if len(outputs) != len(m.outputs) or any(c.name not in outputs for c in m.outputs):
            missing = [c.name for c in m.outputs if c.name not in outputs]
            extra = sorted(set(outputs) - {c.name for c in m.outputs})
            what = []
            if missing:
                what.append(f"without its described outputs {', '.join(missing)}")
            if extra:
                what.append(f"with outputs it does not describe: {', '.join(extra)}")
            raise ParticipantError(
                f"answered {call} for t={time:g} s {' and '.join(what)}; a participant returns "
                "every output it describes at every step",
                participant=m.name,
                call=call,
            )
        for channel, value in outputs.items():
            self.store[(m.name, channel)] = value

    def _record(self, time: float) -> None:
        row = [self.store[k] for k in self._keys]
        timing = self._timing
        for observer in self.observers:
            observer.stepped(time, row)
            observer.timed(timing)
        self._timing = [None] * len(timing)

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
