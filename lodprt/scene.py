"""Scene: triangle meshes with Phong materials, an optional floor, and the grid of point-light samples (SPEC 2).

A scene is given as one of
  * ``"demo"`` -- the embedded default: pymeshlab's bundled bunny (or, where that file is missing, a procedural
    torus with self-shadowing) on a floor, thesis material ``0.88 (L.N) + 0.19 (R.V)^2``;
  * a TOML scene file (``*.toml``, format in ``docs/SCENE.md``);
  * a bare mesh path (OBJ, PLY, STL, OFF, GLB/GLTF): that mesh with the thesis material, no floor, default lights.

Meshes are read with trimesh keeping the file's vertex order (``process=False``, ``maintain_order=True``): store
vertex ``i`` of an object is vertex ``i`` of its file. Objects are concatenated in file order, the floor last.
Coordinates are y-up.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import tomllib
from pathlib import Path

import numpy as np

from lodprt.errors import SceneError

log = logging.getLogger(__name__)

#: Thesis chapter 4.1 material: 0.88 (L.N) + 0.19 (R.V)^2.
THESIS_KD = (0.88, 0.88, 0.88)
THESIS_KS = 0.19
THESIS_SHININESS = 2.0

FALLOFFS = ("inverse-square", "none")

_OBJECT_KEYS = {"mesh", "name", "kd", "ks", "shininess", "scale", "translate"}
_FLOOR_KEYS = {"resolution", "margin", "kd", "ks", "shininess"}
_LIGHT_KEYS = {"grid", "box", "intensity", "falloff", "radius"}
_TOP_KEYS = {"object", "floor", "lights"}


@dataclasses.dataclass(frozen=True)
class Material:
    """Phong material ``kd (L.N) + ks max(R.s, 0)^shininess`` (SPEC 2)."""

    kd: tuple[float, float, float]
    ks: float
    shininess: float

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

    @property
    def num_vertices(self) -> int:
        return len(self.positions)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner of the referenced vertices."""
        p = self.positions[self.referenced] if self.referenced.any() else self.positions
        return np.stack([p.min(axis=0), p.max(axis=0)])

    @property
    def diagonal(self) -> float:
        b = self.bounds
        return float(np.linalg.norm(b[1] - b[0]))


# ---------------------------------------------------------------------------------------------------------------
# geometry


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


