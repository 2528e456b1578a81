"""The plates' shapes: procedural outlines, meshes (procedural or the
release's files) and quadrature samples on the wall-facing face.

Frame and units as in `objects`: local metres, +z away from the wall, areas
m^2. Conventions shared with the real release's meshes (docs/deviations.md,
section 2): largest dimension SIZES[size], centred in x, bottom edge at
y = BOTTOM_Y, glyphs mirrored in x so that they read correctly from the
wall. Where the release's meshes break these rules (off-centre A/minus, an
up-pointing `downarrow`, ...) the procedural meshes follow the rules instead.
"""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

import numpy as np
import shapely
import trimesh
from shapely import affinity
from shapely.geometry import MultiPolygon, Point, Polygon, box

from denali_pipe.core.objects import BASE_SHAPES, BOTTOM_Y, ITALIC_SHEAR_DEG, SIZES, THICKNESS, ObjectSpec, class_type

# --- procedural outlines ------------------------------------------------------------

_FONT_FILE = "DejaVuSans-Bold.ttf"  # bundled with matplotlib; bold strokes like real cut-outs
# DejaVu Sans's capital I is a bare bar; the real cut-out is a serifed I (so it
# cannot be confused with 1 or a rotated minus), so I comes from the serif face.
_FONT_FOR = {"I": "DejaVuSerif-Bold.ttf"}
_GLYPH_PT = 500.0  # TextPath size; the curve flattening is in these units, so larger = finer
_BAR = 0.3  # stroke of plus/minus as a fraction of the largest dimension


def _rings_to_geometry(rings: list[np.ndarray]) -> Polygon | MultiPolygon:
    """Closed rings -> a polygon by the even-odd rule.

    The font's contour winding is not consistent between glyphs, but contours
    never overlap, so XOR-ing the rings turns every inner ring into a hole.
    """
    polys = [shapely.make_valid(Polygon(r)) for r in rings if len(r) >= 4]
    return functools.reduce(shapely.symmetric_difference, polys)


def _font(ch: str):
    """matplotlib FontProperties of the bundled face used for glyph `ch`."""
    import matplotlib
    from matplotlib.font_manager import FontProperties

    # by file, not family name, so no system font can stand in for it
    font = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / _FONT_FOR.get(ch, _FONT_FILE)
    return FontProperties(fname=str(font))


@functools.lru_cache(maxsize=None)
def _glyph_raw(ch: str) -> Polygon | MultiPolygon:
    """The glyph as it reads on paper (unmirrored), in font units."""
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), ch, size=_GLYPH_PT, prop=_font(ch))
    return _rings_to_geometry(path.to_polygons(closed_only=True))


def _arrow_up() -> Polygon:
    """An up-pointing arrow 0.8 wide by 1 tall: a triangular head on a shaft."""
    w, head, shaft = 0.8, 0.4, 0.35
    return Polygon(
        [(-shaft / 2, 0), (shaft / 2, 0), (shaft / 2, 1 - head), (w / 2, 1 - head),
         (0, 1), (-w / 2, 1 - head), (-shaft / 2, 1 - head)]
    )  # fmt: skip


def _shape_raw(cls: str) -> Polygon:
    """A geometric shape in arbitrary units (the caller normalises the size)."""
    if cls == "circle":
        return Point(0, 0).buffer(0.5, quad_segs=32)  # a filled disc (the letter O is a ring)
    if cls == "halfcircle":
        # the flat edge down, so it stands on the mount
        return Point(0, 0).buffer(0.5, quad_segs=32).intersection(box(-1, 0, 1, 1))
    if cls == "hexagon":
        # flat top and bottom, so it stands on an edge
        a = np.deg2rad(np.arange(6) * 60.0)
        return Polygon(np.c_[np.cos(a), np.sin(a)] * 0.5)
    if cls == "minus":
        return box(-0.5, -_BAR / 2, 0.5, _BAR / 2)
    if cls == "plus":
        return box(-0.5, -_BAR / 2, 0.5, _BAR / 2).union(box(-_BAR / 2, -0.5, _BAR / 2, 0.5))
    if cls == "square":
        return box(-0.5, -0.5, 0.5, 0.5)
    if cls == "triangle":
        return Polygon([(-0.5, 0), (0.5, 0), (0, math.sqrt(3) / 2)])  # equilateral, base down
    if cls == "uparrow":
        return _arrow_up()
    if cls == "downarrow":
        # pointing down as the label says (the release's mesh points up; see module docstring)
        return affinity.scale(_arrow_up(), 1, -1, origin=(0, 0))
    if cls == "widerectangle":
        return box(-0.5, -0.25, 0.5, 0.25)
    raise ValueError(f"unknown shape class {cls!r}")


