"""A mosaik API v3 simulator as a Coupler participant: ``MosaikParticipant``.

Made from a ``MosaikConfig`` (a small TOML file, ``coupler_mosaik.config``)::

    coupler-mosaik participant csv.toml --port 50061     # serves it over gRPC

What maps to what (docs/frameworks.md):

- Describe: the configured channels (mosaik's META says neither direction, type nor unit);
  ``fixed_step_size`` = ``time_resolution``: every Coupler step is whole ticks.
- Initialize: a fresh simulator (mosaik's simulators are made for one run: the process is
  started, or the class instantiated, per run), ``init(sid, time_resolution, **params)``,
  ``create(1, model, **model params)`` (parameter channels override them), ``setup_done()``,
  then the step at tick 0 with the inputs' start values; its ``get_data`` is the outputs at
  ``start_time``. Each configured attribute must be in the model's META (checked here).
- DoStep from t to t + h: the simulator is stepped at the tick of t + h with the inputs given
  (held: the latest value of each), and ``get_data`` gives the outputs at t + h. Coupler's
  Gauss-Seidel is mosaik's data flow: a chain of them under ``coupler run --algorithm
  gauss-seidel`` records what a pure mosaik World records (Jacobi: what mosaik records with
  ``time_shifted`` connections).
- The simulator's own next-step answers are followed where they fit Coupler's grid: a next
  step beyond t + h leaves the simulator alone until Coupler's time reaches it (outputs held,
  as mosaik holds them); one at t + h steps it there; one between two communication points,
  or not later than the current tick, is refused naming the tick and the fix.
  Event-based and hybrid simulators are also stepped at t + h when an input changed (mosaik
  steps them when new data arrive).
- Terminate: mosaik's ``stop`` (``finalize`` in process); the process is waited for.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from coupler.channels import (
    Capabilities,
    Causality,
    Channel,
    Description,
    RunSetup,
    Value,
)
from coupler.errors import ChannelValueError, ParticipantError, ScenarioError
from coupler.participant import Participant, Values
from coupler.values import coerce
from coupler_mosaik.config import ChannelConfig, MosaikConfig
from coupler_mosaik.links import SimulatorLink, start
from coupler_mosaik.ticks import Ticks
from coupler_mosaik.values import from_mosaik, to_mosaik

FAR = 2**53
"""max_advance when the run has no stop time (mosaik's ``until`` stands for it)."""


class MosaikParticipant(Participant):
    """One entity of a mosaik simulator, its attributes as channels."""

    def __init__(self, config: MosaikConfig, *, source: str | Path = "") -> None:
        self.config = config
        self.source = str(source) or config.name
        """Where the configuration came from, for messages."""
        self._channels = {c.name: c for c in config.channel}
        self._described = tuple(_channel(c) for c in config.channel)
        self._by_name = {c.name: c for c in self._described}
        self._link: SimulatorLink | None = None
        self._eid = ""
        self._type = "time-based"
        self._ticks = Ticks(0.0, config.time_resolution)
        self._step_ticks = 1
        self._stop_tick: int | None = None
        self._tick = 0
        """The tick Coupler's time has reached."""
        self._next: int | None = None
        """The simulator's own next step (its last answer), None: none asked for."""
        self._held: dict[str, Any] = {}
        """The inputs as mosaik takes them, the latest of each."""
        self._changed = False
        self._outputs: Values = {}

    @classmethod
    def from_file(cls, path: str | Path) -> MosaikParticipant:
        return cls(MosaikConfig.load(path), source=path)

    async def describe(self) -> Description:
        return Description(
            name=self.config.name,
            channels=self._described,
            capabilities=Capabilities(
                variable_step_size=False, fixed_step_size=self.config.time_resolution
            ),
            implementation=f"coupler-mosaik ({self._starter()})",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        await self._end("a new run")
        self._ticks = Ticks(setup.start_time, self.config.time_resolution)
        try:
            self._step_ticks = self._ticks.ticks(setup.step_size, "the step size")
            self._stop_tick = (
                None
                if setup.stop_time is None
                else self._ticks.tick(setup.stop_time, "the stop time")
            )
        except ValueError as exc:
            raise ScenarioError(f"{self.config.name}: {exc}") from None
        self._link = await start(self.config.name, self.config.simulator, self._progress)
        meta = await self._link.call(
            "init",
            self.config.name,
            time_resolution=self.config.time_resolution,
            **self.config.simulator.params,
        )
        self._check_meta(meta)
        self._type = str(meta.get("type", "time-based"))
        created = await self._link.call(
            "create", 1, self.config.model.name, **self._model_params(setup.parameters)
        )
        self._eid = _entity(created, self.config.name)
        await self._link.call("setup_done")
        self._held = {}
        for c in self._of(Causality.INPUT):
            value = setup.inputs.get(c.name, c.start)
            if value is not None:
                self._held[c.name] = value
        self._tick, self._next, self._outputs = 0, None, {}
        await self._step_at(0)
        return dict(self._outputs)

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self._running("DoStep")
        target = self._target(time, step)
        for name, value in inputs.items():
            if self._held.get(name) != value:
                self._held[name] = value
                self._changed = True
        due = self._next == target or (self._type != "time-based" and self._changed)
        if self._next is not None and self._next < target:
            raise ParticipantError(
                f"the mosaik simulator asked for its next step at tick {self._next} "
                f"(t = {self._ticks.time(self._next)!r} s), between Coupler's communication "
                f"points {time!r} s and {time + step!r} s: Coupler cannot give it inputs there; "
                f"make the step size a divisor of its steps ({self.config.time_resolution!r} s "
                f"per tick)",
                participant=self.config.name,
                call="DoStep",
            )
        self._tick = target
        if due:
            await self._step_at(target)
        return dict(self._outputs)

    async def terminate(self, reason: str = "") -> None:
        await self._end(reason)

    async def close(self) -> None:
        await self._end("participant closed")

    # -- the simulator ------------------------------------------------------------------------

    async def _step_at(self, tick: int) -> None:
        link = self._running("DoStep")
        inputs = {
            self._eid: {
                self._channels[n].attribute: {f"Coupler.{n}": to_mosaik(self._by_name[n], v)}
                for n, v in self._held.items()
            }
        }
        answer = await link.call("step", tick, inputs, self._max_advance(tick))
        self._changed = False
        if answer is not None and (
            isinstance(answer, bool) or not isinstance(answer, int) or answer <= tick
        ):
            raise ParticipantError(
                f"the mosaik simulator answered step({tick}) with next step {answer!r}: a next "
                f"step must be a whole tick after {tick} (or None)",
                participant=self.config.name,
                call="step",
            )
        if answer is None and self._type == "time-based":
            raise ParticipantError(
                f"the time-based mosaik simulator answered step({tick}) with no next step",
                participant=self.config.name,
                call="step",
            )
        self._next = answer
        outputs = self._of(Causality.OUTPUT)
        if not outputs:
            return
        request = {self._eid: [self._channels[c.name].attribute for c in outputs]}
        data = await link.call("get_data", request)
        self._read(data, tick)

    def _read(self, data: Mapping[str, Any], tick: int) -> None:
        if not isinstance(data, Mapping):
            raise ParticipantError(
                f"get_data answered {type(data).__name__}, not a mapping",
                participant=self.config.name,
                call="get_data",
            )
        at = data.get("time", tick)
        if at != tick:
            raise ParticipantError(
                f"get_data gave outputs for tick {at!r} after a step at tick {tick}: Coupler "
                "has no delayed outputs; give them at the step's tick",
                participant=self.config.name,
                call="get_data",
            )
        values = data.get(self._eid, {})
        for c in self._of(Causality.OUTPUT):
            raw = (
                values.get(self._channels[c.name].attribute)
                if isinstance(values, Mapping)
                else None
            )
            if raw is None:
                if c.name in self._outputs:  # mosaik keeps the last value (persistent)
                    continue
                if c.start is None:
                    raise ParticipantError(
                        f"the mosaik simulator gave no value for output '{c.name}' (attribute "
                        f"'{self._channels[c.name].attribute}') at tick {tick} and it has no start "
                        f"value: give it start = ... in {self.source}",
                        participant=self.config.name,
                        call="get_data",
                    )
                self._outputs[c.name] = c.start
                continue
            try:
                self._outputs[c.name] = from_mosaik(c, raw)
            except ChannelValueError as exc:
                raise ParticipantError(
                    f"{exc} (attribute '{self._channels[c.name].attribute}' at tick {tick})",
                    participant=self.config.name,
                    call="get_data",
                ) from exc

    def _target(self, time: float, step: float) -> int:
        try:
            here = self._ticks.tick(time)
            target = here + self._ticks.ticks(step)
        except ValueError as exc:
            raise ParticipantError(
                str(exc), participant=self.config.name, call="DoStep", status="INVALID_ARGUMENT"
            ) from None
        if here != self._tick:
            raise ParticipantError(
                f"DoStep from t = {time!r} s (tick {here}), but the run is at tick {self._tick}",
                participant=self.config.name,
                call="DoStep",
                status="INVALID_ARGUMENT",
            )
        return target

    def _max_advance(self, tick: int) -> int:
        """mosaik's promise: no new inputs before ``max_advance + 1``."""
        if self._of(Causality.INPUT):
            return tick + self._step_ticks - 1
        return self._stop_tick + 1 if self._stop_tick is not None else FAR

    def _progress(self) -> float:
        if not self._stop_tick:
            return 0.0
        return 100.0 * self._tick / self._stop_tick

    def _check_meta(self, meta: Any) -> None:
        models = meta.get("models", {}) if isinstance(meta, Mapping) else {}
        model = models.get(self.config.model.name)
        where = f"{self.source}"
        if not isinstance(model, Mapping) or not model.get("public", False):
            public = [n for n, m in models.items() if isinstance(m, Mapping) and m.get("public")]
            raise ScenarioError(
                f"{where}: the mosaik simulator has no public model "
                f"'{self.config.model.name}'; its public models: {', '.join(public) or 'none'}"
            )
        attrs = set(model.get("attrs", []))
        params = set(model.get("params", []))
        problems = []
        for c in self.config.channel:
            if c.causality is Causality.PARAMETER:
                if c.attribute not in params:
                    problems.append(
                        f"channel '{c.name}': model '{self.config.model.name}' has no parameter "
                        f"'{c.attribute}' (its params: {', '.join(sorted(params)) or 'none'})"
                    )
            elif c.attribute not in attrs and not (
                c.causality is Causality.INPUT and model.get("any_inputs")
            ):
                problems.append(
                    f"channel '{c.name}': model '{self.config.model.name}' has no attribute "
                    f"'{c.attribute}' (its attrs: {', '.join(sorted(attrs)) or 'none'})"
                )
        if problems:
            raise ScenarioError(f"{where}: " + "; ".join(problems))

    def _model_params(self, given: Mapping[str, Value]) -> dict[str, Any]:
        params = dict(self.config.model.params)
        for c in self._of(Causality.PARAMETER):
            value = given.get(c.name, c.start)
            if value is not None:
                params[self._channels[c.name].attribute] = to_mosaik(c, value)
        return params

    def _of(self, causality: Causality) -> tuple[Channel, ...]:
        return tuple(c for c in self._described if c.causality is causality)

    def _running(self, call: str) -> SimulatorLink:
        if self._link is None:
            raise ParticipantError(
                "no run: Initialize first", participant=self.config.name, call=call,
                status="FAILED_PRECONDITION",
            )  # fmt: skip
        return self._link

    def _starter(self) -> str:
        s = self.config.simulator
        return (
            f"python {s.python}"
            if s.python
            else f"cmd {s.cmd}"
            if s.cmd
            else f"connect {s.connect}"
        )

    async def _end(self, reason: str) -> None:
        """Stop the simulator of the run, if one runs (``reason``: for the log)."""
        link, self._link = self._link, None
        if link is not None:
            await link.close()


def _channel(c: ChannelConfig) -> Channel:
    return Channel(
        name=c.name,
        causality=c.causality,
        type=c.type,
        unit=c.unit,
        start=coerce(c.type, c.start) if c.start is not None else None,
        description=c.description or f"mosaik attribute {c.attribute}",
    )


def _entity(created: Any, name: str) -> str:
    try:
        return str(created[0]["eid"])
    except (TypeError, KeyError, IndexError) as exc:
        raise ParticipantError(
            f"create() answered {created!r:.80}, not a list of entities with an 'eid'",
            participant=name,
            call="create",
        ) from exc
