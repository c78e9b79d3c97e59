"""Distant lighting from environment maps (SPEC 6): lat-long and cube maps of linear RGB radiance read from .hdr,
.exr or .npy files, a folder of six faces or a procedural name; exact texel solid angles, SH projection (T-6), mip
levels (I-3.2) and rotation of the lighting (P-4).

Texels hold **linear** radiance: nothing here applies or removes a gamma curve, and 8-bit (sRGB) images are refused
(playcanvas#547: projecting sRGB values is the classic bug). Directions are in the world frame, y up
(:func:`texel_directions`). Details and accuracy: docs/ENVIRONMENT.md, "Environment maps".
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
import warnings
from pathlib import Path

import numpy as np

from lodprt.model import sh
from lodprt.errors import LodprtError, is_whole
from lodprt.model.scene import RADIANCE_LIMIT

#: file names of the six faces of a cube map given as a folder, in face order
CUBE_FACE_NAMES = ("px", "nx", "py", "ny", "pz", "nz")
#: procedural environments :func:`load_environment` accepts by name
PROCEDURAL = ("sky", "spots", "constant")


class EnvironmentMapError(LodprtError, ValueError):
    """An environment map is missing, unreadable, of the wrong shape, or holds non-finite, negative or overflowing
    radiance (above ``RADIANCE_LIMIT``)."""


@dataclasses.dataclass(frozen=True)
class Environment:
    """An environment map of linear RGB radiance.

    kind   : ``"latlong"`` (data (H, 2H, 3)) or ``"cube"`` (data (6, N, N, 3))
    data   : float64 radiance, finite and >= 0
    source : what it was loaded from (file, folder, procedural name)
    """

    kind: str
    data: np.ndarray
    source: str

    @property
    def resolution(self) -> int:
        """H of a lat-long map, N of a cube map."""
        return int(self.data.shape[0] if self.kind == "latlong" else self.data.shape[1])

    @property
    def num_texels(self) -> int:
        return int(np.prod(self.data.shape[:-1]))

    def directions(self) -> np.ndarray:
        """(T, 3) float64 unit directions of the texel centres, texels in ``data`` order."""
        return texel_directions(self.kind, self.resolution)

    def solid_angles(self) -> np.ndarray:
        """(T,) float64 exact solid angle of every texel (sums to 4 pi)."""
        return texel_solid_angles(self.kind, self.resolution)

    def radiance(self) -> np.ndarray:
        """(T, 3) float64 texel radiance in ``directions()`` order."""
        return self.data.reshape(-1, 3)

    def project(self, order: int, *, supersample: int = 2) -> np.ndarray:
        """SH coefficients of the map's radiance (T-6): (3, order^2) float64.

        f_i = sum_t L_t W_ti with W_ti = integral over texel t of y_i, from :func:`projection_weights` (exact
        sub-texel solid angles, ``supersample`` x ``supersample`` basis samples per texel, cached per resolution).
        """
        return self.radiance().T @ projection_weights(self.kind, self.resolution, order, supersample)

    def stored(self, order: int) -> tuple[np.ndarray, dict]:
        """What a store records of the lighting it was baked with (``StoreWriter.environment``): the SH
        coefficients (3, order^2) float64 and {"source", "kind", "resolution"}."""
        return self.project(order), {"source": self.source, "kind": self.kind, "resolution": self.resolution}

    def mip(self, level: int) -> "Environment":
        """The map downsampled ``level`` times by the solid-angle-weighted 2 x 2 box filter (I-3.2): the four
        children of a texel cover exactly its solid angle, so total power and the constant coefficient are kept."""
        if not is_whole(level, 0):
            raise EnvironmentMapError(f"{self.source}: mip level {level!r}: a whole number >= 0 (0: the map itself)")
        env = self
        for done in range(int(level)):
            if env.resolution < 2 or env.resolution % 2:  # named once, with how far it got (not "(mip)" per level)
                raise EnvironmentMapError(f"{self.source}: mip level {level}: resolution {self.resolution} halves "
                                          f"only {done} time(s), to {env.resolution}")
            env = env._half()
        return env

    def _half(self) -> "Environment":
        if self.resolution < 2 or self.resolution % 2:
            raise EnvironmentMapError(f"{self.source}: resolution {self.resolution} cannot be halved again")
        w = self.solid_angles()[:, None]
        s = box_sum(self.radiance() * w, self.kind, self.resolution, 2)
        sw = box_sum(w, self.kind, self.resolution, 2)
        shape = self.data.shape[:-3] + (self.data.shape[-3] // 2, self.data.shape[-2] // 2, 3)
        return Environment(self.kind, (s / sw).reshape(shape), f"{self.source} (mip)")

    def lookup(self, dirs) -> np.ndarray:
        """Radiance of the texel each direction falls in (nearest texel): dirs (..., 3) -> (..., 3) float64."""
        d = sh.unit_vectors(dirs)
        if self.kind == "latlong":
            h, w = self.data.shape[:2]
            theta = np.arccos(np.clip(d[..., 1], -1.0, 1.0))
            phi = np.mod(np.arctan2(-d[..., 2], d[..., 0]), 2 * np.pi)
            i = np.clip((theta / np.pi * h).astype(np.int64), 0, h - 1)
            j = np.clip((phi / (2 * np.pi) * w).astype(np.int64), 0, w - 1)
            return self.data[i, j]
        face, u, v = _cube_face_uv(d)
        n = self.resolution
        c = np.clip(((u + 1) / 2 * n).astype(np.int64), 0, n - 1)
        r = np.clip(((v + 1) / 2 * n).astype(np.int64), 0, n - 1)
        return self.data[face, r, c]

    def to_cube(self, resolution: int) -> "Environment":
        """Resample (nearest texel) onto a cube map of ``resolution`` texels per face edge."""
        d = texel_directions("cube", resolution)
        return Environment("cube", self.lookup(d).reshape(6, resolution, resolution, 3), f"{self.source} (cube)")

    def rotated_azimuth(self, texels: int) -> "Environment":
        """A lat-long map rotated about +y by ``texels`` columns (2 pi texels / W radians), exactly."""
        if self.kind != "latlong":
            raise EnvironmentMapError(f"{self.source}: rotated_azimuth needs a lat-long map")
        return Environment("latlong", np.roll(self.data, int(texels), axis=1), f"{self.source} (rotated)")


# -- geometry of texels -----------------------------------------------------------------------------------------


def texel_directions(kind: str, resolution: int) -> np.ndarray:
    """(T, 3) float64 unit directions of texel centres of a ``kind`` map, texels in ``data`` order.

    * ``latlong`` (H, W, 3), W = 2 H: row ``i`` (first row = top) has polar angle ``theta = pi (i + 1/2) / H`` from
      +y, column ``j`` the azimuth ``phi = 2 pi (j + 1/2) / W``; the texel looks along
      ``(sin theta cos phi, cos theta, -sin theta sin phi)``, so a rotation by ``a`` about +y shifts the columns.
    * ``cube`` (6, N, N, 3), faces in OpenGL order +x, -x, +y, -y, +z, -z; texel (row ``r``, column ``c``) has
      ``u = 2 (c + 1/2)/N - 1`` (right), ``v = 2 (r + 1/2)/N - 1`` (down) and looks along
      +x: (1, -v, -u), -x: (-1, -v, u), +y: (u, 1, v), -y: (u, -1, -v), +z: (u, -v, 1), -z: (-u, -v, -1)
      (the OpenGL cube-map table, so a cube map made for OpenGL reads as is).
    """
    n = int(resolution)
    if kind == "latlong":
        theta = np.pi * (np.arange(n) + 0.5) / n
        phi = 2 * np.pi * (np.arange(2 * n) + 0.5) / (2 * n)
        t, p = np.meshgrid(theta, phi, indexing="ij")
        d = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], axis=-1)
        return d.reshape(-1, 3)
    if kind == "cube":
        c = 2 * (np.arange(n) + 0.5) / n - 1
        v, u = np.meshgrid(c, c, indexing="ij")  # rows v, columns u
        one = np.ones_like(u)
        faces = [
            (one, -v, -u), (-one, -v, u), (u, one, v), (u, -one, -v), (u, -v, one), (-u, -v, -one),
        ]
        d = np.stack([np.stack(f, axis=-1) for f in faces])
        return (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    raise EnvironmentMapError(f"environment kind must be 'latlong' or 'cube', got {kind!r}")


def texel_solid_angles(kind: str, resolution: int) -> np.ndarray:
    """(T,) float64 exact texel solid angles of a ``kind`` map, in ``texel_directions`` order; they sum to 4 pi.

    Lat-long texel: ``dphi (cos theta_top - cos theta_bottom)``. Cube texel ``[u0, u1] x [v0, v1]`` on the face
    plane at distance 1: ``F(u0,v0) - F(u0,v1) - F(u1,v0) + F(u1,v1)``, ``F(u, v) = atan2(u v, sqrt(u^2 + v^2 + 1))``
    (the integral of the solid-angle density ``(1 + u^2 + v^2)^(-3/2)``).
    """
    n = int(resolution)
    if kind == "latlong":
        edges = np.pi * np.arange(n + 1) / n
        band = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2 * np.pi / (2 * n))
        return np.repeat(band, 2 * n)
    if kind == "cube":
        e = 2 * np.arange(n + 1) / n - 1

        def f(u, v):
            return np.arctan2(u * v, np.sqrt(u * u + v * v + 1))

        v0, u0 = np.meshgrid(e[:-1], e[:-1], indexing="ij")
        v1, u1 = np.meshgrid(e[1:], e[1:], indexing="ij")
        face = f(u0, v0) - f(u0, v1) - f(u1, v0) + f(u1, v1)
        return np.tile(face.ravel(), 6)
    raise EnvironmentMapError(f"environment kind must be 'latlong' or 'cube', got {kind!r}")


def box_sum(values: np.ndarray, kind: str, resolution: int, factor: int) -> np.ndarray:
    """Sum ``factor`` x ``factor`` blocks of per-texel rows: values (T, K) at ``resolution`` -> (T / factor^2, K).

    Texels of the coarse map at ``resolution // factor`` are the unions of those blocks (both layouts nest).
    """
    n, f = int(resolution), int(factor)
    k = values.shape[1]
    if n % f:
        raise EnvironmentMapError(f"resolution {n} is not divisible by {f}")
    if kind == "latlong":
        return values.reshape(n // f, f, 2 * n // f, f, k).sum(axis=(1, 3)).reshape(-1, k)
    return values.reshape(6, n // f, f, n // f, f, k).sum(axis=(2, 4)).reshape(-1, k)


@functools.lru_cache(maxsize=8)
def projection_weights(kind: str, resolution: int, order: int, supersample: int = 2) -> np.ndarray:
    """W_ti ~ integral over texel t of y_i(s) ds: (T, order^2) float64, read-only, cached.

    Built as the seed's mip-mapped basis (I-3.2): y_i sampled at the texel centres of the map ``supersample``
    times finer, times their exact solid angles, box-summed back to ``resolution``. With it a constant map
    projects to exactly sqrt(4 pi) in y_0 and every coarser level of a mip pyramid sees the same basis.
    """
    s = max(1, int(supersample))
    fine = int(resolution) * s
    faces = 1 if kind == "latlong" else 6
    rows_per_face = fine  # lat-long: fine x 2 fine texels; cube: 6 faces of fine x fine
    dirs = texel_directions(kind, fine)
    om = texel_solid_angles(kind, fine)
    per_face = len(dirs) // faces
    cols = per_face // rows_per_face
    out = []
    step = max(s, (1 << 16) // max(cols, 1) // s * s)  # fine rows per chunk, a multiple of s
    for f in range(faces):
        for r0 in range(0, rows_per_face, step):
            a = f * per_face + r0 * cols
            b = f * per_face + min(r0 + step, rows_per_face) * cols
            y = sh.basis(dirs[a:b], order) * om[a:b, None]
            rows = (b - a) // cols
            out.append(y.reshape(rows // s, s, cols // s, s, -1).sum(axis=(1, 3)).reshape(-1, order * order))
    w = np.concatenate(out)
    w.setflags(write=False)
    return w


def _cube_face_uv(d: np.ndarray):
    """Face index and face coordinates (u right, v down, in [-1, 1]) of unit directions (..., 3)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    face = np.where((ax >= ay) & (ax >= az), np.where(x > 0, 0, 1), np.where(ay >= az, np.where(y > 0, 2, 3), np.where(z > 0, 4, 5)))
    ma = np.choose(face, [ax, ax, ay, ay, az, az])
    u = np.choose(face, [-z, z, x, x, x, -x]) / ma
    v = np.choose(face, [-y, -y, z, -z, -y, -y]) / ma
    return face, u, v


