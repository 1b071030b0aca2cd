"""The files OpenRails' viewer opens besides the track: environments, track types, shapes and
their textures, terrain tiles, consists and rolling stock -- read and checked as OpenRails
reads them.

The mock itself runs on the track database (:mod:`openrails_mock.routefolder`); this module
reads the rest of a route folder so that a route is known to hold what a real OpenRails opens
at start and draws (the exporter's tests read every file of an exported route with it):

    NAME.trk Environment     twelve ENVFILES/<name> files: world ( world_sky ( ... ) )
    TTYPE.DAT                a count, then that many TrackType ( label inside outside )
    SHAPES/<name>.s          every shape a world file's Static, Signal or TrackObj names
    TEXTURES/<name>.ace      every image those shapes name (uncompressed, structured ACE)
    TILES/<name>.t           a terrain tile for every world file's tile, with its _y.raw
                             heights and _f.raw flags (MSTS' quadtree tile names)
    TERRTEX/<name>.ace       every terrain texture the tiles name
    TRAINS/CONSISTS/*.con    consists; the .eng/.wag each names (TRAINS/TRAINSET/<folder>/),
                             their shapes and textures

Shapes, terrain and world files go through OpenRails' structured block reader, which refuses
a file without its UTF-16 byte order mark; so does :func:`~openrails_mock.stf.read_stf`.
Every problem is a :class:`~openrails_mock.stf.RouteError` naming the file, line and fix.
"""

from __future__ import annotations

import itertools
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .routefolder import RouteFolder, load_route
from .stf import Block, RouteError, read_stf

SAMPLES = 256
"""Samples per side of a terrain tile (OpenRails' tiles: 256 at 8 m)."""


@dataclass(frozen=True)
class Shape:
    """What a shape file holds, as counted by its reader."""

    points: int
    matrices: tuple[str, ...]
    images: tuple[str, ...]
    triangles: int


@dataclass(frozen=True)
class Texture:
    width: int
    height: int
    pixels: np.ndarray
    """``(height, width, 4)`` RGBA bytes."""


@dataclass(frozen=True)
class Tile:
    floor: float
    scale: float
    heights: np.ndarray
    """``(256, 256)`` float32 heights, rows from the north edge, west to east (OpenRails')."""
    textures: tuple[str, ...]


@dataclass
class RouteContent:
    """Everything :func:`read_content` read, and the files it read."""

    environments: dict[str, int] = field(default_factory=dict)
    """ENVFILES name -> number of sky satellites."""
    track_types: list[tuple[str, str, str]] = field(default_factory=list)
    shapes: dict[str, Shape] = field(default_factory=dict)
    """Shape file path (relative to the route folder) -> shape."""
    textures: dict[str, Texture] = field(default_factory=dict)
    tiles: dict[tuple[int, int], Tile] = field(default_factory=dict)
    consists: dict[str, list[str]] = field(default_factory=dict)
    """Consist name -> its engine and wagon files (relative to the route folder)."""
    files: set[Path] = field(default_factory=set)
    """Every file read."""


def read_content(route: RouteFolder | str | Path) -> RouteContent:
    """Read and check everything OpenRails' viewer opens in a route folder."""
    folder = route if isinstance(route, RouteFolder) else load_route(route)
    root = folder.folder
    content = RouteContent()
    content.files.update(_route_files(folder))
    _environments(root, content)
    _track_types(root, content)
    _signals(folder, content)
    world_files: dict[str, Path] = {}
    for (tile_x, tile_z, _), obj in folder.objects.items():
        if obj.kind in ("Static", "Signal", "TrackObj") and obj.file_name:
            world_files.setdefault(obj.file_name, _world_file(root, tile_x, tile_z))
    for name, referrer in sorted(world_files.items()):
        path = _need(root / "SHAPES", name, referrer, "the shape a world object names")
        _shape(path, root, root / "TEXTURES", content)
    for tile in sorted({(x, z) for x, z, _ in folder.objects} | _world_tiles(root)):
        _tile(root, tile, content)
    consists = _folder(root / "TRAINS" / "CONSISTS")
    for path in sorted(consists.iterdir()) if consists else []:
        if path.suffix.lower() == ".con":
            _consist(path, root, content)
    return content


# -- helpers ----------------------------------------------------------------------------------


def _folder(path: Path) -> Path | None:
    """``path`` found case-insensitively (routes come from Windows)."""
    current = Path(path.anchor) if path.is_absolute() else Path(".")
    for part in path.parts[1:] if path.is_absolute() else path.parts:
        if not current.is_dir():
            return None
        match = next((c for c in current.iterdir() if c.name.lower() == part.lower()), None)
        if match is None:
            return None
        current = match
    return current


