"""The HELICS value federate behind the participant: the only module that calls ``helics``.

Every call runs on one thread of its own (HELICS's calls block: joining the federation, the
time request until its grant), so the participant's event loop keeps serving. HELICS's errors
(``HelicsException``) are translated here, in ``_translated``, and nowhere else.

Time: HELICS time starts at 0; Coupler's ``start_time`` is HELICS's 0, and a communication
point t is HELICS time t - start_time (HELICS resolves it to 1 ns). The federate is
``uninterruptible`` (granted exactly what it requests) and ``wait_for_current_time_update``
(granted t only once every other federate has been granted t and moved on, so values published
at t by the others are read at t).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import helics as h

from coupler.channels import Value, ValueType
from coupler.errors import ParticipantError, ParticipantUnavailable
from coupler_helics.config import HelicsConfig, Interface, split_address

T = TypeVar("T")

TYPES = {
    ValueType.REAL: "double",
    ValueType.INTEGER: "int",
    ValueType.BOOLEAN: "bool",
    ValueType.STRING: "string",
    ValueType.BINARY: "bytes",
}
"""Coupler's types as HELICS names them."""

_PUBLISH: dict[ValueType, Callable[[Any, Any], None]] = {
    ValueType.REAL: h.helicsPublicationPublishDouble,
    ValueType.INTEGER: h.helicsPublicationPublishInteger,
    ValueType.BOOLEAN: h.helicsPublicationPublishBoolean,
    ValueType.STRING: h.helicsPublicationPublishString,
    ValueType.BINARY: h.helicsPublicationPublishBytes,
}
_READ: dict[ValueType, Callable[[Any], Any]] = {
    ValueType.REAL: h.helicsInputGetDouble,
    ValueType.INTEGER: h.helicsInputGetInteger,
    ValueType.BOOLEAN: h.helicsInputGetBoolean,
    ValueType.STRING: h.helicsInputGetString,
    ValueType.BINARY: h.helicsInputGetBytes,
}
_DEFAULT: dict[ValueType, Callable[[Any, Any], None]] = {
    ValueType.REAL: h.helicsInputSetDefaultDouble,
    ValueType.INTEGER: h.helicsInputSetDefaultInteger,
    ValueType.BOOLEAN: h.helicsInputSetDefaultBoolean,
    ValueType.STRING: h.helicsInputSetDefaultString,
    ValueType.BINARY: h.helicsInputSetDefaultBytes,
}

GRANT_TOLERANCE = 1e-9
"""HELICS's time resolution [s]: a grant within it of the request is the request."""


class Federate:
    """One HELICS value federate for one run: joined, stepped, left."""

    def __init__(self, participant: str, config: HelicsConfig, broker: str, name: str) -> None:
        self.participant = participant
        self.config = config
        self.broker = broker
        self.name = name
        self._thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"helics-{name}")
        self._federate: Any = None
        self._publications: dict[str, tuple[Interface, Any]] = {}
        self._inputs: dict[str, tuple[Interface, Any]] = {}

    async def join(self, starts: Mapping[str, Value]) -> dict[str, Value]:
        """Join the federation, publish ``starts`` while it initializes, enter executing mode
        (HELICS time 0); the subscriptions' values then."""
        return await self._run("join", lambda: self._join(starts))

    async def advance(self, to: float, values: Mapping[str, Value]) -> dict[str, Value]:
        """Publish ``values`` at the granted time, request HELICS time ``to`` (its grant);
        the subscriptions' values at ``to``."""
        return await self._run("time request", lambda: self._advance(to, values))

    async def leave(self) -> None:
        """Disconnect from the federation and free the federate (errors ignored: the run has
        ended either way)."""
        if self._federate is not None:
            with contextlib.suppress(ParticipantError):
                await self._run("disconnect", self._leave)
        self._thread.shutdown(wait=False)

    # -- on the federate's thread -----------------------------------------------------------

    def _join(self, starts: Mapping[str, Value]) -> dict[str, Value]:
        host, port = split_address(self.broker)
        info = h.helicsCreateFederateInfo()
        try:
            h.helicsFederateInfoSetCoreTypeFromString(info, self.config.core_type)
            h.helicsFederateInfoSetCoreInitString(
                info,
                f"--federates=1 --broker_address={host} --brokerport={port} "
                f"--local_interface=127.0.0.1 --tick={self.config.tick * 1000:.0f}ms "
                f"--timeout={self.config.timeout * 1000:.0f}ms "
                f"{self.config.core_init}",
            )
            h.helicsFederateInfoSetFlagOption(info, h.HELICS_FLAG_UNINTERRUPTIBLE, True)
            h.helicsFederateInfoSetFlagOption(
                info, h.HELICS_FLAG_WAIT_FOR_CURRENT_TIME_UPDATE, True
            )
            self._federate = h.helicsCreateValueFederate(self.name, info)
        finally:
            h.helicsFederateInfoFree(info)
        fed = self._federate
        for i in self.config.publication:
            pub = h.helicsFederateRegisterGlobalTypePublication(fed, i.key, TYPES[i.type], i.unit)
            self._publications[i.channel] = (i, pub)
        for i in self.config.subscription:
            sub = h.helicsFederateRegisterSubscription(fed, i.key, i.unit)
            if i.start is not None:
                _DEFAULT[i.type](sub, i.start)
            self._inputs[i.channel] = (i, sub)
        h.helicsFederateEnterInitializingMode(fed)
        self._publish(starts)
        h.helicsFederateEnterExecutingMode(fed)
        return self._read()

    def _advance(self, to: float, values: Mapping[str, Value]) -> dict[str, Value]:
        self._publish(values)
        granted = h.helicsFederateRequestTime(self._federate, to)
        if abs(granted - to) > GRANT_TOLERANCE * max(1.0, abs(to)):
            raise ParticipantError(
                f"HELICS granted time {granted!r} s for a request of {to!r} s: the federate is "
                "uninterruptible, so the federation ended or broke its time rules",
                participant=self.participant,
                call="DoStep",
            )
        return self._read()

    def _publish(self, values: Mapping[str, Value]) -> None:
        for channel, value in values.items():
            interface, pub = self._publications[channel]
            _PUBLISH[interface.type](pub, value)

    def _read(self) -> dict[str, Value]:
        return {channel: _READ[i.type](sub) for channel, (i, sub) in self._inputs.items()}

    def _leave(self) -> None:
        fed, self._federate = self._federate, None
        try:
            h.helicsFederateDisconnect(fed)
        finally:
            h.helicsFederateFree(fed)

    async def _run(self, what: str, call: Callable[[], T]) -> T:
        loop = asyncio.get_running_loop()
        try:
            return await loop.run_in_executor(self._thread, call)
        except h.HelicsException as exc:
            raise self._translated(what, exc) from exc

    def _translated(self, what: str, exc: Exception) -> ParticipantError:
        """The one place HELICS's errors become Coupler's."""
        text = str(exc)
        if "connect to broker" in text or "lost connection with broker" in text:
            return ParticipantUnavailable(
                f"HELICS federate '{self.name}': {what} failed: {text}: the broker at "
                f"{self.broker} is not there (not started, or it ended); is helics_broker "
                f"running with --port on that address?",
                participant=self.participant,
                call=what,
                status="UNAVAILABLE",
            )
        return ParticipantError(
            f"HELICS federate '{self.name}': {what} failed: {text}",
            participant=self.participant,
            call=what,
        )