# -- projection -------------------------------------------------------------------------------------------------


def project_texels(radiance, dirs, solid_angles, order: int, *, chunk: int = 1 << 16) -> np.ndarray:
    """f_i = sum_t L_t y_i(d_t) Omega_t (T-6): radiance (T, 3), dirs (T, 3), solid_angles (T,) -> (3, order^2).

    Evaluated in chunks of ``chunk`` texels so a large map at a high order does not hold T x order^2 basis values.
    """
    radiance = np.asarray(radiance, np.float64)
    out = np.zeros((radiance.shape[1], order * order))
    for s in range(0, len(radiance), chunk):
        sl = slice(s, s + chunk)
        y = sh.basis(dirs[sl], order)
        out += (radiance[sl] * solid_angles[sl, None]).T @ y
    return out


def rotation_about_y(degrees: float) -> np.ndarray:
    """3x3 rotation by ``degrees`` about +y (right-handed: +z turns toward +x)."""
    a = np.radians(float(degrees))
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotate_lighting(coeffs, R) -> np.ndarray:
    """Lighting coefficients (..., n^2) of the environment turned by the rotation R (P-4): L'(s) = L(R^T s).

    To express world lighting in an object's frame whose axes are the columns of ``R_obj``, pass ``R_obj.T``.
    """
    return sh.rotate(coeffs, R)


