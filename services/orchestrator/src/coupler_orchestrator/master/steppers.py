"""How each member steps, chosen once per member after Initialize (``stepper_of``): the loop
never asks a participant what it is again.

- On the master's thread, without awaiting (``Stepper.now``): an in-process FMU
  (``FmuParticipant.step_now``) or an OpenMCx built-in computes here, where a hop to another
  thread would cost more than its step; the watchdog watches it against its deadline.
- In two halves on the master's thread (``Stepper.split``): a remote participant on the
  native step channel (``native_step_channel``) is sent its request first and answered last,
  so many requests are on their way while the master computes what it computes itself.
- Awaited (neither): every other participant, through ``Participant.do_step``.

A run of in-process FMUs only is stepped whole by the native FMU step (``native_fmu_step``).
Every way has the meaning and the errors of ``Participant.do_step``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from coupler.channels import Value
from coupler.client import RemoteParticipant
from coupler.participant import Participant, Values
from coupler_orchestrator.master.native_step_channel import NativeSteps
from coupler_orchestrator.master.watchdog import IN_PROCESS

StepNow = Callable[[float, float, Mapping[str, Value]], Values]
"""A step taken on the caller's thread: (time, step, inputs) -> outputs."""


class Split(Protocol):
    """A step taken in two halves on the caller's thread: ``send`` the request, ``receive`` the
    answer (blocking until it is there or the call deadline has passed)."""

    described: tuple[str, str]
    """How summary.json names this way of stepping (``StepPath``), and why."""

    def send(self, time: float, step: float, inputs: Mapping[str, Value]) -> None: ...

    def receive(self) -> Values: ...


@runtime_checkable
class StepsHere(Protocol):
    """A participant that computes in the orchestrator's process (an in-process FMU, an
    OpenMCx built-in) and can step on the caller's thread, never waiting on anything."""

    def step_now(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values: ...


@dataclass(frozen=True)
class Stepper:
    """How one member steps; neither ``now`` nor ``split``: awaited."""

    now: StepNow | None = None
    split: Split | None = None
    overrun: str = IN_PROCESS
    """What a ``now`` step past its deadline means (the participant's ``overrun``, if any)."""


def stepper_of(participant: Participant) -> Stepper:
    """The way ``participant`` steps in this run (after its Initialize)."""
    if isinstance(participant, StepsHere):
        return Stepper(
            now=participant.step_now, overrun=getattr(participant, "overrun", IN_PROCESS)
        )
    if (
        isinstance(participant, RemoteParticipant)
        and isinstance(participant.steps, NativeSteps)
        and (halves := participant.steps.split()) is not None
    ):
        return Stepper(split=halves)
    return Stepper()
