"""``LocalisationUnit``: the estimator behind the adapter SDK, as a user's own localisation would
be -- a system of its own (here ``localisation.estimator``), seen through its field names, made
a participant by ``coupler.adapter.AdapterParticipant`` and the channel map ``channels.toml``.

To validate another localisation, write an ``Adapter`` whose ``apply_inputs`` hands it the
odometer's measurements and the telegrams (or detections), whose ``advance`` lets it run to the
step's end and whose ``get_state`` reads its estimate, and keep the channel names.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib.resources import files
from pathlib import Path
from typing import Any

from coupler.adapter import Adapter, AdapterConfig, AdapterParticipant
from coupler.channels import RunSetup, Value
from coupler.errors import ChannelValueError
from coupler.messages import decode_message
from coupler_railway.messages import BALISE_DETECTIONS
from localisation.estimator import Estimate, Estimator, EstimatorSettings, Odometry, Sighting
from localisation.linking import Linking
from localisation.transmission import parse_telegrams

CHANNELS = Path(str(files("localisation") / "channels.toml"))
"""The packaged channel map."""
IMPLEMENTATION = "coupler localisation 0.1.0 (odometry + balise groups, ETCS-style interval)"


class LocalisationUnit(Adapter):
    """The estimator of ``localisation.estimator`` over the line of ``linking``."""

    def __init__(self, linking: Linking) -> None:
        self._linking = linking
        self._estimator: Estimator | None = None
        self._inputs: dict[str, Value] = {}
        self._estimate: Estimate | None = None
        self._fresh: set[str] = set()
        self._time = 0.0

    async def connect(self) -> None:
        """Nothing to reach: the estimator runs in this process."""

    async def start(self, setup: RunSetup, parameters: Mapping[str, Value]) -> None:
        fields = {k: float(v) for k, v in parameters.items()}
        accuracy = fields.pop("location_accuracy_m", 1.0)
        self._estimator = Estimator(
            self._linking.with_accuracy(accuracy), EstimatorSettings(**fields)
        )
        self._inputs = {}
        self._fresh = set()
        self._estimate = None
        self._time = setup.start_time

    async def apply_inputs(self, inputs: Mapping[str, Value]) -> None:
        self._inputs.update(inputs)
        # readings count in the step they arrive in: a value left over from an earlier step
        # (when only changed inputs are sent) is not read again
        self._fresh.update(k for k in ("telegrams", "detections") if k in inputs)
        if self._estimate is None and self._estimator is not None:
            self._estimate = self._estimator.start(self._time, self._odometry())

    async def advance(self, time: float, step: float) -> None:
        assert self._estimator is not None, "start() first"
        if self._estimate is None:
            self._estimate = self._estimator.start(time, self._odometry())
        text = str(self._inputs.get("telegrams", "")) if "telegrams" in self._fresh else ""
        try:
            telegrams = parse_telegrams(text)
        except ValueError as exc:
            raise ChannelValueError(f"channel 'telegrams': {exc}", channel="telegrams") from exc
        frames = self._frames() if "detections" in self._fresh else []
        self._fresh.clear()
        self._estimate = self._estimator.step(time, step, self._odometry(), telegrams, frames)

    async def get_state(self) -> Mapping[str, Any]:
        if self._estimate is None:
            assert self._estimator is not None, "start() first"
            self._estimate = self._estimator.start(self._time, self._odometry())
        return vars(self._estimate)

    async def stop(self, reason: str) -> None:
        self._estimate = None

    async def shutdown(self) -> None:
        self._estimator = None

    def _odometry(self) -> Odometry:
        get = self._inputs.get
        return Odometry(
            distance_m=float(get("odometer_distance", 0.0)),
            speed_mps=float(get("odometer_speed", 0.0)),
            radar_speed_mps=float(get("radar_speed", 0.0)),
            radar_valid=bool(get("radar_valid", False)),
        )

    def _frames(self) -> list[list[Sighting]]:
        data = self._inputs.get("detections", b"")
        if not isinstance(data, bytes) or not data:
            return []
        message = decode_message(BALISE_DETECTIONS, data)
        frame_time = float(message.get("time_s", 0.0))
        return [
            [
                Sighting(float(d.get("time_s", frame_time)), float(d.get("distance_ahead_m", 0.0)))
                for d in message.get("detections", ())
            ]
        ]


def participant(railml: Path, channels: Path | None = None) -> AdapterParticipant:
    """The localisation on the line in ``railml`` as a participant: the unit and its channel
    map. RailMLError for a bad railML file, ScenarioError for a bad channel map."""
    return AdapterParticipant(
        LocalisationUnit(Linking.from_railml(railml)),
        AdapterConfig.load(channels or CHANNELS),
        implementation=IMPLEMENTATION,
    )
