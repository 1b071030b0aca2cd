"""The mock's world on a route folder: the track network, its junctions, its objects, and the
trains' routes through it.

``open_world`` loads a route folder (or exports a railML file to one first) and resolves the
player's path and the other trains' paths (the public client's trains config: a JSON list of
``{"trainNumber", "trainName", "trainConfig", "trainPath"}``, ``trainPath`` naming
``PATHS/<trainPath>.pat``). At the start and on reset every junction a path runs through is set
the path's way (the player's last, so it wins); ``SwitchCommands`` then throw junctions by TDB
index, and every train's route is replanned beyond the track it stands on.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from coupler.errors import CouplerError, ScenarioError
from coupler_railway.openrails.config import read_json

from .objects import CommandError, Pose, WorldObjects
from .paths import TrainPath, load_path
from .routefolder import RouteFolder, load_route
from .simulation import Simulation
from .stf import RouteError, read_stf
from .tdb import TrackNetwork
from .trackroute import Geography, TrackRoute


class SwitchError(CouplerError):
    """A switch command names no junction or no route of it; nothing was applied."""


@dataclass(frozen=True)
class OtherTrain:
    """A train of the trains config besides the player."""

    name: str
    number: int
    consist: str
    path: TrainPath


@dataclass
class TrackWorld:
    """A loaded route folder with the paths of the trains on it."""

    folder: RouteFolder
    network: TrackNetwork
    geography: Geography
    objects: WorldObjects
    player: TrainPath
    others: list[OtherTrain] = field(default_factory=list)

    def initial_switches(self) -> dict[int, int]:
        settings: dict[int, int] = {i: 0 for i in self.network.selected}
        for other in self.others:
            settings.update(other.path.settings)
        settings.update(self.player.settings)
        return settings

    def reset(self) -> None:
        self.network.selected.update(self.initial_switches())
        self.objects.reset()

    def route(self, path: TrainPath) -> TrackRoute:
        return TrackRoute(self.network, path, self.geography)

    def check_switches(self, states: object) -> dict[int, int]:
        """``SwitchCommands`` as {junction index: route}; SwitchError when one is wrong."""
        if not isinstance(states, dict):
            raise SwitchError(
                f'"SwitchCommands" must be an object {{"<junction>": 0 or 1}}, got {states!r}'
            )
        parsed: dict[int, int] = {}
        junctions = self.folder.junctions
        for key, value in states.items():
            try:
                index = int(key)
            except (TypeError, ValueError):
                raise SwitchError(f"SwitchCommands key {key!r} is not a track node index") from None
            if index not in self.network.selected:
                listed = ", ".join(map(str, junctions)) or "none"
                raise SwitchError(
                    f"SwitchCommands: track node {index} is not a junction of "
                    f"{self.folder.tdb_file.name} (junctions: {listed})"
                )
            if value not in (0, 1) or isinstance(value, bool):
                raise SwitchError(
                    f"SwitchCommands: junction {index} takes route 0 or 1 (SelectedRoute), "
                    f"got {value!r}"
                )
            parsed[index] = int(value)
        return parsed


def _resolve_path(folder: Path, path: Path) -> Path:
    """A path given on the command line: as is, or relative to the route folder."""
    if path.is_file():
        return path
    inside = folder / path
    if inside.is_file():
        return inside
    paths = folder / "PATHS"
    known = sorted(p.name for p in paths.glob("*.pat")) if paths.is_dir() else []
    fix = f"give --path one of PATHS/{{{', '.join(known)}}}" if known else "give a .pat file"
    raise RouteError(path, None, f"is no path file (nor {inside})", fix)


def _default_path(folder: RouteFolder) -> Path:
    """The first path (by name) that starts at the route's RouteStart."""
    tx, tz, x, z = folder.start
    for candidate in sorted((folder.folder / "PATHS").glob("*.pat")):
        first = read_stf(candidate).block("TrackPDPs").blocks("TrackPDP")
        if first:
            p = first[0]
            dx = (p.integer(0, "tile x") - tx) * 2048.0 + p.real(2, "x") - x
            dz = (p.integer(1, "tile z") - tz) * 2048.0 + p.real(4, "z") - z
            if dx * dx + dz * dz < 1.0:
                return candidate
    raise RouteError(folder.folder, None, "has no path starting at RouteStart", "give --path")


