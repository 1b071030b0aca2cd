"""The host's configuration, from ``BALISE_FMU_*`` environment variables or keywords."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from coupler.settings import ParticipantSettings


class BaliseFmuSettings(ParticipantSettings):
    """Which FMU to serve, under which name, and where."""

    model_config = SettingsConfigDict(env_prefix="BALISE_FMU_", extra="ignore", frozen=True)

    port: int = Field(default=50062, ge=0, le=65535)
    """gRPC port of the host; 0 picks a free one."""
    fmu: Path | None = None
    """FMU to serve (FMI 1.0/2.0/3.0 co-simulation); unset: TrackBalises.fmu in build/fmus,
    built from ``railml`` when missing."""
    name: str | None = None
    """Participant name; unset: the FMU's model name."""
    railml: Path | None = None
    """railML file the default TrackBalises.fmu is built from when it is missing; unset: the
    Annaberg-Schwarzenberg scenario line."""
