"""The master with OpenMCx's semantics: a scenario written for OpenMCx steps as OpenMCx steps it
(its ``core/Task.c``, ``core/Model.c``, ``steptypes/``), on Coupler's exact time grid.

- Initialization: members one after another in OpenMCx's evaluation order, each given its
  connected inputs from what the members before it produced (a cut connection carries its
  ``initial`` value), its defaulted inputs and its start values.
- A synchronization step [t_k, t_{k+1}]: every member whose own time is before t_{k+1} steps
  (a member with its own step, m * h, runs ahead: it steps from its own time by m * h at the
  first synchronization step that ends after its own time), reading its inputs through its
  connections' filters (``filters``) at the start of its step, or at its end with
  ``inputAtEndTime``; an Integrator with sub-steps reads them again at each sub-step. After a
  member's steps its connections are committed: at once in ``sequential`` (the next member sees
  it: Gauss-Seidel), after all members in the parallel step types (Jacobi).
- results.csv shows at t_k each member's outputs of its latest time not after t_k; the
  ``ComponentObserver``s see each member's own steps (OpenMCx's result files).
- A member that finishes (an FMU's fmi2Discard with fmi2Terminated) stops stepping; with endType
  first_component the run ends after that synchronization step (``terminated``), else the
  others go on (and the run ends when every member has finished).
- After the last step every member reads its inputs once more (OpenMCx's last input row).

Where OpenMCx sums time (an FMU's communication point, a member's own time), Coupler's times are
exact (t_0 + k h); docs/openmcx.md says what that changes.
"""

from __future__ import annotations

import asyncio
from collections import defaultdict
from collections.abc import Sequence

from coupler.channels import RunSetup, Value
from coupler.errors import ParticipantTimeout
from coupler.participant import EndRun, Values
from coupler_orchestrator.master.filters import (
    Comparison,
    Extrapolation,
    Filter,
    InterExtrapolation,
)
from coupler_orchestrator.master.loop import Master
from coupler_orchestrator.model import Filtering, Link, Member, OpenMcx, Plan
from coupler_orchestrator.observer import ComponentObserver, Observer


def master_of(plan: Plan) -> type[Master]:
    """The master that executes ``plan``: this one when the plan carries OpenMCx's additions
    (``Plan.openmcx``), else Coupler's."""
    return Master if plan.openmcx is None else OpenMcxMaster


def filter_of(filtering: Filtering, compare: Comparison) -> Filter:
    """The filter a connection is read through."""
    if filtering.interpolation is None:
        return Extrapolation(filtering.extrapolation)
    return InterExtrapolation(filtering.extrapolation, filtering.interpolation, compare)


