"""MSTS shapes (``.s``) in their text form, built from coloured boxes.

The grammar is the one OpenRails' ``ShapeFile`` reads, block by block in this order: shape
header, bounding volume, shader and filter names, points, uv points, normals, sort vectors,
colours, matrices, images, textures, light materials and models, vertex states (one per
matrix), primitive states (one per texture), then one level of detail holding one sub-object:
its header (geometry info with one geometry node per matrix), vertices (point, normal, uv),
vertex sets (the vertices of each matrix) and primitives (``prim_state_idx`` then an
``indexed_trilist`` of triangles, normals and flags). Coordinates are MSTS': x right, y up,
z ahead, metres from the object's origin. Every face is written with both windings so it shows
from either side whatever the renderer culls.

A shape's textures are single colours (:mod:`coupler_railway.openrails.ace`), one image per
colour, found by OpenRails in the route's ``TEXTURES`` folder (or beside rolling stock).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from coupler_railway.openrails.stf import StfWriter, number

COLOURS: dict[str, tuple[int, int, int, int]] = {
    "CouplerYellow.ace": (255, 204, 0, 255),
    "CouplerGrey.ace": (128, 128, 128, 255),
    "CouplerBlack.ace": (20, 20, 20, 255),
    "CouplerRed.ace": (190, 30, 30, 255),
    "CouplerBlue.ace": (40, 70, 160, 255),
}
"""The route's and the stock's texture files and their colours (RGBA)."""

_NORMALS = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))
_UVS = ((0, 0), (1, 0), (1, 1), (0, 1))


@dataclass(frozen=True)
class Box:
    """An axis-parallel box from ``low`` to ``high`` (x, y, z), in one colour, drawn by one
    of the shape's matrices."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]
    texture: str
    matrix: int = 0


@dataclass
class Shape:
    """A shape: named matrices (the first is MAIN; a signal's head is a matrix of its own,
    named as sigcfg.dat's sub-object) and the boxes they draw."""

    boxes: list[Box]
    matrices: list[tuple[str, tuple[float, float, float]]] = field(
        default_factory=lambda: [("MAIN", (0.0, 0.0, 0.0))]
    )
    """``(name, translation)``, each the child of MAIN (MAIN's parent is none)."""

    @property
    def textures(self) -> list[str]:
        return sorted({box.texture for box in self.boxes})


def _faces(box: Box) -> list[tuple[int, list[tuple[float, float, float]]]]:
    """``(normal index, four corners)`` of each face of a box."""
    (x0, y0, z0), (x1, y1, z1) = box.low, box.high
    return [
        (0, [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)]),
        (1, [(x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (x0, y0, z0)]),
        (2, [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)]),
        (3, [(x0, y0, z1), (x0, y0, z0), (x1, y0, z0), (x1, y0, z1)]),
        (4, [(x1, y0, z1), (x1, y1, z1), (x0, y1, z1), (x0, y0, z1)]),
        (5, [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)]),
    ]


