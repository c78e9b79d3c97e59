"""Run time of neighbourhood transfer (patent 5; N-3..N-5 of docs/VOLUMES.md): an object O's shadow and reflected
light on a receiver mesh that was not known at bake time.

Once per frame, on the grid: ``L'_p = M_p L`` (N-3; after rotating the lighting, P-4). Per receiver vertex q with
normal N and albedo kd: ``L'_q`` by trilinear interpolation of the grid's ``L'_p`` (N-4; vertices outside the grid
get the unmodified lighting L: O's influence is taken to end at the grid's box), then the diffuse exit radiance

    L_o(q) = kd/pi sum_i sqrt(4 pi/(2l+1)) z_l y_i(N) L'_q,i                                              (N-5)

with z_l the zonal coefficients of max(cos, 0) (P-6): the receiver's unshadowed transfer applied to the
transferred lighting (the receiver's own occlusion of itself is not included).
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model import sh


def open_neighbourhood(path):
    """A :class:`lodprt.store.neighbourhood_store.NeighbourhoodStore` (StoreError when ``path`` is not one)."""
    from lodprt.store.neighbourhood_store import NeighbourhoodStore

    return NeighbourhoodStore(path)


def transferred_lighting(matrices, lighting) -> np.ndarray:
    """N-3: L'_p = M_p L on every grid point: matrices (..., 3, no^2, ni^2), lighting (3, >= ni^2) ->
    (..., 3, no^2) float64 (computed in float32, the precision of the stored matrices)."""
    m = np.asarray(matrices)
    lt = np.asarray(lighting, np.float64)
    ni2 = m.shape[-1]
    if m.ndim < 3 or m.shape[-3] != 3 or lt.ndim != 2 or lt.shape[0] != 3 or lt.shape[1] < ni2:
        raise LodprtError(f"neighbourhood: lighting {lt.shape} does not fit transfer matrices {m.shape}")
    # one batched float32 matrix-vector product per point and channel (BLAS), returned as float64
    return np.matmul(m.astype(np.float32, copy=False), lt[:, :ni2, None].astype(np.float32))[..., 0].astype(np.float64)


def interpolate(values, lo, hi, points) -> tuple[np.ndarray, np.ndarray]:
    """N-4: vertex-centred trilinear interpolation of ``values`` (NX, NY, NZ, ...) over the box [lo, hi] at
    ``points`` (V, 3): (V, ...) float64 and ``inside`` (V,) bool; points outside the box get 0."""
    v = np.asarray(values)
    p = np.asarray(points, np.float64).reshape(-1, 3)
    shape = np.array(v.shape[:3])
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):  # a non-finite point is outside (NaN compares False)
        u = (p - lo) / (hi - lo) * (shape - 1)
    inside = np.all((u >= 0) & (u <= shape - 1), axis=1)
    u = np.where(np.isfinite(u), np.clip(u, 0, shape - 1), 0.0)
    i0 = np.minimum(np.floor(u).astype(np.int64), shape - 2)
    f = u - i0
    out = np.zeros((len(p),) + v.shape[3:])
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                w = (f[:, 0] if cx else 1 - f[:, 0]) * (f[:, 1] if cy else 1 - f[:, 1]) * (f[:, 2] if cz else 1 - f[:, 2])
                out += w.reshape((-1,) + (1,) * (v.ndim - 3)) * v[i0[:, 0] + cx, i0[:, 1] + cy, i0[:, 2] + cz]
    out[~inside] = 0
    return out, inside


def receiver_lighting(grid_lighting, lo, hi, lighting, points) -> tuple[np.ndarray, np.ndarray]:
    """L'_q at receiver points (N-4): grid_lighting (NX, NY, NZ, 3, no^2) from :func:`transferred_lighting`,
    lighting (3, ni^2) -> ((V, 3, no^2) float64, inside (V,) bool); outside the grid, L itself (padded with 0)."""
    lq, inside = interpolate(grid_lighting, lo, hi, points)
    no2 = lq.shape[-1]
    lt = np.asarray(lighting, np.float64)
    plain = np.zeros((3, no2))
    n = min(no2, lt.shape[1])
    plain[:, :n] = lt[:, :n]
    lq[~inside] = plain
    return lq, inside


def diffuse_exit(lq, normals, albedo) -> np.ndarray:
    """N-5: kd/pi times the irradiance of the transferred lighting ``lq`` (V, 3, no^2) about ``normals`` (V, 3):
    (V, 3) float64; albedo (V, 3) or (3,)."""
    lq = np.asarray(lq, np.float64)
    order = int(round(np.sqrt(lq.shape[-1])))
    lobe = sh.basis(np.asarray(normals, np.float64), order) * sh.zonal_scale(sh.cosine_power_zonal(1.0, order))
    return np.asarray(albedo, np.float64) / np.pi * np.einsum("vci,vi->vc", lq, lobe)


def receiver_radiance(store, lighting, positions, normals, albedo) -> tuple[np.ndarray, np.ndarray]:
    """Exit radiance (V, 3) of a receiver (positions, normals (V, 3), albedo (V, 3)) in the neighbourhood of a
    store's object under ``lighting`` (3, ni^2): N-3, N-4, N-5; also ``inside`` (V,) bool (in the grid)."""
    grid = transferred_lighting(store.matrices(), lighting)
    lq, inside = receiver_lighting(grid, store.lo, store.hi, lighting, positions)
    return diffuse_exit(lq, normals, albedo), inside
