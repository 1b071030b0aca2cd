"""Loading an OpenRails route folder the way OpenRails' simulator does.

    ROUTE/NAME.trk          the route file: FileName (the .tdb's stem) and RouteStart
    ROUTE/NAME.tdb          the track database: track nodes (vector, junction, end) and items
    ROUTE/tsection.dat      the route's track sections (OpenRails/tsection.dat, global
                            format: track sections and track shapes, is read first when it
                            exists, as OpenRails does)
    ROUTE/PATHS/*.pat       paths (read on demand, :mod:`openrails_mock.paths`)
    ROUTE/WORLD/w*.w        world files: the objects a ChangeObjectPosition command moves

Everything is checked while loading (pins that link to no node, sections missing from the
section file, counts that disagree), and every problem is a
:class:`~openrails_mock.stf.RouteError` naming the file, the line and the fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from .stf import Block, RouteError, read_stf

TILE_SIZE_M = 2048.0


@dataclass(frozen=True)
class SectionShape:
    """A track section of tsection.dat: a straight of ``length`` or an arc."""

    index: int
    length: float
    """Length along the track [m] (an arc's radius times its angle)."""
    radius: float
    """0 for a straight."""
    angle: float
    """Signed turn in radians, positive to the right; 0 for a straight."""


@dataclass(frozen=True)
class TrackShape:
    """A track shape of the global tsection.dat: a switch's (or a fixed track piece's) paths."""

    index: int
    file_name: str
    paths: tuple[tuple[int, ...], ...]
    """The track sections of each path (SectionIdx), in route order."""
    main_route: int
    """The route a junction of this shape is set to at start (OpenRails' MainRoute)."""


@dataclass(frozen=True)
class VectorSection:
    """One straight or arc of a vector node, where it starts and which way it points."""

    shape: SectionShape
    tile_x: int
    tile_z: int
    x: float
    y: float
    z: float
    ax: float
    """Pitch: negative climbs (OpenRails' AX)."""
    ay: float
    """Heading, radians clockwise from north (AY)."""
    world_tile: tuple[int, int]
    world_uid: int


@dataclass(frozen=True)
class Pin:
    link: int
    """Index of the node at the other end of the pin."""
    direction: int
    """1 or 0: which way a traveller continues on the linked node (OpenRails' TrPin)."""


@dataclass
class TrackNode:
    """A node of the track database: vector (sections), junction or end."""

    index: int
    kind: str
    """``vector``, ``junction`` or ``end``."""
    pins: list[Pin]
    in_pins: int
    sections: list[VectorSection] = field(default_factory=list)
    items: list[int] = field(default_factory=list)
    position: tuple[int, int, float, float, float] | None = None
    """Junction and end nodes: (tile_x, tile_z, x, y, z) of their UiD."""
    line: int = 0
    """Line of the TrackNode in the .tdb, for error messages."""
    shape: int | None = None
    """A junction's track shape index (TrJunctionNode's second value)."""

    @property
    def length(self) -> float:
        return sum(s.shape.length for s in self.sections)


@dataclass(frozen=True)
class TrackItem:
    """A track item of the TDB: its kind, where it is, and what it says."""

    id: int
    kind: str
    """The TDB block name: SpeedPostItem, SignalItem, PlatformItem, ..."""
    offset: float
    """TrItemSData: distance into its vector node [m]."""
    position: tuple[int, int, float, float, float] | None
    """TrItemRData: (tile_x, tile_z, x, y, z)."""
    number: float | None = None
    """A speed post's number (a milepost's value; a balise's code in Coupler's routes)."""
    name: str = ""


@dataclass
class WorldObject:
    """An object of a world file, addressed by its tile and UID."""

    tile: tuple[int, int]
    uid: int
    kind: str
    """The world block name: Static, Signal, Dyntrack, TrackObj, ..."""
    file_name: str
    position: tuple[float, float, float]
    """x, y, z in its tile."""
    rotation: tuple[float, float, float, float]
    """QDirection quaternion (x, y, z, w)."""
    animated: bool
    """StaticFlags has the animated bit: OpenRails keeps it apart so it can move."""


@dataclass
class RouteFolder:
    """Everything the mock loads from a route folder."""

    folder: Path
    name: str
    start: tuple[int, int, float, float]
    """RouteStart: tile_x, tile_z, x, z."""
    nodes: dict[int, TrackNode]
    items: dict[int, TrackItem]
    objects: dict[tuple[int, int, int], WorldObject]
    """Keyed by (tile_x, tile_z, uid)."""
    tdb_file: Path
    track_shapes: dict[int, TrackShape] = field(default_factory=dict)
    """OpenRails/tsection.dat's TrackShapes, by index."""

    @property
    def junctions(self) -> list[int]:
        return sorted(i for i, n in self.nodes.items() if n.kind == "junction")


def _find(folder: Path, pattern: str) -> list[Path]:
    """Files matching ``pattern`` case-insensitively (routes come from Windows)."""
    wanted = pattern.lower()
    return (
        sorted(p for p in folder.iterdir() if p.name.lower() == wanted) if folder.is_dir() else []
    )


def _child(folder: Path, name: str) -> Path | None:
    found = _find(folder, name)
    return found[0] if found else None


def load_route(folder: str | Path) -> RouteFolder:
    """Load the route folder ``folder`` (the one holding NAME.trk)."""
    root = Path(folder)
    if not root.is_dir():
        raise RouteError(root, None, "is not a folder", "give --route the route's folder")
    tracks = [p for p in root.iterdir() if p.suffix.lower() == ".trk"]
    if len(tracks) != 1:
        raise RouteError(
            root,
            None,
            f"holds {len(tracks)} .trk route files",
            "give --route the folder of one OpenRails route (it holds NAME.trk)",
        )
    route_file = read_stf(tracks[0])
    route = route_file.block("Tr_RouteFile")
    stem = route.block("FileName").text(0, "the route's file name")
    start_block = route.block("RouteStart")
    start = (
        start_block.integer(0, "tile x"),
        start_block.integer(1, "tile z"),
        start_block.real(2, "x"),
        start_block.real(3, "z"),
    )
    shapes, track_shapes = _load_sections(root)
    tdb_file = _child(root, f"{stem}.tdb")
    if tdb_file is None:
        raise RouteError(
            tracks[0],
            route.block("FileName").line,
            f"names the track database {stem}.tdb, which is not in {root}",
            "export the route again or correct FileName",
        )
    nodes, items = _load_tdb(tdb_file, shapes)
    world = _child(root, "WORLD")
    objects = _load_world(world) if world is not None else {}
    route_id = route.optional("RouteID")
    name = route_id.text(0, "the route id") if route_id is not None else stem
    return RouteFolder(root, name, start, nodes, items, objects, tdb_file, track_shapes)


MAX_SECTIONS = 1_000_000
"""The largest section index a TrackSections table may declare (a global tsection.dat declares
its highest index, about 40,000)."""
MAX_SECTION_M = 10_000.0
"""The longest track section [m] (exported ones are at most 1000 m; a section is one straight
or one arc)."""


def _load_sections(root: Path) -> tuple[dict[int, SectionShape], dict[int, TrackShape]]:
    shapes: dict[int, SectionShape] = {}
    track_shapes: dict[int, TrackShape] = {}
    openrails = _child(root, "OpenRails")
    global_file = _child(openrails, "tsection.dat") if openrails is not None else None
    if global_file is not None:
        global_root = read_stf(global_file)
        track_shapes = _track_shapes(global_root)
        for section in _sections(global_root):
            index = section.integer(0, "the section index")
            size, curve = section.optional("SectionSize"), section.optional("SectionCurve")
            if curve is not None:
                radius = curve.real(0, "the radius")
                angle = math.radians(curve.real(1, "the angle"))
                shapes[index] = _shape(section, index, radius * abs(angle), radius, angle)
            elif size is not None:
                shapes[index] = _shape(section, index, size.real(1, "the length"), 0.0, 0.0)
    local = _child(root, "tsection.dat")
    if local is None and not shapes:
        raise RouteError(root, None, "has no tsection.dat", "export the route again")
    if local is not None:
        for section in _sections(read_stf(local)):
            index = section.integer(0, "the section index")
            a, b = section.real(1, "the length or angle"), section.real(2, "0 or the radius")
            if b == 0.0:
                shapes[index] = _shape(section, index, a, 0.0, 0.0)
            else:
                shapes[index] = _shape(section, index, b * abs(a), b, a)
    for shape in track_shapes.values():
        for path in shape.paths:
            missing = [i for i in path if i not in shapes]
            if missing:
                raise RouteError(
                    global_file or root,
                    None,
                    f"track shape {shape.index} uses track section {missing[0]}, which no "
                    "tsection.dat of the route defines",
                    "export the route again, or add the section",
                )
    return shapes, track_shapes


def _track_shapes(root: Block) -> dict[int, TrackShape]:
    """The TrackShapes of a global tsection.dat: each shape's paths (NumPaths SectionIdx
    blocks, ``SectionIdx ( n x y z angle sections... )``) and its MainRoute."""
    found: dict[int, TrackShape] = {}
    for table in root.blocks("TrackShapes"):
        for block in table.blocks("TrackShape"):
            index = block.integer(0, "the shape index")
            paths = []
            for path in block.blocks("SectionIdx"):
                count = path.integer(0, "the number of sections")
                if len(path.values) != 5 + count:
                    raise path.error(
                        f"SectionIdx declares {count} sections but holds {len(path.values) - 5}",
                        "write SectionIdx ( n x y z angle section... ) with n sections",
                    )
                paths.append(tuple(path.integer(5 + k, "a section index") for k in range(count)))
            declared = block.optional("NumPaths")
            if declared is not None and declared.integer(0, "NumPaths") != len(paths):
                raise block.error(
                    f"TrackShape {index} declares {declared.integer(0, 'NumPaths')} paths but "
                    f"holds {len(paths)}",
                    "give one SectionIdx per path",
                )
            main = block.optional("MainRoute")
            main_route = main.integer(0, "the main route") if main is not None else 0
            if paths and not 0 <= main_route < len(paths):
                raise block.error(
                    f"TrackShape {index} has MainRoute {main_route} but {len(paths)} paths",
                    "give a route of the shape, from 0",
                )
            name = block.optional("FileName")
            found[index] = TrackShape(
                index, name.text(0, "the shape file") if name else "", tuple(paths), main_route
            )
    return found


def _sections(root: Block) -> list[Block]:
    """The TrackSection blocks of a tsection.dat, each table's declared highest index checked:
    at least every index it holds, at most MAX_SECTIONS."""
    found = []
    for table in root.blocks("TrackSections"):
        sections = table.blocks("TrackSection")
        declared = table.integer(0, "the highest section index")
        highest = max((s.integer(0, "the section index") for s in sections), default=0)
        if not highest <= declared <= MAX_SECTIONS:
            raise table.error(
                f"TrackSections declares {declared} as its highest index, but holds {highest}",
                f"give the highest index it holds (at most {MAX_SECTIONS})",
            )
        found.extend(sections)
    return found


def _shape(section: Block, index: int, length: float, radius: float, angle: float) -> SectionShape:
    """A section's shape, its length a finite 0 < length <= MAX_SECTION_M."""
    if not (0.0 < length <= MAX_SECTION_M and math.isfinite(radius) and math.isfinite(angle)):
        raise section.error(
            f"track section {index} is {length:g} m long (radius {radius:g} m)",
            f"a section is a straight or an arc of 0 to {MAX_SECTION_M:g} m",
        )
    return SectionShape(index, length, radius, angle)


def _load_tdb(
    file: Path, shapes: dict[int, SectionShape]
) -> tuple[dict[int, TrackNode], dict[int, TrackItem]]:
    database = read_stf(file).block("TrackDB")
    table = database.block("TrackNodes")
    declared = table.integer(0, "the number of track nodes")
    nodes: dict[int, TrackNode] = {}
    for block in table.blocks("TrackNode"):
        node = _track_node(block, shapes)
        if node.index in nodes:
            raise block.error(f"track node {node.index} is defined twice", "number nodes 1, 2, ...")
        nodes[node.index] = node
    if len(nodes) != declared or sorted(nodes) != list(range(1, declared + 1)):
        raise table.error(
            f"TrackNodes declares {declared} nodes but holds {len(nodes)} numbered "
            f"{sorted(nodes)[:5]}...",
            "number the nodes 1..N and give N",
        )
    for node in nodes.values():
        for pin in node.pins:
            other = nodes.get(pin.link)
            if other is None:
                raise RouteError(
                    file,
                    node.line,
                    f"track node {node.index} has a pin to node {pin.link}, "
                    f"which does not exist (nodes 1..{declared})",
                    "correct the TrPin",
                )
            if node.index not in [p.link for p in other.pins]:
                raise RouteError(
                    file,
                    node.line,
                    f"track node {node.index} links to node {pin.link}, which does not link back",
                    "make the TrPins of both nodes name each other",
                )
    items: dict[int, TrackItem] = {}
    item_table = database.optional("TrItemTable")
    if item_table is not None:
        for number, block in enumerate(i for i in item_table.items if isinstance(i, Block)):
            item = _track_item(block, number)
            items[item.id] = item
    for node in nodes.values():
        for ref in node.items:
            if ref not in items:
                raise RouteError(
                    file,
                    node.line,
                    f"track node {node.index} refers to track item {ref}, "
                    "which is not in the TrItemTable",
                    "correct the TrItemRef",
                )
    return nodes, items


def _vector_section(
    sections_block: Block, index: int, k: int, row: list[str], shapes: dict[int, SectionShape]
) -> VectorSection:
    """Vector section ``k`` of node ``index``: its 16 values of TrVectorSections."""
    try:
        shape_index = int(row[0])
        numbers = [float(v) for v in row[8:16]]
        world = (int(row[2]), int(row[3]), int(row[4]))
        if not all(math.isfinite(v) for v in numbers):
            raise ValueError("not finite")
    except ValueError:
        raise sections_block.error(
            f"vector section {k} of node {index} has a value that is not a number",
            "write 16 numbers per vector section",
        ) from None
    shape = shapes.get(shape_index)
    if shape is None:
        raise sections_block.error(
            f"vector section {k} of node {index} uses track section {shape_index}, "
            "which no tsection.dat of the route defines",
            "export the route again, or add the section to tsection.dat",
        )
    return VectorSection(
        shape,
        int(numbers[0]),
        int(numbers[1]),
        numbers[2],
        numbers[3],
        numbers[4],
        numbers[5],
        numbers[6],
        (world[0], world[1]),
        world[2],
    )


def _track_node(block: Block, shapes: dict[int, SectionShape]) -> TrackNode:
    index = block.integer(0, "the node index")
    pins_block = block.block("TrPins")
    in_pins, out_pins = pins_block.integer(0, "in pins"), pins_block.integer(1, "out pins")
    pins = [
        Pin(p.integer(0, "the linked node"), p.integer(1, "the direction"))
        for p in pins_block.blocks("TrPin")
    ]
    if len(pins) != in_pins + out_pins:
        raise pins_block.error(
            f"TrPins declares {in_pins} + {out_pins} pins but holds {len(pins)}",
            "give one TrPin per declared pin",
        )
    vector = block.optional("TrVectorNode")
    if vector is not None:
        node = TrackNode(index, "vector", pins, in_pins, line=block.line)
        sections_block = vector.block("TrVectorSections")
        count = sections_block.integer(0, "the number of sections")
        values = sections_block.values[1:]
        if len(values) != 16 * count:
            raise sections_block.error(
                f"TrVectorSections declares {count} sections of 16 values but holds "
                f"{len(values)} values",
                "write 16 values per vector section",
            )
        node.sections.extend(
            _vector_section(sections_block, index, k, values[16 * k : 16 * k + 16], shapes)
            for k in range(count)
        )
        if not node.sections:
            raise sections_block.error(f"vector node {index} has no sections", "give it some")
        refs = vector.optional("TrItemRefs")
        if refs is not None:
            node.items = [r.integer(0, "the item id") for r in refs.declared("TrItemRef", "items")]
        if in_pins != 1 or out_pins != 1:
            raise pins_block.error(
                f"vector node {index} has {in_pins}/{out_pins} pins",
                "a vector node has TrPins ( 1 1 ...)",
            )
        return node
    uid = block.optional("UiD")
    position = None
    if uid is not None:
        position = (
            uid.integer(4, "tile x"),
            uid.integer(5, "tile z"),
            uid.real(6, "x"),
            uid.real(7, "y"),
            uid.real(8, "z"),
        )
    if block.optional("TrJunctionNode") is not None:
        if in_pins != 1 or out_pins != 2:
            raise pins_block.error(
                f"junction node {index} has {in_pins} in and {out_pins} out pins",
                "a junction has TrPins ( 1 2 ...): its trunk, then its two routes",
            )
        shape = block.block("TrJunctionNode").integer(1, "the junction's track shape")
        return TrackNode(
            index, "junction", pins, in_pins, position=position, line=block.line, shape=shape
        )
    if block.optional("TrEndNode") is not None:
        if len(pins) != 1:
            raise pins_block.error(f"end node {index} has {len(pins)} pins", "give it one")
        return TrackNode(index, "end", pins, in_pins, position=position, line=block.line)
    raise block.error(
        f"track node {index} is neither a TrVectorNode, a TrJunctionNode nor a TrEndNode",
        "give it one of them",
    )


def _track_item(block: Block, number: int) -> TrackItem:
    ident = block.block("TrItemId").integer(0, "the item id")
    if ident != number:
        raise block.error(
            f"track item number {number} has TrItemId {ident}", "number the items 0, 1, ..."
        )
    sdata = block.optional("TrItemSData")
    rdata = block.optional("TrItemRData")
    position = None
    if rdata is not None:
        position = (
            rdata.integer(3, "tile x"),
            rdata.integer(4, "tile z"),
            rdata.real(0, "x"),
            rdata.real(1, "y"),
            rdata.real(2, "z"),
        )
    number_value = None
    speedpost = block.optional("SpeedpostTrItemData")
    if speedpost is not None and len(speedpost.values) >= 2:
        number_value = speedpost.real(1, "the number")
    name = ""
    for token in ("PlatformName", "SidingName"):
        named = block.optional(token)
        if named is not None and named.values:
            name = named.text(0, "the name")
    return TrackItem(
        ident,
        block.name,
        sdata.real(0, "the offset") if sdata is not None else 0.0,
        position,
        number_value,
        name,
    )


def _load_world(folder: Path) -> dict[tuple[int, int, int], WorldObject]:
    objects: dict[tuple[int, int, int], WorldObject] = {}
    for path in sorted(folder.iterdir()):
        name = path.name.lower()
        if not (name.startswith("w") and name.endswith(".w") and len(name) == 17):
            continue
        try:
            tile = (int(name[1:8]), int(name[8:15]))
        except ValueError:
            continue
        root = read_stf(path)
        world = root.block("Tr_Worldfile")
        for block in world.items:
            if not isinstance(block, Block) or block.optional("UiD") is None:
                continue
            uid = block.block("UiD").integer(0, "the UID")
            position = block.optional("Position")
            rotation = block.optional("QDirection")
            flags = block.optional("StaticFlags")
            file_name = block.optional("FileName")
            objects[(tile[0], tile[1], uid)] = WorldObject(
                tile=tile,
                uid=uid,
                kind=block.name,
                file_name=file_name.text(0, "the shape") if file_name is not None else "",
                position=(
                    (position.real(0, "x"), position.real(1, "y"), position.real(2, "z"))
                    if position is not None
                    else (0.0, 0.0, 0.0)
                ),
                rotation=(
                    tuple(rotation.real(i, "a quaternion value") for i in range(4))  # type: ignore[arg-type]
                    if rotation is not None
                    else (0.0, 0.0, 0.0, 1.0)
                ),
                animated=bool(flags is not None and flags.hexadecimal(0, "the flags") & 0x00080000),
            )
    return objects