def _normalise(geom, largest: float):
    """Scale to `largest` (m) along the longer side, centre in x, bottom at BOTTOM_Y."""
    x0, y0, x1, y1 = geom.bounds
    s = largest / max(x1 - x0, y1 - y0)
    return affinity.affine_transform(geom, [s, 0, 0, s, -s * (x0 + x1) / 2, BOTTOM_Y - s * y0])


@functools.lru_cache(maxsize=None)
def outline(cls: str, size: str, italic: bool = False) -> Polygon | MultiPolygon:
    """The plate's outline in its local XY plane, metres.

    Largest dimension SIZES[size], centred in x, bottom edge at y = BOTTOM_Y;
    mirrored (x -> -x) so glyphs read correctly from the wall (local +z points
    away from it). `italic` shears the reading-side outline by
    x += tan(12 deg) * y before mirroring, so the slant leans forward as seen
    from the wall, then re-normalises the size.
    """
    if cls not in BASE_SHAPES:
        raise ValueError(f"unknown object class {cls!r}; expected one of {BASE_SHAPES}")
    if size not in SIZES:
        raise ValueError(f"unknown size {size!r}; expected one of {list(SIZES)}")
    geom = _shape_raw(cls) if class_type(cls) == "shape" else _glyph_raw(cls)
    if italic:
        geom = affinity.skew(geom, xs=ITALIC_SHEAR_DEG, origin=(0, 0))
    geom = affinity.scale(geom, -1, 1, origin=(0, 0))
    geom = _normalise(geom, SIZES[size])
    return shapely.normalize(geom)


# --- meshes ----------------------------------------------------------------------------


def _extrude(geom: Polygon | MultiPolygon, thickness: float) -> trimesh.Trimesh:
    parts = [trimesh.creation.extrude_polygon(p, thickness, mid_plane=True, engine="earcut") for p in getattr(geom, "geoms", [geom])]
    return parts[0] if len(parts) == 1 else trimesh.util.concatenate(parts)


@functools.lru_cache(maxsize=None)
def _procedural_mesh(cls: str, size: str, italic: bool) -> trimesh.Trimesh:
    return _extrude(outline(cls, size, italic), THICKNESS)


def make_mesh(spec_or_cls: ObjectSpec | str, size: str, italic: bool = False) -> trimesh.Trimesh:
    """Procedural mesh: the outline extruded THICKNESS along local z, z in +-THICKNESS/2.

    `spec_or_cls` is an ObjectSpec (italic if its variant is, or if `italic`)
    or a class label. Returns a fresh, watertight Trimesh in local metres
    (a copy, so callers may transform it without touching the cache).
    """
    if isinstance(spec_or_cls, ObjectSpec):
        cls, italic = spec_or_cls.cls, italic or spec_or_cls.italic
    else:
        cls = spec_or_cls
    return _procedural_mesh(cls, size, bool(italic)).copy()


_FILE_ALIASES = {"halfcircle": ("semicircle", "halfcircle")}


def _inch(size: str) -> str:
    """`4inch` or `4in` -> `4in` (the release's file suffix)."""
    if size in SIZES:
        return size.replace("inch", "in")
    if size.replace("in", "inch") in SIZES:
        return size
    raise ValueError(f"unknown size {size!r}; expected one of {list(SIZES)}")


