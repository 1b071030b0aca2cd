"""``python -m openrails_mock``: run the mock; options override ``OPENRAILS_MOCK_*``."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from pathlib import Path
from typing import Any

import structlog
from aiohttp import web
from pydantic import ValidationError

from coupler.errors import CouplerError
from coupler.ports import host_port, listening
from coupler.server import run

from .api import SERVER, create_app
from .config import MockConfig

log = structlog.get_logger("openrails_mock")


def _parse(argv: list[str] | None) -> MockConfig:
    parser = argparse.ArgumentParser(
        prog="openrails-mock", description="An OpenRails web API with train physics."
    )
    parser.add_argument("--host")
    parser.add_argument("--port", type=int, help="0 picks a free port (default 2150)")
    parser.add_argument("--mode", choices=["lockstep", "stock"])
    parser.add_argument("--step-ms", type=float, dest="step_ms")
    parser.add_argument("--speedup", type=float)
    parser.add_argument("--route", type=Path, help="OpenRails route folder (holds NAME.trk)")
    parser.add_argument("--path", type=Path, help="the train's path, e.g. PATHS/X.pat")
    parser.add_argument("--trains", type=Path, help="other trains (the client's trains config)")
    parser.add_argument("--railml", type=Path, help="railML file, exported to a route first")
    parser.add_argument("--loading-delay-s", type=float, dest="loading_delay_s")
    parser.add_argument("--start-time-s", type=float, dest="start_time_s")
    parser.add_argument(
        "--sensors",
        type=Path,
        help="sensor configuration: JSON list of {sensorName, sensorType, trainName, width, "
        "height, fov[, range]} (lockstep only)",
    )
    parser.add_argument("--camera-height", type=float, dest="camera_height_m")
    parser.add_argument("--camera-pitch", type=float, dest="camera_pitch_deg")
    parser.add_argument(
        "--no-reset",
        action="store_false",
        dest="reset",
        default=None,
        help="answer POST /API/RESET with 404, as OpenRails' builds do",
    )
    args = parser.parse_args(argv)
    overrides: dict[str, Any] = {k: v for k, v in vars(args).items() if v is not None}
    return MockConfig(**overrides)


async def _serve(config: MockConfig) -> None:
    app = create_app(config)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, config.host, config.port)
    try:
        with listening(config.host, config.port, "the OpenRails mock"):
            await site.start()
    except CouplerError:
        await runner.cleanup()
        raise
    port = runner.addresses[0][1]
    consist = app[SERVER].simulation.consist
    cameras = app[SERVER].cameras
    log.info(
        "openrails_mock.started",
        host=config.host,
        port=port,
        mode=config.mode,
        step_ms=config.step_ms,
        route=str(config.route) if config.route else None,
        path=str(config.path) if config.path else None,
        railml=str(config.railml) if config.railml else None,
        consist=consist.name,
        sensors=sorted(cameras.specs) if cameras else [],
    )
    print(f"openrails-mock listening on http://{host_port(config.host, port)}/API", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    try:
        await stop.wait()
    finally:
        await runner.cleanup()
        log.info("openrails_mock.stopped")


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        config = _parse(argv)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()
        )
        print(f"openrails-mock: error: invalid configuration: {problems}", file=sys.stderr)
        sys.exit(1)
    try:
        with contextlib.suppress(KeyboardInterrupt):
            run(_serve(config))  # on uvloop, as the participants
    except CouplerError as exc:  # a route, path or railML file the mock cannot use; a taken port
        print(f"openrails-mock: error: {exc}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
