"""Neighbourhood transfer bake (patent 5; N-1, N-2 of docs/VOLUMES.md): transfer matrices on a 3-D grid around one
object O of a scene, with the kernels of ``lodprt.kernels.neighbourhood``.

At each grid point p, ``M_p`` maps the distant lighting's SH coefficients L (``order`` bands) to those of the
radiance arriving at p as O modifies it, ``L'_p = M_p L`` (``transferred_order`` bands, N-1):

    M_p = I - B_p + R_p,  B_ij = integral (1 - V(p, s)) y_i(s) y_j(s) ds,
                          R_cij = integral front(p, s) y_i(s) T_cj(hit(p, s)) ds                              (N-2)

(V: O does not block s from p; T: O's own diffuse transfer, albedo/pi included, shadowed or interreflected
with ``bounces`` passes, so R is the light O reflects once toward p.) The grid is vertex-centred: NX x NY x NZ
points from ``lo`` to ``hi`` inclusive, the box of O widened by ``margin`` times O's largest extent on every side.
Other objects of the scene take no part. Written as a ``lodprt-neighbourhood`` store.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from lodprt.devices import resolve_device, warp
from lodprt.launches import launch_ranges
from lodprt.deprecation import renamed_arguments
from lodprt.errors import LodprtError, is_whole
from lodprt.precompute.transfer import Geometry, diffuse_transfer, fibonacci_directions
from lodprt.store.neighbourhood_store import prepare_neighbourhood_destination, write_neighbourhood_store

#: most grid points (a grid of 3 x 25 x 9 float32 matrices: 2^20 points is 2.8 GB)
MAX_POINTS = 1 << 20


def object_mesh(scene, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The object ``name`` of ``scene`` alone: (positions (V, 3), faces (F, 3) int32 reindexed, normals (V, 3),
    albedo kd (V, 3)), LodprtError listing the scene's objects when there is no such object."""
    if name not in scene.object_names:
        raise LodprtError(f"{scene.source}: --object {name!r}: no such object; the scene has "
                          f"{', '.join(repr(n) for n in scene.object_names)}")
    if scene.object_names.count(name) > 1:
        raise LodprtError(f"{scene.source}: --object {name!r}: {scene.object_names.count(name)} objects have that "
                          "name; give them distinct 'name' keys in the scene file")
    k = scene.object_names.index(name)
    keep = scene.object_id == k
    faces = scene.faces[keep[scene.faces].all(axis=1)]
    if not len(faces):
        raise LodprtError(f"{scene.source}: object {name!r} has no faces")
    used = np.unique(faces)
    remap = np.full(len(scene.positions), -1, np.int64)
    remap[used] = np.arange(len(used))
    kd = np.array([m.kd for m in scene.materials], np.float64)[scene.material_id[used]]
    return scene.positions[used], remap[faces].astype(np.int32), scene.normals[used], kd


