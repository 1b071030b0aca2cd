"""OpenMCx's built-in components as participants in the orchestrator's process: Constant,
Integrator and VectorIntegrator (``application/avl-mcx-*``), with OpenMCx's meaning.

- Constant: every output holds its value from the start on (the SSD's ``SpecificData`` values,
  bound to the output connectors by position).
- Integrator: one input u, at most one output y; y = initialState at the start, and each step
  of size s adds ``gain * u * s`` (explicit Euler). OpenMCx's ``numSubSteps`` splits a step into
  sub-steps whose inputs are read again through the connection: the OpenMCx master steps it in
  those sub-steps (``Member.sub_steps``).
- VectorIntegrator: input element i (every input connector's elements, in connector order)
  integrates into output element i: ``y_i += u_i * s``, y_i = initialState at the start.

Channels are the SSD's connectors (their ``nameInModel`` if given); an input nothing drives
reads 0, as in OpenMCx.
"""

from __future__ import annotations

from collections.abc import Mapping

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.participant import Participant, Values
from coupler_orchestrator import ssp


def builtin_of(component: ssp.Component) -> Participant | None:
    """The participant of a built-in component; None for any other component."""
    if component.builtin is None:
        return None
    return Builtin(component)


class Builtin(Participant):
    """One OpenMCx built-in component of the scenario."""

    overrun = (
        "the OpenMCx built-in computes longer than the call deadline (the run had reached "
        "t={time:g} s; give it fewer numSubSteps or a longer --call-timeout)"
    )
    """What its step past the call deadline means (the master's watchdog says it)."""

    def __init__(self, component: ssp.Component) -> None:
        assert component.builtin is not None
        self.component = component
        self.data = component.builtin
        self.inputs = [c.channel for c in component.connectors if c.kind == "input"]
        self.outputs = [c.channel for c in component.connectors if c.kind == "output"]
        self._channels = tuple(
            Channel(
                name=c.channel,
                causality=Causality.INPUT if c.kind == "input" else Causality.OUTPUT,
                type=c.type or ValueType.REAL,
                start=0.0 if c.kind == "input" else None,
            )
            for c in component.connectors
        )
        self._state: list[Value] = []
        self._inputs: dict[str, Value] = {}
        """The inputs last set (an input keeps its value until it is set again)."""

    async def describe(self) -> Description:
        kind = self.component.type.removeprefix("application/avl-mcx-")
        return Description(
            name=self.component.name,
            channels=self._channels,
            implementation=f"OpenMCx built-in {kind} (coupler_orchestrator)",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        data = self.data
        self._inputs = {name: 0.0 for name in self.inputs} | dict(setup.inputs)
        if isinstance(data, ssp.Constant):
            self._state = list(data.values)
        elif isinstance(data, ssp.Integrator):
            self._state = [data.initial_state] * len(self.outputs)
        else:
            self._state = [data.initial_state] * len(self.outputs)
        return self._values()

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return self.step_now(time, step, inputs)

    def step_now(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        """One step on the caller's thread (nothing here waits)."""
        data = self.data
        state = self._state
        known = self._inputs
        known.update(inputs)
        if isinstance(data, ssp.Integrator):
            if state:  # OpenMCx: state += gain * deriv * subDeltaTime
                state[0] = float(state[0]) + data.gain * float(known[self.inputs[0]]) * step
        elif isinstance(data, ssp.VectorIntegrator):
            for i, name in enumerate(self.inputs):
                state[i] = float(state[i]) + float(known[name]) * step
        return self._values()

    async def terminate(self, reason: str = "") -> None:
        self._state = []

    def _values(self) -> Values:
        return dict(zip(self.outputs, self._state, strict=True))
