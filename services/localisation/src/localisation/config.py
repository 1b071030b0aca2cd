"""The service's configuration, from ``LOCALISATION_*`` environment variables or options."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from coupler.settings import ParticipantSettings

Role = Literal["localisation", "odometer", "transmission"]

PORTS: dict[str, int] = {"localisation": 50064, "odometer": 50065, "transmission": 50066}
"""Each role's default gRPC port."""

SCENARIO_RAILML = (
    Path(__file__).resolve().parents[4] / "scenarios/railway/data/annaberg-schwarzenberg.railml"
)
"""The railway scenario's line, in a source checkout."""


class LocalisationSettings(ParticipantSettings):
    """Which participant this process serves, where, and on which line."""

    model_config = SettingsConfigDict(env_prefix="LOCALISATION_", extra="ignore", frozen=True)

    role: Role = "localisation"
    """``localisation`` (the system under test), ``odometer`` or ``transmission`` (the sensor
    models that feed it)."""
    port: int = Field(default=-1, ge=-1, le=65535)
    """gRPC port; 0 picks a free one; unset: the role's (50064, 50065, 50066)."""
    railml: Path = SCENARIO_RAILML
    """The line's railML file: the localisation's linking data."""
    channels: Path | None = None
    """The localisation's channel map (TOML); unset: the packaged ``channels.toml``."""

    def role_port(self) -> int:
        return PORTS[self.role] if self.port < 0 else self.port