def mip_projections(env: Environment, order: int, *, min_resolution: int = 2, repeats: int = 1) -> list[dict]:
    """Project every mip level of ``env`` and report its cost and error against level 0 (I-3.2).

    Every level projects with its own :func:`projection_weights` (the seed's mip-mapped SH basis, built once per
    resolution and not timed). Returns one dict per level: ``level``, ``shape``, ``texels``, ``seconds`` (best of
    ``repeats`` projections, filtering not included), ``filter_seconds``, ``coefficients`` (3, order^2), ``relative_error``
    (||c_k - c_0|| / ||c_0||, Frobenius over channels) and ``max_abs_error``.
    """
    out = []
    level, cur = 0, env
    ref = None
    while True:
        weights = projection_weights(cur.kind, cur.resolution, order)  # built once per resolution, not timed
        best = np.inf
        for _ in range(max(1, repeats)):
            t0 = time.perf_counter()
            c = cur.radiance().T @ weights
            best = min(best, time.perf_counter() - t0)
        if ref is None:
            ref = c
        out.append(
            {
                "level": level,
                "shape": list(cur.data.shape[:-1]),
                "texels": cur.num_texels,
                "seconds": best,
                "coefficients": c,
                "relative_error": float(np.linalg.norm(c - ref) / max(np.linalg.norm(ref), 1e-300)),
                "max_abs_error": float(np.abs(c - ref).max()),
            }
        )
        if cur.resolution // 2 < min_resolution or cur.resolution % 2:
            return out
        t0 = time.perf_counter()
        cur = cur._half()
        out[-1]["filter_seconds"] = time.perf_counter() - t0
        level += 1


