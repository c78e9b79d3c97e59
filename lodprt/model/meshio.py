"""Reading one triangle mesh file, keeping the file's vertex order, and placing it in the scene (SPEC 2).

Readers: trimesh first (``process=False``, ``maintain_order=True``: vertex ``i`` is the file's ``i``-th vertex).
When trimesh finds no faces -- it reads a PLY stored as triangle strips (``element tristrips``, common in scan
archives) as a point cloud -- pymeshlab reads the file instead. pymeshlab keeps the vertex count and order of the
file as long as no cleaning filter runs (none does here); the two readers' vertices are compared to make sure.

pymeshlab's readers are C++ and crash the process on some malformed files (a PLY strip index past the last vertex
is a segmentation fault, an OFF face index out of range an abort), so it runs in a child process with a time
limit: a bad file becomes a SceneError, never a crashed or hung bake.

OBJ text is made plain before either reader sees it (``normalised_obj``), each line kept at its number and every
``v`` line in its place: trimesh misread indented or tab-separated lines, trailing ``#`` comments and CR-only line
ends. Negative (relative) face indices are made absolute where ``v`` lines follow faces (``resolve_obj_indices``):
trimesh counted them back from the file's last vertex, not the face's. A face index past the vertices is a
SceneError naming the line (``refuse_obj_index_past_end``), where trimesh raised a bare IndexError.

Compressed files: a name ending in ``.gz``, ``.xz`` or ``.bz2`` (``bunny.obj.xz``) is decompressed in memory and
read as the format its inner suffix names; the test meshes ship this way (``tests/data``).

Placement: positions are rotated so that the file's up axis becomes +y (``up``), then rotated by ``rotate``
(degrees about x, then y, then z, fixed axes, right-handed), scaled uniformly and translated. Every rotation is
proper (determinant +1), so triangles keep their winding and normals recomputed from faces follow the geometry.
"""

from __future__ import annotations

import bz2
import gzip
import io
import logging
import lzma
import os
import re
import signal
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from lodprt.errors import SceneError

log = logging.getLogger(__name__)

#: Largest allowed absolute coordinate after placement. The kernels work in float32, whose largest finite value is
#: about 3.4e38: squared distances between points up to 2e18 apart stay finite, so every coordinate must be below.
COORDINATE_LIMIT = 1e18

#: Compressed mesh suffix -> the module whose ``decompress`` reads it.
COMPRESSED = {".gz": gzip, ".xz": lzma, ".bz2": bz2}

#: Seconds the pymeshlab child process may take to read one file before it counts as hung.
PYMESHLAB_TIMEOUT = 600.0

#: The file's up axis -> the proper rotation (rows) that turns it into +y. "z": -90 degrees about x,
#: (x, y, z) -> (x, z, -y); "-z": +90 degrees about x; "x": +90 degrees about z, (x, y, z) -> (-y, x, z);
#: "-x": -90 degrees about z; "-y": 180 degrees about x.
UP_AXES: dict[str, np.ndarray] = {
    "y": np.eye(3),
    "-y": np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]]),
    "z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
    "-z": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    "x": np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]),
    "-x": np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]),
}


