"""The simulated world: time of day, the player's train on its route, and the driver's controls.

Other trains (a route folder's trains config) are simulations of their own, advanced with the
player's and addressed by their ``LocomotiveName``. A route that knows OpenRails' track
database (:class:`~openrails_mock.trackroute.TrackRoute`) gives the track location and world
position; any other route gives them from its sections and local frame (see the README).

Errors::

    CouplerError (coupler.errors)
    └── ControlError     a posted control is unknown, for an unknown train, or out of range;
                         nothing was applied
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from coupler.errors import CouplerError

from .physics import Consist, Controls, TrainDynamics, TrainState
from .route import Route

SECONDS_PER_DAY = 86400.0
TILE_SIZE_M = 2048.0
"""Side of an OpenRails (MSTS) world tile; positions are a tile and an offset from its centre."""
ELEVATION_SPACING_M = 10.0
"""Spacing of the samples of the elevation profile integrated from the gradient."""


class ControlError(CouplerError):
    """A posted control cannot be applied; the simulation is unchanged."""


@dataclass(frozen=True)
class ControlSpec:
    """A cab control the mock's train has, as listed by GET /API/CABCONTROLS."""

    type_name: str
    min_value: float
    max_value: float


CONTROL_SPECS: dict[str, ControlSpec] = {
    spec.type_name: spec
    for spec in (
        ControlSpec("THROTTLE", 0.0, 1.0),
        ControlSpec("TRAIN_BRAKE", 0.0, 1.0),
        ControlSpec("DYNAMIC_BRAKE", 0.0, 1.0),
        ControlSpec("DIRECTION", -1.0, 1.0),
        ControlSpec("REGULATOR", 0.0, 1.0),
    )
}
"""REGULATOR (a steam engine's throttle) drives the same traction as THROTTLE."""


@dataclass(frozen=True, kw_only=True)
class ControlPost:
    """One control setting as posted, before validation against the train."""

    type_name: str
    value: float
    control_index: int = 0
    locomotive_name: str | None = None


TravellerDirection = Literal["Forward", "Backward"]
"""OpenRails' ``Traveller.TravellerDirection``: the way the train faces along a track node."""


@dataclass(frozen=True, kw_only=True)
class TrackLocation:
    """A route distance in OpenRails' track terms (see the README for the mapping)."""

    track_node_index: int
    track_node_length: float
    track_node_offset: float
    """Distance into the node, counted in the direction the train faces."""
    track_vector_section_index: int
    movement_direction: TravellerDirection


@dataclass(frozen=True, kw_only=True)
class WorldPosition:
    """A point in OpenRails' world frame: 2048 m tiles, x east, y up, z north within a tile."""

    tile_x: int
    tile_z: int
    x: float
    y: float
    z: float


@dataclass(frozen=True, kw_only=True)
class Snapshot:
    """Everything the API reports about the train at one instant."""

    clock_time_s: float
    state: TrainState
    controls: Controls
    front: TrackLocation
    rear: TrackLocation
    latitude_deg: float
    longitude_deg: float
    heading_deg: float
    """Compass heading the train faces (towards increasing route distance)."""
    lead: WorldPosition
    """Centre of the lead locomotive (the first car)."""
    first_car: WorldPosition
    last_car: WorldPosition
    gradient_per_mille: float
    length_m: float