# -- procedural environments ------------------------------------------------------------------------------------

#: sun direction of the procedural sky (unit, world frame, y up)
SUN_DIRECTION = np.array([0.5, 0.6, -0.35]) / np.linalg.norm([0.5, 0.6, -0.35])


def sky_radiance(dirs, *, sun: float = 2.0, sun_exponent: float = 32.0) -> np.ndarray:
    """Procedural sky: zenith-to-horizon gradient, dim ground, and a smooth sun lobe ``sun (d.s)^k``.

    dirs (..., 3) -> (..., 3) float64 linear RGB radiance. Smooth everywhere (no hard horizon), so a 9-coefficient
    irradiance reproduces it to about 0.5% mean, 2% worst (Ramamoorthi-Hanrahan: about 1%, under 5%).
    """
    d = sh.unit_vectors(dirs)
    y = d[..., 1:2]
    zenith = np.array([0.25, 0.45, 1.0])
    horizon = np.array([0.9, 0.85, 0.8])
    ground = np.array([0.25, 0.2, 0.15])
    up = np.clip(y, 0, 1)
    sky = horizon + (zenith - horizon) * np.sqrt(up)
    t = 0.5 * (1 + np.tanh(8 * y))  # smooth horizon
    base = t * sky + (1 - t) * ground
    lobe = np.clip(d @ SUN_DIRECTION, 0, None)[..., None] ** sun_exponent
    return base + sun * lobe * np.array([1.0, 0.9, 0.75])


