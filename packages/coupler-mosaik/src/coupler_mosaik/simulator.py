"""A Coupler participant as a mosaik API v3 simulator: ``CouplerSimulator``.

In a mosaik scenario::

    SIM_CONFIG = {
        "Gain": {"python": "coupler_mosaik:CouplerSimulator"},            # in mosaik's process
        # "Gain": {"cmd": "coupler-mosaik simulator %(addr)s"},           # a process of its own
    }
    world = mosaik.World(SIM_CONFIG, time_resolution=0.1)   # seconds per mosaik tick
    gain = world.start("Gain", address="grpc://127.0.0.1:50051", step_size=1)
    entity = gain.Gain(gain=4.0)          # the participant's parameters are the model's params
    world.connect(source, entity, ("value", "u"))

What maps to what (docs/frameworks.md):

- Describe -> META: one public model named after the participant (or ``model=``), its parameters
  as ``params``, its inputs and outputs as ``attrs``; type ``time-based``. ``channels()`` (an
  extra method) lists every channel with causality, type and unit: mosaik's META has no units.
- ``create(1, model, **params)`` -> one entity (a participant serves one run at a time).
- Time: mosaik tick ``k`` is Coupler's ``start_time + k * time_resolution`` (exact decimals).
  The step at tick ``k0`` (the first) is Initialize, with the inputs mosaik gives at ``k0`` as
  start values; the step at tick ``k`` is DoStep from the previous step's tick to ``k`` with the
  inputs given at ``k``, held over the step; ``get_data`` answers the outputs at ``k``. That is
  Coupler's Gauss-Seidel (a successor sees its predecessor's output at the step's end): a mosaik
  chain source -> participant -> sink records what ``coupler run --algorithm gauss-seidel``
  records. The simulator steps every ``step_size`` ticks.
- Values: one source per input attribute (several are refused, naming them); Binary as base64.
- Errors: the participant's errors end the mosaik run with the participant's message; a
  participant that asks to end the run (``EndRun``) ends it too (mosaik cannot end early).
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from typing import Any

import mosaik_api_v3
from mosaik_api_v3.types import CreateResult, Meta

from coupler.channels import Causality, Description, RunSetup, Value
from coupler.client import RemoteParticipant
from coupler.errors import CouplerError
from coupler.participant import EndRun, Values
from coupler_mosaik.background import BackgroundLoop
from coupler_mosaik.ticks import Ticks
from coupler_mosaik.values import from_mosaik, to_mosaik

META: Meta = {
    "api_version": "3.0",
    "type": "time-based",
    "models": {},
    "extra_methods": ["channels"],
}


class CouplerSimulator(mosaik_api_v3.Simulator):
    """One Coupler participant (its address given to ``init``) as one mosaik entity."""

    def __init__(self) -> None:
        super().__init__({**META, "models": {}})
        self._loop: BackgroundLoop | None = None
        self._remote: RemoteParticipant | None = None
        self._description: Description | None = None
        self._ticks = Ticks(0.0, 1.0)
        self._step_ticks = 1
        self._sid = ""
        self._eid = ""
        self._parameters: dict[str, Value] = {}
        self._outputs: Values | None = None
        self._last_tick = 0
        self._run_id = ""

    # -- mosaik's calls -------------------------------------------------------------------

    def init(
        self,
        sid: str,
        time_resolution: float = 1.0,
        *,
        address: str = "",
        step_size: int = 1,
        start_time: float = 0.0,
        model: str = "",
        connect_timeout: float = 10.0,
        call_timeout: float = 30.0,
        **unknown: Any,
    ) -> Meta:
        """Connect to the participant at ``address`` and describe it as META.

        ``time_resolution``: seconds per mosaik tick (the World's); ``step_size``: ticks per
        step; ``start_time``: Coupler's time at tick 0 [s]; ``model``: the model's name
        (default: the participant's)."""
        if unknown:
            raise ValueError(
                f"unknown simulator parameters {sorted(unknown)} for {sid}; CouplerSimulator "
                "takes address, step_size, start_time, model, connect_timeout, call_timeout"
            )
        if not address:
            raise ValueError(f"{sid}: give address= (the Coupler participant's HOST:PORT)")
        if not isinstance(step_size, int) or isinstance(step_size, bool) or step_size < 1:
            raise ValueError(f"step_size of {sid} must be a whole number of ticks >= 1")
        self._sid = sid
        self._ticks = Ticks(start_time, time_resolution)
        self._step_ticks = step_size
        self._loop = BackgroundLoop(f"coupler-mosaik-{sid}")
        self._remote = RemoteParticipant(
            address, name=sid, connect_timeout=connect_timeout, call_timeout=call_timeout
        )
        self._description = self._call(self._remote.describe())
        d = self._description
        name = model or d.name
        self.meta["models"] = {
            name: {
                "public": True,
                "params": [c.name for c in d.of(Causality.PARAMETER)],
                "attrs": [c.name for c in (*d.of(Causality.INPUT), *d.of(Causality.OUTPUT))],
            }
        }
        return self.meta

    def create(self, num: int, model: str, **params: Any) -> list[CreateResult]:
        """The participant as one entity; ``params``: its parameter values."""
        d = self._described()
        if num != 1 or self._eid:
            raise ValueError(
                f"{self._sid}: a Coupler participant is one entity (it serves one run at a time): "
                f"create one (num=1) and start one simulator per participant address"
            )
        if model not in self.meta["models"]:
            raise ValueError(
                f"{self._sid}: no model {model!r}; it offers {list(self.meta['models'])}"
            )
        for name, raw in params.items():
            channel = d.channel(name)
            if channel is None or channel.causality is not Causality.PARAMETER:
                raise ValueError(
                    f"{self._sid}: {d.name} has no parameter {name!r}; its parameters are "
                    f"{[c.name for c in d.of(Causality.PARAMETER)]}"
                )
            self._parameters[name] = from_mosaik(channel, raw)
        self._eid = d.name
        return [{"eid": self._eid, "type": model}]

    def step(self, time: int, inputs: dict[str, Any], max_advance: int) -> int:
        """Initialize at the first tick, else DoStep from the last step's tick to ``time``."""
        remote = self._connected()
        given = self._inputs(inputs.get(self._eid, {}))
        try:
            if self._outputs is None:
                self._run_id = f"mosaik-{self._sid}-{uuid.uuid4().hex[:8]}"
                setup = RunSetup(
                    run_id=self._run_id,
                    start_time=self._ticks.time(time),
                    step_size=self._ticks.span(self._step_ticks),
                    parameters=self._parameters,
                    inputs=given,
                )
                self._outputs = self._call(remote.initialize(setup))
            else:
                start = self._ticks.time(self._last_tick)
                step = self._ticks.span(time - self._last_tick)
                self._outputs = self._call(remote.do_step(start, step, given))
        except EndRun as end:
            self._outputs = end.outputs
            raise RuntimeError(
                f"{self._sid}: participant {self._eid} ended the run at t = "
                f"{self._ticks.time(time)!r} s ({end.reason}); mosaik cannot end a run early"
            ) from None
        self._last_tick = time
        return time + self._step_ticks

    def get_data(self, outputs: Mapping[str, list[str]]) -> dict[str, dict[str, Any]]:
        """The outputs at the last step's tick."""
        d = self._described()
        if self._outputs is None:
            raise RuntimeError(f"{self._sid}: get_data before the first step")
        data: dict[str, dict[str, Any]] = {}
        for eid, attrs in outputs.items():
            if eid != self._eid:
                raise ValueError(f"{self._sid}: no entity {eid!r}; its entity is {self._eid!r}")
            values = data.setdefault(eid, {})
            for attr in attrs:
                channel = d.channel(attr)
                if channel is None or channel.causality is not Causality.OUTPUT:
                    raise ValueError(
                        f"{self._sid}: {attr!r} is not an output of {d.name}; its outputs are "
                        f"{[c.name for c in d.of(Causality.OUTPUT)]}"
                    )
                values[attr] = to_mosaik(channel, self._outputs[attr])
        return data

    def channels(self) -> list[dict[str, str]]:
        """Every channel of the participant: name, causality, type, unit, description."""
        return [
            {
                "name": c.name,
                "causality": str(c.causality),
                "type": str(c.type),
                "unit": c.unit,
                "description": c.description,
            }
            for c in self._described().channels
        ]

    def finalize(self) -> None:
        """Terminate the participant's run and close the connection."""
        if self._loop is None:
            return
        remote, self._remote = self._remote, None
        try:
            if remote is not None:
                self._loop.run(_finish(remote, started=self._outputs is not None))
        finally:
            self._loop.close()
            self._loop = None

    # -- helpers ----------------------------------------------------------------------------

    def _inputs(self, given: Mapping[str, Mapping[str, Any]]) -> Values:
        d = self._described()
        values: Values = {}
        for attr, sources in given.items():
            channel = d.channel(attr)
            if channel is None or channel.causality is not Causality.INPUT:
                raise ValueError(
                    f"{self._sid}: {attr!r} is not an input of {d.name}; its inputs are "
                    f"{[c.name for c in d.of(Causality.INPUT)]}"
                )
            if len(sources) != 1:
                raise ValueError(
                    f"{self._sid}: input {attr!r} of {d.name} is connected to "
                    f"{sorted(sources)}: a Coupler input takes one source; connect one"
                )
            [raw] = sources.values()
            values[attr] = from_mosaik(channel, raw)
        return values

    def _call(self, coroutine: Any) -> Any:
        assert self._loop is not None
        try:
            return self._loop.run(coroutine)
        except CouplerError as exc:  # mosaik shows the message, not where it came from
            raise RuntimeError(f"{self._sid}: {exc}") from exc

    def _described(self) -> Description:
        if self._description is None:
            raise RuntimeError("init() first: the simulator has no participant yet")
        return self._description

    def _connected(self) -> RemoteParticipant:
        if self._remote is None:
            raise RuntimeError(f"{self._sid}: not connected (finalized, or init() not called)")
        return self._remote


async def _finish(remote: RemoteParticipant, *, started: bool) -> None:
    try:
        if started:
            await remote.terminate("mosaik finalized the simulation")
    finally:
        await remote.close()