def _load_trains(world_folder: RouteFolder, network: TrackNetwork, file: Path) -> list[OtherTrain]:
    config = read_json(file, what="trains config", setting="OPENRAILS_MOCK_TRAINS, --trains")
    if not isinstance(config, list):
        raise ScenarioError(f"{file}: the trains config must be a JSON list of trains")
    trains = []
    for n, entry in enumerate(config):
        if not isinstance(entry, dict) or not {"trainName", "trainPath"} <= entry.keys():
            raise ScenarioError(
                f"{file}: train {n} must be an object with trainNumber, trainName, trainConfig "
                "and trainPath"
            )
        pat = world_folder.folder / "PATHS" / f"{entry['trainPath']}.pat"
        if not pat.is_file():
            raise ScenarioError(
                f"{file}: train {entry['trainName']!r} runs on path {entry['trainPath']!r}, but "
                f"{pat} does not exist"
            )
        trains.append(
            OtherTrain(
                name=str(entry["trainName"]),
                number=int(entry.get("trainNumber", n + 1)),
                consist=str(entry.get("trainConfig", "")),
                path=load_path(network, pat),
            )
        )
    return trains


def open_world(
    route: Path | None,
    *,
    railml: Path | None = None,
    path: Path | None = None,
    trains: Path | None = None,
) -> TrackWorld:
    """Load the route folder ``route`` (or export ``railml`` to one first: the one exported
    before from the same file by the same exporter when the cache holds it)."""
    if route is None:
        if railml is None:
            raise ValueError("give a route folder or a railML file")
        cached = _cached_export(railml)
        if cached is not None:
            return _open(cached, path, trains, railml_mode=True)
        with tempfile.TemporaryDirectory(prefix="openrails-mock-") as tmp:
            exported = _export(railml, Path(tmp) / railml.stem.replace(" ", "_"))
            return _open(exported, path, trains, railml_mode=True)
    return _open(route, path, trains, railml_mode=False)


ROUTE_CACHE = "OPENRAILS_MOCK_ROUTE_CACHE"
"""The environment variable naming the folder of exported routes (empty: no cache)."""


def route_cache() -> Path | None:
    """Where exported routes are kept: ``$OPENRAILS_MOCK_ROUTE_CACHE``, else the user's cache
    folder (``$XDG_CACHE_HOME`` or ``~/.cache``) ``/coupler/openrails-mock-routes``."""
    named = os.environ.get(ROUTE_CACHE)
    if named is not None:
        return Path(named) if named else None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "coupler" / "openrails-mock-routes"


def _cached_export(railml: Path) -> Path | None:
    """``railml``'s route folder from the cache, exported into it first when missing; None
    when there is no cache to use (unset, not writable: the caller exports to a temporary
    folder). The key is the railML file's bytes and the exporter's own sources, so a changed
    file or a changed exporter exports anew; a folder appears whole (renamed into place) or
    not at all, and a cache folder is the user's alone (0700)."""
    root = route_cache()
    if root is None:
        return None
    import coupler_railway

    try:
        digest = hashlib.sha256(railml.read_bytes())
    except OSError:
        return None  # the export says what is wrong with the file
    for source in sorted(Path(coupler_railway.__file__).parent.rglob("*.py")):
        digest.update(source.read_bytes())
    folder = root / digest.hexdigest()[:32]
    route = folder / railml.stem.replace(" ", "_")
    if route.is_dir():
        return route
    try:
        root.mkdir(mode=0o700, parents=True, exist_ok=True)
        partial = Path(tempfile.mkdtemp(prefix=".partial-", dir=root))
    except OSError:
        return None
    try:
        _export(railml, partial / route.name)
        try:
            partial.rename(folder)
        except OSError:  # another mock put the same export there first
            if not route.is_dir():
                raise
    except OSError:
        return None
    finally:
        shutil.rmtree(partial, ignore_errors=True)
    return route