class Simulation:
    """One train on one route; ``advance`` moves time on, ``apply`` changes the controls,
    ``reset`` puts everything back where the scenario starts."""

    def __init__(
        self,
        *,
        consist: Consist,
        route: Route,
        start_time_s: float = 8 * 3600.0,
        start_distance_m: float | None = None,
        train_name: str = "PLAYER",
        origin_tile: tuple[int, int] = (0, 0),
        track_nodes_reversed: bool = False,
    ) -> None:
        if route.length - getattr(route, "begin", 0.0) < consist.length_m:
            raise ValueError(
                f"the route ({route.length - getattr(route, 'begin', 0.0):.1f} m) is shorter "
                "than the train "
                f"({consist.length_m:.1f} m)"
            )
        self.route = route
        self.consist = consist
        self.train_name = train_name
        self.start_time_s = start_time_s
        self.origin_tile = origin_tile
        self.facing: TravellerDirection = "Backward" if track_nodes_reversed else "Forward"
        self._start_time_s = start_time_s
        self._start_position_m = consist.length_m if start_distance_m is None else start_distance_m
        self._elevation = _ElevationProfile(route)
        self.others: dict[str, Simulation] = {}
        """Other trains by name, advanced with this one (a route folder's trains config)."""
        self.reset()

    def reset(self) -> None:
        """Back to the scenario's initial state: start time and place, standstill, controls
        at rest (reverser forward), odometer 0."""
        self.elapsed_s = 0.0
        self.controls = Controls()
        self.dynamics = TrainDynamics(
            self.consist,
            self.route.gradient,
            position_m=self._start_position_m,
            min_position_m=getattr(self.route, "begin", 0.0) + self.consist.length_m,
            max_position_m=self.route.length,
        )
        for other in self.others.values():
            other.reset()

    def set_start_time(self, start_time_s: float) -> None:
        """The time of day the scenario starts at (every train's clock; takes effect now)."""
        self._start_time_s = start_time_s
        for other in self.others.values():
            other.set_start_time(start_time_s)

    def follow_route(self) -> None:
        """The route changed beyond the train (a junction was thrown): new buffer stops."""
        self.dynamics.set_limits(
            getattr(self.route, "begin", 0.0) + self.consist.length_m, self.route.length
        )

    @property
    def front_distance_m(self) -> float:
        """Route distance of the train's front: where its cameras are."""
        return self.dynamics.state.position_m

    @property
    def clock_time_s(self) -> float:
        """Time of day, seconds since midnight."""
        return (self._start_time_s + self.elapsed_s) % SECONDS_PER_DAY

    def apply(self, posts: Iterable[ControlPost]) -> None:
        """Set the posted controls, all or none: any bad one raises ControlError. A post
        naming another train's locomotive goes to that train."""
        trains = {self.train_name: self, **self.others}
        controls = {name: train.controls for name, train in trains.items()}
        for post in posts:
            name = self.train_name if post.locomotive_name is None else post.locomotive_name
            if name not in trains:
                raise ControlError(
                    f"unknown locomotive {name!r}: this simulation has the train"
                    f"{'s' if len(trains) > 1 else ''} {', '.join(map(repr, trains))}"
                )
            controls[name] = trains[name]._applied(controls[name], post)
        for name, train in trains.items():
            train.controls = controls[name]

    def advance(self, dt_s: float) -> None:
        """Move the simulation on by dt_s seconds with the current controls."""
        self.dynamics.step(dt_s, self.controls)
        self.elapsed_s += dt_s
        for other in self.others.values():
            other.advance(dt_s)

    def range_fraction(self, type_name: str) -> float:
        """Where a control stands in its range, 0..1."""
        spec = CONTROL_SPECS[type_name]
        value = {
            "THROTTLE": self.controls.throttle,
            "REGULATOR": self.controls.throttle,
            "TRAIN_BRAKE": self.controls.train_brake,
            "DYNAMIC_BRAKE": self.controls.dynamic_brake,
            "DIRECTION": float(self.controls.direction),
        }[type_name]
        return (value - spec.min_value) / (spec.max_value - spec.min_value)

    def snapshot(self) -> Snapshot:
        """The train's state in the API's terms."""
        state = self.dynamics.state
        front = state.position_m
        length = self.consist.length_m
        rear = front - length
        car = length / self.consist.car_count
        point = self.route.position(front)
        return Snapshot(
            clock_time_s=self.clock_time_s,
            state=state,
            controls=self.controls,
            front=self._track_location(front),
            rear=self._track_location(rear),
            latitude_deg=point.latitude_deg,
            longitude_deg=point.longitude_deg,
            heading_deg=point.heading_deg,
            lead=self._world(front - car / 2.0),
            first_car=self._world(front - car / 2.0),
            last_car=self._world(rear + car / 2.0),
            gradient_per_mille=self.route.gradient(front - length / 2.0),
            length_m=length,
        )

    def _track_location(self, distance: float) -> TrackLocation:
        located = getattr(self.route, "track_location", None)
        if located is not None:  # a route on OpenRails' track database reports it itself
            location: TrackLocation = located(distance)
            return location
        index, offset = self.route.locate(distance)
        # The train faces increasing route distance; on a node laid the other way it faces
        # "Backward", and OpenRails counts the offset from the node's far end, which is again
        # the distance from the node's end the train came in at: the same number.
        return TrackLocation(
            track_node_index=index + 1,
            track_node_length=self.route.sections[index].length,
            track_node_offset=offset,
            track_vector_section_index=0,
            movement_direction=self.facing,
        )

    def _world(self, distance: float) -> WorldPosition:
        """The route point at ``distance`` in tiles; the local frame's origin is the centre of
        ``origin_tile``."""
        placed = getattr(self.route, "world_position", None)
        if placed is not None:  # a route on OpenRails' track database knows its world
            position: WorldPosition = placed(distance)
            return position
        point = self.route.position(distance)
        east = self.origin_tile[0] * TILE_SIZE_M + point.x_m
        north = self.origin_tile[1] * TILE_SIZE_M + point.y_m
        tile_x = math.floor(east / TILE_SIZE_M + 0.5)
        tile_z = math.floor(north / TILE_SIZE_M + 0.5)
        return WorldPosition(
            tile_x=tile_x,
            tile_z=tile_z,
            x=east - tile_x * TILE_SIZE_M,
            y=self._elevation.at(distance),
            z=north - tile_z * TILE_SIZE_M,
        )

    def _applied(self, controls: Controls, post: ControlPost) -> Controls:
        spec = CONTROL_SPECS.get(post.type_name)
        if spec is None:
            raise ControlError(
                f"unknown TypeName {post.type_name!r}; known: {', '.join(CONTROL_SPECS)}"
            )
        value = post.value
        if not math.isfinite(value) or not spec.min_value <= value <= spec.max_value:
            raise ControlError(
                f"{spec.type_name} value {value!r} is out of range "
                f"[{spec.min_value:g}, {spec.max_value:g}]"
            )
        if spec.type_name in ("THROTTLE", "REGULATOR"):
            return dataclasses.replace(controls, throttle=value)
        if spec.type_name == "TRAIN_BRAKE":
            return dataclasses.replace(controls, train_brake=value)
        if spec.type_name == "DYNAMIC_BRAKE":
            return dataclasses.replace(controls, dynamic_brake=value)
        if value not in (-1.0, 0.0, 1.0):
            raise ControlError(
                f"DIRECTION must be 1 (forward), 0 (neutral) or -1 (reverse), got {value!r}"
            )
        return dataclasses.replace(controls, direction=int(value))


class _ElevationProfile:
    """Elevation relative to the route's start, integrated from the gradient."""

    def __init__(self, route: Route) -> None:
        if hasattr(route, "world_position"):  # heights come from the track database
            self._distances, self._heights = [0.0, 1.0], [0.0, 0.0]
            return
        count = max(1, math.ceil(route.length / ELEVATION_SPACING_M))
        spacing = route.length / count
        self._distances = [i * spacing for i in range(count + 1)]
        gradients = [route.gradient(d) for d in self._distances]
        self._heights = [0.0]
        for i in range(count):
            mean = (gradients[i] + gradients[i + 1]) / 2.0
            self._heights.append(self._heights[-1] + mean / 1000.0 * spacing)

    def at(self, distance: float) -> float:
        d = self._distances
        i = min(max(bisect.bisect_right(d, distance) - 1, 0), len(d) - 2)
        t = (distance - d[i]) / (d[i + 1] - d[i])
        return self._heights[i] + t * (self._heights[i + 1] - self._heights[i])
