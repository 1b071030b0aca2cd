"""The infrastructure object model read from railML: lines of tracks, balises, groups, stations,
signals, and the switches that join lines into a network."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from coupler_railway.track import TrackModel


@dataclass(frozen=True)
class Track:
    """A railML ``<track>`` as declared (positions in its own pos/absPos reference)."""

    id: str
    name: str
    begin_pos: float
    end_pos: float
    begin_abs_pos: float | None
    end_abs_pos: float | None
    line: int
    """Line of the ``<track>`` element in the source file."""


@dataclass(frozen=True)
class Balise:
    """One balise placed on the line."""

    id: str
    """railML ``id`` (XML identity)."""
    code: int
    """Numeric balise id (railML ``code``): the value of the FMU's Integer channel."""
    name: str
    group: int
    """Numeric id (``code``) of the balise group it belongs to."""
    position_in_group: int
    """1-based rank of its ``baliseRef`` in the group."""
    distance_m: float
    """Distance along the line from its start [m]."""
    direction: str
    """railML ``dir``: up, down, both, none or unknown (default)."""
    latitude_deg: float
    """Latitude of the track point at ``distance_m``."""
    longitude_deg: float
    line: int
    """Line of the ``<balise>`` element in the source file."""


@dataclass(frozen=True)
class BaliseGroup:
    """A railML ``<baliseGroup>``: its numeric id and its balises in group order."""

    id: str
    code: int
    name: str
    type: str
    """railML ``type`` (infill, signal, technicalFixed, ...), empty when not given."""
    balise_ids: tuple[str, ...]
    distance_m: float
    """Distance of its first balise along the line [m]."""
    line: int


@dataclass(frozen=True)
class Station:
    """A railML ``<ocp>`` with coordinates, projected onto the line."""

    id: str
    name: str
    latitude_deg: float
    longitude_deg: float
    distance_m: float
    """Distance along the line of the nearest track point [m]."""
    offset_m: float
    """Distance between the ocp's coordinates and the track [m]."""
    line: int


@dataclass(frozen=True)
class Signal:
    """A railML ``<signal>`` placed on the line."""

    id: str
    name: str
    distance_m: float
    """Distance along the line from its start [m]."""
    direction: str
    """railML ``dir``: ``up`` (for trains towards increasing distance), ``down``, ``both``, ..."""
    type: str
    """railML ``type`` (main, distant, repeater, ...), empty when not given."""
    function: str
    """railML ``function`` (entry, exit, block, ...), empty when not given."""
    side: str
    """Where it stands, seen towards increasing distance: ``right`` for ``dir="up"`` (and
    ``both``/``none``/``unknown``), ``left`` for ``dir="down"`` (right-hand running)."""
    line: int


@dataclass(frozen=True)
class PlatformEdge:
    """A railML ``<platformEdge>``: the edge of a platform along the line."""

    id: str
    name: str
    start_m: float
    """Distance along the line where it begins [m]."""
    end_m: float
    side: str
    """``left`` or ``right`` of the track, seen towards increasing distance."""
    height_m: float
    """Height of the edge above the top of the rails [m]."""
    line: int


@dataclass(frozen=True)
class Switch:
    """A railML ``<switch>`` on a line, where another line (its branch) begins or ends."""

    id: str
    name: str
    distance_m: float
    """Distance along the line it sits on [m]."""
    branch: int
    """Index in :attr:`Network.lines` of the line that branches off here."""
    branch_begins: bool
    """True: the branch line begins at the switch (railML ``orientation="outgoing"``); False: it
    ends there (``incoming``)."""
    course: str
    """railML ``course`` of the branch: left, right, straight, or empty when not given."""
    line: int


@dataclass(frozen=True, eq=False)
class Infrastructure:
    """Everything :func:`~coupler_railway.railml.load_infrastructure` reads from one file."""

    source: Path
    tracks: tuple[Track, ...]
    """Tracks in line order (following their connections)."""
    model: TrackModel
    balises: tuple[Balise, ...]
    """Sorted by distance along the line."""
    groups: tuple[BaliseGroup, ...]
    """Sorted by distance along the line."""
    stations: tuple[Station, ...]
    """Sorted by distance along the line."""
    warnings: tuple[str, ...]
    """Content that was read but not interpreted, one message per kind."""
    signals: tuple[Signal, ...] = ()
    """Sorted by distance along the line."""
    switches: tuple[Switch, ...] = ()
    """Switches on this line, sorted by distance (only in a :class:`Network`)."""
    platform_edges: tuple[PlatformEdge, ...] = ()
    """Sorted by where they begin along the line."""
    altitude_m: float | None = None
    """Altitude of the line's first point above sea level [m]: the third value of its first
    trackBegin's geoCoord (``coord="lat lon altitude"``), None when railML gives none."""


@dataclass(frozen=True, eq=False)
class Network:
    """A railML file of several lines joined by switches (:func:`~coupler_railway.load_network`).

    Every line is an :class:`Infrastructure` of its own (tracks chained end to begin, one
    B-spline track model); all models share the first line's local frame.
    """

    source: Path
    lines: tuple[Infrastructure, ...]
    """The first line holds the file's first track that begins without a connection."""
    warnings: tuple[str, ...]
