"""The map server's configuration, from ``MAPSERVER_*`` environment variables or keywords."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from coupler.settings import SecuritySettings

SCENARIO_RAILML = (
    Path(__file__).resolve().parents[4]
    / "scenarios"
    / "railway"
    / "data"
    / "annaberg-schwarzenberg.railml"
)
"""The railway scenario's infrastructure, in a source checkout."""


class MapServerSettings(SecuritySettings):
    """Where the map server listens, what it draws and how it treats browsers."""

    model_config = SettingsConfigDict(env_prefix="MAPSERVER_", extra="ignore", frozen=True)

    grpc_host: str = "127.0.0.1"
    """Address the participant's gRPC server binds; 0.0.0.0 in containers."""
    grpc_port: int = Field(default=50071, ge=0, le=65535)
    """gRPC port of the participant; 0 picks a free one (logged at start)."""
    socket: Path | None = None
    """Unix socket the participant serves on instead of ``grpc_host:grpc_port`` (same host
    only; the web app stays on ``http_host:http_port``)."""
    http_host: str = "127.0.0.1"
    """Address the web app binds; 0.0.0.0 in containers."""
    http_port: int = Field(default=8080, ge=0, le=65535)
    """Port of the web app (the page browsers open); 0 picks a free one."""
    railml: Path = SCENARIO_RAILML
    """railML file with the line, balises and stations: the same file the scenario runs on."""
    tile_url: str = ""
    """Leaflet tile URL template, e.g. ``https://tile.openstreetmap.org/{z}/{x}/{y}.png``.
    Empty: no tiles, the track is drawn on a plain background (works offline)."""
    tile_attribution: str = ""
    """Attribution shown with the tiles (required by most tile providers)."""
    max_readings: int = Field(default=10_000, ge=1)
    """Balise readings kept per run; older ones leave the table (and snapshots) first."""
    client_backlog: int = Field(default=256, ge=1)
    """Readings queued per browser; a browser further behind gets a full snapshot instead."""
    client_write_timeout_s: float = Field(default=30.0, gt=0)
    """A browser that takes longer than this to accept one message is disconnected."""
    heartbeat_s: float = Field(default=15.0, gt=0)
    """Idle time after which the event stream sends a comment, keeping proxies from closing it."""
    log_level: str = "INFO"
    """DEBUG, INFO, WARNING or ERROR."""
    log_json: bool | None = None
    """JSON log lines; default: when stderr is not a terminal."""