def _need(folder: Path, name: str, referrer: Path, what: str) -> Path:
    found = _folder(folder / name)
    if found is None or not found.is_file():
        raise RouteError(
            referrer,
            None,
            f"names {name}, {what}, which is not in {folder}",
            "export the route again, or add the file",
        )
    return found


def _world_file(root: Path, tile_x: int, tile_z: int) -> Path:
    return root / "WORLD" / f"w{tile_x:+07d}{tile_z:+07d}.w"


def _world_tiles(root: Path) -> set[tuple[int, int]]:
    world = _folder(root / "WORLD")
    tiles = set()
    for path in world.iterdir() if world else []:
        name = path.name.lower()
        if name.startswith("w") and name.endswith(".w") and len(name) == 17:
            tiles.add((int(name[1:8]), int(name[8:15])))
    return tiles


def _route_files(folder: RouteFolder) -> set[Path]:
    """The files :func:`~openrails_mock.routefolder.load_route` and the path reader read."""
    root = folder.folder
    found = {folder.tdb_file, *(p for p in root.iterdir() if p.suffix.lower() == ".trk")}
    for name in ("tsection.dat", "OpenRails/tsection.dat"):
        path = _folder(root / name)
        if path is not None:
            found.add(path)
    for sub, suffix in (("WORLD", ".w"), ("PATHS", ".pat")):
        directory = _folder(root / sub)
        if directory is not None:
            found.update(p for p in directory.iterdir() if p.suffix.lower() == suffix)
    return found


def _counted(block: Block, child: str, what: str) -> list[Block]:
    return block.declared(child, what)


# -- environments and track types -------------------------------------------------------------


def _environments(root: Path, content: RouteContent) -> None:
    track = next(p for p in root.iterdir() if p.suffix.lower() == ".trk")
    route = read_stf(track).block("Tr_RouteFile")
    environment = route.block("Environment")
    entries = [b for b in environment.items if isinstance(b, Block)]
    if len(entries) != 12:
        raise environment.error(
            f"Environment names {len(entries)} files; OpenRails reads twelve (four seasons by "
            "clear, rain and snow)",
            "give SpringClear ( sun.env ) ... WinterSnow ( snow.env )",
        )
    for entry in entries:
        name = entry.text(0, "the environment file")
        if name in content.environments:
            continue
        path = _need(root / "ENVFILES", name, track, f"the {entry.name} environment")
        world = read_stf(path).block("world")
        satellites = world.block("world_sky").block("world_sky_satellites")
        found = _counted(satellites, "world_sky_satellite", "sky satellites")
        for satellite in found:
            for token in ("world_sky_satellite_rise_time", "world_sky_satellite_set_time"):
                time = satellite.block(token).text(0, "the time")
                parts = time.split(":")
                if len(parts) != 3 or not all(p.isdigit() for p in parts):
                    raise satellite.error(f"{token} is {time!r}", "write HH:MM:SS")
        content.environments[name] = len(found)
        content.files.add(path)


def _track_types(root: Path, content: RouteContent) -> None:
    path = _folder(root / "TTYPE.DAT")
    if path is None:
        raise RouteError(root, None, "has no TTYPE.DAT", "export the route again")
    top = read_stf(path)
    count = top.integer(0, "the number of track types")
    types = top.blocks("TrackType")
    if count != len(types):
        raise top.error(
            f"declares {count} track types but holds {len(types)}", "give the number it holds"
        )
    for block in types:
        content.track_types.append(
            (
                block.text(0, "the label"),
                block.text(1, "the inside sound"),
                block.text(2, "the outside sound"),
            )
        )
    content.files.add(path)


