"""OpenRails' web API over the simulation: routes under the case-sensitive prefix ``/API``.

Lockstep mode (OpenRails' build for simulation): GET /API/READY gates start-up, and each
POST /API/CABCONTROLS applies the controls, advances one fixed step and returns the trains.
Stock mode (upstream OpenRails): POST /API/CABCONTROLS takes a plain list and returns no body;
the simulation follows the wall clock times ``speedup``. POST /API/RESET (the mock's own
extension, both modes) puts the simulation back to the scenario's start. The JSON shapes are
the simulation build's (README: "Endpoints"). Every request the mock cannot take gets 400 with
``{"error": "..."}`` and leaves the simulation as it was.
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
import json
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from aiohttp import web

from coupler.errors import ScenarioError

from .conditions import clock_of
from .config import MAX_STEP_MS, MockConfig
from .objects import CommandError
from .renderer import Mount, ObjectLabel, Renderer, View
from .route import Route, StraightRoute, load_infrastructure_file
from .scene import Scene
from .sensors import Cameras, Rendered, Shot, load_sensors, sensor_names
from .simulation import (
    CONTROL_SPECS,
    ControlError,
    ControlPost,
    Simulation,
    Snapshot,
    TrackLocation,
    WorldPosition,
)
from .world import (
    SwitchError,
    TrackWorld,
    add_other_trains,
    apply_request,
    check_request,
    open_world,
    reset_world,
)

Clock = Callable[[], float]

DEFAULT_ROUTE_LENGTH_M = 20_000.0
"""Length of the straight route used when no railML file is configured."""

CONTROL_MODE = "EXPLORER"
"""OpenRails' TRAIN_CONTROL of a train driven freely, without path or signals."""


class BadRequest(Exception):
    """The request is malformed; answered with 400 and its message."""


class MockServer:
    """The state behind the handlers: the simulation, the mode and the clocks."""

    def __init__(
        self,
        config: MockConfig,
        simulation: Simulation,
        clock: Clock,
        world: TrackWorld | None = None,
        cameras: Cameras | None = None,
    ) -> None:
        self.config = config
        self.simulation = simulation
        self.world = world
        """The route folder's track, junctions and objects; None on the straight route."""
        self.clock = clock
        self.cameras = cameras
        """The configured camera and depth sensors (None: none)."""
        self.ready_at = math.inf
        self.last_wall_s = 0.0
        self.conditions = config.build_conditions()
        """The world's conditions as the mock was started with them (a reset without an
        environment goes back to them)."""
        self.start_time_s = config.start_time_s
        self.environment: dict[str, Any] = {}
        """The environment of the current run, as the last reset gave it."""
        if cameras is not None:
            cameras.set_conditions(self.conditions)

    def shot(self) -> Shot:
        """What the cameras see now."""
        simulation = self.simulation
        return Shot(
            simulation.front_distance_m,
            View(
                elapsed_s=simulation.elapsed_s,
                clock_s=simulation.clock_time_s,
                speed_mps=abs(simulation.dynamics.state.speed_mps),
            ),
        )

    def start_run(self, environment: Mapping[str, Any]) -> None:
        """The conditions and start time of a run: the start's, changed by ``environment``
        (condition names, and ``time``: HH:MM or seconds; setting the time makes the sun
        follow the clock unless ``light`` is given). Checked whole before anything changes;
        ScenarioError naming the key."""
        changes = dict(environment)
        start_time = self.start_time_s
        if "time" in changes:
            start_time = clock_of(changes.pop("time"), "Environment.time")
            changes.setdefault("light", "sun")
        conditions = self.conditions.updated(changes, source="Environment")
        self.simulation.set_start_time(start_time)
        self.environment = dict(environment)
        if self.cameras is not None:
            self.cameras.set_conditions(conditions)

    def start(self) -> None:
        """Start the loading phase and the wall clock."""
        now = self.clock()
        self.ready_at = now + self.config.loading_delay_s
        self.last_wall_s = now

    @property
    def ready(self) -> bool:
        return self.clock() >= self.ready_at

    def catch_up(self) -> None:
        """Stock mode: advance the simulation by the wall time since the last request."""
        now = self.clock()
        dt = (now - self.last_wall_s) * self.config.speedup
        self.last_wall_s = now
        if dt > 0.0:
            self.simulation.advance(dt)


SERVER = web.AppKey("server", MockServer)