def rotation_matrix(up: str = "y", rotate=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(3, 3) rotation applied to column vectors: up-axis conversion, then ``rotate`` about x, then y, then z."""
    if not isinstance(up, str) or up not in UP_AXES:
        raise SceneError(f"up: expected one of {', '.join(map(repr, UP_AXES))}, got {up!r}")
    rx, ry, rz = np.radians(np.asarray(rotate, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx @ UP_AXES[up]


def load_mesh(
    path: str | os.PathLike,
    *,
    scale: float = 1.0,
    translate=(0.0, 0.0, 0.0),
    up: str = "y",
    rotate=(0.0, 0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Read one triangle mesh keeping the file's vertex order; returns (positions (V,3) float64, faces (F,3) int32).

    Placement order: ``up`` conversion, ``rotate``, ``scale``, ``translate`` (module docstring).
    Raises SceneError naming the file for a missing or unreadable file, an empty mesh or point cloud, non-finite
    or out-of-range coordinates (``COORDINATE_LIMIT``) or face indices out of range.
    """
    path = Path(path)
    if not isinstance(up, str) or up not in UP_AXES:
        raise SceneError(f"{path}: up: expected one of {', '.join(map(repr, UP_AXES))}, got {up!r}")
    require_file(path, "mesh")
    data = decompressed(path)
    obj = suffix_of(path) == ".obj"
    text = path.read_bytes() if obj and data is None else data  # an OBJ read once: the checks and trimesh
    if obj:
        raw, text = text, normalised_obj(text)
        refuse_obj_index_zero(path, text)
        text = resolve_obj_indices(path, text)
        if text != raw:  # pymeshlab reads the text trimesh reads
            data = text
    n = obj_vertex_count(text) if obj else 0
    try:
        verts, faces, points = _read_trimesh(path, text)
    except SceneError:
        if obj:  # the reason in the file's terms, where it is a face index
            refuse_obj_index_past_end(path, text)
        raise
    reader = "trimesh"
    if obj and len(faces) == 0:
        refuse_obj_index_past_end(path, text)  # pymeshlab would crash on one (trimesh's faces were in range)
    if len(faces) == 0:
        verts, faces = _fallback(path, verts, points, data)
        reader = "pymeshlab (trimesh found no faces)"
    elif obj and (made := len(verts)) != n:
        verts, faces = _obj_by_pymeshlab(path, data, made, n)
        reader = f"pymeshlab (trimesh made {made} vertices of the file's {n})"
    log.info("%s: read with %s: %d vertices, %d triangles", path, reader, len(verts), len(faces))
    _check_coordinates(path, verts, np.inf, "in the file")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise SceneError(f"{path}: field 'faces': face indices out of range 0..{len(verts) - 1}")
    rot = rotation_matrix(up, rotate)
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below, with the vertex named
        placed = verts @ rot.T * float(scale) + np.asarray(translate, dtype=np.float64)
    _check_coordinates(path, placed, COORDINATE_LIMIT, "after up, rotate, scale and translate")
    return placed, faces.astype(np.int32)


def referenced_mask(n: int, faces) -> np.ndarray:
    """(n,) bool: True for the vertices ``faces`` use."""
    mask = np.zeros(n, bool)
    mask[np.asarray(faces).ravel()] = True
    return mask


def require_file(path: Path, what: str) -> None:
    """SceneError unless ``path`` is a regular file; a name the OS refuses (too long, ...) is an error too, which
    ``Path.is_file`` would raise as OSError."""
    try:
        ok = path.is_file()
    except (OSError, ValueError) as exc:
        raise SceneError(f"{path}: cannot access the {what} file: {getattr(exc, 'strerror', None) or exc}") from exc
    if not ok:
        raise SceneError(f"{path}: {what} file not found")


def mesh_name(path: str | os.PathLike) -> str:
    """The object name a mesh file gives: its stem without a compression suffix (``bunny.obj.xz`` -> ``bunny``)."""
    path = Path(path)
    return Path(path.stem).stem if path.suffix.lower() in COMPRESSED else path.stem


def decompressed(path: Path) -> bytes | None:
    """The decompressed bytes of a ``.gz``/``.xz``/``.bz2`` mesh file (None for any other name); SceneError naming the
    file when it cannot be decompressed or names no mesh format inside."""
    codec = COMPRESSED.get(path.suffix.lower())
    if codec is None:
        return None
    if not Path(path.stem).suffix:
        raise SceneError(f"{path}: mesh file: a compressed mesh names its format before {path.suffix} "
                         f"(e.g. m.obj{path.suffix})")
    try:
        return codec.decompress(path.read_bytes())
    except (OSError, EOFError, ValueError, lzma.LZMAError) as exc:
        raise SceneError(f"{path}: cannot decompress the mesh file ({path.suffix}): {exc}") from exc


def _check_coordinates(path: Path, verts: np.ndarray, limit: float, when: str) -> None:
    with np.errstate(invalid="ignore"):
        good = (np.abs(verts) < limit).all(axis=1) if limit < np.inf else np.isfinite(verts).all(axis=1)
    if not good.all():
        bad = np.flatnonzero(~good)
        what = "NaN or infinite" if limit == np.inf else f"NaN, infinite or beyond +-{limit:g}"
        raise SceneError(
            f"{path}: field 'vertices': {len(bad)} vertices have {what} coordinates {when} "
            f"(first: vertex {bad[0]}, {verts[bad[0]].tolist()})"
        )


def _read_trimesh(path: Path, data: bytes | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices of the meshes, their faces, the vertices trimesh read as point clouds); ``data``: the file's bytes
    (decompressed where it is compressed), read as its inner suffix's format, with files it names (an OBJ's
    ``mtllib``) looked up beside ``path``."""
    import trimesh

    try:
        with warnings.catch_warnings():  # e.g. 'All-NaN slice' from trimesh's texture code on usemtl groups
            warnings.simplefilter("ignore", RuntimeWarning)
            if data is None:
                loaded = trimesh.load_scene(str(path), process=False, maintain_order=True)
            else:
                loaded = trimesh.load_scene(io.BytesIO(data), file_type=suffix_of(path)[1:], process=False,
                                            maintain_order=True,
                                            resolver=trimesh.resolvers.FilePathResolver(str(path.parent)))
            mesh = loaded.to_mesh()
    except NotImplementedError as exc:  # trimesh knows no reader for the suffix
        raise SceneError(f"{path}: not a file type lodprt reads ({suffix_of(path) or 'no suffix'}): a scene file ends "
                         "in .toml; a mesh in .obj, .ply, .stl, .off, .glb or .gltf (each optionally .gz, .xz or "
                         ".bz2)") from exc
    except Exception as exc:  # trimesh raises many types for bad files
        raise SceneError(f"{path}: cannot read mesh: {type(exc).__name__}: {exc}") from exc
    clouds = [g.vertices for g in loaded.geometry.values() if isinstance(g, trimesh.PointCloud)]
    points = np.concatenate([_rows(path, "vertices", c, np.float64) for c in clouds]) if clouds else np.zeros((0, 3))
    verts = _rows(path, "vertices", getattr(mesh, "vertices", None), np.float64)
    faces = _rows(path, "faces", getattr(mesh, "faces", None), np.int64)
    counts = {len(g.vertices) for g in loaded.geometry.values() if isinstance(g, trimesh.Trimesh)}
    if len(counts) == 1:
        verts, faces = _fold_material_copies(path, verts, faces, counts.pop())
    return verts, faces, points


def suffix_of(path: Path) -> str:
    """The format suffix of ``path``, lower case: the inner one of a compressed file (``bunny.obj.xz``: ``.obj``)."""
    suffix = path.suffix.lower()
    return Path(path.stem).suffix.lower() if suffix in COMPRESSED else suffix


def obj_vertex_count(text: bytes) -> int:
    """How many ``v`` lines (vertex positions) the OBJ file's bytes ``text`` have."""
    return len(re.findall(rb"(?m)^[ \t]*v[ \t]", text))


