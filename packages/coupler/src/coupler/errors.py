"""Coupler's exception tree. Every error a user sees is one of these.

    CouplerError
    ├── ScenarioError          bad SSP, wiring or configuration; raised before anything runs
    │   ├── ValidationError    several problems found together (``.problems``)
    │   └── PortInUse          a server's port is taken (``.port``, ``.holders``: pid + command)
    ├── ChannelValueError      a value does not fit its channel (``channel``, ``expected``)
    │   ├── MessageTooLarge    a message is over the message limit (``size``, ``total``, ``limit``)
    │   └── ValueTooLarge      a value is over its channel's maximum (``size``, ``maximum``)
    └── ParticipantError       a participant failed at run time (participant, call, status)
        ├── ParticipantUnavailable   cannot be reached, or the wrapped simulator is down
        └── ParticipantTimeout       a call exceeded its deadline

Foreign errors (grpc.aio.AioRpcError, FMI statuses, aiohttp errors) are translated where they
are caught -- ``coupler.client`` for gRPC, ``coupler.fmu`` for FMI -- as ``raise X(...) from exc``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence

_UNPRINTABLE = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def foreign(text: str) -> str:
    """Text from another program (a participant's status message, its reason to end a run, the
    names and words of its Describe) as Coupler shows it: control characters -- an escape
    sequence, a line break, a carriage return, a bidi override -- written as escapes (``\\x1b``,
    ``\\n``), so that it can never move the cursor, recolour the terminal or fake a line of
    Coupler's own (``completed: ...``); everything else as it was."""
    return _UNPRINTABLE.sub(lambda found: found.group().encode("unicode_escape").decode(), text)


class CouplerError(Exception):
    """Base of every error Coupler raises on purpose."""


def answered_unasked(count: int) -> str:
    """Why a run whose step stream brought ``count`` answers after its last request cannot be
    trusted (said by every transport that finds them)."""
    return (
        f"{count} step answer{'s' if count > 1 else ''} came after the run's last request, "
        "which no request had asked for: the participant answered a request twice, so every "
        "row after it holds the answer to the step before; the results cannot be trusted"
    )


class ScenarioError(CouplerError):
    """The scenario (SSP, wiring, configuration) is wrong; nothing has run."""


class ValidationError(ScenarioError):
    """Several problems found together, each a sentence naming its culprit and the fix."""

    def __init__(self, problems: Iterable[str], *, subject: str = "scenario") -> None:
        self.problems = list(problems)
        self.subject = subject
        lines = "\n".join(f"  - {p}" for p in self.problems)
        count = len(self.problems)
        super().__init__(f"{subject}: {count} problem{'' if count == 1 else 's'}\n{lines}")


class PortInUse(ScenarioError):
    """A server cannot listen: another process holds its port (``coupler.ports``)."""

    def __init__(self, message: str, *, port: int, holders: Sequence[object] = ()) -> None:
        self.port = port
        self.holders = list(holders)
        """``coupler.ports.PortHolder`` of each process seen listening there."""
        super().__init__(message)


class ChannelValueError(CouplerError):
    """A value does not fit its channel: unknown channel, wrong type, out of range."""

    def __init__(self, message: str, *, channel: str, expected: str = "") -> None:
        self.channel = channel
        self.expected = expected
        super().__init__(message)


class MessageTooLarge(ChannelValueError):
    """A message's Binary and String values together are over the message limit; ``channel`` is
    the largest of them (``size`` bytes), ``total`` the message's, ``limit`` the limit's."""

    def __init__(self, *, channel: str, kind: str, size: int, total: int, limit: int) -> None:
        self.kind = kind
        """``input``, ``output`` or ``parameter``."""
        self.size, self.total, self.limit = size, total, limit
        self.channel = channel
        super().__init__(self.naming(""), channel=channel, expected=f"at most {limit} bytes")

    def naming(self, owner: str) -> str:
        """The message, the channel written ``owner.channel`` when ``owner`` is given."""
        where = f"{owner}.{self.channel}" if owner else f"'{self.channel}'"
        others = (
            f", {self.total} bytes with the message's other values"
            if self.total > self.size
            else ""
        )
        return (
            f"{self.kind} {where} carries {self.size} bytes{others}: over the message limit of "
            f"{self.limit} bytes ({self.limit / 2**20:g} MiB); raise the limit on both sides "
            f"(coupler run --max-message-size MiB; a participant's server: max_message_bytes, "
            f'docs/protocol.md "Message size") or send smaller values'
        )


class ValueTooLarge(ChannelValueError):
    """A Binary or String value is over the maximum its channel declares (``Channel.max_bytes``):
    ``size`` bytes against ``maximum``."""

    def __init__(self, *, channel: str, kind: str, size: int, maximum: int) -> None:
        self.kind = kind
        """``input``, ``output`` or ``parameter``."""
        self.size, self.maximum = size, maximum
        self.channel = channel
        super().__init__(self.naming(""), channel=channel, expected=f"at most {maximum} bytes")

    def naming(self, owner: str) -> str:
        """The message, the channel written ``owner.channel`` when ``owner`` is given."""
        where = f"{owner}.{self.channel}" if owner else f"'{self.channel}'"
        fix = (
            "the participant must send at most that, or declare a larger maximum"
            if self.kind == "output"
            else "send at most that (declare the connected output's maximum: coupler validate "
            "then checks the connection), or declare a larger maximum"
        )
        return (
            f"{self.kind} {where} carries {self.size} bytes, over its declared maximum of "
            f"{self.maximum} bytes (max_bytes); {fix} "
            f'(docs/protocol.md "Message size")'
        )


class ParticipantError(CouplerError):
    """A participant failed at run time.

    ``status`` is the gRPC status code name (``"INVALID_ARGUMENT"``, ...) or the FMI status
    (``"fmi2Error"``, ...) that the participant reported.
    """

    def __init__(self, message: str, *, participant: str, call: str, status: str = "") -> None:
        self.participant = participant
        self.call = call
        self.status = status
        self.detail = message
        """The message without the ``participant.call [status]`` prefix."""
        prefix = f"{participant}.{call}"
        if status:
            prefix += f" [{status}]"
        super().__init__(f"{prefix}: {message}")


class ParticipantUnavailable(ParticipantError):
    """The participant cannot be reached, or the simulator it wraps is down."""


class ParticipantTimeout(ParticipantError):
    """A call to the participant exceeded its deadline."""