class OpenMcxMaster(Master):
    """Executes a plan with OpenMCx's semantics (``Plan.openmcx``)."""

    def __init__(self, plan: Plan, observers: Sequence[Observer] = ()) -> None:
        super().__init__(plan, observers)
        assert plan.openmcx is not None
        self.spec: OpenMcx = plan.openmcx
        compare = Comparison(self.spec.eps)
        by_name = {m.name: m for m in plan.members}
        self.order = [by_name[name] for name in self.spec.order]
        self.into: dict[str, list[tuple[Link, Filter]]] = defaultdict(list)
        self.out_of: dict[str, list[tuple[Link, Filter]]] = defaultdict(list)
        self.filters: list[Filter] = []
        for link in plan.links:
            f = filter_of(self.spec.filters.get((link.target, link.input), Filtering()), compare)
            self.filters.append(f)
            self.into[link.target].append((link, f))
            self.out_of[link.source].append((link, f))
        self.reached = {m.name: 0 for m in plan.members}
        """The base step each member's own time has reached."""
        self.clock = {m.name: plan.grid.start for m in plan.members}
        """Each member's time as OpenMCx keeps it: for a member with its own step a running
        sum of its steps (its connections are read and written, its rows stamped, at that
        time; it is still stepped at the exact t_k), else the synchronization point."""
        self.latest: dict[str, Values] = {}
        """Each member's latest outputs (through its output ports)."""
        self.ahead: dict[str, list[tuple[int, Values]]] = defaultdict(list)
        """Outputs of members that ran ahead, until the synchronization time reaches them."""
        self.finished: set[str] = set()
        self.watchers = [o for o in observers if isinstance(o, ComponentObserver)]

    # -- initialization ----------------------------------------------------------------------

    async def initialize(self, initialized: list[Member]) -> None:
        grid = self.plan.grid
        for m in self.order:
            inputs: Values = dict(m.start_inputs)
            for link, _ in self.into[m.name]:
                if link.decoupled:
                    inputs[link.input] = self.spec.initial[(link.target, link.input)]
                    continue
                raw = self.latest.get(link.source, {}).get(link.output, 0.0)
                inputs[link.input] = link.convert(raw) if link.convert else raw
            setup = RunSetup(
                run_id=self.plan.run_id,
                run_secret=self.plan.run_secret,
                start_time=grid.start,
                step_size=m.step,
                stop_time=grid.stop,
                parameters=m.parameters,
                inputs=inputs,
                lease=self.plan.lease,
            )
            initialized.append(m)
            try:
                outputs = await asyncio.wait_for(m.participant.initialize(setup), m.deadline)
            except TimeoutError as exc:
                raise ParticipantTimeout(
                    f"no answer within {m.deadline:g} s",
                    participant=m.name,
                    call="Initialize",
                    status="DEADLINE_EXCEEDED",
                ) from exc
            self._reached(m, outputs, "Initialize", grid.start)
            self.store_outputs(m, self.latest[m.name], "Initialize", grid.start)
        for links in self.out_of.values():
            for link, f in links:
                f.write(grid.start, self.latest[link.source][link.output])
                f.commit(grid.start)

    # -- a synchronization step --------------------------------------------------------------

    async def advance(self, k: int) -> None:
        for f in self.filters:
            f.begin()
        finished = len(self.finished)
        for m in self.order:
            while m.name not in self.finished and self.reached[m.name] < k + 1:
                await self._step_member(m)
            if self.spec.sequential:
                self._enter(m, k + 1)
        if not self.spec.sequential:
            for m in self.order:
                self._enter(m, k + 1)
        for m in self.plan.members:
            queue = self.ahead.get(m.name)
            while queue and queue[0][0] <= k + 1:
                self.store_outputs(m, queue.pop(0)[1], "DoStep", self.plan.grid.time(k + 1))
        if len(self.finished) > finished:
            self._end_if_done()

    def _end_if_done(self) -> None:
        """End the run after this step: with endType first_component once a member finished,
        else once every member has."""
        if not (self.spec.first_component or len(self.finished) == len(self.order)):
            return
        names = ", ".join(m.name for m in self.order if m.name in self.finished)
        rule = "first_component" if self.spec.first_component else "end_time, every member"
        self.end_run(names, f"{names} finished (OpenMCx endType {rule})")

    async def _step_member(self, m: Member) -> None:
        """One step of ``m`` from its own time by its own step."""
        grid = self.plan.grid
        start = self.reached[m.name]
        begin = self.clock[m.name]
        own = m.name in self.spec.own_time  # OpenMCx: time += deltaTime
        end = begin + m.step if own else grid.time(start + m.multiple)
        read_at = end if m.name in self.spec.input_at_end else begin
        inputs = self._read(m, read_at)
        for watcher in self.watchers:
            watcher.component_inputs(m.name, read_at, {**m.start_inputs, **inputs})
        parts = self.spec.sub_steps.get(m.name, 1)
        step = m.step / parts
        exact = grid.time(start)
        try:
            if parts == 1:
                outputs = await self._call(m, exact, step, inputs)
            else:
                outputs = await self._sub_steps(m, exact, begin, step, parts, inputs)
        except EndRun as stop:
            self.finished.add(m.name)
            outputs = stop.outputs
        self.reached[m.name] = start + m.multiple
        self.clock[m.name] = end
        self._reached(m, outputs, "DoStep", end)
        self.ahead[m.name].append((start + m.multiple, self.latest[m.name]))

    def _reached(self, m: Member, outputs: Values, call: str, time: float) -> None:
        """``m``'s outputs at ``time``: through its output ports, written to its connections,
        told to the component observers."""
        self.check_answer(m, outputs, call, time)
        ports = self.spec.outputs.get(m.name)
        if ports:
            outputs = {n: (ports[n](v) if n in ports else v) for n, v in outputs.items()}
        self.latest[m.name] = outputs
        for link, f in self.out_of[m.name]:
            f.write(time, outputs[link.output])
        for watcher in self.watchers:
            watcher.component_outputs(m.name, time, outputs)

    def _enter(self, m: Member, k: int) -> None:
        """``m`` enters the communication point t_k: its connections take what it wrote."""
        time = self.plan.grid.time(k)
        own = self.clock[m.name]
        latest = self.latest[m.name]
        for link, f in self.out_of[m.name]:
            f.commit(time)
            f.write(own, latest[link.output])

    def _read(self, m: Member, time: float) -> Values:
        values: Values = {}
        for link, f in self.into[m.name]:
            raw: Value = f.read(time)
            values[link.input] = link.convert(raw) if link.convert else raw
        return values

    async def _sub_steps(
        self, m: Member, exact: float, begin: float, step: float, parts: int, inputs: Values
    ) -> Values:
        """OpenMCx's Integrator steps in ``parts`` sub-steps, reading its input at each, held to
        one deadline for them all."""
        with self.steppers[m.name].held(exact):
            outputs = await self._call(m, exact, step, inputs)
            at = begin
            for i in range(1, parts):
                at += step
                outputs = await self._call(m, exact + i * step, step, self._read(m, at))
        return outputs

    async def _call(self, m: Member, time: float, step: float, inputs: Values) -> Values:
        """One call of ``m``'s step, the way the master's steppers step it (on this thread,
        watched against its deadline, or awaited)."""
        stepper = self.steppers[m.name]
        if stepper.here:
            stepper.begin(time, step, inputs)
            outputs = stepper.finish()
        else:
            outputs = await stepper.whole(time, step, inputs)
        self.took(m, stepper)
        if self.abandoned:  # it came back after the watchdog had ended the run
            raise asyncio.CancelledError
        return outputs

    # -- the end -----------------------------------------------------------------------------

    async def wind_up(self) -> None:
        """OpenMCx's finish: every member reads its inputs once more, at its own time."""
        for f in self.filters:
            f.begin()
        for m in self.order:
            if m.name in self.spec.input_at_end:
                continue
            time = self.clock[m.name]
            inputs = self._read(m, time)
            for watcher in self.watchers:
                watcher.component_inputs(m.name, time, {**m.start_inputs, **inputs})
