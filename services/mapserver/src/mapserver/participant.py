"""``MapParticipant``: the map server as a co-simulation participant (inputs only).

Every input has a start value, so the SSD connects whichever of them its other participants
provide; ``mapserver.state`` explains how they combine. DoStep only updates ``RunState``,
whose listeners queue events for browsers without waiting for them.
"""

from __future__ import annotations

from collections.abc import Mapping

from coupler.channels import Capabilities, Causality, Channel, Description, RunSetup, Value
from coupler.channels import ValueType as T
from coupler.participant import Participant, Values
from coupler_railway.messages import (
    BALISE_DETECTIONS,
    BALISE_READING,
    IMAGE,
    MAX_FRAME,
    RGB8,
    TRAIN_STATE,
    TRAIN_STATE_BYTES,
    image_bytes,
)
from mapserver.state import RunState

NAME = "MapServer"


def _input(
    name: str,
    type: T,
    start: Value,
    unit: str = "",
    description: str = "",
    message: str = "",
    max_bytes: int = 0,
) -> Channel:
    return Channel(
        name=name,
        causality=Causality.INPUT,
        type=type,
        unit=unit,
        start=start,
        description=description,
        message_type=message,
        max_bytes=max_bytes,
    )


CHANNELS = (
    _input("latitude", T.REAL, 0.0, "deg", "Train position, WGS84 latitude"),
    _input("longitude", T.REAL, 0.0, "deg", "Train position, WGS84 longitude"),
    _input("distance", T.REAL, 0.0, "m", "Distance travelled along the track"),
    _input("speed", T.REAL, 0.0, "m/s", "Train speed"),
    _input("balise_id", T.INTEGER, 0, "", "Last balise passed (0: none yet)"),
    _input("group_id", T.INTEGER, 0, "", "Group of the last balise passed"),
    _input("balises_passed", T.INTEGER, 0, "", "Count of balises passed; a reading per increase"),
    _input(
        "passed_in_step",
        T.STRING,
        "",
        "",
        'Balises crossed in the last step, "id:group:distance;..." in travel order',
    ),
    _input(
        "train_state",
        T.BINARY,
        b"",
        "",
        "Train state (empty: not connected)",
        TRAIN_STATE,
        TRAIN_STATE_BYTES,
    ),
    _input(
        "balise_reading", T.BINARY, b"", "", "Last balise reading (empty: none)", BALISE_READING
    ),
    _input(
        "camera",
        T.BINARY,
        b"",
        "",
        "Camera frame, rgb8, up to 3840 x 2160 (empty: no camera)",
        IMAGE,
        image_bytes(*MAX_FRAME, RGB8),
    ),
    _input(
        "detections",
        T.BINARY,
        b"",
        "",
        "Balises a perception saw in a camera frame (empty: none connected)",
        BALISE_DETECTIONS,
    ),
    _input("estimated_front", T.REAL, 0.0, "m", "A localisation's estimated front end"),
    _input("min_safe_front", T.REAL, 0.0, "m", "Its confidence interval's near end"),
    _input("max_safe_front", T.REAL, 0.0, "m", "Its confidence interval's far end (0: none)"),
    _input("linking_error", T.BOOLEAN, False, "", "The localisation's linking error"),
    _input("true_front", T.REAL, 0.0, "m", "The true front end (0: not connected)"),
)


class MapParticipant(Participant):
    """Feeds ``state`` from Initialize, DoStep and Terminate; has no outputs."""

    def __init__(self, state: RunState) -> None:
        self.state = state
        self._defaults = {c.name: c.start for c in CHANNELS if c.start is not None}

    async def describe(self) -> Description:
        return Description(
            name=NAME,
            channels=CHANNELS,
            capabilities=Capabilities(streaming=True, variable_step_size=True),
            implementation="coupler mapserver 0.1.0",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        self.state.start(setup, self._defaults)
        return {}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.state.step(time, step, inputs)
        return {}

    async def terminate(self, reason: str = "") -> None:
        self.state.end(reason or "terminated")