def load_mesh(path: str | os.PathLike, *, scale: float = 1.0, translate=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Read one triangle mesh keeping the file's vertex order; returns (positions (V,3) float64, faces (F,3) int32).

    Raises SceneError naming the file for a missing or unreadable file, an empty mesh, non-finite coordinates or
    face indices out of range.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: mesh file not found")
    try:
        mesh = trimesh.load(str(path), process=False, maintain_order=True, force="mesh")
    except Exception as exc:  # trimesh raises many types for bad files
        raise SceneError(f"{path}: cannot read mesh: {exc}") from exc
    verts = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(verts) == 0:
        raise SceneError(f"{path}: field 'vertices': the mesh has no vertices")
    if len(faces) == 0:
        raise SceneError(f"{path}: field 'faces': the mesh has no faces (point clouds cannot be baked)")
    finite = np.isfinite(verts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise SceneError(
            f"{path}: field 'vertices': {len(bad)} vertices have NaN or infinite coordinates (first: vertex {bad[0]})"
        )
    if faces.min() < 0 or faces.max() >= len(verts):
        raise SceneError(f"{path}: field 'faces': face indices out of range 0..{len(verts) - 1}")
    verts = verts * float(scale) + np.asarray(translate, dtype=np.float64)
    return verts, faces.astype(np.int32)


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


def _check_keys(where: str, table: dict, known: set[str]) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} (known: {', '.join(sorted(known))})")


def _number(where: str, value, *, minimum: float | None = None, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}: expected a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise SceneError(f"{where}: must be finite, got {value!r}")
    if positive and v <= 0:
        raise SceneError(f"{where}: must be > 0, got {value!r}")
    if minimum is not None and v < minimum:
        raise SceneError(f"{where}: must be >= {minimum}, got {value!r}")
    return v


def _vector(where: str, value, n: int, **kw) -> tuple[float, ...]:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and n == 3:
        value = [value] * 3  # a grey colour given as one number
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SceneError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return tuple(_number(f"{where}[{i}]", v, **kw) for i, v in enumerate(value))


def _material(where: str, table: dict, default: Material) -> Material:
    kd = _vector(f"{where}.kd", table["kd"], 3, minimum=0.0) if "kd" in table else default.kd
    ks = _number(f"{where}.ks", table["ks"], minimum=0.0) if "ks" in table else default.ks
    n = _number(f"{where}.shininess", table["shininess"], minimum=0.0) if "shininess" in table else default.shininess
    return Material(kd=kd, ks=ks, shininess=n)


def default_light_box(bounds: np.ndarray) -> tuple[float, ...]:
    """A slab above the objects: x/z over their bounds widened by half the largest extent, y from 0.4 to 0.75
    extents above their top."""
    ext = float((bounds[1] - bounds[0]).max())
    lo, hi = bounds
    return (lo[0] - 0.5 * ext, hi[1] + 0.4 * ext, lo[2] - 0.5 * ext, hi[0] + 0.5 * ext, hi[1] + 0.75 * ext, hi[2] + 0.5 * ext)


def _lights(where: str, table: dict, bounds: np.ndarray, diagonal: float) -> Lights:
    _check_keys(where, table, _LIGHT_KEYS)
    grid = table.get("grid", [3, 1, 3])
    if not isinstance(grid, list) or len(grid) != 3 or not all(isinstance(g, int) and not isinstance(g, bool) for g in grid):
        raise SceneError(f"{where}.grid: expected 3 integers, got {grid!r}")
    if min(grid) < 1:
        raise SceneError(f"{where}.grid: every axis needs at least 1 sample, got {grid!r}")
    box = _vector(f"{where}.box", table["box"], 6) if "box" in table else default_light_box(bounds)
    for a, name in enumerate("xyz"):
        if not box[a + 3] > box[a]:
            raise SceneError(
                f"{where}.box: the light box has zero or negative size along {name} "
                f"({name}min={box[a]}, {name}max={box[a + 3]}); give xmin ymin zmin xmax ymax zmax with max > min"
            )
    intensity = _vector(f"{where}.intensity", table.get("intensity", [1.0, 1.0, 1.0]), 3, minimum=0.0)
    falloff = table.get("falloff", "inverse-square")
    if falloff not in FALLOFFS:
        raise SceneError(f"{where}.falloff: expected one of {FALLOFFS}, got {falloff!r}")
    radius = _number(f"{where}.radius", table["radius"], positive=True) if "radius" in table else 1e-3 * diagonal
    return Lights(grid=tuple(grid), box=tuple(box), intensity=intensity, falloff=falloff, radius=radius)


# ---------------------------------------------------------------------------------------------------------------
# assembly


def _assemble(objects, floor, light_table, where_lights, source) -> Scene:
    """objects: list of (name, positions, faces, Material); floor: None or (resolution, margin, Material)."""
    all_pos = np.concatenate([o[1] for o in objects])
    bounds = np.stack([all_pos.min(axis=0), all_pos.max(axis=0)])
    extent = max(float((o[1].max(axis=0) - o[1].min(axis=0)).max()) for o in objects)
    parts = list(objects)
    if floor is not None:
        resolution, margin, mat = floor
        fp, ff = floor_mesh(bounds, resolution, margin, extent)
        parts.append(("floor", fp, ff, mat))
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
    referenced = np.zeros(len(positions), bool)
    referenced[faces.ravel()] = True
    full_bounds = np.stack([positions[referenced].min(axis=0), positions[referenced].max(axis=0)])
    diagonal = float(np.linalg.norm(full_bounds[1] - full_bounds[0]))
    lights = _lights(where_lights, light_table, bounds, diagonal)
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
    return _assemble([(name, pos, faces, THESIS_MATERIAL)], (floor_resolution, 1.0, THESIS_MATERIAL), {}, "demo.lights", source)


def scene_from_toml(path: str | os.PathLike) -> Scene:
    """Read a TOML scene file (docs/SCENE.md); mesh paths are relative to the file."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: scene file not found")
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"{path}: cannot parse TOML: {exc}") from exc
    _check_keys(f"{path}", doc, _TOP_KEYS)
    tables = doc.get("object")
    if not isinstance(tables, list) or not tables:
        raise SceneError(f"{path}: field 'object': at least one [[object]] table with a 'mesh' is required")
    objects = []
    for k, table in enumerate(tables):
        where = f"{path}: object[{k}]"
        _check_keys(where, table, _OBJECT_KEYS)
        if "mesh" not in table or not isinstance(table["mesh"], str):
            raise SceneError(f"{where}.mesh: required, a path relative to the scene file")
        mesh_path = (path.parent / table["mesh"]).resolve() if not os.path.isabs(table["mesh"]) else Path(table["mesh"])
        scale = _number(f"{where}.scale", table["scale"], positive=True) if "scale" in table else 1.0
        translate = _vector(f"{where}.translate", table["translate"], 3) if "translate" in table else (0.0, 0.0, 0.0)
        try:
            pos, faces = load_mesh(mesh_path, scale=scale, translate=translate)
        except SceneError as exc:
            raise SceneError(f"{where}.mesh: {exc}") from exc
        name = str(table.get("name", Path(table["mesh"]).stem))
        objects.append((name, pos, faces, _material(where, table, THESIS_MATERIAL)))
    floor = None
    if "floor" in doc:
        where = f"{path}: floor"
        ft = doc["floor"]
        _check_keys(where, ft, _FLOOR_KEYS)
        res = ft.get("resolution", 380)
        if isinstance(res, bool) or not isinstance(res, int) or res < 2:
            raise SceneError(f"{where}.resolution: expected an integer >= 2, got {res!r}")
        margin = _number(f"{where}.margin", ft.get("margin", 1.0), minimum=0.0)
        floor = (res, margin, _material(where, ft, THESIS_MATERIAL))
    return _assemble(objects, floor, doc.get("lights", {}), f"{path}: lights", str(path))


def load_scene(spec: str | os.PathLike) -> Scene:
    """Load ``"demo"``, a TOML scene file, or a bare mesh path (see module docstring)."""
    if str(spec) == "demo":
        return demo_scene()
    path = Path(spec)
    if path.suffix.lower() == ".toml":
        return scene_from_toml(path)
    pos, faces = load_mesh(path)
    return _assemble([(path.stem, pos, faces, THESIS_MATERIAL)], None, {}, f"{path}: lights", str(path))