def _signals(folder: RouteFolder, content: RouteContent) -> None:
    """sigcfg.dat (OpenRails' grammar: counted tables, ScriptFiles without a count), the light
    textures it names and its script files; every signal shape a world file places is one of
    its SignalShapes."""
    root = folder.folder
    path = _folder(root / "sigcfg.dat")
    if path is None:
        raise RouteError(root, None, "has no sigcfg.dat", "export the route again")
    config = read_stf(path)
    for texture in _counted(config.block("LightTextures"), "LightTex", "light textures"):
        found = _need(root / "TEXTURES", texture.text(1, "the texture"), path, "a light texture")
        content.textures[str(found.relative_to(root))] = _texture(found)
        content.files.add(found)
    _counted(config.block("LightsTab"), "LightsTabEntry", "lights")
    types = [
        t.text(0, "the type")
        for t in _counted(config.block("SignalTypes"), "SignalType", "signal types")
    ]
    shapes = {
        s.text(0, "the shape").lower()
        for s in _counted(config.block("SignalShapes"), "SignalShape", "signal shapes")
    }
    for obj in folder.objects.values():
        if obj.kind == "Signal" and obj.file_name.lower() not in shapes:
            raise RouteError(
                _world_file(root, *obj.tile),
                None,
                f"places signal shape {obj.file_name}, which sigcfg.dat does not describe",
                "add it to SignalShapes",
            )
    scripts = config.block("ScriptFiles")
    if scripts.values:
        raise scripts.error(
            f"ScriptFiles holds {scripts.values[0]!r} before its ScriptFile blocks; OpenRails "
            "reads no count there",
            "write ScriptFiles ( ScriptFile ( name ) ... )",
        )
    for script in scripts.blocks("ScriptFile"):
        found = _need(root, script.text(0, "the script"), path, "a signal script")
        data = found.read_bytes()
        text = data[2:].decode("utf-16-le") if data.startswith(b"\xff\xfe") else data.decode()
        for name in types:
            if f"SCRIPT {name}".lower() not in text.lower():
                raise RouteError(found, None, f"has no SCRIPT {name}", "add the type's script")
        content.files.add(found)
    content.files.add(path)


# -- shapes and textures ----------------------------------------------------------------------

_SHAPE_ORDER = (
    "shape_header", "volumes", "shader_names", "texture_filter_names", "points", "uv_points",
    "normals", "sort_vectors", "colours", "matrices", "images", "textures", "light_materials",
    "light_model_cfgs", "vtx_states", "prim_states", "lod_controls",
)  # fmt: skip


def _labelled(block: Block, kind: str) -> list[tuple[str, Block]]:
    """``kind NAME ( ... )`` items (a matrix, a prim_state): the word, then a block named by
    the label."""
    found = []
    items = block.items
    for item, following in itertools.pairwise(items):
        if item == kind and isinstance(following, Block):
            found.append((following.name, following))
    return found


def _shape(path: Path, root: Path, textures: Path, content: RouteContent) -> Shape:
    key = str(path.relative_to(root))
    if key in content.shapes:
        return content.shapes[key]
    shape = read_stf(path).block("shape")
    order = [b.name.lower() for b in shape.items if isinstance(b, Block)]
    if order[: len(_SHAPE_ORDER)] != list(_SHAPE_ORDER):
        raise shape.error(
            f"holds {', '.join(order)}; OpenRails reads {', '.join(_SHAPE_ORDER)} in this order",
            "write the shape's blocks in OpenRails' order",
        )
    points = len(_counted(shape.block("points"), "point", "points"))
    uvs = len(_counted(shape.block("uv_points"), "uv_point", "uv points"))
    normals = len(_counted(shape.block("normals"), "vector", "normals"))
    matrices_block = shape.block("matrices")
    matrices = _labelled(matrices_block, "matrix")
    if matrices_block.integer(0, "the number of matrices") != len(matrices):
        raise matrices_block.error("declares another number of matrices", "count them")
    images = [b.text(0, "the image") for b in _counted(shape.block("images"), "image", "images")]
    texture_blocks = _counted(shape.block("textures"), "texture", "textures")
    for texture in texture_blocks:
        if not 0 <= texture.integer(0, "the image index") < len(images):
            raise texture.error("names an image the shape does not have", "fix the index")
    states = _labelled(shape.block("prim_states"), "prim_state")
    for _, state in states:
        for index in state.block("tex_idxs").values[1:]:
            if not 0 <= int(index) < len(texture_blocks):
                raise state.error("names a texture the shape does not have", "fix tex_idxs")
    triangles = 0
    for lod in _counted(shape.block("lod_controls"), "lod_control", "levels of detail"):
        for level in _counted(lod.block("distance_levels"), "distance_level", "levels"):
            hierarchy = level.block("distance_level_header").block("hierarchy")
            if hierarchy.integer(0, "the hierarchy's size") != len(matrices):
                raise hierarchy.error("has not one entry per matrix", "give one per matrix")
            for sub in _counted(level.block("sub_objects"), "sub_object", "sub-objects"):
                triangles += _sub_object(sub, points, normals, uvs, len(matrices), len(states))
    for image in images:
        found = _need(textures, image, path, "an image of the shape")
        content.textures[str(found.relative_to(root))] = _texture(found)
        content.files.add(found)
    result = Shape(points, tuple(name for name, _ in matrices), tuple(images), triangles)
    content.shapes[key] = result
    content.files.add(path)
    return result