def shape_text(shape: Shape) -> StfWriter:
    """The shape as STF text (``SIMISA@@@@@@@@@@JINX0s1t______``)."""
    textures = shape.textures
    matrices = len(shape.matrices)
    points: list[tuple[float, float, float]] = []
    vertices: list[tuple[int, int, int]] = []  # point, normal, uv
    vertex_sets: list[tuple[int, int, int]] = []  # matrix, first vertex, count
    triangles: dict[int, list[tuple[int, int, int, int]]] = {}  # texture -> (a, b, c, normal)
    for matrix in range(matrices):
        first = len(vertices)
        for box in (b for b in shape.boxes if b.matrix == matrix):
            for normal, corners in _faces(box):
                base = len(vertices)
                for corner, uv in zip(corners, range(4), strict=True):
                    points.append(corner)
                    vertices.append((len(points) - 1, normal, uv))
                flipped = normal ^ 1  # the opposite normal (pairs 0/1, 2/3, 4/5)
                triangles.setdefault(textures.index(box.texture), []).extend(
                    [
                        (base, base + 1, base + 2, normal),
                        (base, base + 2, base + 3, normal),
                        (base + 2, base + 1, base, flipped),
                        (base + 3, base + 2, base, flipped),
                    ]
                )
        vertex_sets.append((matrix, first, len(vertices) - first))
    low = [min(p[i] for p in points) for i in range(3)]
    high = [max(p[i] for p in points) for i in range(3)]
    centre = [(a + b) / 2.0 for a, b in zip(low, high, strict=True)]
    radius = max(sum((p[i] - centre[i]) ** 2 for i in range(3)) ** 0.5 for p in points)

    stf = StfWriter("JINX0s1t")
    stf.block("shape")
    stf.line("shape_header", "00000000", "00000000")
    stf.block("volumes", 1)
    stf.line("vol_sphere", _Raw(f"vector ( {_xyz(centre)} )"), radius)
    stf.end()
    stf.block("shader_names", 1)
    stf.line("named_shader", "TexDiff")
    stf.end()
    stf.block("texture_filter_names", 1)
    stf.line("named_filter_mode", "MipLinear")
    stf.end()
    _table(stf, "points", "point", points)
    _table(stf, "uv_points", "uv_point", _UVS)
    _table(stf, "normals", "vector", _NORMALS)
    stf.line("sort_vectors", 0)
    stf.line("colours", 0)
    stf.block("matrices", matrices)
    for name, (dx, dy, dz) in shape.matrices:
        stf.line(f"matrix {name}", 1, 0, 0, 0, 1, 0, 0, 0, 1, dx, dy, dz)
    stf.end()
    stf.block("images", len(textures))
    for texture in textures:
        stf.line("image", texture)
    stf.end()
    stf.block("textures", len(textures))
    for index in range(len(textures)):
        stf.line("texture", index, 0, -3, "ff000000")
    stf.end()
    stf.line("light_materials", 0)
    stf.block("light_model_cfgs", 1)
    stf.line("light_model_cfg", "00000000", _Raw("uv_ops ( 1 uv_op_copy ( 1 0 ) )"))
    stf.end()
    stf.block("vtx_states", matrices)
    for matrix in range(matrices):
        stf.line("vtx_state", "00000000", matrix, -5, 0, "00000002")
    stf.end()
    stf.block("prim_states", len(textures))
    for index, texture in enumerate(textures):
        name = texture.removesuffix(".ace")
        stf.line(
            f"prim_state {name}", "00000000", 0, _Raw(f"tex_idxs ( 1 {index} )"), 0, 0, 0, 0, 1
        )
    stf.end()
    stf.block("lod_controls", 1)
    stf.block("lod_control")
    stf.line("distance_levels_header", 0)
    stf.block("distance_levels", 1)
    stf.block("distance_level")
    stf.block("distance_level_header")
    stf.line("dlevel_selection", 2000)
    stf.line("hierarchy", matrices, -1, *([0] * (matrices - 1)))
    stf.end()
    stf.block("sub_objects", 1)
    stf.block("sub_object")
    stf.block("sub_object_header", "00000400", -1, -1, "000001d2", "000001c4")
    stf.block("geometry_info", 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    stf.block("geometry_nodes", matrices)
    for _ in range(matrices):
        stf.line("geometry_node", 2, 0, 0, 0, 0, _Raw("cullable_prims ( 0 0 0 )"))
    stf.end()
    stf.line("geometry_node_map", matrices, *range(matrices))
    stf.end()
    stf.line("subobject_shaders", 1, 0)
    stf.line("subobject_light_cfgs", 1, 0)
    stf.values(0)
    stf.end()
    stf.block("vertices", len(vertices))
    for point, normal, uv in vertices:
        stf.line(
            "vertex",
            "00000000",
            point,
            normal,
            "ffffffff",
            "ff000000",
            _Raw(f"vertex_uvs ( 1 {uv} )"),
        )
    stf.end()
    stf.block("vertex_sets", len(vertex_sets))
    for matrix, first, count in vertex_sets:
        stf.line("vertex_set", matrix, first, count)
    stf.end()
    stf.block("primitives", 2 * len(triangles))
    for image, tris in sorted(triangles.items()):
        stf.line("prim_state_idx", image)
        stf.block("indexed_trilist")
        stf.line("vertex_idxs", 3 * len(tris), *(i for a, b, c, _ in tris for i in (a, b, c)))
        stf.line("normal_idxs", len(tris), *(v for *_, n in tris for v in (n, 3)))
        stf.line("flags", len(tris), *(["00000000"] * len(tris)))
        stf.end()
    stf.end()
    for _ in range(6):  # sub_object, sub_objects, distance_level(s), lod_control(s)
        stf.end()
    stf.end()  # shape
    return stf


class _Raw(str):
    """A nested block written inline, as is."""


def _xyz(values: list[float]) -> str:
    return " ".join(number(v) for v in values)


def _table(stf: StfWriter, name: str, item: str, rows: Sequence[Sequence[float | int]]) -> None:
    stf.block(name, len(rows))
    for row in rows:
        stf.line(item, *row)
    stf.end()


def save_shape(path: Path, shape: Shape) -> Path:
    return shape_text(shape).save(path)


# -- the route's shapes -----------------------------------------------------------------------


def balise() -> Shape:
    """A Eurobalise between the rails: 491 x 58 x 358 mm (across, up, along), yellow, its top
    at sleeper height (0.2 m above the track's origin)."""
    return Shape([Box((-0.2455, 0.142, -0.179), (0.2455, 0.2, 0.179), "CouplerYellow.ace")])


SIGNAL_HEAD = "HEAD1"
"""The signal head's matrix: sigcfg.dat's SignalSubObj and its lights refer to it."""


def signal() -> Shape:
    """A main signal: a grey mast and a black head (its own matrix, HEAD1) facing the trains
    it governs (its lights, drawn by OpenRails from sigcfg.dat, at 3 and 3.5 m)."""
    return Shape(
        [
            Box((-0.08, 0.0, -0.08), (0.08, 4.0, 0.08), "CouplerGrey.ace"),
            Box((-0.25, 2.6, 0.08), (0.25, 3.9, 0.25), "CouplerBlack.ace", matrix=1),
        ],
        [("MAIN", (0.0, 0.0, 0.0)), (SIGNAL_HEAD, (0.0, 0.0, 0.0))],
    )


def switch_stand() -> Shape:
    """A switch stand 2.2 m right of the trunk, at the junction."""
    return Shape([Box((2.0, 0.0, -0.3), (2.5, 1.0, 0.3), "CouplerGrey.ace")])


def vehicle(length: float, width: float, height: float, body: str) -> Shape:
    """Placeholder rolling stock: a body box on a black underframe, centred on the origin
    along the track (OpenRails' origin of a car: its centre, at rail height)."""
    half, side = length / 2.0, width / 2.0
    return Shape(
        [
            Box((-side, 0.3, -half), (side, 1.2, half), "CouplerBlack.ace"),
            Box((-side, 1.2, -half), (side, height, half), body),
        ]
    )
