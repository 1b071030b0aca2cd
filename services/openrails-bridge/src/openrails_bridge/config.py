"""The bridge's configuration, from ``OPENRAILS_BRIDGE_*`` environment variables or keywords."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from coupler.settings import ParticipantSettings

Mode = Literal["lockstep", "stock"]


class BridgeSettings(ParticipantSettings):
    """Where OpenRails is, how to drive it, and where the bridge serves."""

    model_config = SettingsConfigDict(env_prefix="OPENRAILS_BRIDGE_", extra="ignore", frozen=True)

    port: int = Field(default=50061, ge=0, le=65535)
    """gRPC port of the bridge; 0 picks a free one."""
    openrails_url: str = "http://127.0.0.1:2150"
    """OpenRails' web server (its API lives under ``/API``)."""
    mode: Mode = "lockstep"
    """``lockstep``: each POST /API/CABCONTROLS advances one ``sim_step_s`` (OpenRails' build
    for simulation); ``stock``: upstream OpenRails running on the wall clock."""
    sim_step_s: float = Field(default=0.2, gt=0)
    """Lockstep: OpenRails' fixed step [s]; communication steps must be whole multiples."""
    speedup: float = Field(default=1.0, gt=0)
    """Stock: simulated seconds per wall-clock second of the OpenRails run."""
    request_timeout_s: float = Field(default=5.0, gt=0)
    """Deadline of every HTTP request to OpenRails [s]."""
    ready_timeout_s: float = Field(default=10.0, ge=0)
    """How long Initialize waits for OpenRails to be ready before UNAVAILABLE [s]; the
    bridge itself starts at once and reports OpenRails' state through health."""
    max_body_bytes: int = Field(default=1024 * 1024, ge=1024)
    """Largest answer read from OpenRails; a bigger one is refused without reading the rest."""
    channels: Path | None = None
    """Channel mapping (TOML); unset: the packaged ``channels.toml``."""
    sensors: Path | None = None
    """OpenRails' sensor configuration (the JSON list it was started with): one Binary
    output channel per camera or depth sensor (lockstep only). Unset: no sensor channels."""
    locomotive: str = "PLAYER"
    """Lockstep: ``LocomotiveName`` of the driven train and its key in the step reply."""
    control_index: int = 1
    """``ControlIndex`` sent with every control."""