def refuse_obj_index_zero(path: Path, text: bytes) -> None:
    """SceneError naming the line of the first ``f`` line with a vertex index 0 (or -0) in ``text``, the bytes of the OBJ
    file at ``path``: OBJ counts vertices from 1 (and from -1 backwards), so 0 names none, and the readers silently
    took another vertex for it."""
    for found in re.finditer(rb"[ \t][+-]?0+(?=[/ \t\r\n]|$)", text):  # a token 0 (or -0): on an f line, an index
        start = text.rfind(b"\n", 0, found.start()) + 1
        if text[start:found.start() + 1].lstrip(b" \t")[:2] not in (b"f ", b"f\t"):
            continue
        line = text.count(b"\n", 0, start) + 1
        raise SceneError(f"{path}: field 'faces': line {line} uses vertex index 0; OBJ vertex indices start at 1 "
                         "(negative ones count back from the last vertex)")


def normalised_obj(text: bytes) -> bytes:
    """The OBJ bytes ``text`` as trimesh reads them right, each line at its number and in its order: a UTF-8 BOM
    dropped, CR-only line ends made LF, tabs spaces, leading blanks dropped (not on a line continued by a trailing
    backslash, where they separate values) and ``#`` comments dropped (not on ``mtllib``/``usemtl``/``o``/``g``
    lines, whose names may hold a ``#``)."""
    out = text.removeprefix(b"\xef\xbb\xbf").replace(b"\r\n", b"\n").replace(b"\r", b"\n").replace(b"\t", b" ")
    out = re.sub(rb"(?<!\\)\n +", b"\n", out.lstrip(b" "))
    return re.sub(rb"#[^\n]*", _uncommented, out) if b"#" in out else out