def create_app(
    config: MockConfig, *, route: Route | None = None, clock: Clock = time.monotonic
) -> web.Application:
    """The mock's aiohttp application.

    The track is the route folder ``config.route`` with the path ``config.path``, or the
    railML file ``config.railml`` exported to a route folder first, or a straight line.
    ``route`` replaces all of them (tests use small routes); ``clock`` (monotonic seconds)
    drives the loading delay and stock mode's wall-clock pacing.
    """
    world = None
    if route is None:
        if config.route is not None or config.railml is not None:
            world = open_world(
                config.route, railml=config.railml, path=config.path, trains=config.trains
            )
            route = world.route(world.player)
        else:
            route = StraightRoute(length_m=DEFAULT_ROUTE_LENGTH_M)
    simulation = Simulation(
        consist=config.build_consist(),
        route=route,
        start_time_s=config.start_time_s,
        start_distance_m=config.start_distance_m,
        train_name=config.train_name,
        origin_tile=(config.origin_tile_x, config.origin_tile_z),
        track_nodes_reversed=config.track_nodes_reversed,
    )
    if world is not None:
        add_other_trains(world, simulation)
    server = MockServer(config, simulation, clock, world, _cameras(config, route))
    app = web.Application(middlewares=[_errors, _pacing])
    app[SERVER] = server

    async def on_startup(app: web.Application) -> None:
        cameras = app[SERVER].cameras
        if cameras is not None:  # before serving: READY means frames come at once
            await asyncio.to_thread(cameras.warm)
        app[SERVER].start()

    app.on_startup.append(on_startup)
    if config.mode == "lockstep":
        app.router.add_get("/API/READY", ready)
        app.router.add_post("/API/CABCONTROLS", post_cabcontrols_lockstep)
    else:
        app.router.add_post("/API/CABCONTROLS", post_cabcontrols_stock)
    if config.reset:
        app.router.add_post("/API/RESET", post_reset)
    app.router.add_get("/API/CABCONTROLS", get_cabcontrols)
    app.router.add_get("/API/TIME", get_time)
    app.router.add_get("/API/MAP", get_map)
    app.router.add_get("/API/MAP/INIT", get_map_init)
    app.router.add_get("/API/TRAININFO", get_traininfo)
    app.router.add_get("/API/TRAINDRIVINGDISPLAY", get_traindrivingdisplay)
    app.router.add_get("/API/OBJECTS", get_objects)
    app.router.add_get("/API/CAMERASENSOR/{name}", get_camerasensor)
    app.router.add_get("/API/CAMERASENSOR/{name}/LABELS", get_camerasensor_labels)
    app.router.add_get("/API/ENVIRONMENT", get_environment)
    return app


def _cameras(config: MockConfig, route: Route) -> Cameras | None:
    """The configured sensors. With a railML file (``--railml``) they see its balises, signals
    and platform edges on its track; on a route folder alone, the bare track of the train's
    path."""
    if config.sensors is None:
        return None
    specs = load_sensors(config.sensors, train_name=config.train_name)
    if specs and config.mode != "lockstep":
        raise ScenarioError(
            f"{config.sensors}: camera sensors are a feature of OpenRails' build for "
            f"simulation: run the mock with --mode lockstep, or without --sensors"
        )
    if config.railml is not None:
        scene = Scene.of_infrastructure(load_infrastructure_file(config.railml))
    else:
        scene = Scene(route)
    mount = Mount(height_m=config.camera_height_m, pitch_deg=config.camera_pitch_deg)
    renderer = Renderer(scene, mount, config.build_conditions(), threads=config.render_threads)
    return Cameras(specs, renderer)


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)


@web.middleware
async def _errors(request: web.Request, handler: Any) -> web.StreamResponse:
    """Translate the mock's errors into JSON answers, in this one place."""
    try:
        response: web.StreamResponse = await handler(request)
    except (BadRequest, ControlError, SwitchError, CommandError) as exc:
        return _error(400, str(exc))
    return response


@web.middleware
async def _pacing(request: web.Request, handler: Any) -> web.StreamResponse:
    """Lockstep: 425 while the route loads. Stock: bring the simulation up to the wall clock."""
    server = request.app[SERVER]
    if server.config.mode == "lockstep":
        if request.path != "/API/READY" and request.path.startswith("/API/") and not server.ready:
            return _error(425, "the route is still loading; poll GET /API/READY until 200")
    else:
        server.catch_up()
    response: web.StreamResponse = await handler(request)
    return response


async def ready(request: web.Request) -> web.Response:
    """200 once the route is loaded, 425 (Too Early) before; no body."""
    return web.Response(status=200 if request.app[SERVER].ready else 425)


