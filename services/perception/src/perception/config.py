"""The service's configuration, from ``PERCEPTION_*`` environment variables or options."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from coupler.settings import ParticipantSettings


class PerceptionSettings(ParticipantSettings):
    """Where the perception participant serves, and its logging."""

    model_config = SettingsConfigDict(env_prefix="PERCEPTION_", extra="ignore", frozen=True)

    port: int = Field(default=50063, ge=0, le=65535)
    """gRPC port; 0 picks a free one."""
    model: Path = Path("build/models/balise-pixels.json")
    """The learned detector's model file (``make detector-model``), read when a run asks for
    ``detector = learned``."""
