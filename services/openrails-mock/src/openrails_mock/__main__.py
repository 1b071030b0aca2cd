"""``python -m openrails_mock``: run the mock; options override ``OPENRAILS_MOCK_*``.

It also takes OpenRails' own start command line, as OpenRails' simulation client launches
``RunActivity.exe`` (``openrails_interface/open_rails_server_interface.py``)::

    -start -syncsimulation "<route>\\PATHS\\<path>.pat" "<consist>" HH:MM <season 0-3>
        <weather 0-2> <step_ms> <trains.json> <sensors.json> port=<port>
    -start -explore "<route>\\PATHS\\<path>.pat" "<consist>" HH:MM <season> <weather> port=<port>

beside its own options (``--host``, ``--loading-delay-s``, ...): the synced form runs in
lockstep, the explore form in stock mode; the route folder is the part of the path before
``PATHS`` (backslashes or slashes), the consist a name holding one of the mock's presets
(``br642``), and the time of day makes the sun follow the clock (light ``sun``).
"""

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

from coupler.errors import CouplerError, ScenarioError
from coupler.ports import host_port, listening
from coupler.server import run

from .api import SERVER, create_app
from .conditions import clock_of
from .config import MockConfig
from .physics import PRESETS

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
    parser.add_argument(
        "--time", type=_clock, dest="start_time_s", help="time of day HH:MM (the sun follows)"
    )
    parser.add_argument("--season", help="spring, summer, autumn, winter (or 0-3)")
    parser.add_argument("--weather", help="clear, snow, rain (or 0-2)")
    parser.add_argument(
        "--environment", type=Path, help="JSON object of conditions (docs/railway-perception.md)"
    )
    parser.add_argument(
        "--condition",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="one condition, e.g. visibility_m=50 (repeatable)",
    )
    parser.add_argument("--consist-preset", dest="consist_preset")
    parser.add_argument("--camera-height", type=float, dest="camera_height_m")
    parser.add_argument("--camera-pitch", type=float, dest="camera_pitch_deg")
    parser.add_argument(
        "--render-threads",
        type=int,
        dest="render_threads",
        help="threads a frame is rendered on, 1 or 2 (default: 2 on two cores or more)",
    )
    parser.add_argument(
        "--no-reset",
        action="store_false",
        dest="reset",
        default=None,
        help="answer POST /API/RESET with 404, as OpenRails' builds do",
    )
    openrails: dict[str, Any] = {}
    arguments = list(sys.argv[1:] if argv is None else argv)
    if "-start" in arguments:
        openrails, arguments = _openrails_form(arguments)
    args = parser.parse_args(arguments)
    overrides: dict[str, Any] = {k: v for k, v in vars(args).items() if v is not None}
    conditions = {**openrails.pop("conditions", {}), **_pairs(overrides.pop("condition"))}
    if args.start_time_s is not None:
        conditions.setdefault("light", "sun")
    return MockConfig(**{**openrails, **overrides, "conditions": conditions})


def _clock(text: str) -> float:
    try:
        return clock_of(text, "--time")
    except ScenarioError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _pairs(items: list[str]) -> dict[str, str]:
    pairs = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ScenarioError(f"--condition {item!r}: write NAME=VALUE, e.g. visibility_m=50")
        pairs[key.strip()] = value.strip()
    return pairs


def _openrails_form(argv: list[str]) -> tuple[dict[str, Any], list[str]]:
    """OpenRails' start command line (the module docstring) as configuration, and the
    arguments that are the mock's own options."""
    rest = list(argv)
    rest.remove("-start")
    modes = [a for a in rest if a in ("-syncsimulation", "-explore")]
    if len(modes) != 1:
        raise ScenarioError(
            "OpenRails' command line: -start needs -syncsimulation or -explore, e.g. -start "
            '-syncsimulation "ROUTE\\PATHS\\1.pat" "CONSIST" 12:00 0 0 200 trains.json '
            "sensors.json port=2150"
        )
    rest.remove(modes[0])
    synced = modes[0] == "-syncsimulation"
    own: list[str] = []
    words: list[str] = []
    options = iter(rest)
    for item in options:
        if item.startswith("--"):
            own.append(item)
            if "=" not in item and item not in FLAGS:
                own.append(next(options, ""))
        elif item.startswith("port="):
            own += ["--port", item.removeprefix("port=")]
        else:
            words.append(item)
    wanted = 8 if synced else 5
    names = ["path", "consist", "HH:MM", "season", "weather", "step_ms", "trains", "sensors"]
    if len(words) != wanted:
        raise ScenarioError(
            f"OpenRails' command line ({modes[0]}): expected {', '.join(names[:wanted])} and "
            f"port=N, got {len(words)} arguments: {' '.join(words)}"
        )
    route, path = _route_and_path(words[0])
    config: dict[str, Any] = {
        "mode": "lockstep" if synced else "stock",
        "route": route,
        "path": path,
        "consist_preset": _preset(words[1]),
        "start_time_s": clock_of(words[2], "OpenRails' command line, HH:MM"),
        "season": words[3],
        "weather": words[4],
        "conditions": {"light": "sun"},
    }
    if synced:
        try:
            config["step_ms"] = float(words[5])
        except ValueError:
            raise ScenarioError(
                f"OpenRails' command line: step_ms must be a number, got {words[5]!r}"
            ) from None
        config["trains"] = Path(words[6])
        config["sensors"] = Path(words[7])
    return config, own


FLAGS = ("--no-reset",)
"""The mock's options that take no value."""


def _route_and_path(text: str) -> tuple[Path, Path]:
    """``<route>\\PATHS\\<n>.pat`` as the route folder and the path inside it."""
    parts = [p for p in text.replace("\\", "/").split("/")]
    upper = [p.upper() for p in parts]
    if "PATHS" not in upper or upper.index("PATHS") != len(parts) - 2:
        raise ScenarioError(
            f"OpenRails' command line: the path {text!r} is not <route>\\PATHS\\<name>.pat"
        )
    at = upper.index("PATHS")
    route = Path("/".join(parts[:at]) or ".")
    if not route.is_dir():
        raise ScenarioError(
            f"OpenRails' command line: the route folder {str(route)!r} (of {text!r}) does not "
            f"exist here; give the route's folder on this machine"
        )
    return route, Path("PATHS") / parts[-1]


def _preset(consist: str) -> str:
    """The mock's consist preset a consist name holds (``Dlr\\BR642.con``: ``br642``)."""
    plain = "".join(ch for ch in consist.lower() if ch.isalnum())
    for name in PRESETS:
        if name in plain:
            return name
    raise ScenarioError(
        f"OpenRails' command line: the consist {consist!r} is not one the mock models; it has "
        f"{', '.join(sorted(PRESETS))} (a consist whose name holds one of them)"
    )


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
    except ScenarioError as exc:
        print(f"openrails-mock: error: {exc}", file=sys.stderr)
        sys.exit(1)
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