async def post_cabcontrols_lockstep(request: web.Request) -> web.Response:
    """Apply ``Controls``, advance one step, return the trains."""
    server = request.app[SERVER]
    body = await _json_body(request)
    if not isinstance(body, dict):
        raise BadRequest(
            'the body must be an object {"Controls": [...], "Commands": [], '
            '"SwitchCommands": {}} in lockstep mode'
        )
    controls = body.get("Controls")
    if not isinstance(controls, list):
        raise BadRequest('"Controls" must be a list of {LocomotiveName, TypeName, Value}')
    world = check_request(server.world, body.get("SwitchCommands", {}), body.get("Commands", []))
    step_ms = body.get("StepMs", server.config.step_ms)
    if not _is_number(step_ms) or not 0.0 < step_ms <= MAX_STEP_MS:
        raise BadRequest(f'"StepMs" must be a number in (0, {MAX_STEP_MS:g}], got {step_ms!r}')
    posts = [_control_post(item, with_locomotive=True) for item in controls]
    simulation = server.simulation
    simulation.apply(posts)
    apply_request(server.world, simulation, world)
    simulation.advance(float(step_ms) / 1000.0)
    return web.json_response(_state(server))


async def post_reset(request: web.Request) -> web.Response:
    """A mock extension: back to the scenario's initial state; answers like a step would.

    The body is empty or ``{}``. In stock mode the wall clock restarts from now.
    """
    server = request.app[SERVER]
    text = await request.text()
    body = await _json_body(request) if text.strip() else {}
    if not isinstance(body, dict) or set(body) - {"Environment"}:
        raise BadRequest(
            'POST /API/RESET takes no body, {} or {"Environment": {...}} (the run\'s time and '
            "conditions)"
        )
    environment = body.get("Environment", {})
    if not isinstance(environment, dict):
        raise BadRequest('"Environment" must be an object of conditions, e.g. {"weather": "snow"}')
    try:
        server.start_run(environment)
    except ScenarioError as exc:
        raise BadRequest(str(exc)) from None
    reset_world(server.world, server.simulation)
    server.last_wall_s = server.clock()
    return web.json_response(_state(server))


async def post_cabcontrols_stock(request: web.Request) -> web.Response:
    """Apply a plain list of controls; the simulation runs on by itself. No body."""
    body = await _json_body(request)
    if not isinstance(body, list):
        raise BadRequest("the body must be a list of {TypeName, ControlIndex, Value} in stock mode")
    posts = [_control_post(item, with_locomotive=False) for item in body]
    request.app[SERVER].simulation.apply(posts)
    return web.Response(status=200)


async def get_cabcontrols(request: web.Request) -> web.Response:
    simulation = request.app[SERVER].simulation
    return web.json_response(
        [
            {
                "TypeName": spec.type_name,
                "MinValue": spec.min_value,
                "MaxValue": spec.max_value,
                "RangeFraction": simulation.range_fraction(spec.type_name),
            }
            for spec in CONTROL_SPECS.values()
        ]
    )


async def get_time(request: web.Request) -> web.Response:
    return web.json_response(request.app[SERVER].simulation.clock_time_s)


async def get_map(request: web.Request) -> web.Response:
    snap = request.app[SERVER].simulation.snapshot()
    return web.json_response(
        {
            "LatLon": {"Lat": snap.latitude_deg, "Lon": snap.longitude_deg},
            "DirectionDeg": snap.heading_deg,
        }
    )


TYPE_OF_LOCOMOTIVE = "diesel"
"""MAP/INIT's locomotive type (steam, diesel or electric); the mock's consists are diesel."""
MAP_POINT_SPACING_M = 50.0
"""Largest distance between two track points of MAP/INIT."""
TRACK_POINT = 0
"""OpenRails' ``TypeOfPointOnApiMap.Track``, serialized as its number."""


async def get_map_init(request: web.Request) -> web.Response:
    """The route as points and lines in lat/lon, with its bounds (OpenRails' ``InfoApiMap``)."""
    route = request.app[SERVER].simulation.route
    distances: list[float] = []
    for section in route.sections:
        count = max(1, math.ceil(section.length / MAP_POINT_SPACING_M))
        step = section.length / count
        distances += [section.start_distance + i * step for i in range(count)]
    distances.append(route.length)
    latlons = [
        {"Lat": p.latitude_deg, "Lon": p.longitude_deg} for p in map(route.position, distances)
    ]
    # OpenRails puts track points first in the list, each before the one added earlier
    points = [
        {"LatLon": ll, "Color": "red", "TypeOfPointOnApiMap": TRACK_POINT, "Name": "track"}
        for ll in reversed(latlons)
    ]
    lines = [{"LatLonFrom": a, "LatLonTo": b} for a, b in itertools.pairwise(latlons)]
    return web.json_response(
        {
            "TypeOfLocomotive": TYPE_OF_LOCOMOTIVE,
            "PointOnApiMapList": points,
            "LineOnApiMapList": lines,
            "LatMin": min(ll["Lat"] for ll in latlons),
            "LatMax": max(ll["Lat"] for ll in latlons),
            "LonMin": min(ll["Lon"] for ll in latlons),
            "LonMax": max(ll["Lon"] for ll in latlons),
        }
    )