def neighbourhood_box(positions, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """O's bounding box widened by ``margin`` x its largest extent on every side: (lo, hi) float64."""
    if not np.isfinite(margin) or margin < 0:
        raise LodprtError(f"--margin {margin!r}: must be a finite number >= 0")
    p = np.asarray(positions, np.float64)
    lo, hi = p.min(0), p.max(0)
    extent = float((hi - lo).max())
    reach = margin * extent
    lo, hi = lo - reach, hi + reach
    # N-4 interpolates (p - lo) / (hi - lo): an axis the box is flat along (a flat object, margin 0) gets a
    # thickness of 1e-3 of the largest extent, centred on the object
    flat = hi - lo < 1e-3 * extent
    pad = np.where(flat, 0.5e-3 * extent, 0.0)
    return lo - pad, hi + pad


def grid_points(lo, hi, shape) -> np.ndarray:
    """(NX, NY, NZ, 3) float64 vertex-centred grid points from ``lo`` to ``hi`` inclusive."""
    axes = [np.linspace(lo[a], hi[a], int(shape[a])) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def check_grid(shape) -> tuple[int, int, int]:
    try:
        nx, ny, nz = (int(n) for n in shape)
    except (TypeError, ValueError):
        raise LodprtError(f"--grid {shape!r}: expected three integers NX NY NZ") from None
    if min(nx, ny, nz) < 2:
        raise LodprtError(f"--grid {nx} {ny} {nz}: need at least 2 points per axis (the box's corners)")
    if nx * ny * nz > MAX_POINTS:
        raise LodprtError(f"--grid {nx} {ny} {nz}: {nx * ny * nz:,} points, more than {MAX_POINTS:,}")
    return nx, ny, nz


def transfer_matrices(positions, faces, points, *, order: int, transferred_order: int, rays: int,
                      object_transfer=None, rotate: bool = False, seed: int = 0, device: str | None = None,
                      jobs: int | None = None) -> np.ndarray:
    """N-2 at ``points`` (P, 3) around the mesh (positions, faces): (P, 3, no^2, ni^2) float32 with ``no`` =
    ``transferred_order``, ``ni`` = ``order``. ``object_transfer`` (V, 3, ni^2): O's exit transfer for the reflected
    part (None: occlusion only)."""
    from lodprt.kernels import neighbourhood as kn

    for o in (order, transferred_order):
        if not is_whole(o, 1, 8):
            raise LodprtError(f"sh order {o!r}: the neighbourhood kernels offer orders 1..8")
    if not is_whole(rays, 1):
        raise LodprtError(f"rays {rays!r}: need at least one direction per grid point")
    wp = warp()
    device = resolve_device(device)
    wp.load_module(kn, device=device)
    pos = np.asarray(positions, np.float32)
    fc = np.asarray(faces, np.int32)
    pts = np.asarray(points, np.float32).reshape(-1, 3)
    no2, ni2 = transferred_order**2, order**2
    refl = np.zeros((0, 3, ni2), np.float32) if object_transfer is None else np.asarray(object_transfer, np.float32)
    if refl.ndim != 3 or refl.shape[1:] != (3, ni2) or (len(refl) and len(refl) != len(pos)):
        raise LodprtError(f"neighbourhood: object transfer {refl.shape} does not fit {len(pos)} vertices x 3 x {ni2}")
    mesh = wp.Mesh(points=wp.array(pos, dtype=wp.vec3, device=device),
                   indices=wp.array(fc.ravel(), dtype=wp.int32, device=device))
    n = len(pts)
    extent = np.vstack([pos, pts])
    max_dist = 4.0 * float(np.linalg.norm(extent.max(0) - extent.min(0))) + 1.0
    blocked = wp.zeros((n, no2, ni2), dtype=wp.float32, device=device)
    reflected = wp.zeros((n, 3, no2, ni2) if len(refl) else (1, 3, 1, 1), dtype=wp.float32, device=device)
    scratch = wp.zeros((n, max(no2, ni2)), dtype=wp.float32, device=device)
    dirs = wp.array(fibonacci_directions(rays).astype(np.float32), dtype=wp.vec3, device=device)
    inputs = [mesh.id, wp.array(fc, dtype=wp.int32, device=device), wp.array(pts, dtype=wp.vec3, device=device), dirs,
              int(rotate), int(seed), max_dist, wp.array(refl, dtype=wp.float32, device=device)]
    launch_ranges(kn.neighbourhood_transfer, n, device, lambda first: inputs + [int(first), scratch, blocked, reflected],
                  jobs)
    m = np.repeat(-blocked.numpy()[:, None], 3, axis=1)
    if len(refl):
        m += reflected.numpy()
    idx = np.arange(min(no2, ni2))
    m[:, :, idx, idx] += 1.0  # N-2: the identity, exactly
    return m.astype(np.float32)


@dataclasses.dataclass
class NeighbourhoodBake:
    path: Path | None
    matrices: np.ndarray
    object_transfer: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    shape: tuple[int, int, int]
    object_vertices: int
    reflection: bool
    seconds: float
    device: str
    grid_seconds: float = 0.0  # the matrices alone (the rest of ``seconds`` is O's own transfer)


@renamed_arguments(order="sh_order")
def bake_neighbourhood(scene, object_name: str, out, *, grid=(16, 16, 16), margin: float = 1.0, sh_order: int = 3,
                       transferred_order: int | None = None, rays: int = 256, reflection: bool = True,
                       bounces: int = 1, rotate: bool = False, seed: int = 0, environment=None,
                       device: str | None = None, overwrite: bool = False, progress=None,
                       jobs: int | None = None) -> NeighbourhoodBake:
    """Bake O's self-transfer and the grid's matrices (N-1, N-2); write a ``lodprt-neighbourhood`` store to ``out``
    (None: only return them). ``transferred_order`` defaults to ``sh_order``."""
    shape = check_grid(grid)
    transferred_order = sh_order if transferred_order is None else transferred_order
    device = resolve_device(device)
    if out is not None:
        prepare_neighbourhood_destination(out, overwrite=overwrite)
    t0 = time.perf_counter()
    pos, faces, normals, kd = object_mesh(scene, object_name)
    geom = Geometry.from_arrays(pos, faces, normals, kd, device=device)
    own = diffuse_transfer(geom, order=sh_order, mode="interreflected" if bounces else "shadowed", rays=rays,
                           bounces=bounces, rotate=rotate, seed=seed, jobs=jobs).transfer
    if progress:
        progress(1, 2)
    lo, hi = neighbourhood_box(pos, margin)
    pts = grid_points(lo, hi, shape)
    t_grid = time.perf_counter()
    m = transfer_matrices(pos, faces, pts, order=sh_order, transferred_order=transferred_order, rays=rays,
                          object_transfer=own if reflection else None, rotate=rotate, seed=seed, device=device,
                          jobs=jobs).reshape(shape + (3, transferred_order**2, sh_order**2))
    if progress:
        progress(2, 2)
    seconds = time.perf_counter() - t0
    res = NeighbourhoodBake(None, m, own, lo, hi, shape, len(pos), reflection, seconds, device,
                            time.perf_counter() - t_grid)
    if out is None:
        return res
    env = None if environment is None else environment.stored(sh_order)
    arrays = {"object/positions": pos.astype(np.float32), "object/normals": normals.astype(np.float32),
              "object/faces": faces, "object/albedo": kd.astype(np.float32), "object/transfer": own}
    res.path = write_neighbourhood_store(
        Path(out), overwrite=overwrite, matrices=m, arrays=arrays, environment=env,
        attrs=dict(source=str(scene.source), object=object_name, grid=list(shape), lo=lo.tolist(), hi=hi.tolist(),
                   margin=float(margin), sh_order=int(sh_order), transferred_order=int(transferred_order),
                   rays=int(rays), directions="spherical-fibonacci", rotate_per_point=bool(rotate), seed=int(seed),
                   reflection=bool(reflection), object_bounces=int(bounces), bake_seconds=float(seconds),
                   grid_seconds=float(res.grid_seconds),
                   device=device))
    return res
