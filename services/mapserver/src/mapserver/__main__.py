"""``python -m mapserver``: the participant's gRPC server and the web app in one event loop.

Options override ``MAPSERVER_*`` environment variables; SIGTERM/SIGINT stop both servers.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
from pathlib import Path
from typing import Any

import structlog

from coupler.errors import CouplerError
from coupler.logs import configure_logging
from coupler.ports import host_port, listening
from coupler.server import ParticipantServer
from coupler.server import run as run_participant
from coupler.settings import add_security_arguments, add_socket_argument
from coupler_railway import Infrastructure, RailMLError, load_infrastructure
from mapserver.config import MapServerSettings
from mapserver.feed import Feed
from mapserver.participant import MapParticipant
from mapserver.state import RunState
from mapserver.web import create_app, start_site

log = structlog.get_logger("mapserver")


def _parse(argv: list[str] | None) -> MapServerSettings:
    parser = argparse.ArgumentParser(
        prog="mapserver", description="Live browser map of a running co-simulation."
    )
    parser.add_argument("--grpc-host", dest="grpc_host")
    parser.add_argument("--grpc-port", dest="grpc_port", type=int, help="default 50071")
    add_socket_argument(parser)
    parser.add_argument("--http-host", dest="http_host")
    parser.add_argument("--http-port", dest="http_port", type=int, help="default 8080")
    parser.add_argument("--railml", type=Path, help="default: the railway scenario's file")
    parser.add_argument("--tile-url", dest="tile_url", help="Leaflet tile URL; empty: no tiles")
    parser.add_argument("--tile-attribution", dest="tile_attribution")
    parser.add_argument("--log-level", dest="log_level")
    add_security_arguments(parser)
    args = parser.parse_args(argv)
    overrides: dict[str, Any] = {k: v for k, v in vars(args).items() if v is not None}
    return MapServerSettings(**overrides)


def build_state(infrastructure: Infrastructure, settings: MapServerSettings) -> RunState:
    """A run state that knows the line (to place balises and a distance-only train)."""
    return RunState(
        track=infrastructure.model,
        balise_distances={b.code: b.distance_m for b in infrastructure.balises},
        max_readings=settings.max_readings,
    )


async def run(settings: MapServerSettings) -> None:
    """Serve until SIGTERM or SIGINT."""
    infrastructure = load_infrastructure(settings.railml)
    state = build_state(infrastructure, settings)
    feed = Feed(state, backlog=settings.client_backlog)
    server = ParticipantServer(
        MapParticipant(state),
        host=settings.grpc_host,
        port=settings.grpc_port,
        unix_socket=settings.socket,
        security=settings.security(),
        reflection=settings.reflection,
    )
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    runner = None
    try:
        await server.start()
        with listening(settings.http_host, settings.http_port, "the map (--http-port)"):
            runner, http_port = await start_site(
                create_app(feed, infrastructure, settings), settings.http_host, settings.http_port
            )
        url = f"http://{host_port(settings.http_host, http_port)}/"
        log.info(
            "mapserver_started",
            grpc=server.address,
            http=url,
            railml=str(settings.railml),
            tiles=settings.tile_url or "none",
        )
        print(f"mapserver: participant at {server.address}, map at {url}", flush=True)
        await stop.wait()
    finally:
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(sig)
        await server.stop()
        if runner is not None:
            await runner.cleanup()
        log.info("mapserver_stopped")


def main(argv: list[str] | None = None) -> None:
    settings = _parse(argv)
    configure_logging(settings.log_level, json=settings.log_json)
    try:
        run_participant(run(settings))
    except CouplerError as exc:
        raise SystemExit(f"mapserver: {exc}") from exc
    except (RailMLError, FileNotFoundError) as exc:
        log.error("mapserver_failed", problem=str(exc), railml=str(settings.railml))
        raise SystemExit(f"mapserver: {exc}") from exc
    except (OSError, RuntimeError) as exc:  # a port in use, most likely
        log.error("mapserver_failed", problem=str(exc))
        raise SystemExit(f"mapserver: {exc} (is another process using the port?)") from exc


if __name__ == "__main__":
    main()
