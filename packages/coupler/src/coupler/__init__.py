"""Coupler's participant SDK: what a participant author installs.

A participant implements ``Participant`` (or wraps a simulator with an ``Adapter``) and is
served with ``serve`` (``serve_main``: a participant program's main, with every option
``coupler fleet`` passes); ``step_end`` is the end of a step on the run's exact time grid;
``RemoteParticipant`` talks to one; ``FmuParticipant`` runs an FMU
(the ``fmu`` extra); ``coupler.testing`` serves one in a test. The names below are the public
API (``__all__``; ``tests/test_exported_members.py`` keeps it). Each is imported when first
used, so ``import coupler`` stays light (no gRPC until a name that needs it).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from coupler.adapter import Adapter, AdapterConfig, AdapterParticipant, ChannelMap
    from coupler.channels import (
        Capabilities,
        Causality,
        Channel,
        Description,
        RunSetup,
        Value,
        ValueType,
    )
    from coupler.client import RemoteParticipant
    from coupler.costs import waiting
    from coupler.errors import (
        ChannelValueError,
        CouplerError,
        ParticipantError,
        ParticipantTimeout,
        ParticipantUnavailable,
        ScenarioError,
        ValidationError,
    )
    from coupler.fmu import FmuParticipant
    from coupler.grid import step_end
    from coupler.logs import configure_logging
    from coupler.messages import register
    from coupler.participant import EndRun, HealthReport, Participant, Values
    from coupler.security import ClientSecurity, ServerSecurity
    from coupler.server import ParticipantServer, run, serve
    from coupler.settings import ParticipantSettings, SecuritySettings, serve_main

_HOMES = {
    "Adapter": "adapter",
    "AdapterConfig": "adapter",
    "AdapterParticipant": "adapter",
    "Capabilities": "channels",
    "Causality": "channels",
    "Channel": "channels",
    "ChannelMap": "adapter",
    "ChannelValueError": "errors",
    "ClientSecurity": "security",
    "CouplerError": "errors",
    "Description": "channels",
    "EndRun": "participant",
    "FmuParticipant": "fmu",
    "HealthReport": "participant",
    "Participant": "participant",
    "ParticipantError": "errors",
    "ParticipantServer": "server",
    "ParticipantSettings": "settings",
    "ParticipantTimeout": "errors",
    "ParticipantUnavailable": "errors",
    "RemoteParticipant": "client",
    "RunSetup": "channels",
    "ScenarioError": "errors",
    "SecuritySettings": "settings",
    "ServerSecurity": "security",
    "StepTransport": "client",
    "ValidationError": "errors",
    "Value": "channels",
    "ValueType": "channels",
    "Values": "participant",
    "configure_logging": "logs",
    "register": "messages",
    "run": "server",
    "serve": "server",
    "serve_main": "settings",
    "step_end": "grid",
    "waiting": "costs",
}
"""Each public name and the module of this package that defines it."""

__all__ = [
    "Adapter",
    "AdapterConfig",
    "AdapterParticipant",
    "Capabilities",
    "Causality",
    "Channel",
    "ChannelMap",
    "ChannelValueError",
    "ClientSecurity",
    "CouplerError",
    "Description",
    "EndRun",
    "FmuParticipant",
    "HealthReport",
    "Participant",
    "ParticipantError",
    "ParticipantServer",
    "ParticipantSettings",
    "ParticipantTimeout",
    "ParticipantUnavailable",
    "RemoteParticipant",
    "RunSetup",
    "ScenarioError",
    "SecuritySettings",
    "ServerSecurity",
    "StepTransport",
    "ValidationError",
    "Value",
    "ValueType",
    "Values",
    "configure_logging",
    "register",
    "run",
    "serve",
    "serve_main",
    "step_end",
    "waiting",
]


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'coupler' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"coupler.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
