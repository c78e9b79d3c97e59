"""Participating media for volumetric self-transfer (patent 4.3; docs/VOLUMES.md): a density grid over a box with a
single-scattering albedo, read from a ``.npy`` grid, a small TOML/JSON description, or the procedural ``cloud``.

Conventions (V-1). ``density[i, j, k]`` is the extinction coefficient sigma_t (per scene unit) at the centre of
voxel (i, j, k), ``lo + (i + 1/2, j + 1/2, k + 1/2) h`` with ``h = (hi - lo) / (X, Y, Z)``; between centres it is
trilinear, between the outermost centres and the box faces it is constant (clamp to edge, as an OpenGL 3D texture
with CLAMP_TO_EDGE samples it), and outside the box it is 0. Scattering is isotropic, sigma_s = albedo sigma_t.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tomllib
from pathlib import Path

import numpy as np

from lodprt.errors import LodprtError

#: most voxels a grid may have (the transfer is X Y Z x 3 x n^2 float32: 16.8 M voxels at order 3 is 1.8 GB)
MAX_VOXELS = 1 << 24
#: procedural media, ``name`` or ``name:N`` (N voxels along x)
PROCEDURAL = ("cloud",)
#: keys of a TOML/JSON volume description
DESCRIPTION_KEYS = {"density", "bounds", "albedo", "density_scale"}
CLOUD_RESOLUTION = 32


class VolumeError(LodprtError, ValueError):
    """A volume file or field is missing, unreadable or out of range."""


@dataclasses.dataclass
class Volume:
    """A density grid over an axis-aligned box (V-1).

    density : (X, Y, Z) float32 extinction coefficient per scene unit at voxel centres, finite, >= 0
    lo, hi  : (3,) float64 box corners, hi > lo
    albedo  : (3,) float64 single-scattering albedo per channel, in [0, 1]
    """

    density: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    albedo: np.ndarray
    source: str

    def __post_init__(self):
        self.density = check_density(self.density, self.source)
        self.lo, self.hi = check_bounds(self.lo, self.hi, f"{self.source}: bounds")
        self.albedo = check_albedo(self.albedo, self.source)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(n) for n in self.density.shape)

    @property
    def voxel_size(self) -> np.ndarray:
        """(3,) float64 edge lengths h of a voxel."""
        return (self.hi - self.lo) / np.array(self.shape, np.float64)

    def centres(self) -> np.ndarray:
        """(X, Y, Z, 3) float64 voxel centres."""
        axes = [self.lo[a] + (np.arange(n) + 0.5) * self.voxel_size[a] for a, n in enumerate(self.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def sample(self, points) -> np.ndarray:
        """Trilinear density (V-1) at ``points`` (..., 3): (...,) float64; 0 outside the box."""
        return sample_grid(self.density.astype(np.float64)[..., None], self.lo, self.hi, points)[..., 0]


def sample_grid(values, lo, hi, points) -> np.ndarray:
    """Cell-centred trilinear interpolation with clamp to edge (V-1) of ``values`` (X, Y, Z, C) at ``points``
    (..., 3): (..., C) float64, 0 outside the box [lo, hi]."""
    v = np.asarray(values, np.float64)
    p = np.asarray(points, np.float64)
    shape = np.array(v.shape[:3])
    u = (p - lo) / (np.asarray(hi, np.float64) - lo) * shape - 0.5
    inside = np.all((p >= lo) & (p <= hi), axis=-1)
    f0 = np.floor(u)
    f = u - f0
    i0 = np.clip(f0.astype(np.int64), 0, shape - 1)
    i1 = np.clip(f0.astype(np.int64) + 1, 0, shape - 1)
    out = np.zeros(p.shape[:-1] + v.shape[3:])
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                w = ((f[..., 0] if cx else 1 - f[..., 0]) * (f[..., 1] if cy else 1 - f[..., 1])
                     * (f[..., 2] if cz else 1 - f[..., 2]))
                ix = (i1 if cx else i0)[..., 0]
                iy = (i1 if cy else i0)[..., 1]
                iz = (i1 if cz else i0)[..., 2]
                out += w[..., None] * v[ix, iy, iz]
    return np.where(inside[..., None], out, 0.0)


def check_density(density, where: str) -> np.ndarray:
    """The density grid as (X, Y, Z) float32, or VolumeError naming ``where`` and what is wrong."""
    d = np.asarray(density)
    if d.ndim != 3 or min(d.shape) < 1:
        raise VolumeError(f"{where}: density must be a 3-D grid (X, Y, Z), got shape {d.shape}")
    if d.size > MAX_VOXELS:
        raise VolumeError(f"{where}: density has {d.size:,} voxels, more than the {MAX_VOXELS:,} a bake handles")
    if not np.issubdtype(d.dtype, np.floating) and not np.issubdtype(d.dtype, np.integer):
        raise VolumeError(f"{where}: density must hold numbers, got dtype {d.dtype}")
    d = d.astype(np.float32)
    bad = ~np.isfinite(d) | (d < 0)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise VolumeError(f"{where}: density has {int(bad.sum())} negative or non-finite voxel(s), the first at "
                          f"{first} ({float(d[first])})")
    return d


def check_bounds(lo, hi, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The box's corners as float64 (3,) arrays; VolumeError prefixed ``where`` (the field, e.g. 'X: bounds')."""
    lo = np.asarray(lo, np.float64).reshape(-1)
    hi = np.asarray(hi, np.float64).reshape(-1)
    if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise VolumeError(f"{where}: must be six finite numbers xmin ymin zmin xmax ymax zmax")
    if not (hi > lo).all():
        raise VolumeError(f"{where}: max must exceed min on every axis (min {lo.tolist()}, max {hi.tolist()})")
    return lo, hi