def _uncommented(found: re.Match) -> bytes:
    """``found``, a ``#`` and the rest of its line, dropped unless the line names something (``normalised_obj``)."""
    text = found.string
    start = text.rfind(b"\n", 0, found.start()) + 1
    return found.group(0) if re.match(rb"(?:mtllib|usemtl|o|g) ", text[start:start + 7]) else b""


#: A vertex index on an ``f`` line's text after the ``f``: the first number of each ``v/vt/vn`` group.
_INDEX = re.compile(rb"(?m)(?:^| )([+-]?\d+)(?=[/ ]|$)")


def resolve_obj_indices(path: Path, text: bytes) -> bytes:
    """``text``, the normalised bytes of the OBJ file at ``path``, with negative (relative) vertex indices made absolute
    where ``v`` lines follow a face: they count back from the face's line, trimesh counted from the file's end."""
    first = re.search(rb"(?m)^f ", text)
    if first is None or text.rfind(b"\nv ") < first.start():
        return text
    if not re.search(rb"\nf [^\n-]*-", b"\n" + text):
        return text  # no face line has a "-"
    return _obj_face_lines(path, text)


def refuse_obj_index_past_end(path: Path, text: bytes) -> None:
    """SceneError naming the line of the first vertex index in ``text`` (normalised OBJ bytes) past the file's
    vertices (a negative one: past those before its line). Line by line, so run only where trimesh failed or found no
    faces: trimesh raised a bare IndexError for one, pymeshlab crashes."""
    _obj_face_lines(path, text)


def _obj_face_lines(path: Path, text: bytes) -> bytes:
    """``text`` with each face line's negative vertex indices made absolute; SceneError for the first past the file's
    vertices."""
    n, out, seen, face = obj_vertex_count(text), [], 0, 0
    for number, line in enumerate(text.split(b"\n"), 1):
        seen += line.startswith(b"v ")
        if line.startswith(b"f "):
            face += 1
            line = b"f " + _INDEX.sub(lambda found: _absolute(path, number, face, found, n, seen), line[2:])
        out.append(line)
    return b"\n".join(out)


def _absolute(path: Path, line: int, face: int, found: re.Match, n: int, seen: int) -> bytes:
    """The ``_INDEX`` match ``found`` on face ``face`` (line ``line``) with a negative index made absolute, ``seen``
    vertices before it of the file's ``n``; SceneError for an index past them."""
    k = int(found.group(1))
    if k > n or -k > seen:
        raise SceneError(f"{path}: field 'faces': line {line}: face {face} refers to vertex {k}, but the file has "
                         f"only {n if k > 0 else seen} vertices" + ("" if k > 0 else " before that line"))
    return found.group(0) if k >= 0 else found.group(0).replace(found.group(1), b"%d" % (seen + k + 1))