def _export(railml: Path, out: Path) -> Path:
    from coupler_railway import RailMLError
    from coupler_railway.openrails.export import ExportError, export_route

    try:
        export_route(railml, out, terrain=False)  # the mock never opens the terrain
    except (OSError, RailMLError, ExportError) as exc:
        raise ScenarioError(
            f"cannot use {railml} as the route (OPENRAILS_MOCK_RAILML): {exc}"
        ) from exc
    return out


def _open(
    folder_path: Path, path: Path | None, trains: Path | None, *, railml_mode: bool
) -> TrackWorld:
    folder = load_route(folder_path)
    network = TrackNetwork(folder)
    if path is None:
        if not railml_mode:
            known = sorted(p.name for p in (folder.folder / "PATHS").glob("*.pat"))
            raise RouteError(
                folder.folder,
                None,
                "needs a path for the train",
                f"give --path PATHS/<name>.pat ({', '.join(known) or 'the route has none'})",
            )
        pat = _default_path(folder)
    else:
        pat = _resolve_path(folder.folder, path)
    player = load_path(network, pat)
    others = _load_trains(folder, network, trains) if trains is not None else []
    world = TrackWorld(
        folder=folder,
        network=network,
        geography=Geography(folder.start),
        objects=WorldObjects(folder.objects),
        player=player,
        others=others,
    )
    world.reset()
    return world


def trains_of(simulation: Simulation) -> list[Simulation]:
    """The player's simulation and the other trains'."""
    return [simulation, *simulation.others.values()]


def place_trains(world: TrackWorld, simulation: Simulation) -> None:
    """Every train on a fresh route from its path's start (at start-up and on reset)."""
    simulation.route = world.route(world.player)
    for other in world.others:
        simulation.others[other.name].route = world.route(other.path)


def add_other_trains(world: TrackWorld, simulation: Simulation) -> None:
    """A simulation for each train of the trains config, next to the player's."""
    for other in world.others:
        if other.name == simulation.train_name or other.name in simulation.others:
            raise ScenarioError(f"the trains config names train {other.name!r} twice")
        try:
            simulation.others[other.name] = Simulation(
                consist=simulation.consist,
                route=world.route(other.path),
                start_time_s=simulation.start_time_s,
                train_name=other.name,
            )
        except ValueError as exc:
            raise ScenarioError(f"train {other.name!r} on {other.path.file}: {exc}") from exc


@dataclass(frozen=True)
class WorldRequest:
    """The world part of a lockstep request, checked: switches to set, objects to move."""

    switches: dict[int, int]
    moves: list[tuple[tuple[int, int, int], Pose]]


def check_request(world: TrackWorld | None, switches: object, commands: object) -> WorldRequest:
    """``SwitchCommands`` and ``Commands`` of a lockstep request; SwitchError or CommandError
    (nothing applied) when one is wrong."""
    if not isinstance(commands, list):
        raise CommandError(f'"Commands" must be a list of world commands, got {commands!r}')
    if world is None:
        if switches:
            raise SwitchError(
                "SwitchCommands: the straight route has no junctions (start the mock on a route "
                "folder: --route ROUTE --path PATHS/X.pat)"
            )
        if commands:
            raise CommandError(
                "Commands: the straight route has no world objects (start the mock on a route "
                "folder: --route ROUTE --path PATHS/X.pat)"
            )
        if not isinstance(switches, dict):
            raise SwitchError(f'"SwitchCommands" must be an object, got {switches!r}')
        return WorldRequest({}, [])
    return WorldRequest(world.check_switches(switches), world.objects.check(commands))


def apply_request(world: TrackWorld | None, simulation: Simulation, request: WorldRequest) -> None:
    """Throw the junctions (every train then follows them beyond the track it stands on) and
    move the objects."""
    if world is None:
        return
    changed = {i: r for i, r in request.switches.items() if world.network.selected[i] != r}
    if changed:
        world.network.selected.update(changed)
        for train in trains_of(simulation):
            if isinstance(train.route, TrackRoute):
                front = train.dynamics.state.position_m
                train.route.replan(front - train.consist.length_m, front)
                train.follow_route()
    world.objects.move(request.moves)


def reset_world(world: TrackWorld | None, simulation: Simulation) -> None:
    """Junctions and objects as at the start, every train back on its path's start."""
    if world is not None:
        world.reset()
        place_trains(world, simulation)
    simulation.reset()
