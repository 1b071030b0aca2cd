"""Configuration from environment variables, one prefix per service (pydantic-settings)."""

from __future__ import annotations

from pydantic_settings import BaseSettings, SettingsConfigDict


class ParticipantSettings(BaseSettings):
    """What every participant process reads; services subclass it with their own prefix."""

    model_config = SettingsConfigDict(env_prefix="COUPLER_", extra="ignore", frozen=True)

    host: str = "127.0.0.1"
    """Address the gRPC server binds; 0.0.0.0 in containers."""
    port: int = 50051
    """gRPC port; 0 picks a free one (printed at start)."""
    log_level: str = "INFO"
    """DEBUG, INFO, WARNING or ERROR."""
    log_json: bool | None = None
    """JSON log lines; default: when stderr is not a terminal."""
