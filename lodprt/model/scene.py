"""Scene: triangle meshes with Phong materials, an optional floor, and the grid of point-light samples (SPEC 2).

A scene is given as one of
  * ``"demo"`` -- the embedded default: pymeshlab's bundled bunny (or, where that file is missing, a procedural
    torus with self-shadowing) on a floor, thesis material ``0.88 (L.N) + 0.19 (R.V)^2``;
  * a TOML scene file (``*.toml``, format in ``docs/SCENE.md``);
  * a bare mesh path (OBJ, PLY, STL, OFF, GLB/GLTF): that mesh with the thesis material, no floor, default lights.

Meshes are read by ``lodprt.model.meshio`` keeping the file's vertex order: store vertex ``i`` of an object is vertex
``i`` of its file. Objects are concatenated in file order, the floor last. Coordinates are y-up; an object's
``up`` key turns a z-up (or x-up) file upright.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import tomllib
from pathlib import Path

import numpy as np

from lodprt.errors import SceneError, is_whole
from lodprt.model.meshio import (  # noqa: F401  (load_mesh is public)
    COORDINATE_LIMIT, UP_AXES, load_mesh, mesh_name, referenced_mask, require_file,
)

log = logging.getLogger(__name__)

#: Thesis chapter 4.1 material: 0.88 (L.N) + 0.19 (R.V)^2.
THESIS_KD = (0.88, 0.88, 0.88)
THESIS_KS = 0.19
THESIS_SHININESS = 2.0

FALLOFFS = ("inverse-square", "none")

_OBJECT_KEYS = {"mesh", "name", "kd", "ks", "shininess", "scale", "translate", "up", "rotate", "mirror"}
_FLOOR_KEYS = {"resolution", "margin", "kd", "ks", "shininess", "mirror"}
_LIGHT_KEYS = {"grid", "box", "intensity", "falloff", "radius"}
_TOP_KEYS = {"object", "floor", "lights"}

#: Most light samples a scene may ask for (product of ``lights.grid``): every sample is a group of the store
#: (``samples/00000`` ...), baked and written in full, and five digits keep the groups in sample order.
MAX_LIGHT_SAMPLES = 100_000

#: Largest ``floor.resolution``: 4096^2 = 16.8 M floor vertices, about 2 GB of positions, faces and normals on the
#: host before the bake starts.
MAX_FLOOR_RESOLUTION = 4096

# The kernels compute in float32 (largest finite value about 3.4e38): irradiance 1/max(d, radius)^2 is at most
# 1/MIN_RADIUS^2 = 1e24, and times kd or ks (at most MATERIAL_LIMIT) and the SH basis stays far below it.
#: Smallest light radius; the default radius is 1e-3 scene diagonals, hence MIN_SCENE_DIAGONAL.
MIN_RADIUS = 1e-12
#: Smallest bounding diagonal of the referenced vertices (a 1e-20 scene bakes to NaN: squares underflow float32).
MIN_SCENE_DIAGONAL = 1e-9
#: Largest kd (each channel) and ks.
MATERIAL_LIMIT = 1e6
#: Largest light intensity (each channel); radiance = coefficients x intensity is returned as float32.
INTENSITY_LIMIT = 1e12
#: Largest radiance a scene may reach, intensity x (kd + ks) / radius^2 at a light's own radius: each limit above
#: holds alone, but their product (1e42) would overflow float32 (3.4e38); two orders of magnitude are left for the
#: SH basis and the sums over samples.
RADIANCE_LIMIT = 1e36


@dataclasses.dataclass(frozen=True)
class Material:
    """Phong material ``kd (L.N) + ks max(R.s, 0)^shininess`` (SPEC 2).

    ``mirror``: the surface is also a perfect mirror of reflectance ``ks`` (<= 1) whose specular bounce the
    interreflected transfer bake follows, so caustics reach diffuse receivers (docs/ENVIRONMENT.md, "Mirror
    paths"); the point-light bake ignores it.
    """

    kd: tuple[float, float, float]
    ks: float
    shininess: float
    mirror: bool = False

    @property
    def grey(self) -> bool:
        return self.kd[0] == self.kd[1] == self.kd[2]


@dataclasses.dataclass(frozen=True)
class Lights:
    """Uniform grid of point-light samples over a box (SPEC 4) and the light model shared by every sample.

    ``grid[a]`` samples along axis ``a`` sit at the centres of ``grid[a]`` equal cells of ``box``. Irradiance from
    a light of intensity ``I`` at distance ``d`` is ``I / max(d, radius)^2`` (``falloff="inverse-square"``) or ``I``
    (``"none"``): ``radius`` makes the light a small sphere so a light on a surface stays finite.
    """

    grid: tuple[int, int, int]
    box: tuple[float, float, float, float, float, float]
    intensity: tuple[float, float, float]
    falloff: str
    radius: float

    @property
    def positions(self) -> np.ndarray:
        """(S, 3) float64 sample positions, x fastest, then y, then z."""
        lo = np.array(self.box[:3])
        hi = np.array(self.box[3:])
        axes = [lo[a] + (np.arange(self.grid[a]) + 0.5) * (hi[a] - lo[a]) / self.grid[a] for a in range(3)]
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


@dataclasses.dataclass
class Scene:
    """A static scene ready to bake.

    positions : (V, 3) float64, file order per object, objects concatenated, floor last
    faces     : (F, 3) int32 triangles (quads and polygons triangulated by trimesh)
    normals   : (V, 3) float64 unit area-weighted vertex normals (fallback +y where no face has area)
    material_id : (V,) int32 index into ``materials``
    object_id : (V,) int32 index into ``object_names``
    referenced : (V,) bool, False for vertices no face uses (kept for id stability, never baked)
    """

    positions: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    material_id: np.ndarray
    object_id: np.ndarray
    referenced: np.ndarray
    materials: list[Material]
    object_names: list[str]
    lights: Lights
    source: str

    def __repr__(self) -> str:
        names = ", ".join(self.object_names[:4]) + (", ..." if len(self.object_names) > 4 else "")
        return (f"Scene({self.source!r}: {self.num_vertices:,} vertices, {len(self.faces):,} triangles, objects "
                f"[{names}], {len(self.lights.positions)} light samples)")

    @property
    def num_vertices(self) -> int:
        return len(self.positions)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner of the referenced vertices."""
        return referenced_bounds(self.positions, self.referenced)

    @property
    def diagonal(self) -> float:
        b = self.bounds
        return float(np.linalg.norm(b[1] - b[0]))


def referenced_bounds(positions: np.ndarray, referenced: np.ndarray) -> np.ndarray:
    """(2, 3) min and max corner of the referenced vertices (of all of them when none is referenced): a vertex no
    face uses is never baked nor drawn, so it does not size anything."""
    p = positions[referenced] if referenced.any() else positions
    return np.stack([p.min(axis=0), p.max(axis=0)])


# ---------------------------------------------------------------------------------------------------------------
# geometry


#: ray-origin offset as a fraction of the bounding diagonal of the referenced vertices (every bake: point-light,
#: transfer, neighbourhood)
RAY_OFFSET_FRACTION = 1e-4


def ray_offset(scene: "Scene") -> float:
    """Ray-origin offset in scene units: scales with the scene's size and with float32 resolution of its coordinates,
    both taken over the referenced vertices (``Scene.bounds``: a far vertex no face uses changes nothing)."""
    return bounds_offset(scene.bounds)


def bounds_offset(bounds: np.ndarray) -> float:
    """:func:`ray_offset` of a scene whose referenced vertices span ``bounds`` ((2, 3) min and max corner)."""
    bounds = np.asarray(bounds, np.float64)
    coord = float(np.abs(bounds).max())
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    # a Python float: numpy's float32 eps would make the product float32, which the store's JSON attributes refuse
    return max(RAY_OFFSET_FRACTION * diagonal, 64.0 * float(np.finfo(np.float32).eps) * coord)


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, (V, 3) float64.

    Zero-area faces contribute nothing; a vertex with no face of non-zero area (unreferenced, or only on
    degenerate faces) gets +y, so no normal is ever NaN.
    """
    p = np.asarray(positions, dtype=np.float64)
    n = np.zeros_like(p)
    if len(faces):
        f = np.asarray(faces, dtype=np.int64)
        # cross product length = 2 x area: summing unnormalised face normals weights by area
        fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        for k in range(3):
            np.add.at(n, f[:, k], fn)
    length = np.linalg.norm(n, axis=1)
    scale = np.abs(p).max(axis=1) if len(p) else np.zeros(0)
    # "no area" relative to coordinate size, so 1e-4 and 1e4 scenes behave alike
    bad = ~(length > 1e-30 * np.maximum(scale, 1e-30) ** 2)
    n[bad] = (0.0, 1.0, 0.0)
    length[bad] = 1.0
    return n / length[:, None]


def face_has_area(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: the face's area is not zero up to rounding.

    Relative to the face's longest edge, so the test does not depend on the scene's size or offset: a face counts as
    zero-area when |e1 x e2| <= 1e-12 |e_max|^2 (collinear float64 points leave a cross product of about 1e-16
    |e|^2 from rounding), or when it is not finite.
    """
    p = np.asarray(positions, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    a, b, c = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    with np.errstate(over="ignore", invalid="ignore"):
        cross = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        longest = np.maximum.reduce([np.einsum("ij,ij->i", e, e) for e in (b - a, c - a, c - b)])
        return np.isfinite(cross) & (cross > 1e-12 * longest)


def floor_mesh(bounds: np.ndarray, resolution: int, margin: float, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """A y-up grid of ``resolution`` x ``resolution`` vertices at the objects' lowest y.

    It reaches ``margin * extent`` beyond the objects' x/z bounds. Returns (positions (R*R, 3), faces (2(R-1)^2, 3))
    with counter-clockwise triangles seen from +y.
    """
    r = resolution
    lo = bounds[0] - margin * extent
    hi = bounds[1] + margin * extent
    xs = np.linspace(lo[0], hi[0], r)
    zs = np.linspace(lo[2], hi[2], r)
    zz, xx = np.meshgrid(zs, xs, indexing="ij")
    pos = np.stack([xx.ravel(), np.full(r * r, bounds[0][1]), zz.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(r - 1), np.arange(r - 1), indexing="ij")
    a = (i * r + j).ravel()
    b, c, d = a + 1, a + r, a + r + 1
    # (a, c, b): x along +j, z along +i, so (c - a) x (b - a) = +z x +x = +y
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)]).astype(np.int32)
    return pos, faces


# ---------------------------------------------------------------------------------------------------------------
# reading


def _demo_mesh_path() -> Path | None:
    try:
        import pymeshlab
    except ImportError:  # pragma: no cover - pymeshlab is a dependency
        return None
    p = Path(pymeshlab.__file__).parent / "tests" / "sample_meshes" / "bunny.obj"
    return p if p.is_file() else None


def _procedural_mesh() -> tuple[np.ndarray, np.ndarray]:
    """A torus standing upright over a slab: it shadows itself and the floor."""
    import trimesh

    # trimesh's torus rings around z: its ring stands upright in the x-y plane (y up), resting on the slab
    torus = trimesh.creation.torus(major_radius=0.3, minor_radius=0.1, major_sections=96, minor_sections=32)
    torus.apply_translation([0.0, 0.5, 0.0])
    slab = trimesh.creation.box(extents=[0.3, 0.1, 0.3])
    slab.apply_translation([0.0, 0.05, 0.0])
    v = np.concatenate([torus.vertices, slab.vertices])
    f = np.concatenate([torus.faces, slab.faces + len(torus.vertices)])
    return v.astype(np.float64), f.astype(np.int32)


# ---------------------------------------------------------------------------------------------------------------
# validation helpers: every message names the file and the field


def _show(value) -> str:
    """repr for messages: at most 80 characters, and safe for integers too long for str()."""
    try:
        text = repr(value)
    except ValueError:  # Python refuses to print integers of more than 4300 digits
        text = f"<an integer of {value.bit_length()} bits>"
    return text if len(text) <= 80 else text[:77] + "..."


def _check_keys(where: str, table, known: set[str]) -> None:
    if not isinstance(table, dict):
        raise SceneError(f"{where}: expected a table (keys {', '.join(sorted(known))}), got {_show(table)}")
    unknown = sorted(set(table) - known)
    if unknown:
        known_list = ", ".join(sorted(known))
        raise SceneError(f"{where}: unknown key(s) {', '.join(map(_show, unknown))} (known: {known_list})")


def _number(
    where: str, value, *, minimum: float | None = None, positive: bool = False, maximum: float | None = None
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}: expected a number, got {_show(value)}")
    try:
        v = float(value)
    except OverflowError:  # TOML integers have no size limit in tomllib; floats stop near 1.8e308
        v = math.inf
    if not math.isfinite(v):
        raise SceneError(f"{where}: must be finite, got {_show(value)}")
    if positive and v <= 0:
        raise SceneError(f"{where}: must be > 0, got {_show(value)}")
    if minimum is not None and v < minimum:
        raise SceneError(f"{where}: must be >= {minimum}, got {_show(value)}")
    if maximum is not None and v > maximum:
        raise SceneError(f"{where}: must be <= {maximum:g}, got {_show(value)}")
    return v


def _vector(where: str, value, n: int, *, grey: bool = False, **kw) -> tuple[float, ...]:
    """``value`` as ``n`` numbers; with ``grey`` (a colour: kd, intensity) one number stands for all three."""
    if grey and isinstance(value, (int, float)) and not isinstance(value, bool) and n == 3:
        value = [value] * 3  # a grey colour given as one number
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SceneError(f"{where}: expected a list of {n} numbers, got {_show(value)}")
    return tuple(_number(f"{where}[{i}]", v, **kw) for i, v in enumerate(value))


def _material(where: str, table: dict, default: Material) -> Material:
    lim = {"minimum": 0.0, "maximum": MATERIAL_LIMIT}
    kd = _vector(f"{where}.kd", table["kd"], 3, grey=True, **lim) if "kd" in table else default.kd
    ks = _number(f"{where}.ks", table["ks"], **lim) if "ks" in table else default.ks
    n = _number(f"{where}.shininess", table["shininess"], minimum=0.0) if "shininess" in table else default.shininess
    mirror = table.get("mirror", default.mirror)
    if not isinstance(mirror, bool):
        raise SceneError(f"{where}.mirror: expected true or false, got {_show(mirror)}")
    if mirror and ks > 1.0:
        raise SceneError(f"{where}.ks: a mirror reflects the fraction ks of the light, so ks must be <= 1, got {ks:g}")
    return Material(kd=kd, ks=ks, shininess=n, mirror=mirror)


def default_light_box(bounds: np.ndarray) -> tuple[float, ...]:
    """A slab above the objects: x/z over their bounds widened by half the largest extent, y from 0.4 to 0.75
    extents above their top."""
    ext = float((bounds[1] - bounds[0]).max())
    lo, hi = bounds
    return (lo[0] - 0.5 * ext, hi[1] + 0.4 * ext, lo[2] - 0.5 * ext, hi[0] + 0.5 * ext, hi[1] + 0.75 * ext, hi[2] + 0.5 * ext)


def _grid(where: str, table) -> tuple[int, int, int]:
    """The light grid, refused when it asks for more than MAX_LIGHT_SAMPLES samples (before anything is allocated)."""
    _check_keys(where, table, _LIGHT_KEYS)
    grid = table.get("grid", [3, 1, 3])
    if not isinstance(grid, list) or len(grid) != 3 or not all(is_whole(g, integer_type=True) for g in grid):
        raise SceneError(f"{where}.grid: expected 3 integers, got {_show(grid)}")
    if min(grid) < 1:
        raise SceneError(f"{where}.grid: every axis needs at least 1 sample, got {_show(grid)}")
    if math.prod(grid) > MAX_LIGHT_SAMPLES:
        raise SceneError(
            f"{where}.grid: {_show(grid)} asks for {_show(math.prod(grid))} light samples; at most "
            f"{MAX_LIGHT_SAMPLES:,} are allowed"
        )
    return tuple(grid)


def _lights(where: str, table: dict, bounds: np.ndarray, diagonal: float) -> Lights:
    grid = _grid(where, table)
    box = _vector(f"{where}.box", table["box"], 6) if "box" in table else default_light_box(bounds)
    if max(map(abs, box)) >= COORDINATE_LIMIT:
        raise SceneError(f"{where}.box: coordinates must lie within +-{COORDINATE_LIMIT:g}, got {_show(box)}")
    for a, name in enumerate("xyz"):
        if not box[a + 3] > box[a]:
            raise SceneError(
                f"{where}.box: the light box has zero or negative size along {name} "
                f"({name}min={box[a]}, {name}max={box[a + 3]}); give xmin ymin zmin xmax ymax zmax with max > min"
            )
    intensity = _vector(
        f"{where}.intensity", table.get("intensity", [1.0, 1.0, 1.0]), 3, grey=True, minimum=0.0,
        maximum=INTENSITY_LIMIT
    )
    falloff = table.get("falloff", "inverse-square")
    if falloff not in FALLOFFS:
        raise SceneError(f"{where}.falloff: expected one of {FALLOFFS}, got {_show(falloff)}")
    radius = _number(f"{where}.radius", table["radius"], positive=True) if "radius" in table else 1e-3 * diagonal
    if not MIN_RADIUS <= radius < COORDINATE_LIMIT:
        raise SceneError(f"{where}.radius: must lie in [{MIN_RADIUS:g}, {COORDINATE_LIMIT:g}), got {_show(radius)}")
    return Lights(grid=grid, box=tuple(box), intensity=intensity, falloff=falloff, radius=radius)


# ---------------------------------------------------------------------------------------------------------------
# assembly


def check_mesh_arrays(where: str, positions, faces) -> None:
    """SceneError naming ``where`` unless ``positions`` is (V, 3) finite numbers within +-COORDINATE_LIMIT and
    ``faces`` (F, 3) integers in 0..V-1 (what ``load_mesh`` guarantees for a file; arrays given in memory too)."""
    p, f = np.asarray(positions), np.asarray(faces)
    if p.ndim != 2 or p.shape[1] != 3 or not np.issubdtype(p.dtype, np.number) or np.iscomplexobj(p):
        raise SceneError(f"{where}: positions: expected (V, 3) real numbers, got shape {p.shape} of {p.dtype}")
    if f.ndim != 2 or f.shape[1] != 3 or not (np.issubdtype(f.dtype, np.integer) or f.size == 0):
        raise SceneError(f"{where}: faces: expected (F, 3) integer vertex indices, got shape {f.shape} of {f.dtype}")
    bad = ~np.isfinite(p).all(axis=1) | (np.abs(p) >= COORDINATE_LIMIT).any(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise SceneError(f"{where}: positions: vertex {i} is {p[i].tolist()}: coordinates must be finite and within "
                         f"+-{COORDINATE_LIMIT:g}")
    if f.size and (f.min() < 0 or f.max() >= len(p)):
        raise SceneError(f"{where}: faces: indices must lie in 0..{len(p) - 1}, got {int(f.min())}..{int(f.max())}")


def check_radiance_range(source: str, lights: Lights, materials: list[Material]) -> None:
    """SceneError when the brightest radiance the scene can reach, intensity x (kd + ks) / radius^2 (a light at
    its own radius), passes RADIANCE_LIMIT: float32 radiance would be infinite."""
    near = 1.0 / lights.radius**2 if lights.falloff == "inverse-square" else 1.0
    reflect = max(max(m.kd) + m.ks for m in materials)
    peak = max(lights.intensity) * reflect * near
    if peak > RADIANCE_LIMIT:
        raise SceneError(f"{source}: lights.intensity {max(lights.intensity):g} x (kd + ks) {reflect:g} / "
                         f"lights.radius^2 ({lights.radius:g}^2) reaches radiance {peak:.3g}, beyond "
                         f"{RADIANCE_LIMIT:g} (float32 would overflow): lower the intensity or the materials, or "
                         "raise the radius")


def assemble_scene(objects, floor, light_table, where_lights, source, *, wheres=None, origins=None) -> Scene:
    """Build a :class:`Scene` from meshes already in memory: what every scene reader ends with.

    objects: list of (name, positions (V, 3), faces (F, 3), Material), concatenated in this order; floor: None or
    (resolution, margin, Material), a floor under the objects added last (:func:`floor_mesh`); light_table: the
    ``[lights]`` table of a scene file (docs/SCENE.md; ``{}`` for the defaults), named ``where_lights`` in
    messages; source: what the scene is called (``Scene.source``).

    Messages about object ``k`` start with ``wheres[k]`` (default ``"{source}: object[k] (name ...)"``) and call
    its mesh ``origins[k]`` (default "its mesh"). Raises SceneError when an object has no face of non-zero area:
    it would bake "successfully" with nothing but fallback normals.
    """
    used, masks = [], []  # each object's referenced vertices: one no face uses is never baked, so it sizes nothing
    for k, (name, p, f, _) in enumerate(objects):
        where = wheres[k] if wheres else f"{source}: object[{k}] (name {_show(name)})"
        origin = origins[k] if origins else "its mesh"
        check_mesh_arrays(where, p, f)
        if not face_has_area(p, f).any():
            raise SceneError(f"{where}: every face of {origin} has zero area after placement; nothing to bake (faces "
                             "with area in the file collapse when 'translate' takes them far from the origin)")
        masks.append(referenced_mask(len(p), f))
        used.append(np.asarray(p)[masks[-1]])
    all_pos = np.concatenate(used)
    bounds = np.stack([all_pos.min(axis=0), all_pos.max(axis=0)])
    extent = max(float((u.max(axis=0) - u.min(axis=0)).max()) for u in used)
    parts = list(objects)
    if floor is not None:
        resolution, margin, mat = floor
        reach = float(np.abs(bounds).max()) + margin * extent
        if not reach < COORDINATE_LIMIT:
            raise SceneError(
                f"{source}: floor.margin: a margin of {margin:g} object extents ({extent:g}) takes the floor beyond "
                f"the coordinate limit +-{COORDINATE_LIMIT:g}"
            )
        fp, ff = floor_mesh(bounds, resolution, margin, extent)
        parts.append(("floor", fp, ff, mat))
        masks.append(referenced_mask(len(fp), ff))
    materials: list[Material] = []
    positions, faces, mat_id, obj_id, names = [], [], [], [], []
    offset = 0
    for k, (name, p, f, mat) in enumerate(parts):
        if mat not in materials:
            materials.append(mat)
        positions.append(p)
        faces.append(f.astype(np.int64) + offset)
        mat_id.append(np.full(len(p), materials.index(mat), np.int32))
        obj_id.append(np.full(len(p), k, np.int32))
        names.append(name)
        offset += len(p)
    positions = np.concatenate(positions)
    faces = np.concatenate(faces)
    if offset >= 2**31:
        raise SceneError(f"{source}: {offset} vertices do not fit the int32 face indices of the store")
    referenced = np.concatenate(masks)
    full_bounds = np.stack([positions[referenced].min(axis=0), positions[referenced].max(axis=0)])
    diagonal = float(np.linalg.norm(full_bounds[1] - full_bounds[0]))
    coord = float(np.abs(full_bounds).max())
    if diagonal < 1e3 * float(np.finfo(np.float32).eps) * coord:
        # float32 positions of the bake keep fewer than ~1000 steps across the scene: shapes collapse into a few points
        log.warning("%s: the scene (diagonal %g) lies %g from the origin: float32 positions cannot resolve it; move it "
                    "nearer the origin with 'translate'", source, diagonal, coord)
    if not diagonal >= MIN_SCENE_DIAGONAL:
        raise SceneError(
            f"{source}: the scene's bounding diagonal is {diagonal:g}, below {MIN_SCENE_DIAGONAL:g}: too small for "
            "the float32 kernels; enlarge it with an object's 'scale'"
        )
    lights = _lights(where_lights, light_table, bounds, diagonal)
    check_radiance_range(source, lights, materials)
    return Scene(
        positions=positions,
        faces=faces.astype(np.int32),
        normals=vertex_normals(positions, faces),
        material_id=np.concatenate(mat_id),
        object_id=np.concatenate(obj_id),
        referenced=referenced,
        materials=materials,
        object_names=names,
        lights=lights,
        source=source,
    )


THESIS_MATERIAL = Material(kd=THESIS_KD, ks=THESIS_KS, shininess=THESIS_SHININESS)


def demo_scene(*, floor_resolution: int = 200) -> Scene:
    """The embedded default scene: pymeshlab's bunny (else a procedural torus) on a floor, thesis material."""
    path = _demo_mesh_path()
    if path is not None:
        pos, faces = load_mesh(path)
        name, source = "bunny", "demo (pymeshlab sample bunny.obj)"
    else:
        pos, faces = _procedural_mesh()
        name, source = "torus", "demo (procedural torus)"
    return assemble_scene([(name, pos, faces, THESIS_MATERIAL)], (floor_resolution, 1.0, THESIS_MATERIAL), {},
                          "demo.lights", source)


def _object(path: Path, k: int, table) -> tuple[tuple, str]:
    """Object ``k`` of scene file ``path``: ((name, positions, faces, Material), where to name it in messages)."""
    where = f"{path}: object[{k}]"
    _check_keys(where, table, _OBJECT_KEYS)
    mesh = table.get("mesh")
    if not isinstance(mesh, str) or not mesh.strip() or "\0" in mesh:
        raise SceneError(f"{where}.mesh: required, a path relative to the scene file, got {_show(mesh)}")
    mesh_path = Path(mesh) if os.path.isabs(mesh) else path.parent / mesh
    name = table.get("name", mesh_name(mesh))
    if not isinstance(name, str):
        raise SceneError(f"{where}.name: expected a string, got {_show(name)}")
    up = table.get("up", "y")
    if not isinstance(up, str) or up not in UP_AXES:
        raise SceneError(f"{where}.up: expected one of {', '.join(map(repr, UP_AXES))}, got {_show(up)}")
    rotate = _vector(f"{where}.rotate", table["rotate"], 3) if "rotate" in table else (0.0, 0.0, 0.0)
    scale = _number(f"{where}.scale", table["scale"], positive=True) if "scale" in table else 1.0
    translate = _vector(f"{where}.translate", table["translate"], 3) if "translate" in table else (0.0, 0.0, 0.0)
    material = _material(where, table, THESIS_MATERIAL)
    try:
        pos, faces = load_mesh(mesh_path, scale=scale, translate=translate, up=up, rotate=rotate)
    except SceneError as exc:
        raise SceneError(f"{where}.mesh: {exc}") from exc
    return (name, pos, faces, material), f"{where} (name {_show(name)})"


def _floor(path: Path, ft) -> tuple[int, float, Material]:
    where = f"{path}: floor"
    _check_keys(where, ft, _FLOOR_KEYS)
    res = ft.get("resolution", 380)
    if not is_whole(res, 2, MAX_FLOOR_RESOLUTION, integer_type=True):
        raise SceneError(f"{where}.resolution: expected an integer from 2 to {MAX_FLOOR_RESOLUTION}, got {_show(res)}")
    margin = _number(f"{where}.margin", ft.get("margin", 1.0), minimum=0.0)
    return res, margin, _material(where, ft, THESIS_MATERIAL)


def scene_from_toml(path: str | os.PathLike) -> Scene:
    """Read a TOML scene file (docs/SCENE.md); mesh paths are relative to the file."""
    path = Path(path)
    require_file(path, "scene")
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:  # TOML must be UTF-8
        raise SceneError(f"{path}: cannot parse TOML: {exc}") from exc
    _check_keys(f"{path}", doc, _TOP_KEYS)
    lights = doc.get("lights", {})
    _grid(f"{path}: lights", lights)  # a huge grid or floor fails now, not after the meshes are read
    floor = _floor(path, doc["floor"]) if "floor" in doc else None
    tables = doc.get("object")
    if not isinstance(tables, list) or not tables:
        raise SceneError(f"{path}: field 'object': at least one [[object]] table with a 'mesh' is required")
    objects, wheres, origins = [], [], []
    for k, table in enumerate(tables):
        obj, where = _object(path, k, table)
        objects.append(obj)
        wheres.append(where)
        origins.append(table["mesh"])
    return assemble_scene(objects, floor, lights, f"{path}: lights", str(path), wheres=wheres, origins=origins)


def load_scene(spec: str | os.PathLike) -> Scene:
    """Load ``"demo"``, a TOML scene file, or a bare mesh path (see module docstring)."""
    if str(spec) == "demo":
        return demo_scene()
    path = Path(spec)
    if path.suffix.lower() == ".toml":
        return scene_from_toml(path)
    pos, faces = load_mesh(path)
    return assemble_scene(
        [(mesh_name(path), pos, faces, THESIS_MATERIAL)], None, {}, f"{path}: lights", str(path), wheres=[str(path)],
        origins=["the mesh"],
    )
