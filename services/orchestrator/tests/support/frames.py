"""Camera frames served to runs of their own (test_message_size.py, outputs/test_frames.py).

Camera (frame: Binary, `size` bytes) --frame--> Gain.blob --> Gain.blob_out
"""

from __future__ import annotations

from collections.abc import Mapping
from contextlib import ExitStack

import pytest

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.examples.gain import GainParticipant
from coupler.participant import Participant, Values
from coupler.testing import SystemStructure, remote

from . import serving

FRAME = 800 * 600 * 3
MIB = 1024 * 1024
SSD = SystemStructure(
    "Frames",
    components=[
        remote("Camera", "grpc://127.0.0.1:${CAMERA_PORT}", outputs=["frame"]),
        remote("Gain", "grpc://127.0.0.1:${GAIN_PORT}", inputs=["blob"], outputs=["blob_out"]),
    ],
    connections=[("Camera.frame", "Gain.blob")],
    stop_time=0.3,
)


class Camera(Participant):
    """One Binary output: ``size`` bytes per step (``larger`` from step ``larger_from`` on), a
    different pattern each step; declaring at most ``maximum`` bytes (0: nothing)."""

    def __init__(
        self, size: int, *, maximum: int = 0, larger: int = 0, larger_from: int = 0
    ) -> None:
        self.size, self.maximum = size, maximum
        self.larger, self.larger_from = larger, larger_from
        self.steps = 0

    async def describe(self) -> Description:
        frame = Channel(
            name="frame",
            causality=Causality.OUTPUT,
            type=ValueType.BINARY,
            max_bytes=self.maximum,
        )
        return Description(name="Camera", channels=(frame,), implementation="tests.Camera")

    async def initialize(self, setup: RunSetup) -> Values:
        self.steps = 0
        return {"frame": b""}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.steps += 1
        size = self.larger if self.larger and self.steps >= self.larger_from else self.size
        return {"frame": bytes([self.steps % 256]) * size}

    async def terminate(self, reason: str = "") -> None:
        self.steps = 0


class Fleet:
    """Camera and Gain served in this process (the run is a process of its own)."""

    def __init__(self, stack: ExitStack, monkeypatch: pytest.MonkeyPatch) -> None:
        self.stack, self.monkeypatch = stack, monkeypatch

    def serve(
        self,
        size: int = 0,
        *,
        camera: Participant | None = None,
        camera_limit: int = 64 * MIB,
        gain_limit: int = 64 * MIB,
    ) -> None:
        for name, participant, limit in (
            ("CAMERA", camera or Camera(size), camera_limit),
            ("GAIN", GainParticipant(), gain_limit),
        ):
            server = self.stack.enter_context(serving(participant, max_message_bytes=limit))
            self.monkeypatch.setenv(f"{name}_PORT", str(server.port))