def _sub_object(sub: Block, points: int, normals: int, uvs: int, matrices: int, states: int) -> int:
    header = sub.block("sub_object_header")
    node_map = header.block("geometry_info").block("geometry_node_map")
    if node_map.integer(0, "the map's size") != matrices:
        raise node_map.error("has not one entry per matrix", "give one per matrix")
    listed = _counted(sub.block("vertices"), "vertex", "vertices")
    for vertex in listed:
        if not (
            0 <= vertex.integer(1, "the point") < points
            and 0 <= vertex.integer(2, "the normal") < normals
            and all(0 <= int(u) < uvs for u in vertex.block("vertex_uvs").values[1:])
        ):
            raise vertex.error("names a point, normal or uv the shape does not have", "fix it")
    total = 0
    for vertex_set in _counted(sub.block("vertex_sets"), "vertex_set", "vertex sets"):
        if not 0 <= vertex_set.integer(0, "the vertex state") < matrices:
            raise vertex_set.error("names a vertex state the shape does not have", "fix it")
        total += vertex_set.integer(2, "the vertex count")
    if total != len(listed):
        raise sub.error(f"its vertex sets cover {total} of {len(listed)} vertices", "cover all")
    primitives = sub.block("primitives")
    blocks = [b for b in primitives.items if isinstance(b, Block)]
    if primitives.integer(0, "the number of primitives") != len(blocks):
        raise primitives.error("declares another number of primitives", "count them")
    triangles = 0
    for block in blocks:
        if block.name.lower() == "prim_state_idx":
            if not 0 <= block.integer(0, "the primitive state") < states:
                raise block.error("names a primitive state the shape does not have", "fix it")
            continue
        indices = block.block("vertex_idxs")
        count = indices.integer(0, "the number of indices")
        values = [int(v) for v in indices.values[1:]]
        if count != len(values) or count % 3 or not all(0 <= v < len(listed) for v in values):
            raise indices.error("is not a list of triangles of the shape's vertices", "fix it")
        triangles += count // 3
        if block.block("normal_idxs").integer(0, "the number of normals") != count // 3:
            raise block.error("has not one normal per triangle", "give one per triangle")
        if block.block("flags").integer(0, "the number of flags") != count // 3:
            raise block.error("has not one flag per triangle", "give one per triangle")
    return triangles


def _texture(path: Path) -> Texture:
    """An uncompressed ACE texture as OpenRails' AceFile reads its structured form."""
    data = path.read_bytes()

    def bad(problem: str) -> RouteError:
        return RouteError(path, None, problem, "write an uncompressed ACE texture")

    if not data.startswith(b"SIMISA@@@@@@@@@@"):
        raise bad(f"starts with {data[:16]!r}, not SIMISA@@@@@@@@@@ (compressed or no ACE)")
    base = 16
    if len(data) < base + 24 + 128:
        raise bad("is shorter than an ACE header")
    one, options, width, height, _, count = struct.unpack_from("<6i", data, base)
    if one != 1 or options & 0x10 or not (0 < width <= 4096 and 0 < height <= 4096):
        raise bad(f"has header {one} {options} {width}x{height}, not a structured image")
    at = base + 24 + 128
    kinds = []
    for _ in range(count):
        bits, kind = struct.unpack_from("<2Q", data, at)
        if bits not in (1, 8) or not 2 <= kind <= 6:
            raise bad(f"has a channel of {bits} bits of type {kind}")
        kinds.append((bits, kind))
        at += 16
    offsets = struct.unpack_from(f"<{height}i", data, at)
    pixels = np.zeros((height, width, 4), dtype=np.uint8)
    pixels[:, :, 3] = 255
    for y, offset in enumerate(offsets):
        start = base + offset
        for bits, kind in kinds:
            size = (width * bits + 7) // 8
            if start + size > len(data):
                raise bad(f"has scan line {y} beyond its end")
            plane = np.frombuffer(data, np.uint8, size, start)
            if bits == 1:
                plane = np.unpackbits(plane)[:width] * 255
            pixels[y, :, {3: 0, 4: 1, 5: 2, 6: 3, 2: 3}[kind]] = plane
            start += size
    return Texture(width, height, pixels)


# -- terrain ----------------------------------------------------------------------------------


def tile_name(tile_x: int, tile_z: int) -> str:
    """MSTS' name of a 2048 m terrain tile: the quadtree path to it, two bits a level (north
    0 / south 2, plus 1 when east and north agree), two levels a hex digit, ``-`` first."""
    left = bottom = -16384
    half = 16384
    digits, partial = [], 0
    for level in range(15):
        east, north = tile_x >= left + half, tile_z >= bottom + half
        partial = partial * 4 + (0 if north else 2) + (1 if east == north else 0)
        if level % 2:
            digits.append(partial)
            partial = 0
        left += half if east else 0
        bottom += half if north else 0
        half //= 2
    digits.append(partial * 4)
    return "-" + "".join(f"{d:X}" for d in digits)