#: centres, colours and widths of the procedural hot spots
SPOTS = (
    (np.array([0.0, 1.0, 0.0]), np.array([6.0, 6.0, 5.5]), 0.3),
    (np.array([0.8, 0.3, 0.5]), np.array([5.0, 1.5, 0.5]), 0.2),
    (np.array([-0.7, 0.1, -0.7]), np.array([0.6, 1.5, 6.0]), 0.25),
)


def spots_radiance(dirs) -> np.ndarray:
    """A dim ambient and a few area-like hot spots ``C exp((d.c - 1)/w)``: dirs (..., 3) -> (..., 3) float64."""
    d = sh.unit_vectors(dirs)
    out = np.full(d.shape[:-1] + (3,), 0.2)
    for c, col, w in SPOTS:
        c = c / np.linalg.norm(c)
        out = out + np.exp((d @ c - 1) / w)[..., None] * col
    return out


def procedural(name: str, *, resolution: int = 128, kind: str = "latlong") -> Environment:
    """Rasterise a procedural environment (``sky``, ``spots``, ``constant``) at texel centres."""
    funcs = {"sky": sky_radiance, "spots": spots_radiance, "constant": lambda d: np.ones(d.shape[:-1] + (3,))}
    if name not in funcs:
        raise EnvironmentMapError(f"procedural environment {name!r}: known names are {', '.join(PROCEDURAL)}")
    d = texel_directions(kind, resolution)
    shape = (resolution, 2 * resolution, 3) if kind == "latlong" else (6, resolution, resolution, 3)
    return Environment(kind, funcs[name](d).reshape(shape), f"procedural {name} ({kind} {resolution})")


# -- files ------------------------------------------------------------------------------------------------------


def load_environment(spec: str | os.PathLike, *, resolution: int = 128) -> Environment:
    """Read an environment: a procedural name (``sky``, ``spots``, ``constant``; ``sky:256`` sets its
    resolution), a lat-long ``.hdr`` / ``.exr`` / ``.npy`` image (H, 2H, 3), a ``.npy`` cube (6, N, N, 3), or a
    folder holding six faces ``px nx py ny pz nz`` (same extension, square, equal sizes).

    Raises EnvironmentMapError (a LodprtError) naming the file and what is wrong with it.
    """
    text = str(spec)
    name, _, res = text.partition(":")
    if name in PROCEDURAL and not Path(text).exists():
        if res:
            try:
                resolution = int(res)
            except ValueError:
                raise EnvironmentMapError(f"{text}: the resolution after ':' must be an integer") from None
        if resolution < 1:
            raise EnvironmentMapError(f"{text}: resolution must be >= 1")
        return procedural(name, resolution=resolution)
    path = Path(spec)
    if path.is_dir():
        return _load_cube_folder(path)
    if not path.exists():
        raise EnvironmentMapError(f"{path}: no such environment file (or procedural name: {', '.join(PROCEDURAL)})")
    data = read_image(path)
    if data.ndim == 4:
        return Environment("cube", _check_cube(data, str(path)), str(path))
    return Environment("latlong", _check_latlong(data, str(path)), str(path))


def _check_radiance(data: np.ndarray, where: str) -> np.ndarray:
    bad = ~np.isfinite(data)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise EnvironmentMapError(f"{where}: {int(bad.sum())} texel value(s) are NaN or infinite (first at index {first})")
    neg = data < 0
    if neg.any():
        first = tuple(int(i) for i in np.argwhere(neg)[0])
        raise EnvironmentMapError(
            f"{where}: {int(neg.sum())} texel value(s) are negative (first at index {first}, value "
            f"{float(data[first]):.3g}); radiance must be >= 0"
        )
    big = data > RADIANCE_LIMIT
    if big.any():  # each texel is finite, but the projections and the relighting sum them in float32
        first = tuple(int(i) for i in np.argwhere(big)[0])
        raise EnvironmentMapError(
            f"{where}: {int(big.sum())} texel value(s) are above {RADIANCE_LIMIT:g} (first at index {first}, value "
            f"{float(data[first]):.3g}): float32 relighting would overflow; scale the map down"
        )
    return data


