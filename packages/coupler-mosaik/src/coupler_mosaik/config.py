"""What a mosaik simulator as a Coupler participant is made of: a small TOML file.

::

    name = "CSV"                        # the participant's name (Describe)
    time_resolution = 1.0               # seconds per mosaik tick

    [simulator]                         # exactly one of python, cmd, connect (mosaik's starters)
    python = "mosaik_csv:CSV"           # module:Class, run in the participant's process
    # cmd = "python sim.py %(addr)s"    # a process of its own that connects to the participant
    # connect = "127.0.0.1:5678"        # a simulator already running, listening there
    params = { sim_start = "2024-01-01 00:00:00", datafile = "ramp.csv" }   # init(**params)

    [model]                             # the entity created (one)
    name = "Source"
    params = {}                         # create(**params); parameter channels override them

    [[channel]]
    name = "value"                      # the channel (SSD connector) name
    attr = "value"                      # the entity's attribute (default: name)
    causality = "output"                # input, output, or parameter (a model param)
    type = "Real"
    unit = "m/s"

Relative paths in ``cmd`` and in ``simulator.params`` are the user's to mean: they are passed
as written (the simulator resolves them against the participant's working directory).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic import ValidationError as PydanticValidationError

from coupler.channels import Causality, ValueType
from coupler.errors import ScenarioError


class SimulatorConfig(BaseModel):
    """How to reach the simulator: one of mosaik's three starters."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    python: str = ""
    """``module:Class``: the simulator class, instantiated in this process."""
    cmd: str = ""
    """A command line with ``%(addr)s`` (and ``%(python)s``): started as a process of its own,
    it connects to the participant over mosaik's TCP protocol."""
    connect: str = ""
    """``HOST:PORT`` of a simulator already listening (started with ``--remote``)."""
    params: dict[str, Any] = Field(default_factory=dict)
    """Keyword arguments of the simulator's ``init`` (besides ``sid`` and ``time_resolution``)."""
    start_timeout: float = Field(default=30.0, gt=0)
    """Seconds a started process (``cmd``) or a ``connect`` address has to connect."""

    @model_validator(mode="after")
    def _one_starter(self) -> SimulatorConfig:
        given = [k for k in ("python", "cmd", "connect") if getattr(self, k)]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of python = 'module:Class', cmd = '... %(addr)s' or "
                f"connect = 'HOST:PORT' (given: {', '.join(given) or 'none'})"
            )
        if self.python and ":" not in self.python:
            raise ValueError(f"python = {self.python!r}: write module:Class")
        if self.cmd and "%(addr)s" not in self.cmd:
            raise ValueError(f"cmd = {self.cmd!r} has no %(addr)s: the simulator cannot connect")
        return self


class ModelConfig(BaseModel):
    """The entity the participant creates."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    """A public model of the simulator's META."""
    params: dict[str, Any] = Field(default_factory=dict)
    """Keyword arguments of ``create``; a parameter channel's value replaces its entry."""


class ChannelConfig(BaseModel):
    """One channel and the entity attribute (or model parameter) behind it."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    """Channel name, as the SSD's connector names it."""
    causality: Causality
    """input (Coupler -> the simulator), output (the simulator -> Coupler), or parameter (a
    model parameter, given to ``create``)."""
    type: ValueType = ValueType.REAL
    """Real, Integer, Boolean, String or Binary."""
    attr: str = ""
    """The entity's attribute (a parameter's name for parameters); default: ``name``."""
    unit: str = ""
    """Unit symbol (mosaik has none: say what the simulator means)."""
    start: float | int | bool | str | None = None
    """Start value: of an input or parameter; of an output when the simulator's first step has
    none (an event-based simulator without an event at the start)."""
    description: str = ""
    """Free text."""

    @property
    def attribute(self) -> str:
        return self.attr or self.name


class MosaikConfig(BaseModel):
    """A mosaik simulator as a participant."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    """The participant's name (Describe); also the simulator's mosaik id (sid)."""
    time_resolution: float = Field(default=1.0, gt=0)
    """Seconds per mosaik tick: Coupler's steps must be whole numbers of it."""
    simulator: SimulatorConfig
    model: ModelConfig
    channel: list[ChannelConfig] = Field(min_length=1)
    """Every channel, in order."""

    @model_validator(mode="after")
    def _unique(self) -> MosaikConfig:
        names = [c.name for c in self.channel]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"channel names must be unique: {', '.join(twice)} more than once")
        return self

    @classmethod
    def load(cls, path: str | Path) -> MosaikConfig:
        """Read the TOML file; ScenarioError naming the file and the bad entry."""
        path = Path(path)
        try:
            return cls.model_validate(tomllib.loads(path.read_text(encoding="utf-8")))
        except OSError as exc:
            raise ScenarioError(
                f"cannot read mosaik participant file {path}: {exc.strerror}"
            ) from exc
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError(f"{path}: not valid TOML: {exc}") from exc
        except PydanticValidationError as exc:
            problems = "; ".join(
                f"{'.'.join(str(p) for p in e['loc']) or 'file'}: {e['msg']}" for e in exc.errors()
            )
            raise ScenarioError(f"{path}: invalid mosaik participant: {problems}") from exc