def load_mesh(folder: str | os.PathLike, cls: str, size: str) -> trimesh.Trimesh:
    """Load a release mesh `<name>_<4in|8in>.obj` from `folder`.

    Handles the release's naming: class `halfcircle` is stored as `semicircle_*`,
    and letters may be either case (`I_8in.obj` but `i_4in.obj`). Returns the
    mesh in local metres. Raises FileNotFoundError naming the folder and the
    names tried.
    """
    folder = Path(folder)
    inch = _inch(size)
    stems = list(dict.fromkeys([*_FILE_ALIASES.get(cls, (cls,)), cls.upper(), cls.lower()]))
    names = [f"{s}_{inch}.obj" for s in stems]
    for name in names:
        p = folder / name
        if p.is_file():
            return trimesh.load(p, force="mesh")
    raise FileNotFoundError(f"no mesh for class {cls!r} size {size!r} in {folder}; tried {names}")


def object_mesh(spec: ObjectSpec, size: str) -> trimesh.Trimesh:
    """The spec's mesh at `size`: its mesh file if the sheet names one, else
    the procedural mesh (sheared for italics)."""
    if size not in spec.sizes:
        raise ValueError(f"object {spec.name!r} has no size {size!r}; it has {spec.sizes}")
    if spec.mesh:
        p = Path(spec.mesh.format(size=size, inch=_inch(size)))
        if not p.is_file():
            raise FileNotFoundError(f"mesh of object {spec.name!r} not found: {p}")
        return trimesh.load(p, force="mesh")
    return make_mesh(spec, size)


# --- samples on the wall-facing face ---------------------------------------------------


def sample_spacing(size: str) -> float:
    """Default sample spacing (m): 20 samples across the largest dimension."""
    return SIZES[size] / 20


def mesh_outline(mesh: trimesh.Trimesh) -> Polygon | MultiPolygon:
    """The union of the wall-facing (-z) faces projected onto local XY, metres."""
    faces = mesh.faces[mesh.face_normals[:, 2] < -0.5]
    tris = shapely.polygons(mesh.vertices[faces][:, :, :2])
    geom = shapely.union_all(tris[shapely.area(tris) > 0])
    # Release meshes are triangle soup: rounding leaves hairline gaps between
    # triangles; closing by 1 micron removes them without changing the area.
    return geom.buffer(1e-6, join_style="mitre").buffer(-1e-6, join_style="mitre")


def front_samples(mesh: trimesh.Trimesh, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic quadrature points on the plate's wall-facing face.

    The face is the outline projected onto local XY at z = -THICKNESS/2 (local
    -z faces the wall). It is cut into the cells of a regular grid of pitch
    `spacing` (m, cell edges at integer multiples of `spacing`): each cell that
    meets the outline gives one point, the centre of a fully covered cell or
    the centroid of the covered part of a partial one (a point inside the
    outline if that centroid is not), weighted by the covered area. The
    weights therefore sum to the outline area up to rounding.

    Returns points (N, 3) in local metres and weights (N,) in m^2.
    """
    if spacing <= 0:
        raise ValueError(f"spacing must be positive, got {spacing}")
    geom = mesh_outline(mesh)
    x0, y0, x1, y1 = geom.bounds
    i = np.arange(math.floor(x0 / spacing), math.ceil(x1 / spacing))
    j = np.arange(math.floor(y0 / spacing), math.ceil(y1 / spacing))
    I, J = np.meshgrid(i, j, indexing="ij")
    cells = shapely.box(I.ravel() * spacing, J.ravel() * spacing, (I.ravel() + 1) * spacing, (J.ravel() + 1) * spacing)
    shapely.prepare(geom)
    parts = shapely.intersection(cells, geom)
    area = shapely.area(parts)
    keep = area > 1e-6 * spacing**2  # drop numerical slivers
    parts, area = parts[keep], area[keep]
    pts = shapely.get_coordinates(shapely.centroid(parts))
    outside = ~shapely.contains_xy(geom, pts[:, 0], pts[:, 1])
    if outside.any():
        pts[outside] = shapely.get_coordinates(shapely.point_on_surface(parts[outside]))
    z = np.full(len(pts), mesh.bounds[0, 2])
    return np.c_[pts, z], area
