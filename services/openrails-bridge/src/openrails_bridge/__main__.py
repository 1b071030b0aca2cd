"""``python -m openrails_bridge``: serve OpenRails as a Coupler participant.

Options override the ``OPENRAILS_BRIDGE_*`` environment variables (see ``config.py``).
"""

from __future__ import annotations

import argparse
from importlib import resources
from pathlib import Path

from coupler.adapter import AdapterConfig, AdapterParticipant
from coupler.channels import Causality
from coupler.errors import CouplerError, ScenarioError
from coupler.logs import configure_logging
from coupler.server import ParticipantServer
from coupler.settings import add_security_arguments, add_socket_argument

from .adapter import OpenRailsAdapter
from .config import BridgeSettings
from .sensors import load_sensors


def _parse(argv: list[str] | None) -> BridgeSettings:
    parser = argparse.ArgumentParser(prog="openrails-bridge", description=__doc__)
    parser.add_argument(
        "--openrails-url", dest="openrails_url", help="default http://127.0.0.1:2150"
    )
    parser.add_argument("--mode", choices=["lockstep", "stock"])
    parser.add_argument("--sim-step", type=float, dest="sim_step_s", help="lockstep step [s]")
    parser.add_argument("--speedup", type=float, help="stock: simulated s per wall-clock s")
    parser.add_argument("--request-timeout", type=float, dest="request_timeout_s")
    parser.add_argument(
        "--ready-timeout", type=float, dest="ready_timeout_s", help="Initialize's wait [s]"
    )
    parser.add_argument(
        "--max-body-bytes", type=int, dest="max_body_bytes", help="largest answer read"
    )
    parser.add_argument("--channels", type=Path, help="channel mapping TOML")
    parser.add_argument(
        "--sensors",
        type=Path,
        help="OpenRails' sensor configuration (JSON): one Binary output channel per sensor",
    )
    parser.add_argument("--locomotive", help="lockstep LocomotiveName (default PLAYER)")
    parser.add_argument("--host", help="gRPC bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="gRPC port, 0 = any free one (default 50061)")
    add_socket_argument(parser)
    parser.add_argument("--log-level", dest="log_level")
    add_security_arguments(parser)
    given = {k: v for k, v in vars(parser.parse_args(argv)).items() if v is not None}
    return BridgeSettings(**given)


def load_channels(settings: BridgeSettings) -> AdapterConfig:
    """The channel mapping (the packaged one unless configured), with the lockstep step."""
    if settings.channels is not None:
        config = AdapterConfig.load(settings.channels)
    else:
        with resources.as_file(resources.files(__package__) / "channels.toml") as path:
            config = AdapterConfig.load(path)
    if settings.mode == "lockstep":
        config = config.model_copy(update={"fixed_step_size": settings.sim_step_s})
    return config


def build(settings: BridgeSettings) -> AdapterParticipant:
    """The bridge participant: the adapter and its channel mapping, with a Binary output
    channel per configured sensor."""
    config = load_channels(settings)
    sensors = load_sensors(settings.sensors) if settings.sensors is not None else ()
    if sensors and settings.mode != "lockstep":
        raise ScenarioError(
            f"{settings.sensors} (OPENRAILS_BRIDGE_SENSORS): camera sensors exist in OpenRails' "
            f"build for simulation only: use --mode lockstep, or no sensors"
        )
    channels = [*config.channel]
    for sensor in sensors:
        channels.append(sensor.channel())
        if sensor.labelled:
            channels.append(sensor.labels_channel())
    names: set[str] = set()
    for channel in channels:
        if channel.name in names:
            raise ScenarioError(
                f"{settings.sensors}: sensor '{channel.name}' would be a channel of the same "
                f"name as another one (the channel mapping's, or a sensor's labels channel "
                f"<sensor>_labels); rename the sensor"
            )
        names.add(channel.name)
    config = config.model_copy(update={"channel": channels})
    inputs = {c.field: c.name for c in config.channel if c.causality is Causality.INPUT}
    adapter = OpenRailsAdapter(settings, name=config.name, channel_names=inputs, sensors=sensors)
    return AdapterParticipant(adapter, config, implementation="openrails-bridge")


def main(argv: list[str] | None = None) -> None:
    settings = _parse(argv)
    configure_logging(settings.log_level, json=settings.log_json)
    try:
        participant = build(settings)
    except CouplerError as exc:
        raise SystemExit(f"openrails-bridge: {exc}") from None

    def announce(server: ParticipantServer) -> None:
        print(
            f"openrails-bridge listening at {server.address} "
            f"(OpenRails {settings.openrails_url}, {settings.mode}; health SERVING while "
            f"OpenRails answers)",
            flush=True,
        )

    settings.serve(participant, program="openrails-bridge", on_started=announce)


if __name__ == "__main__":
    main()