async def get_objects(request: web.Request) -> web.Response:
    """A mock extension: the route's movable (animated) world objects and where they stand."""
    world = request.app[SERVER].world
    return web.json_response(world.objects.listing() if world is not None else [])


async def get_camerasensor(request: web.Request) -> web.StreamResponse:
    """The current frame of a sensor, raw: RGB bytes, or (class/id, distance, intensity) as
    little-endian uint16 per pixel; rows top to bottom."""
    server = request.app[SERVER]
    name = request.match_info["name"]
    cameras = server.cameras
    if cameras is None or name not in cameras.specs:
        configured = sensor_names(list(cameras.specs.values())) if cameras else "none"
        return _error(
            404,
            f"No camera sensor named {name} found (configured: {configured}; "
            f"OPENRAILS_MOCK_SENSORS / --sensors)",
        )
    rendered = await _rendered(server, cameras, name)
    return await _send_frame(request, rendered.data)


async def _rendered(server: MockServer, cameras: Cameras, name: str) -> Rendered:
    shot = server.shot()
    rendered = cameras.cached(name, shot)  # a standing train's frame: no thread hop
    if rendered is None:
        rendered = await asyncio.to_thread(cameras.frame, name, shot)
    return rendered


async def get_camerasensor_labels(request: web.Request) -> web.StreamResponse:
    """A mock extension: the ground truth of a colour sensor's current frame (the same
    render as GET /API/CAMERASENSOR/<name>): every balise, signal and platform edge in view."""
    server = request.app[SERVER]
    name = request.match_info["name"]
    cameras = server.cameras
    if cameras is None or name not in cameras.specs:
        configured = sensor_names(list(cameras.specs.values())) if cameras else "none"
        return _error(404, f"No camera sensor named {name} found (configured: {configured})")
    spec = cameras.specs[name]
    if spec.type != "rgb":
        return _error(404, f"sensor {name} is a {spec.type} sensor: labels are served for rgb")
    rendered = await _rendered(server, cameras, name)
    return web.json_response(
        {
            "sensor": name,
            "width": spec.width,
            "height": spec.height,
            "exposureMs": rendered.exposure_ms,
            "gain": rendered.gain,
            "objects": [_label(label) for label in rendered.labels],
        }
    )


def _label(label: ObjectLabel) -> dict[str, Any]:
    return {
        "class": label.kind,
        "id": label.id,
        "name": label.name,
        "box": list(label.box),
        "pixels": label.pixels,
        "unoccludedPixels": label.unoccluded_pixels,
        "snowPixels": label.snow_pixels,
        "distanceAlong": label.distance_along_m,
        "distance": label.distance_m,
        "transmittance": label.transmittance,
        "visibleFraction": label.visible_fraction,
    }


async def get_environment(request: web.Request) -> web.Response:
    """A mock extension: the world's time and conditions now."""
    server = request.app[SERVER]
    conditions = server.cameras.renderer.conditions if server.cameras else server.conditions
    return web.json_response(
        {
            "time": server.simulation.clock_time_s,
            "conditions": dataclasses.asdict(conditions),
            "environment": server.environment,
        }
    )


async def _send_frame(request: web.Request, data: bytes) -> web.StreamResponse:
    """``data`` as the body of a 200 ``application/octet-stream`` answer, the same bytes on
    the wire as ``web.Response(body=data)`` sends; but the headers go first, on their own, so
    that the frame is handed to the socket as it is: aiohttp (on Python before 3.12.9) joins
    headers and body into one new bytes object, a copy of the whole frame per request."""
    response = web.StreamResponse(headers={"Content-Type": "application/octet-stream"})
    response.content_length = len(data)
    await response.prepare(request)
    await response.write(b"")  # the headers alone
    await response.write(data)
    await response.write_eof()
    return response


async def get_traininfo(request: web.Request) -> web.Response:
    return web.json_response({"ControlMode": CONTROL_MODE})


ABBREVIATIONS = {
    "Time": "TIME",
    "Speed": "SPED",
    "Gradient": "GRAD",
    "Direction": "DIRC",
    "Throttle": "THRO",
    "Train brake": "BTRN",
    "Dynamic brake": "BDYN",
}
"""OpenRails' short labels, used unless ``?normalText=true``."""


