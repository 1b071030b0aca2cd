"""The mock's configuration, from ``OPENRAILS_MOCK_*`` environment variables or keywords.

Consist figures start from a preset and can be overridden one by one with
``OPENRAILS_MOCK_CONSIST__<FIELD>`` (e.g. ``OPENRAILS_MOCK_CONSIST__MASS_KG=90000``).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from coupler.errors import ScenarioError

from .conditions import Conditions, read_environment
from .physics import PRESETS, Consist

MAX_STEP_MS = 500.0
"""The longest step the lockstep API accepts, as in OpenRails' simulation build."""


class ConsistOverrides(BaseModel):
    """Figures that replace the preset's; unset fields keep the preset value."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    mass_kg: float | None = Field(default=None, gt=0)
    """Total mass of the train."""
    length_m: float | None = Field(default=None, gt=0)
    """Length of the train."""
    max_tractive_effort_n: float | None = Field(default=None, ge=0)
    """Tractive effort at full throttle at low speed."""
    max_power_w: float | None = Field(default=None, ge=0)
    """Power at the wheel at full throttle."""
    davis_a_n: float | None = Field(default=None, ge=0)
    """Davis A."""
    davis_b_n_per_mps: float | None = Field(default=None, ge=0)
    """Davis B."""
    davis_c_n_per_mps2: float | None = Field(default=None, ge=0)
    """Davis C."""
    max_service_brake_decel_mps2: float | None = Field(default=None, ge=0)
    """Deceleration of a full service brake application."""
    max_dynamic_brake_force_n: float | None = Field(default=None, ge=0)
    """Force of the dynamic brake at full application."""
    rotating_mass_fraction: float | None = Field(default=None, ge=0)
    """Rotating masses as a fraction of the mass."""
    car_count: int | None = Field(default=None, ge=1)
    """Cars of equal length (the first one is the lead locomotive)."""


class MockConfig(BaseSettings):
    """How the mock runs: where it listens, its mode, the route and the train."""

    model_config = SettingsConfigDict(
        env_prefix="OPENRAILS_MOCK_", env_nested_delimiter="__", frozen=True, extra="forbid"
    )

    host: str = "127.0.0.1"
    """Address to listen on."""
    port: int = Field(default=2150, ge=0, le=65535)
    """TCP port (OpenRails' default is 2150; 0 picks a free one)."""
    mode: Literal["lockstep", "stock"] = "lockstep"
    """``lockstep``: each POST /API/CABCONTROLS advances one step; ``stock``: wall clock."""
    step_ms: float = Field(default=200.0, gt=0, le=MAX_STEP_MS)
    """Lockstep step size in milliseconds."""
    speedup: float = Field(default=1.0, gt=0)
    """Stock mode: simulated seconds per wall-clock second."""
    route: Path | None = None
    """OpenRails route folder (holding NAME.trk) the train runs on, with ``path``."""
    path: Path | None = None
    """The train's path: a .pat file, or PATHS/X.pat inside the route folder."""
    trains: Path | None = None
    """Other trains on the route folder: the public simulation client's trains config (JSON
    list of trainNumber, trainName, trainConfig, trainPath)."""
    railml: Path | None = None
    """railML infrastructure file, exported to a route folder at start-up (ignored when
    ``route`` is set); unset with ``route``: a straight, flat 20 km line."""
    start_time_s: float = Field(default=8 * 3600.0, ge=0, lt=86400)
    """Time of day at the start, seconds since midnight."""
    start_distance_m: float | None = Field(default=None, ge=0)
    """Route distance of the train's front at the start; unset: the train's rear at 0."""
    loading_delay_s: float = Field(default=1.0, ge=0)
    """Lockstep mode: GET /API/READY answers 425 for this long after start-up."""
    train_name: str = "PLAYER"
    """Name of the train in the lockstep API (``LocomotiveName``, key of ``trains``)."""
    origin_tile_x: int = -5354
    """World tile whose centre is the route's origin (east); the default is the start tile
    OpenRails' simulation client assumes, so its local coordinates match the route's."""
    origin_tile_z: int = 14849
    """World tile whose centre is the route's origin (north)."""
    track_nodes_reversed: bool = False
    """The route's track nodes are laid against the direction the train faces, as in a route
    drawn from the other end: ``movementDirection`` is ``"Backward"``."""
    reset: bool = True
    """Answer POST /API/RESET (a mock extension); false: 404, like OpenRails' builds."""
    sensors: Path | None = None
    """OpenRails-for-simulation's sensor configuration: a JSON list of camera and depth
    sensors (``sensors.py``); lockstep mode only. Unset: no sensors."""
    camera_height_m: float = Field(default=2.5, gt=0, le=10)
    """Height of the sensors above the top of the rails, at the train's front."""
    camera_pitch_deg: float = Field(default=4.0, ge=-45, le=45)
    """How far the sensors look down from the track's direction [deg]."""
    render_threads: int = Field(default_factory=lambda: 2 if (os.cpu_count() or 1) > 1 else 1,
                                ge=1, le=2)  # fmt: skip
    """Threads a frame's pixels are computed on (1 or 2; default 2 where the machine has
    two cores or more): the frame's rows split between them, the bytes the same."""
    season: str | None = None
    """OpenRails' season (spring, summer, autumn, winter or 0-3); unset: summer."""
    weather: str | None = None
    """OpenRails' weather (clear, snow, rain or 0-2); unset: clear."""
    environment: Path | None = None
    """A JSON object of conditions (``conditions.Conditions``' names), applied after
    ``season`` and ``weather``."""
    conditions: dict[str, Any] = {}
    """Conditions by name (``--condition KEY=VALUE``), applied last."""
    consist_preset: str = "br642"
    """Consist the train starts from (see ``physics.PRESETS``)."""
    consist: ConsistOverrides = ConsistOverrides()
    """Per-figure overrides of the preset."""

    def build_conditions(self) -> Conditions:
        """The world's conditions at start: season, weather, the environment file, then
        ``conditions``; ScenarioError naming the setting and the fix."""
        conditions = Conditions()
        if self.season is not None:
            conditions = conditions.updated({"season": self.season}, source="--season")
        if self.weather is not None:
            conditions = conditions.updated({"weather": self.weather}, source="--weather")
        if self.environment is not None:
            conditions = conditions.updated(
                read_environment(self.environment), source=str(self.environment)
            )
        return conditions.updated(self.conditions, source="--condition")

    def build_consist(self) -> Consist:
        """The preset with the overrides applied."""
        try:
            preset = PRESETS[self.consist_preset]
        except KeyError:
            raise ScenarioError(
                f"unknown consist preset {self.consist_preset!r} "
                f"(OPENRAILS_MOCK_CONSIST_PRESET); known: {', '.join(sorted(PRESETS))}"
            ) from None
        changes = {k: v for k, v in self.consist.model_dump().items() if v is not None}
        return dataclasses.replace(preset, **changes)