def _obj_by_pymeshlab(path: Path, data: bytes | None, made: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """pymeshlab's reading of an OBJ whose vertices trimesh duplicated or reordered (several ``usemtl`` groups with
    texture coordinates or normals give each group its own copies), checked to keep the file's ``n`` vertices."""
    log.info("%s: trimesh made %d vertices of the file's %d; reading it with pymeshlab", path, made, n)
    verts, faces = _read_pymeshlab(path, data)
    if len(verts) != n:
        raise SceneError(f"{path}: field 'vertices': the file has {n} vertices, but trimesh made {made} and pymeshlab "
                         f"{len(verts)}; store vertex i would not be the file's vertex i")
    return verts, faces


def _fold_material_copies(path: Path, verts: np.ndarray, faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """trimesh splits an OBJ with several materials (``usemtl``) into one mesh per material, each carrying every
    vertex of the file (``maintain_order``): concatenated, the file's vertices repeat once per material. Fold the
    identical copies back, so vertex ``i`` stays the file's vertex ``i``."""
    if n == 0 or len(verts) <= n or len(verts) % n:
        return verts, faces
    blocks = verts.reshape(-1, n, 3)
    if not (blocks == blocks[:1]).all():
        return verts, faces
    log.info("%s: %d per-material copies of the %d vertices folded into one", path, len(blocks), n)
    return blocks[0], faces % n


def _rows(path: Path, field: str, data, dtype) -> np.ndarray:
    """``data`` as (N, 3) rows; trimesh passes on what the file has, e.g. 2 coordinates from an OBJ line 'v 1 2'."""
    try:
        arr = np.asarray(data if data is not None else np.zeros((0, 3)), dtype=dtype)
    except (ValueError, TypeError, OverflowError) as exc:  # ragged rows, or values that are not numbers
        raise SceneError(f"{path}: field '{field}': not a table of numbers ({exc})") from exc
    if arr.size == 0:
        return arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise SceneError(f"{path}: field '{field}': expected 3 values per row, the file gives shape {arr.shape}")
    return arr


def _fallback(path: Path, verts: np.ndarray, points: np.ndarray, data: bytes | None) -> tuple[np.ndarray, np.ndarray]:
    """pymeshlab's faces for a file trimesh found no faces in, with vertices checked against trimesh's."""
    seen = f"trimesh read {len(verts) + len(points)} vertices and no faces"
    try:
        pv, pf = _read_pymeshlab(path, data)
    except SceneError as exc:
        raise SceneError(
            f"{path}: field 'faces': no faces: {seen}, and pymeshlab could not read it: {exc}"
        ) from exc
    if len(pf) == 0:
        what = "point clouds cannot be baked" if len(pv) or len(verts) or len(points) else "the mesh is empty"
        raise SceneError(f"{path}: field 'faces': no faces: {seen}, pymeshlab read {len(pv)} vertices and no faces; "
                         f"{what}")
    # whatever trimesh did read must be what pymeshlab read, or store vertex i might not be the file's vertex i
    mine = verts if len(verts) else points
    if len(mine) and (mine.shape != pv.shape or not np.allclose(mine, pv, rtol=1e-7, atol=0.0, equal_nan=True)):
        raise SceneError(
            f"{path}: field 'vertices': trimesh read {len(mine)} vertices, pymeshlab {len(pv)} or at other "
            "positions; the file's vertex ids cannot be kept"
        )
    return (mine if len(mine) else pv), pf


_CHILD = """
import sys
import numpy as np
import pymeshlab
ms = pymeshlab.MeshSet()
try:
    ms.load_new_mesh(sys.argv[1])
except Exception as exc:
    sys.stderr.write(" ".join(str(exc).split()))
    sys.exit(3)
m = ms.current_mesh()
np.save(sys.argv[2], np.ascontiguousarray(m.vertex_matrix(), dtype=np.float64))
np.save(sys.argv[3], np.ascontiguousarray(m.face_matrix(), dtype=np.int64))
"""


def _read_pymeshlab(path: Path, data: bytes | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) as pymeshlab reads ``path`` (or ``data``, its bytes, decompressed, written to a temporary
    file with the inner suffix), read in a child process (module docstring)."""
    with tempfile.TemporaryDirectory(prefix="lodprt-meshio-") as tmp:
        vfile, ffile = os.path.join(tmp, "v.npy"), os.path.join(tmp, "f.npy")
        if data is not None:
            path = Path(tmp) / f"mesh{suffix_of(path)}"
            path.write_bytes(data)
        try:
            run = subprocess.run(
                [sys.executable, "-c", _CHILD, str(path), vfile, ffile],
                capture_output=True,
                text=True,
                errors="replace",
                timeout=PYMESHLAB_TIMEOUT,
            )
        except subprocess.TimeoutExpired as exc:
            raise SceneError(f"pymeshlab took more than {PYMESHLAB_TIMEOUT:g} s") from exc
        if run.returncode < 0:
            try:
                name = signal.Signals(-run.returncode).name
            except ValueError:
                name = f"signal {-run.returncode}"
            raise SceneError(f"pymeshlab crashed ({name}), e.g. on a vertex index past the last vertex")
        if run.returncode != 0:
            detail = run.stderr.strip().splitlines()[-1:] or [f"exit status {run.returncode}"]
            # pymeshlab repeats the file name around its reason: keep the reason
            raise SceneError(detail[0].partition("Error details: ")[2][:300] or detail[0][:300])
        return np.load(vfile).reshape(-1, 3), np.load(ffile).reshape(-1, 3)
