"""What OpenRails answers, as typed models: field names as OpenRails spells them.

Written from the simulation build's server source (DLR-SE/openrails-for-simulation,
``Source/RunActivity/Viewer3D/WebServices/OutputGenerator.cs``, ``WebServer.cs``,
``ControlValue.cs``); services/openrails-mock/README.md lists the shapes. Parsing is strict
(a string is not a number, 1 is not ``true``) and ignores fields the bridge does not read
(``carPositions``, ...). Older builds send ``location`` without tiles; the
tiles then read 0.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter


class Reply(BaseModel):
    """Base of the models: strict types, unknown fields ignored, frozen; NaN and infinity
    (JSON extensions Python reads) are not numbers OpenRails means."""

    model_config = ConfigDict(strict=True, extra="ignore", frozen=True, allow_inf_nan=False)


class WorldPosition(Reply):
    """A point in OpenRails' world: a 2048 m tile, x east, y up, z north within it."""

    tileX: int = 0
    tileZ: int = 0
    x: float
    y: float
    z: float


class TrackLocation(Reply):
    """Where one end of the train is on the track database (a ``Traveller``)."""

    trackNodeIndex: int
    trackNodeLength: float
    trackNodeOffset: float
    """Distance into the node, counted the way the train faces."""
    trackVectorSectionIndex: int
    movementDirection: Literal["Forward", "Backward"]
    """How the train faces on the node: with it, or against it."""


class LocomotiveState(Reply):
    """The lead locomotive's kinematics."""

    v: float
    """Speed [m/s], negative when backing."""
    a: float
    """Acceleration [m/s2]."""
    distance: float
    """Odometer [m]."""
    wheelslip: bool
    wheelskid: bool


class TrainLength(Reply):
    length: float


class Train(Reply):
    """One train of a step reply."""

    location: WorldPosition
    """The lead locomotive's centre."""
    trackLocation: TrackLocation
    """The front of the train."""
    rearTrackLocation: TrackLocation
    rotation: float
    """The front's heading [rad]: 0 north, pi/2 east."""
    locomotiveState: LocomotiveState
    trainLength: TrainLength


class CameraSensor(Reply):
    """A sensor as ``CameraSensors`` describes it (``OutputGenerator.GetCameraSensorConfigs``)."""

    width: int
    height: int
    h_scale: float
    """M11 of the sensor's projection matrix."""
    v_scale: float
    """M22 of the sensor's projection matrix."""
    max_distance: float | None = None
    """Depth sensors: the distance 65535 stands for [m]."""


class ObjectLabelReply(Reply):
    """One object of GET /API/CAMERASENSOR/<name>/LABELS (the OpenRails mock's extension)."""

    class_: str = Field(alias="class")
    id: int = Field(ge=0, lt=2**32)
    name: str = ""
    box: tuple[int, int, int, int]
    pixels: int = Field(ge=0)
    unoccludedPixels: int = Field(ge=0)
    snowPixels: int = Field(ge=0)
    distanceAlong: float
    distance: float
    transmittance: float
    visibleFraction: float


class LabelsReply(Reply):
    """GET /API/CAMERASENSOR/<name>/LABELS: the ground truth of the sensor's current frame."""

    sensor: str
    width: int
    height: int
    exposureMs: float = 0.0
    gain: float = 0.0
    objects: list[ObjectLabelReply] = Field(max_length=4096)


class StepReply(Reply):
    """POST /API/CABCONTROLS of the simulation build (and the mock's POST /API/RESET)."""

    trains: dict[str, Train]
    CameraSensors: dict[str, CameraSensor] = {}


class ControlValue(Reply):
    """One cab control as GET /API/CABCONTROLS lists it."""

    TypeName: str
    MinValue: float
    MaxValue: float


class LatLon(Reply):
    Lat: float
    Lon: float


class LatLonDirection(Reply):
    """GET /API/MAP: where the player locomotive is and which way it heads [deg]."""

    LatLon: LatLon
    DirectionDeg: float


class DisplayRow(Reply):
    """A row of GET /API/TRAINDRIVINGDISPLAY."""

    FirstCol: str
    LastCol: str


CONTROLS = TypeAdapter(list[ControlValue])
"""GET /API/CABCONTROLS."""
DISPLAY = TypeAdapter(list[DisplayRow])
"""GET /API/TRAINDRIVINGDISPLAY."""