def _channels(data: np.ndarray, where: str) -> np.ndarray:
    """(..., 3) RGB from grey (...,) / (..., 1), RGB or RGBA (alpha dropped)."""
    if data.ndim >= 1 and data.shape[-1] in (3, 4):
        return data[..., :3]
    if data.ndim >= 1 and data.shape[-1] == 1:
        return np.repeat(data, 3, axis=-1)
    return np.repeat(data[..., None], 3, axis=-1)


def _check_latlong(data: np.ndarray, where: str) -> np.ndarray:
    data = np.asarray(data, np.float64)
    if data.ndim == 2:
        data = data[..., None]
    if data.ndim != 3 or data.shape[-1] not in (1, 3, 4):
        raise EnvironmentMapError(f"{where}: a lat-long map must have shape (H, 2H, 3), got {data.shape}")
    data = _channels(data, where)
    h, w = data.shape[:2]
    if h < 1 or w != 2 * h:
        raise EnvironmentMapError(f"{where}: a lat-long map must be twice as wide as high (H, 2H, 3), got {data.shape}")
    return _check_radiance(data, where)


def _check_cube(data: np.ndarray, where: str) -> np.ndarray:
    data = np.asarray(data, np.float64)
    if (data.ndim != 4 or data.shape[0] != 6 or data.shape[1] != data.shape[2] or data.shape[1] < 1
            or data.shape[3] not in (1, 3, 4)):
        raise EnvironmentMapError(f"{where}: a cube map must have shape (6, N, N, 3) with N >= 1, got {data.shape}")
    return _check_radiance(_channels(data, where), where)


