"""Run-time relighting of a volume transfer bake (patent 4.3; V-6 in docs/VOLUMES.md): per frame and voxel the
source radiance ``J = M . L`` (one dot product per channel of the voxel's transfer vector with the lighting's SH
coefficients, after rotating the lighting, P-4). ``J`` is what the voxel scatters toward any direction (isotropic
phase function); :mod:`lodprt.display.volume_render` marches it with the density toward the eye.
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError


def open_volume(path):
    """A :class:`lodprt.store.volume_store.VolumeStore` (StoreError when ``path`` is not one)."""
    from lodprt.store.volume_store import VolumeStore

    return VolumeStore(path)


def source_radiance(transfer, lighting) -> np.ndarray:
    """V-6: J = M . L per voxel and channel: transfer (X, Y, Z, 3, n^2), lighting (3, >= n^2) -> (X, Y, Z, 3)
    float32."""
    t = np.asarray(transfer, np.float32)
    lt = np.asarray(lighting, np.float64)
    n2 = t.shape[-1]
    if t.ndim != 5 or t.shape[3] != 3 or lt.ndim != 2 or lt.shape[0] != 3 or lt.shape[1] < n2:
        raise LodprtError(f"relight volume: lighting {lt.shape} does not fit transfer vectors {t.shape}")
    return np.einsum("xyzci,ci->xyzc", t, lt[:, :n2].astype(np.float32), optimize=True)
