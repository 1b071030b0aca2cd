"""World objects the lockstep API's ``Commands`` move (the public simulation client's
``DynamicObject``).

A command is ``{"Command": "ChangeObjectPosition", "UID": 7, "TileX": -5608, "TileZ": 14879,
"x": 12.5, "y": 1.0, "z": -3.0, "yaw": 1.57, "pitch": 0.0, "roll": 0.0}``: the object with
that UID in that tile's world file goes to x/y/z (metres in the same tile) turned by yaw,
pitch and roll (radians). As the client requires, only animated objects move (StaticFlags
00080000: OpenRails keeps them apart from the merged static scenery).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from coupler.errors import CouplerError

from .routefolder import WorldObject

COMMANDS = ("ChangeObjectPosition",)
"""The world commands OpenRails' simulation build knows."""
_FIELDS = ("UID", "TileX", "TileZ", "x", "y", "z", "yaw", "pitch", "roll")


class CommandError(CouplerError):
    """A world command cannot be applied; nothing of its request was applied."""


@dataclass(frozen=True)
class Pose:
    """Where a world object stands now: in its tile, turned by yaw/pitch/roll."""

    x: float
    y: float
    z: float
    yaw: float
    pitch: float
    roll: float


def _initial_pose(obj: WorldObject) -> Pose:
    qx, qy, qz, qw = obj.rotation
    yaw = math.atan2(2.0 * (qw * qy + qx * qz), 1.0 - 2.0 * (qx * qx + qy * qy))
    return Pose(*obj.position, yaw, 0.0, 0.0)


class WorldObjects:
    """The route's world objects and where each stands now."""

    def __init__(self, objects: dict[tuple[int, int, int], WorldObject]) -> None:
        self.objects = objects
        self.poses: dict[tuple[int, int, int], Pose] = {}
        self.reset()

    def reset(self) -> None:
        self.poses = {key: _initial_pose(obj) for key, obj in self.objects.items()}

    def check(self, commands: list[object]) -> list[tuple[tuple[int, int, int], Pose]]:
        """The moves the commands ask for; CommandError at the first bad one."""
        return [self._parse(command) for command in commands]

    def move(self, moves: list[tuple[tuple[int, int, int], Pose]]) -> None:
        for key, pose in moves:
            self.poses[key] = pose

    def _parse(self, command: object) -> tuple[tuple[int, int, int], Pose]:
        if not isinstance(command, dict):
            raise CommandError(f'each command must be an object with a "Command", got {command!r}')
        name = command.get("Command")
        if name not in COMMANDS:
            raise CommandError(f"unknown Command {name!r}; known: {', '.join(COMMANDS)}")
        missing = [f for f in _FIELDS if f not in command]
        if missing:
            raise CommandError(f"{name} lacks {', '.join(missing)} (it needs {', '.join(_FIELDS)})")
        for f in _FIELDS:
            value = command[f]
            if (
                not isinstance(value, int | float)
                or isinstance(value, bool)
                or not math.isfinite(value)
            ):
                raise CommandError(f"{name} {f} must be a number, got {value!r}")
        for f in ("UID", "TileX", "TileZ"):
            if command[f] != int(command[f]):
                raise CommandError(f"{name} {f} must be an integer, got {command[f]!r}")
        key = (int(command["TileX"]), int(command["TileZ"]), int(command["UID"]))
        obj = self.objects.get(key)
        if obj is None:
            raise CommandError(
                f"{name}: no world object UID {key[2]} in tile {key[0]} {key[1]} "
                f"(world file w{key[0]:+07d}{key[1]:+07d}.w)"
            )
        if not obj.animated:
            raise CommandError(
                f"{name}: world object UID {key[2]} in tile {key[0]} {key[1]} ({obj.kind} "
                f"{obj.file_name}) is not animated (StaticFlags 00080000), so OpenRails cannot "
                "move it"
            )
        pose = Pose(*(float(command[f]) for f in ("x", "y", "z", "yaw", "pitch", "roll")))
        return key, pose

    def listing(self) -> list[dict[str, object]]:
        """Every object that can move, with its pose (``GET /API/OBJECTS``)."""
        return [
            {
                "UID": key[2],
                "TileX": key[0],
                "TileZ": key[1],
                "Kind": obj.kind,
                "FileName": obj.file_name,
                "x": pose.x,
                "y": pose.y,
                "z": pose.z,
                "yaw": pose.yaw,
                "pitch": pose.pitch,
                "roll": pose.roll,
            }
            for key, obj in sorted(self.objects.items())
            if obj.animated
            for pose in (self.poses[key],)
        ]