def _load_cube_folder(folder: Path) -> Environment:
    faces, shapes = [], []
    for name in CUBE_FACE_NAMES:
        found = sorted(p for p in folder.iterdir() if p.stem == name and p.suffix.lower() in (".hdr", ".exr", ".npy"))
        if not found:
            raise EnvironmentMapError(f"{folder}: cube face '{name}' missing (need {', '.join(CUBE_FACE_NAMES)} .hdr/.exr/.npy)")
        img = np.asarray(read_image(found[0]), np.float64)
        if img.ndim == 2:
            img = img[..., None]
        if img.ndim != 3 or img.shape[0] != img.shape[1] or img.shape[0] < 1 or img.shape[2] not in (1, 3, 4):
            raise EnvironmentMapError(f"{found[0]}: a cube face must be square, (N, N, 1|3|4) with N >= 1, got "
                                      f"{img.shape}")
        faces.append(_channels(img, str(found[0])))
        shapes.append((found[0].name, img.shape[0]))
    sizes = {n for _, n in shapes}
    if len(sizes) != 1:
        listing = ", ".join(f"{f} {n}x{n}" for f, n in shapes)
        raise EnvironmentMapError(f"{folder}: cube faces differ in size ({listing})")
    return Environment("cube", _check_cube(np.stack(faces), str(folder)), str(folder))


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Float radiance array of ``path``: .hdr (Radiance RGBE, built-in reader), .exr (imageio), .npy (numpy)."""
    path = Path(path)
    ext = path.suffix.lower()
    try:
        if ext == ".hdr" or ext == ".pic":
            return read_rgbe(path)
        if ext == ".npy":
            return np.load(path, allow_pickle=False)
        if ext == ".exr":
            import imageio.v3 as iio

            try:
                with warnings.catch_warnings():  # imageio probes every plugin, some of them deprecated
                    warnings.simplefilter("ignore", DeprecationWarning)
                    return np.asarray(iio.imread(path, extension=".exr"), np.float64)
            except (OSError, ValueError, RuntimeError) as exc:
                raise EnvironmentMapError(
                    f"{path}: imageio cannot read this .exr ({exc}); install an EXR backend "
                    "(pip install 'imageio[opencv]' or 'imageio[freeimage]') or convert it to .hdr"
                ) from exc
    except EnvironmentMapError:
        raise
    except (OSError, ValueError) as exc:
        raise EnvironmentMapError(f"{path}: unreadable environment file ({exc})") from exc
    raise EnvironmentMapError(
        f"{path}: unsupported environment file '{ext}' (need linear radiance: .hdr, .exr or .npy; 8-bit images "
        "hold sRGB, not radiance)"
    )


# -- Radiance RGBE (.hdr) ---------------------------------------------------------------------------------------


def read_rgbe(path: str | os.PathLike) -> np.ndarray:
    """Read a Radiance .hdr (RGBE, flat or new run-length scanlines, ``-Y H +X W``): (H, W, 3) float32."""
    path = Path(path)
    raw = path.read_bytes()
    if not (raw.startswith(b"#?RADIANCE") or raw.startswith(b"#?RGBE")):
        raise EnvironmentMapError(f"{path}: not a Radiance .hdr file (header must start with '#?RADIANCE' or '#?RGBE')")
    pos = 0
    fmt = None
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise EnvironmentMapError(f"{path}: header never ends (no blank line before the resolution)")
        line = raw[pos:end].strip()
        pos = end + 1
        if not line:
            break
        if line.startswith(b"FORMAT="):
            fmt = line[7:].decode("ascii", "replace")
    if fmt not in (None, "32-bit_rle_rgbe"):
        raise EnvironmentMapError(f"{path}: FORMAT={fmt} is not supported (only 32-bit_rle_rgbe)")
    end = raw.find(b"\n", pos)
    parts = raw[pos:end].split()
    if len(parts) != 4 or parts[0] != b"-Y" or parts[2] != b"+X":
        raise EnvironmentMapError(f"{path}: resolution line {raw[pos:end]!r}: only '-Y H +X W' is supported")
    try:
        h, w = int(parts[1]), int(parts[3])
    except ValueError:
        raise EnvironmentMapError(f"{path}: resolution line {raw[pos:end]!r} is not '-Y H +X W'") from None
    data = np.frombuffer(raw, np.uint8, offset=end + 1)
    # the fewest bytes H x W pixels take: per scanline a 4-byte header and, per channel, one 2-byte run per 127
    # pixels (the densest run-length coding); a header claiming more than the file holds is refused before
    # anything is allocated (it asked for terabytes)
    if h < 1 or w < 1 or len(data) < h * (4 + 8 * -(-w // 127)):
        raise EnvironmentMapError(f"{path}: truncated or wrong resolution line: {h} x {w} pixels need more than the "
                                  f"file's {len(data):,} bytes of pixel data")
    rgbe = np.empty((h, w, 4), np.uint8)
    p = 0
    try:
        for row in range(h):
            if 8 <= w < 32768 and data[p] == 2 and data[p + 1] == 2 and (int(data[p + 2]) << 8 | int(data[p + 3])) == w:
                p += 4
                for ch in range(4):
                    x = 0
                    while x < w:
                        count = int(data[p])
                        p += 1
                        if count > 128:
                            count -= 128
                            rgbe[row, x : x + count, ch] = data[p]
                            p += 1
                        else:
                            if count == 0 or x + count > w:
                                raise EnvironmentMapError(f"{path}: corrupt run-length data in scanline {row}")
                            rgbe[row, x : x + count, ch] = data[p : p + count]
                            p += count
                        x += count
            else:
                n = w * 4
                if p + n > len(data):
                    raise IndexError
                rgbe[row] = data[p : p + n].reshape(w, 4)
                p += n
    except (IndexError, ValueError):
        raise EnvironmentMapError(f"{path}: truncated pixel data ({h}x{w} expected)") from None
    e = rgbe[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)
    return ((rgbe[..., :3].astype(np.float64) + 0.5) * scale[..., None]).astype(np.float32)


def write_rgbe(path: str | os.PathLike, image) -> None:
    """Write (H, W, 3) linear radiance as a flat (uncompressed) Radiance .hdr file (8-bit mantissas)."""
    img = np.asarray(image, np.float64)
    if img.ndim != 3 or img.shape[2] != 3:
        raise EnvironmentMapError(f"{path}: write_rgbe needs an (H, W, 3) image, got {img.shape}")
    if not np.isfinite(img).all() or (img < 0).any():
        raise EnvironmentMapError(f"{path}: write_rgbe needs finite, non-negative radiance")
    v = img.max(axis=2)
    m, e = np.frexp(v)
    ok = v > 1e-32
    scale = np.where(ok, m * 256.0 / np.where(ok, v, 1.0), 0.0)
    rgbe = np.zeros(img.shape[:2] + (4,), np.uint8)
    rgbe[..., :3] = np.clip(np.floor(img * scale[..., None]), 0, 255).astype(np.uint8)
    rgbe[..., 3] = np.where(ok, e + 128, 0).astype(np.uint8)
    h, w = img.shape[:2]
    header = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode("ascii")
    Path(path).write_bytes(header + rgbe.tobytes())
