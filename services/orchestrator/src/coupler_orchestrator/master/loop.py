"""Stage 7: the master algorithm — drive every member in lockstep on an exact time grid.

Each base step reads like FMPy's SSP loop: gather inputs from the outputs they are connected
to, step the members that are due, store their outputs, record. Jacobi steps all due members
concurrently on the outputs of the previous communication point; Gauss-Seidel steps them one
after another in the plan's order, each seeing what its predecessors just produced.

How each member steps is an object chosen once (``steppers``); the loops only begin and finish
steps. Members that compute in this process (in-process FMUs) step on this thread without
awaiting — while the remote members' steps are in flight — under the eye of a ``Watchdog`` that
ends the run when such a step outlives its deadline. Remote members on the native step channel
are sent their requests first and answered last, on this thread too; the others are awaited. A
run of in-process FMUs only is stepped in C (``native_fmu_step``), with the same meaning:
unpaced, several base steps per call, the observers told of them together
(``Observer.stepped_batch``); else one base step per call.
t_k is the double nearest to the exact decimal t_0 + k*h (``TimeGrid.time``); each member
steps from t_k by exactly its configured step (its deltaTime, else h), never by a difference
of two communication points.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time as wallclock
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from operator import itemgetter

import structlog

from coupler.channels import RunSetup, Value
from coupler.errors import CouplerError, ParticipantError, ParticipantTimeout, ValueTooLarge
from coupler.participant import EndRun, Values
from coupler_orchestrator.master import native_fmu_step
from coupler_orchestrator.master.steppers import Stepper, steppers_of
from coupler_orchestrator.master.watchdog import Watchdog
from coupler_orchestrator.model import Algorithm, Converter, Member, Plan
from coupler_orchestrator.observer import Column, Observer, RunEnd, RunInfo, StepPath, Steps

log = structlog.get_logger("coupler.master")

YIELD_EVERY = 0.02
"""Longest stretch [s] the step loop keeps the event loop to itself when no step awaits (only
in-process and native members): an interrupt, the live monitor and the progress line get
their turn in between."""
TURNS = 4
"""Turns of the event loop the step loop gives after each such stretch: one turn runs only
what is ready at that moment, and what it makes ready (data read from a socket wakes a
future, the future a task) needs the next; an idle turn costs about 10 us."""
DUE_PATTERNS = 1024
"""At most this many distinct sets of due members are kept (members with large, coprime
multiples make more; those are worked out step by step)."""
Key = tuple[str, str]
Due = tuple[Member, Stepper]


async def _landed(flying: list[asyncio.Future[Values]]) -> None:
    """Every answer in flight landed; cancelled (Ctrl-C, SIGTERM), the calls in flight are
    cancelled too: an interrupted run does not wait for a participant stuck in its step."""
    try:
        await asyncio.wait(flying)
    except asyncio.CancelledError:
        for landing in flying:
            landing.cancel()
        raise


def _failed_recording(end: RunEnd, problem: str) -> RunEnd:
    """``end`` after a recorder could not write what it held: failed, saying so."""
    if end.status in ("completed", "terminated"):
        reason = f"{problem} (the run itself had {end.status} at t={end.end_time:g} s)"
    else:
        reason = f"{end.reason}; and {problem}" if end.reason else problem
    log.info("recording_failed", reason=problem)  # the outcome says it (the CLI: once)
    return replace(end, status="failed", reason=reason, ended_by="", request="")


async def _let_others_run() -> None:
    for _ in range(TURNS):
        await asyncio.sleep(0)


def _within(member: str, call: str, outputs: Values, maxima: Mapping[str, int]) -> None:
    """ParticipantError naming the output, its size and its maximum when a value is over the
    maximum its channel declares."""
    for name, maximum in maxima.items():
        value = outputs[name]
        size = len(value.encode()) if isinstance(value, str) else len(value)
        if size > maximum:
            exc = ValueTooLarge(channel=name, kind="output", size=size, maximum=maximum)
            raise ParticipantError(
                exc.naming(member), participant=member, call=call, status="RESOURCE_EXHAUSTED"
            )


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
        self._output_names = {m.name: frozenset(c.name for c in m.outputs) for m in plan.order}
        """What every answer of each member must hold, no more, no less."""
        self._maxima = {
            m.name: {c.name: c.max_bytes for c in m.outputs if c.sized and c.max_bytes > 0}
            for m in plan.order
        }
        """The outputs of each member that declare their largest value, and that value."""
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
        keys = [(m.name, c.name) for m in plan.members for c in m.outputs]
        self._row: Callable[[Mapping[Key, Value]], Sequence[Value]] = (
            itemgetter(*keys) if len(keys) > 1 else lambda store: [store[k] for k in keys]
        )
        """The row of results from ``store``, in column order (a tuple: one call in C)."""
        self._store_keys = {
            m.name: {c.name: (m.name, c.name) for c in m.outputs} for m in plan.order
        }
        """Each member's outputs' keys in ``store``, made once."""
        self._period = math.lcm(*(m.multiple for m in plan.order)) if plan.order else 1
        self._due: dict[int, tuple[list[Due], list[Due]]] = {}
        """Jacobi's members due at step k (by k modulo the multiples' period): those whose
        steps finish on this thread, and the awaited ones."""
        self._slot = {m.name: i for i, m in enumerate(plan.members)}
        self._timing: list[float | None] = [None] * len(plan.members)
        """Each member's step latency at this communication point (None: not due)."""
        self._costs: list[float | None] = [None] * len(plan.members)
        self._waits: list[float | None] = [None] * len(plan.members)
        """What each member's step cost it, and how much of that it waited (None: not said)."""
        self.store: dict[Key, Value] = {}
        """Every member's latest outputs (the native FMU step keeps its own, in C arrays)."""
        self.completed_steps = 0
        self._ended: str | None = None
        """Why a participant asked to end the run, once one did."""
        self._request = ("", "")
        """Who asked to end the run, and the reason given."""
        self._steppers: list[Due] = []
        """Each member and how it steps, in plan order (after Initialize, ``steppers``)."""
        self.steppers: dict[str, Stepper] = {}
        """How each member steps, by name (after Initialize; none under the native FMU
        batch)."""
        self._kernel: native_fmu_step.Kernel | None = None
        """Steps every member in C, when the plan allows it (after Initialize)."""
        self._paths: dict[str, StepPath] = {}
        """How each member steps, and why (after Initialize; summary.json tells it)."""
        self._watchdog: Watchdog | None = None
        self._pending: dict[int, list[tuple[Member, Values]]] = defaultdict(list)
        """Jacobi: outputs by the base step at whose end they are stored."""
        self._held: dict[str, Values] = {}
        """Gauss-Seidel: outputs of members with multiples, until the step they reach."""
        self._wall_start = 0.0
        self._abandoned = False
        """The watchdog ended the run from its thread: nothing more is told to observers."""
        self._stepped: list[Callable[[float, Sequence[Value]], None]] = []
        self._timed: list[Callable[[Sequence[float | None]], None]] = []
        self._costed: list[Callable[[Sequence[float | None], Sequence[float | None]], None]] = []
        """The observers' ``stepped`` and the ``timed`` and ``costed`` of those that take them
        (made when the run starts): what each communication point calls."""
        self._batched: list[Callable[[Steps], None]] = []
        """The observers' ``stepped_batch``: what the points of several steps call."""
        self._telling = threading.Lock()
        """Held while observers are told of several steps, or told the run's end by the
        watchdog: either, never both at once."""

    async def run(self) -> RunEnd:
        """Initialize, step to the end, terminate; never raises for a participant's failure
        (the run ends ``failed``); re-raises an interruption after ending the run ``aborted``."""
        plan, grid = self.plan, self.plan.grid
        wall_start = self._wall_start = wallclock.perf_counter()
        status, reason = "completed", ""
        initialized: list[Member] = []  # every member Initialize was sent to
        log.info(
            "run_started",
            run_id=plan.run_id,
            members=len(plan.members),
            steps=grid.steps,
            algorithm=str(plan.algorithm),
        )
        self._stepped = [o.stepped for o in self.observers]
        self._batched = [o.stepped_batch for o in self.observers]
        self._timed = [o.timed for o in self.observers if type(o).timed is not Observer.timed]
        self._costed = [o.costed for o in self.observers if type(o).costed is not Observer.costed]
        try:
            for observer in self.observers:
                observer.started(self.info)
            await self.initialize(initialized)
            self._choose_steppers()
            self._record(grid.start)
            yielded = wallclock.perf_counter()
            batches = self._kernel is not None and self._kernel.logs and not plan.realtime_factor
            k = 0
            while k < grid.steps:
                if batches:
                    k = self._native_steps(k, grid.steps - k)
                else:
                    await self.advance(k)
                    k += 1
                    self.completed_steps = k
                    self._record(grid.time(k))
                if self._ended is not None:
                    status, reason = "terminated", self._ended
                    break
                if plan.realtime_factor:
                    await self._pace(wall_start, grid.time(k + 1) - grid.start)
                elif wallclock.perf_counter() - yielded > YIELD_EVERY:
                    await _let_others_run()
                    yielded = wallclock.perf_counter()
            await self.wind_up()
        except CouplerError as exc:
            status, reason = "failed", f"{exc} (the run had reached t={self._time_reached():g} s)"
            # an expected end, said by the outcome (the command line prints it once): info
            log.info("run_failed", run_id=plan.run_id, reason=reason)
        except Exception as exc:  # a bug or a foreign error: still a clean end and a summary
            status, reason = "failed", f"{type(exc).__name__}: {exc}"
            log.exception("run_failed", run_id=plan.run_id, reason=reason)
        except (asyncio.CancelledError, KeyboardInterrupt):
            status, reason = "aborted", "interrupted by the user"
            log.info("run_aborted", run_id=plan.run_id, time=self._time_reached())
            raise
        finally:
            if self._watchdog is not None:
                self._watchdog.stop()
            refused = await self._terminate(
                initialized, reason or "run completed", aborted=status != "completed"
            )
            if refused is not None and status in ("completed", "terminated"):
                status, reason = "failed", f"{refused} (after the run's last step)"
                log.error("run_failed", run_id=plan.run_id, reason=reason)
            end = RunEnd(
                status=status,
                reason=reason,
                steps=self.completed_steps,
                end_time=self._time_reached(),
                wall_time=wallclock.perf_counter() - wall_start,
                step_paths=self._paths,
                **self._requested(status),
            )
            end = self._finish(end)
        return end

    async def advance(self, k: int) -> None:
        """Base step k: from t_k to t_{k+1}, by the plan's algorithm."""
        if self._kernel is not None:
            self._native_step(k)
        elif self.plan.algorithm is Algorithm.JACOBI:
            await self._jacobi_step(k, self._pending)
        else:
            await self._gauss_seidel_step(k, self._held)

    async def wind_up(self) -> None:
        """After the last step, before the members are terminated (a run that ends
        ``completed`` or ``terminated``); nothing to do in Coupler's semantics."""

    def end_run(self, by: str, reason: str) -> None:
        """End the run after this base step, ``terminated``: ``by`` asked, for ``reason``."""
        self._ended = reason
        self._request = (by, reason)

    def took(self, m: Member, stepper: Stepper) -> None:
        """``stepper`` took a step of ``m``: its latency and its cost at this communication
        point noted."""
        slot = self._slot[m.name]
        self._timing[slot] = stepper.took
        self._costs[slot] = stepper.cost
        self._waits[slot] = stepper.waited

    @property
    def abandoned(self) -> bool:
        """The watchdog ended the run from its thread: this thread must not go on."""
        return self._abandoned

    def _requested(self, status: str) -> dict[str, str]:
        if status != "terminated":
            return {}
        return {"ended_by": self._request[0], "request": self._request[1]}

    def _time_reached(self) -> float:
        return self.plan.grid.time(self.completed_steps)

    def _finish(self, end: RunEnd) -> RunEnd:
        """Close, then tell every observer, even if one of them fails: a recorder that cannot
        write what it holds fails the run (never ``completed`` with rows missing); any other
        failure is logged. Returns how the run ended."""
        if self._abandoned:
            return end
        for observer in self.observers:
            try:
                observer.closing(end)
            except CouplerError as exc:
                end = _failed_recording(end, str(exc))
            except Exception as exc:
                log.error("observer_failed", observer=type(observer).__name__, error=str(exc))
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
        return end

    async def initialize(self, initialized: list[Member]) -> None:
        """Initialize every member (each added to ``initialized`` as its call is made), and
        store their first outputs."""
        grid = self.plan.grid

        async def init(m: Member) -> Values:
            setup = RunSetup(
                run_id=self.plan.run_id,
                run_secret=self.plan.run_secret,
                start_time=grid.start,
                step_size=m.step,
                stop_time=grid.stop,
                parameters=m.parameters,
                inputs=m.start_inputs,
                lease=self.plan.lease,
            )
            initialized.append(m)  # Terminated on every path, even if its answer is refused
            try:
                return await asyncio.wait_for(m.participant.initialize(setup), m.deadline)
            except TimeoutError as exc:
                raise ParticipantTimeout(
                    f"no answer within {m.deadline:g} s",
                    participant=m.name,
                    call="Initialize",
                    status="DEADLINE_EXCEEDED",
                ) from exc

        members = self.plan.order
        results = await asyncio.gather(*(init(m) for m in members), return_exceptions=True)
        for m, result in zip(members, results, strict=True):
            if isinstance(result, BaseException):
                raise result
            self.store_outputs(m, result, "Initialize", grid.start)

    def _choose_steppers(self) -> None:
        """How each member steps (``steppers.steppers_of``), chosen once after Initialize; the
        watchdog watches the steps taken on this thread (and the native FMU batch's calls)."""
        watchdog = Watchdog(self._abandon)
        self.steppers, self._kernel, self._paths = steppers_of(self.plan, watchdog)
        self._steppers = [(m, self.steppers[m.name]) for m in self.plan.order if self.steppers]
        if self._kernel is not None or any(s.here for _, s in self._steppers):
            self._watchdog = watchdog
            watchdog.start()
        if self._kernel is not None:
            watchdog.follow(self._kernel.under_way)
            for m, keys in self._store_keys.items():  # the Initialize answers
                self._kernel.place(m, {c: self.store[key] for c, key in keys.items()})

    def _abandon(self, status: str, reason: str) -> None:
        """End the run from the watchdog's thread: this thread is stuck in a participant
        (the steps the native FMU step took whole before, in the same call, are told first)."""
        grid = self.plan.grid
        with self._telling:
            steps = self._kernel.claim() if self._kernel is not None else None
            if steps is not None:
                self.completed_steps += len(steps.times)
                for observer in self.observers:
                    try:
                        observer.stepped_batch(steps)
                    except Exception as exc:
                        log.error(
                            "observer_failed", observer=type(observer).__name__, error=str(exc)
                        )
            end = RunEnd(
                status=status,
                reason=reason,
                steps=self.completed_steps,
                end_time=self._time_reached(),
                wall_time=wallclock.perf_counter() - self._wall_start,
                step_paths=self._paths,
            )
            end = self._finish(end)
            self._abandoned = True
        told = self.plan.on_abandoned is not None  # the caller says it (the CLI: once)
        (log.info if told else log.error)(
            "run_abandoned",
            run_id=self.plan.run_id,
            reason=reason,
            time=grid.time(self.completed_steps),
        )
        if self.plan.on_abandoned is not None:
            self.plan.on_abandoned(end)

    def _inputs(self, m: Member) -> Values:
        feed = self.feeds.get(m.name)
        return feed.gather(self.store) if feed is not None else {}

    def _ask_to_end(self, m: Member, k: int, end: EndRun) -> Values:
        if self._ended is None:
            reached = self.plan.grid.time(k + m.multiple)
            self._ended = f"{m.name} asked to end the run at t={reached:g} s: {end.reason}"
            self._request = (m.name, end.reason)
        return end.outputs

    def _finished(self, m: Member, stepper: Stepper, k: int) -> Values:
        """The outputs of the step of ``m`` begun at step k (its latency noted)."""
        try:
            outputs = stepper.finish()
        except EndRun as end:
            outputs = self._ask_to_end(m, k, end)
        self.took(m, stepper)
        if self._abandoned:  # it came back after the watchdog had ended the run
            raise asyncio.CancelledError
        return outputs

    async def _whole(self, m: Member, stepper: Stepper, k: int) -> Values:
        """A whole step of ``m`` from t_k (begun and finished at once)."""
        try:
            outputs = await stepper.whole(self.plan.grid.time(k), m.step, self._inputs(m))
        except EndRun as end:
            outputs = self._ask_to_end(m, k, end)
        self.took(m, stepper)
        if self._abandoned:
            raise asyncio.CancelledError
        return outputs

    def _native_steps(self, k: int, left: int) -> int:
        """Base steps from k in one call into C (``Kernel.steps``: at most ``left``, and as many
        as YIELD_EVERY allows), the observers told of them together; a step a member stopped
        is finished as ``_native_step`` finishes it, and told alone. Returns the next step."""
        native = self._kernel
        assert native is not None
        done, stopped = native.steps(k, left, YIELD_EVERY)
        with self._telling:  # not while the watchdog ends the run (``_abandon``)
            if self._abandoned:  # it came back after the watchdog had ended the run
                raise asyncio.CancelledError
            if done:
                k += done
                self.completed_steps = k
                steps = native.logged()
                for tell in self._batched:
                    tell(steps)
        if stopped is not None:
            self._native_step(k, stopped)
            k += 1
            self.completed_steps = k
            self._record(self.plan.grid.time(k))
        return k

    def _native_step(self, k: int, stopped: tuple[int, Exception] | None = None) -> None:
        """Every member stepped in C (``native_fmu_step``); a member that stops its step is told
        about as it is in Python: its error ends the run, its request to end it is kept and
        the members after it step on (from ``stopped``, when the step has begun so)."""
        native = self._kernel
        assert native is not None
        time = self.plan.grid.time(k)
        if stopped is None:
            stopped = native.step(time)
        while stopped is not None:
            index, meaning = stopped
            if not isinstance(meaning, EndRun):
                raise meaning
            m = self.plan.order[index]
            native.place(m.name, self._ask_to_end(m, k, meaning))
            stopped = native.step(time, index + 1)
        if self._abandoned:  # it came back after the watchdog had ended the run
            raise asyncio.CancelledError
        self._timing = native.timing[:]
        if self._costed:  # computed here: each step's cost is its latency
            self._costs = self._timing[:]

    async def _jacobi_step(self, k: int, pending: dict[int, list[tuple[Member, Values]]]) -> None:
        """Every due member on the outputs of t_k: the awaited ones in flight while the others
        compute or wait here; everyone's outputs stored for the time they reach."""
        here, awaited = self._due_at(k)
        if len(awaited) == 1 and not here:  # one awaited member alone: awaited at once
            m, stepper = awaited[0]
            pending[k + m.multiple].append((m, await self._whole(m, stepper, k)))
        else:
            time = self.plan.grid.time(k)
            for m, stepper in (*here, *awaited):
                stepper.begin(time, m.step, self._inputs(m))
            flying = [s.landing for _, s in awaited if s.landing is not None]
            if flying:
                await asyncio.sleep(0)  # let the requests leave before computing here
            try:
                for m, stepper in here:
                    pending[k + m.multiple].append((m, self._finished(m, stepper, k)))
            finally:
                if flying:
                    await _landed(flying)
            for m, stepper in awaited:
                pending[k + m.multiple].append((m, self._finished(m, stepper, k)))
        for m, outputs in pending.pop(k + 1, []):
            self.store_outputs(m, outputs, "DoStep", self.plan.grid.time(k + 1))

    def _due_at(self, k: int) -> tuple[list[Due], list[Due]]:
        """The members due at step ``k`` and their steppers (in plan order): those whose steps
        finish on this thread, and the awaited ones."""
        phase = k % self._period
        due = self._due.get(phase)
        if due is None:
            here = [(m, s) for m, s in self._steppers if k % m.multiple == 0 and s.here]
            awaited = [(m, s) for m, s in self._steppers if k % m.multiple == 0 and not s.here]
            due = (here, awaited)
            if len(self._due) < DUE_PATTERNS:
                self._due[phase] = due
        return due

    async def _gauss_seidel_step(self, k: int, held: dict[str, Values]) -> None:
        """Members in order; outputs of t_{k+m} are stored in the slot of the base step that
        ends at t_{k+m}, so successors see them then and no row shows a value from later."""
        for m, stepper in self._steppers:
            if k % m.multiple == 0 and stepper.here:
                stepper.begin(self.plan.grid.time(k), m.step, self._inputs(m))
                held[m.name] = self._finished(m, stepper, k)
            elif k % m.multiple == 0:
                held[m.name] = await self._whole(m, stepper, k)
            if (k + 1) % m.multiple == 0 and m.name in held:
                self.store_outputs(m, held.pop(m.name), "DoStep", self.plan.grid.time(k + 1))

    def store_outputs(self, m: Member, outputs: Values, call: str, time: float) -> None:
        """Keep a member's outputs; every output it describes must be there, and no other."""
        self.check_answer(m, outputs, call, time)
        maxima = self._maxima[m.name]
        if maxima:  # a remote member's were checked as they arrived; an in-process one's here
            _within(m.name, call, outputs, maxima)
        store, keys = self.store, self._store_keys[m.name]
        for channel, value in outputs.items():
            store[keys[channel]] = value

    def check_answer(self, m: Member, outputs: Values, call: str, time: float) -> None:
        """ParticipantError unless ``outputs`` are every output ``m`` describes, and no other."""
        if outputs.keys() != self._output_names[m.name]:
            raise self._refused(m, outputs, call, time)

    def _refused(self, m: Member, outputs: Values, call: str, time: float) -> ParticipantError:
        """Why ``outputs`` are not the outputs ``m`` describes."""
        missing = [c.name for c in m.outputs if c.name not in outputs]
        extra = sorted(set(outputs) - {c.name for c in m.outputs})
        what = []
        if missing:
            what.append(f"without its described outputs {', '.join(missing)}")
        if extra:
            what.append(f"with outputs it does not describe: {', '.join(extra)}")
        return ParticipantError(
            f"answered {call} for t={time:g} s {' and '.join(what)}; a participant returns "
            "every output it describes at every step",
            participant=m.name,
            call=call,
        )

    def _record(self, time: float) -> None:
        row = self._kernel.row() if self._kernel is not None else self._row(self.store)
        for stepped in self._stepped:
            stepped(time, row)
        timing = self._timing
        for timed in self._timed:
            timed(timing)
        self._timing = [None] * len(timing)
        if self._costed:
            costs, waits = self._costs, self._waits
            for costed in self._costed:
                costed(costs, waits)
            self._costs, self._waits = [None] * len(costs), [None] * len(waits)

    async def _pace(self, wall_start: float, simulated: float) -> None:
        assert self.plan.realtime_factor
        ahead = simulated / self.plan.realtime_factor - (wallclock.perf_counter() - wall_start)
        if ahead > 0:
            await asyncio.sleep(ahead)

    async def _terminate(
        self, members: Sequence[Member], reason: str, *, aborted: bool = False
    ) -> ParticipantError | None:
        """Terminate every member; after a failure or an interrupt each gets a short deadline,
        so that ending never takes longer than a few seconds. Returns the first member's
        refusal of the run (ABORTED: a stranger called it without the run's secret), which
        fails a run that had seemed to end well."""
        deadline = 3.0 if aborted else None

        async def terminate(m: Member) -> None:
            await asyncio.wait_for(m.participant.terminate(reason), deadline or m.deadline)

        results = await asyncio.gather(*(terminate(m) for m in members), return_exceptions=True)
        refused = None
        for m, result in zip(members, results, strict=True):
            if isinstance(result, Exception):
                log.warning(
                    "terminate_failed",
                    participant=m.name,
                    error=str(result) or type(result).__name__,
                )
                if isinstance(result, ParticipantError) and result.status == "ABORTED":
                    refused = refused or result
        return refused
