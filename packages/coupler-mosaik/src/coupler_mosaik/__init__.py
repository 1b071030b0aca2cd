"""Coupler and mosaik, both ways.

- ``CouplerSimulator``: a Coupler participant (any address) as a mosaik API v3 simulator
  (``{"python": "coupler_mosaik:CouplerSimulator"}``, or ``{"cmd": "coupler-mosaik simulator
  %(addr)s"}`` in a mosaik sim config).
- ``MosaikParticipant``: a mosaik API v3 simulator (in this process, or over mosaik's TCP
  protocol) as a Coupler participant, made from a ``MosaikConfig`` (``coupler-mosaik
  participant FILE.toml`` serves one).

What maps to what, and the limits: docs/frameworks.md.
"""

from __future__ import annotations

from coupler_mosaik.config import MosaikConfig
from coupler_mosaik.participant import MosaikParticipant
from coupler_mosaik.simulator import CouplerSimulator
from coupler_mosaik.ticks import Ticks

__all__ = ["CouplerSimulator", "MosaikConfig", "MosaikParticipant", "Ticks"]