def check_albedo(albedo, where: str) -> np.ndarray:
    try:  # numbers only: a string or a bool (true read as 1) is refused below
        numbers = np.asarray(albedo)
        ok = numbers.dtype.kind in "iuf" and numbers.size in (1, 3)
        a = np.broadcast_to(numbers.astype(np.float64).reshape(-1), (3,)).copy() if ok else None
    except (TypeError, ValueError):
        a = None
    if a is None or not np.isfinite(a).all() or (a < 0).any() or (a > 1).any():
        raise VolumeError(f"{where}: albedo must be one number or three (RGB) in [0, 1], got {albedo!r}")
    return a


def cloud_density(resolution: int = CLOUD_RESOLUTION, *, seed: int = 7, peak: float = 12.0) -> np.ndarray:
    """The procedural cloud on (N, N/2, N) voxels of the box (-1, -0.5, -1)..(1, 0.5, 1): a union of soft
    ellipsoidal puffs over a flattened base, modulated by smoothed noise; ``peak`` is the largest sigma_t."""
    from scipy.ndimage import gaussian_filter

    n = int(resolution)
    if n < 4:
        raise VolumeError(f"cloud:{n}: the procedural cloud needs at least 4 voxels along x")
    shape = (n, max(2, n // 2), n)
    lo, hi = np.array([-1.0, -0.5, -1.0]), np.array([1.0, 0.5, 1.0])
    axes = [lo[a] + (np.arange(shape[a]) + 0.5) * (hi[a] - lo[a]) / shape[a] for a in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    rng = np.random.default_rng(seed)
    field = np.exp(-((x / 0.75) ** 2 + ((y + 0.15) / 0.22) ** 2 + (z / 0.6) ** 2))  # the flattened base
    for _ in range(9):  # puffs sitting on the base
        c = rng.uniform([-0.55, -0.1, -0.4], [0.55, 0.15, 0.4])
        r = rng.uniform(0.18, 0.32)
        field += 0.9 * np.exp(-(((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) / r**2))
    noise = gaussian_filter(rng.standard_normal(shape), sigma=max(1.0, n / 16), mode="wrap")
    noise /= np.abs(noise).max() or 1.0
    field *= 1.0 + 0.45 * noise
    d = np.clip(field - 0.35, 0.0, None)
    return (peak * d / (d.max() or 1.0)).astype(np.float32)


def procedural_volume(spec: str, *, albedo=0.9, density_scale: float = 1.0) -> Volume:
    """``cloud`` or ``cloud:N``: the procedural cloud with N voxels along x (default 32)."""
    name, _, res = spec.partition(":")
    if name not in PROCEDURAL:
        raise VolumeError(f"{spec}: unknown procedural volume; known: {', '.join(PROCEDURAL)}")
    try:
        n = int(res) if res else CLOUD_RESOLUTION
    except ValueError:
        raise VolumeError(f"{spec}: the resolution after ':' must be an integer") from None
    voxels = n * max(2, n // 2) * n  # cloud_density's (N, N/2, N), checked before it is built
    if voxels > MAX_VOXELS:
        top = max(k for k in range(4, 1024) if k * max(2, k // 2) * k <= MAX_VOXELS)
        raise VolumeError(f"{spec}: {voxels:,} voxels, more than the {MAX_VOXELS:,} a bake handles (N up to {top})")
    return Volume(cloud_density(n) * float(density_scale), np.array([-1.0, -0.5, -1.0]), np.array([1.0, 0.5, 1.0]),
                  albedo, f"procedural {spec}")


def _read_npy(path: Path, where: str) -> np.ndarray:
    if not path.is_file():
        raise VolumeError(f"{where}: {path}: no such file")
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise VolumeError(f"{where}: {path}: not a readable .npy array ({exc})") from exc


def _description(path: Path) -> dict:
    try:
        text = path.read_text()
        doc = tomllib.loads(text) if path.suffix.lower() == ".toml" else json.loads(text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise VolumeError(f"{path}: cannot read the volume description ({exc})") from exc
    if not isinstance(doc, dict):
        raise VolumeError(f"{path}: a volume description must be a table/object")
    unknown = set(doc) - DESCRIPTION_KEYS
    if unknown:
        raise VolumeError(f"{path}: unknown key(s) {', '.join(sorted(unknown))}; known: {', '.join(sorted(DESCRIPTION_KEYS))}")
    if "density" not in doc:
        raise VolumeError(f"{path}: density: missing (a .npy path relative to this file, or 'cloud[:N]')")
    return doc


def load_volume(spec: str | os.PathLike, *, bounds=None, albedo=None, density_scale: float | None = None) -> Volume:
    """Read a volume: ``cloud[:N]`` (procedural), a ``.npy`` (X, Y, Z) grid (``bounds`` = xmin ymin zmin xmax ymax
    zmax required), or a ``.toml`` / ``.json`` description with keys ``density`` (a .npy path relative to the file,
    or ``cloud[:N]``), ``bounds``, ``albedo`` (default 0.9) and ``density_scale`` (default 1). Arguments given here
    override the description's fields. VolumeError names the file and the field on bad input.
    """
    text = str(spec)
    doc: dict = {}
    where = text
    path = Path(text)
    if path.suffix.lower() in (".toml", ".json"):
        if not path.is_file():
            raise VolumeError(f"{path}: no such volume description")
        doc = _description(path)
        where = f"{path}: density"
    scale = density_scale if density_scale is not None else doc.get("density_scale", 1.0)
    if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not math.isfinite(scale) or scale < 0:
        raise VolumeError(f"{where if doc else text}: density_scale must be a finite number >= 0, got {scale!r}")
    alb = albedo if albedo is not None else doc.get("albedo", 0.9)
    box = bounds if bounds is not None else doc.get("bounds")
    source = doc.get("density", text) if doc else text
    if not isinstance(source, str):
        raise VolumeError(f"{where}: expected a string, got {source!r}")
    name = source.partition(":")[0]
    if name in PROCEDURAL and not (path.parent / source if doc else Path(source)).exists():
        vol = procedural_volume(source, albedo=check_albedo(alb, f"{text}: albedo"), density_scale=scale)
        if box is not None:
            vol.lo, vol.hi = _box(box, f"{text}: bounds")
        return vol
    npy = (path.parent / source) if doc else Path(source)
    if npy.suffix.lower() != ".npy":
        raise VolumeError(f"{where}: {source}: expected a .npy grid, a .toml/.json description or one of "
                          f"{', '.join(PROCEDURAL)}")
    if box is None:
        raise VolumeError(f"{text}: bounds: a .npy density grid needs its box (--bounds xmin ymin zmin xmax ymax zmax, "
                          "or 'bounds' in a TOML/JSON description)")
    lo, hi = _box(box, f"{text}: bounds")
    dens = check_density(_read_npy(npy, where), str(npy))
    return Volume(dens * np.float32(scale), lo, hi, check_albedo(alb, f"{text}: albedo"), str(npy))


def _box(box, where: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        b = np.asarray(box, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise VolumeError(f"{where}: expected six numbers, got {box!r}") from None
    if b.shape != (6,):
        raise VolumeError(f"{where}: expected six numbers xmin ymin zmin xmax ymax zmax, got {box!r}")
    return check_bounds(b[:3], b[3:], where)
