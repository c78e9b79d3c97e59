"""Run-time relighting of a transfer bake under a (rotating) distant environment (patent P-10..P-12, SPEC 6).

Per frame: rotate the environment's SH coefficients (P-4), then per vertex

    diffuse  L_o = T . L                                              (one dot product per channel, P-10)
    glossy   L_o += ks sum_k (h * (M L))_k y_k(R)                       (matrix-vector, Phong convolution P-6,
                                                                        evaluation in the reflection direction P-12)

with ``R = 2 (n.v) n - v`` the view direction ``v`` (vertex to eye) mirrored about the normal and ``h`` the
material's lobe ``max(cos, 0)^shininess``. Everything is float64 numpy on the host: a frame of the 35k-vertex bunny
at order 3 is a few milliseconds for the diffuse part.
"""

from __future__ import annotations

import numpy as np

from lodprt.model import sh
from lodprt.model.environment import load_environment, rotate_lighting, rotation_about_y
from lodprt.errors import LodprtError


def stored_or_given_lighting(store, store_path, environment) -> np.ndarray:
    """The lighting coefficients (3, n^2) of a transfer or volume ``store`` (at ``store_path``): of the map
    ``environment`` when given, else the ones its bake stored."""
    if environment:
        return load_environment(environment).project(store.order)
    if store.has("environment/coefficients"):
        return store.read("environment/coefficients")
    raise LodprtError(f"{store_path}: the bake stored no environment; pass --environment ENV")


def rotated_lighting(coeffs, degrees: float = 0.0) -> np.ndarray:
    """Environment coefficients (C, n^2) turned by ``degrees`` about +y (the world's up): (C, n^2) float64."""
    c = np.asarray(coeffs, np.float64)
    return c if degrees == 0 else rotate_lighting(c, rotation_about_y(degrees))


def diffuse_radiance(transfer, lighting) -> np.ndarray:
    """L_o = T . L per vertex and channel: transfer (V, 3, n^2), lighting (3, >= n^2) -> (V, 3) float64."""
    t = np.asarray(transfer, np.float64)
    n2 = t.shape[-1]
    lighting = np.asarray(lighting, np.float64)
    if lighting.shape[0] != t.shape[1] or lighting.shape[-1] < n2:
        raise LodprtError(f"relight: lighting {lighting.shape} does not fit transfer vectors {t.shape}")
    return np.einsum("vci,ci->vc", t, lighting[:, :n2])


def glossy_radiance(matrices, positions, normals, ks, shininess, lighting, eye) -> np.ndarray:
    """Glossy radiance toward ``eye`` (P-12) of G vertices: matrices (G, no^2, ni^2), positions and normals (G, 3),
    ks and shininess (G,), lighting (3, >= ni^2) -> (G, 3) float64.
    """
    m = np.asarray(matrices, np.float64)
    g, no2, ni2 = m.shape
    order = int(round(np.sqrt(no2)))
    lt = np.einsum("gij,cj->gci", m, np.asarray(lighting, np.float64)[:, :ni2])  # transferred incident radiance
    scale = np.empty((g, no2))
    shin = np.asarray(shininess, np.float64)
    for n in np.unique(shin):  # P-6 convolution factors sqrt(4 pi/(2l+1)) z_l of each material's lobe
        scale[shin == n] = sh.zonal_scale(sh.cosine_power_zonal(n, order))
    v = np.asarray(eye, np.float64)[None, :] - positions
    v /= np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
    nrm = np.asarray(normals, np.float64)
    r = 2.0 * (nrm * v).sum(1, keepdims=True) * nrm - v
    y = sh.basis(r, order)
    return np.asarray(ks, np.float64)[:, None] * np.einsum("gci,gi,gi->gc", lt, scale, y)


def open_transfer(path):
    from lodprt.store.transfer_store import TransferStore

    return TransferStore(path)


def relit_radiance(store, lighting, eye=None) -> np.ndarray:
    """Radiance (V, 3) float64 of every vertex of a transfer store under ``lighting`` (3, n^2), seen from ``eye``.

    The glossy term is added where the store holds matrices (needs ``eye``); vertices no face uses stay 0.
    """
    rad = diffuse_radiance(store.diffuse(), lighting)
    ids, matrices = store.glossy()  # a LOD store's are completed (T-15)
    if len(ids) and eye is not None and matrices is not None:
        mid = store.read("scene/material_id")[ids]
        ks = store.read("materials/ks")[mid]
        shin = store.read("materials/shininess")[mid]
        rad[ids] += glossy_radiance(matrices, store.read("scene/positions")[ids].astype(np.float64),
                                    store.read("scene/normals")[ids].astype(np.float64), ks, shin, lighting, eye)
    return rad


