"""Coupler in HELICS federations: ``HelicsParticipant``, a Coupler participant that is a HELICS
value federate (``coupler-helics FILE.toml`` serves one); ``HelicsConfig``, its TOML file;
``broker.command``, the wheel's helics_broker on loopback. docs/frameworks.md says what maps to
what.
"""

from __future__ import annotations

from coupler_helics.config import HelicsConfig
from coupler_helics.participant import HelicsParticipant

__all__ = ["HelicsConfig", "HelicsParticipant"]