def _tile(root: Path, tile: tuple[int, int], content: RouteContent) -> None:
    name = tile_name(*tile)
    t_file = _folder(root / "TILES" / f"{name}.t")
    world = _world_file(root, *tile)
    if t_file is None:
        raise RouteError(
            world, None, f"has no terrain tile TILES/{name}.t", "export the route again"
        )
    terrain = read_stf(t_file).block("terrain")
    samples = terrain.block("terrain_samples")
    count = samples.block("terrain_nsamples").integer(0, "the number of samples")
    size = samples.block("terrain_sample_size").real(0, "the sample size")
    if (count, size) != (SAMPLES, 8.0):
        raise samples.error(f"has {count} samples of {size:g} m", "give 256 samples of 8 m")
    floor = np.float32(samples.block("terrain_sample_floor").real(0, "the floor"))
    scale = np.float32(samples.block("terrain_sample_scale").real(0, "the scale"))
    buffers = {}
    for kind, width in (("y", 2), ("f", 1)):
        named = samples.block(f"terrain_sample_{kind}buffer").text(0, "the buffer")
        path = _need(t_file.parent, named, t_file, f"its {kind} buffer")
        data = path.read_bytes()
        if len(data) != SAMPLES * SAMPLES * width:
            raise RouteError(
                path,
                None,
                f"holds {len(data)} bytes, not {SAMPLES * SAMPLES * width}",
                "write one value per sample",
            )
        buffers[kind] = data
        content.files.add(path)
    for kind in ("e", "n"):  # named, present, not read by OpenRails' viewer
        block = samples.optional(f"terrain_sample_{kind}buffer")
        if block is not None:
            content.files.add(_need(t_file.parent, block.text(0, "the buffer"), t_file, "a buffer"))
    values = np.frombuffer(buffers["y"], dtype="<u2").reshape(SAMPLES, SAMPLES)
    heights = values.astype(np.float32) * scale + floor
    shaders = terrain.block("terrain_shaders")
    slots: list[str] = []
    for shader in _counted(shaders, "terrain_shader", "terrain shaders"):
        texslots = shader.block("terrain_texslots")
        for slot in _counted(texslots, "terrain_texslot", "texture slots"):
            name_ = slot.text(0, "the texture")
            path = _need(root / "TERRTEX", name_, t_file, "a terrain texture")
            content.textures[str(path.relative_to(root))] = _texture(path)
            content.files.add(path)
            slots.append(name_)
    patchsets = terrain.block("terrain_patches").block("terrain_patchsets")
    for patchset in _counted(patchsets, "terrain_patchset", "patch sets"):
        n = patchset.block("terrain_patchset_npatches").integer(0, "the patches per side")
        patches = patchset.block("terrain_patchset_patches").blocks("terrain_patchset_patch")
        if len(patches) != n * n:
            raise patchset.error(f"holds {len(patches)} patches, not {n} x {n}", "give them all")
    content.tiles[tile] = Tile(float(floor), float(scale), heights, tuple(slots))
    content.files.add(t_file)


# -- consists ---------------------------------------------------------------------------------


def _consist(path: Path, root: Path, content: RouteContent) -> None:
    config = read_stf(path).block("Train").block("TrainCfg")
    stock = []
    for car in (b for b in config.items if isinstance(b, Block)):
        if car.name.lower() not in ("engine", "wagon"):
            continue
        data = car.optional("EngineData") or car.optional("WagonData")
        if data is None:
            raise car.error(f"{car.name} has no EngineData or WagonData", "add ( name folder )")
        name, folder = data.text(0, "the file"), data.text(1, "the folder")
        suffix = ".eng" if data.name.lower() == "enginedata" else ".wag"
        trainset = root / "TRAINS" / "TRAINSET" / folder
        file = _need(trainset, name + suffix, path, f"the {car.name.lower()}")
        wagon = read_stf(file).block("Wagon")
        shape = wagon.block("WagonShape").text(0, "the shape")
        _shape(_need(trainset, shape, file, "its shape"), root, trainset, content)
        if suffix == ".eng":
            read_stf(file).block("Engine")
        stock.append(str(file.relative_to(root)))
        content.files.add(file)
    if not stock:
        raise config.error("holds no Engine or Wagon", "add them")
    content.consists[config.text(0, "the consist's name")] = stock
    content.files.add(path)
