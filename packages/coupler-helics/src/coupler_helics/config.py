"""What a Coupler participant that is a HELICS value federate is made of: a small TOML file.

::

    name = "HELICS"                 # the participant's name (Describe)
    federate = "coupler"            # the federate's name in the federation
    broker = "127.0.0.1:23500"      # the helics_broker's address (HOST:PORT)
    core_type = "tcp_ss"            # HELICS core type (tcp_ss: one outgoing connection)
timeout = 5.0                   # [s] a broker silent this long has ended: the run fails

    [[publication]]                 # a Coupler input, published to the federation
    channel = "y"
    key = "coupler/y"               # the publication's (global) key
    type = "Real"
    unit = "m/s"
    start = 0.0                     # published while the federation initializes

    [[subscription]]                # a federation's publication, a Coupler output
    channel = "ramp"
    key = "ramp"                    # the publication subscribed to
    type = "Real"
    unit = "m"                      # HELICS converts the publisher's unit to this one
    start = 0.0                     # the value before anything was published

``broker`` and ``federate`` are also String parameters of the participant (channels of those
names), so the SSD may set them per run.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic import ValidationError as PydanticValidationError

from coupler.channels import ValueType
from coupler.errors import ScenarioError

PARAMETERS = ("broker", "federate")
"""The participant's own parameters (String channels), set by the SSD or the file."""


class Interface(BaseModel):
    """One publication or subscription and the channel it is."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    channel: str
    """The channel's name (the SSD's connector)."""
    key: str
    """The HELICS key: a publication's global key, or the key subscribed to."""
    type: ValueType = ValueType.REAL
    """Real (HELICS double), Integer (int), Boolean (bool), String (string), Binary (bytes)."""
    unit: str = ""
    """The unit, in HELICS's unit syntax (it converts between a publication's and an input's)."""
    start: float | int | bool | str | None = None
    """A publication's value during initialization; a subscription's before any value came."""
    description: str = ""
    """Free text."""

    @model_validator(mode="after")
    def _supported(self) -> Interface:
        if self.type is ValueType.ENUMERATION:
            raise ValueError(f"{self.channel}: HELICS has no enumerations; use Integer")
        return self


class HelicsConfig(BaseModel):
    """A HELICS value federate as a participant."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = "HELICS"
    """The participant's name (Describe)."""
    federate: str = "coupler"
    """The federate's name in the federation (the ``federate`` parameter overrides it)."""
    broker: str = "127.0.0.1:23500"
    """``HOST:PORT`` of the broker (the ``broker`` parameter overrides it)."""
    core_type: str = "tcp_ss"
    """HELICS core type; tcp_ss makes one outgoing connection and listens on nothing."""
    core_init: str = ""
    """More of the core's init string (HELICS options), appended as written."""
    tick: float = Field(default=0.5, gt=0)
    """The core's heartbeat [s]: how often it checks on a silent broker."""
    timeout: float = Field(default=5.0, gt=0)
    """How long [s] the core waits for the broker: to connect when the run starts, and to
    answer once it has gone silent; a broker that ended mid-run fails the run after it
    (HELICS's own default is 30 s)."""
    publication: list[Interface] = Field(default_factory=list)
    """Coupler inputs, published."""
    subscription: list[Interface] = Field(default_factory=list)
    """Publications subscribed to, Coupler outputs."""

    @model_validator(mode="after")
    def _names(self) -> HelicsConfig:
        names = [i.channel for i in (*self.publication, *self.subscription)]
        taken = sorted({n for n in names if names.count(n) > 1 or n in PARAMETERS})
        if taken:
            raise ValueError(
                f"channel names must be unique and not {' or '.join(PARAMETERS)}: "
                f"{', '.join(taken)}"
            )
        if not names:
            raise ValueError("give at least one [[publication]] or [[subscription]]")
        return self

    @classmethod
    def load(cls, path: str | Path) -> HelicsConfig:
        """Read the TOML file; ScenarioError naming the file and the bad entry."""
        path = Path(path)
        try:
            return cls.model_validate(tomllib.loads(path.read_text(encoding="utf-8")))
        except OSError as exc:
            raise ScenarioError(
                f"cannot read HELICS participant file {path}: {exc.strerror}"
            ) from exc
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError(f"{path}: not valid TOML: {exc}") from exc
        except PydanticValidationError as exc:
            problems = "; ".join(
                f"{'.'.join(str(p) for p in e['loc']) or 'file'}: {e['msg']}" for e in exc.errors()
            )
            raise ScenarioError(f"{path}: invalid HELICS participant: {problems}") from exc


def split_address(address: str) -> tuple[str, int]:
    """``HOST:PORT`` as (host, port); ScenarioError when it is not one."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ScenarioError(
            f"broker {address!r} is not HOST:PORT (e.g. 127.0.0.1:23500, the port helics_broker "
            "was given with --port)"
        )
    return host.strip("[]"), int(port)