async def get_traindrivingdisplay(request: web.Request) -> web.Response:
    raw = request.query.get("normalText", "false").lower()
    if raw not in ("true", "false"):
        raise BadRequest(f"normalText must be true or false, got {raw!r}")
    normal = raw == "true"
    snap = request.app[SERVER].simulation.snapshot()
    c = snap.controls
    t = int(snap.clock_time_s)
    rows: list[tuple[str, str]] = [
        ("Time", f"{t // 3600:02d}:{t % 3600 // 60:02d}:{t % 60:02d}"),
        ("Speed", f"{abs(snap.state.speed_mps) * 3.6:.1f} km/h"),
    ]
    if normal:
        rows.append(("Gradient", f"{snap.gradient_per_mille / 10.0:.1f}%"))
    rows += [
        ("Sprtr", ""),
        ("Direction", {1: "Forward", 0: "N", -1: "Reverse"}[c.direction]),
        ("Throttle", f"{c.throttle * 100:.0f}%"),
        ("Train brake", f"{c.train_brake * 100:.0f}%"),
        ("Dynamic brake", f"{c.dynamic_brake * 100:.0f}%" if c.dynamic_brake > 0 else "Off"),
    ]
    return web.json_response(
        [
            {
                "FirstCol": first if normal else ABBREVIATIONS.get(first, first),
                "LastCol": last,
                "SymbolCol": "",
                "KeyPressed": "",
            }
            for first, last in rows
        ]
    )


async def _json_body(request: web.Request) -> Any:
    text = await request.text()
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise BadRequest(f"the body is not valid JSON: {exc}") from None


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _control_post(item: object, *, with_locomotive: bool) -> ControlPost:
    if not isinstance(item, dict):
        raise BadRequest(f"each control must be an object with TypeName and Value, got {item!r}")
    type_name = item.get("TypeName")
    if not isinstance(type_name, str):
        raise BadRequest(f"TypeName must be a string, got {type_name!r}")
    value = item.get("Value")
    if not _is_number(value):
        raise BadRequest(f"{type_name} Value must be a number, got {value!r}")
    index = item.get("ControlIndex", 0)
    if not isinstance(index, int) or isinstance(index, bool):
        raise BadRequest(f"{type_name} ControlIndex must be an integer, got {index!r}")
    locomotive = item.get("LocomotiveName") if with_locomotive else None
    if locomotive is not None and not isinstance(locomotive, str):
        raise BadRequest(f"LocomotiveName must be a string, got {locomotive!r}")
    assert isinstance(value, int | float)
    return ControlPost(
        type_name=type_name,
        value=float(value),
        control_index=index,
        locomotive_name=locomotive,
    )


def _track_location(loc: TrackLocation) -> dict[str, float | int | str]:
    return {
        "trackNodeIndex": loc.track_node_index,
        "trackNodeLength": loc.track_node_length,
        "trackNodeOffset": loc.track_node_offset,
        "trackVectorSectionIndex": loc.track_vector_section_index,
        "movementDirection": loc.movement_direction,
    }


def _world(position: WorldPosition) -> dict[str, float | int]:
    return {
        "tileX": position.tile_x,
        "tileZ": position.tile_z,
        "x": position.x,
        "y": position.y,
        "z": position.z,
    }


def _state(server: MockServer) -> dict[str, Any]:
    """The lockstep reply: every train and the camera sensors."""
    simulation = server.simulation
    trains = {simulation.train_name: _train(simulation.snapshot())}
    trains.update({name: _train(other.snapshot()) for name, other in simulation.others.items()})
    return {
        "trains": trains,
        "CameraSensors": server.cameras.descriptions() if server.cameras else {},
    }


def _train(snap: Snapshot) -> dict[str, Any]:
    return {
        "location": _world(snap.lead),
        "trackLocation": _track_location(snap.front),
        "rearTrackLocation": _track_location(snap.rear),
        # the front's Traveller.Rotation.Y: the compass heading it faces, wrapped to +-pi
        "rotation": math.remainder(math.radians(snap.heading_deg), math.tau),
        "locomotiveState": {
            "v": snap.state.speed_mps,
            "a": snap.state.acceleration_mps2,
            "distance": snap.state.odometer_m,
            "wheelslip": False,
            "wheelskid": False,
        },
        "trainLength": {"length": snap.length_m},
        "carPositions": {"Front": _world(snap.first_car), "Rear": _world(snap.last_car)},
    }
