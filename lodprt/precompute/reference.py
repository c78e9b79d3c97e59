"""Float64 numpy bake with Embree rays: the oracle of the tests and the baseline of the benchmarks (visibility and
Phong SH coefficients, T-6, P-6). Shares no code path with the Warp kernels beyond the visibility state numbers
(``lodprt.kernels.visibility``) and the SH reference (``lodprt.model.sh``). Needs the ``dev`` extra (embreex)."""

from __future__ import annotations

import numpy as np

from lodprt.kernels.visibility import BACK_FACING, LIT, SHADOWED
from lodprt.model import sh
from lodprt.model.scene import Scene



class EmbreeCaster:
    """Occlusion queries on the scene's triangles with Embree (embreex)."""

    def __init__(self, scene: Scene):
        try:
            from embreex import rtcore_scene as rtcs
            from embreex.mesh_construction import TriangleMesh
        except ImportError as exc:  # pragma: no cover
            raise ImportError("the reference caster needs embreex: pip install 'lodprt[dev]'") from exc
        self.scene = rtcs.EmbreeScene()
        TriangleMesh(self.scene, scene.positions[scene.faces].astype(np.float32))

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, dists: np.ndarray) -> np.ndarray:
        """(N,) bool: does a ray hit anything within its distance."""
        hit = self.scene.run(
            origins.astype(np.float32), dirs.astype(np.float32), dists=dists.astype(np.float32), query="OCCLUDED"
        )
        return np.asarray(hit) != -1


def shadow_rays(scene: Scene, light: np.ndarray, offset: float, ids: np.ndarray | None = None):
    """The kernel's rays, in float64: origin p + offset n toward the light, stopping offset short of it.

    Returns (facing (K,) bool, origins (K,3), unit dirs (K,3), distances (K,)).
    """
    ids = np.arange(scene.num_vertices) if ids is None else ids
    p, n = scene.positions[ids], scene.normals[ids]
    facing = (n * (light[None, :] - p)).sum(1) > 0
    o = p + offset * n
    d = light[None, :] - o
    dist = np.linalg.norm(d, axis=1)
    return facing, o, d / np.maximum(dist, 1e-300)[:, None], dist - offset


def visibility(caster: EmbreeCaster, scene: Scene, light: np.ndarray, offset: float, ids=None) -> np.ndarray:
    """(K,) uint8 SHADOWED / LIT / BACK_FACING, rays cast only for vertices facing the light."""
    facing, o, d, dist = shadow_rays(scene, light, offset, ids)
    state = np.full(len(facing), BACK_FACING, np.uint8)
    hit = caster.occluded(o[facing], d[facing], dist[facing])
    state[facing] = np.where(hit, SHADOWED, LIT)
    return state


def phong_coefficients(scene: Scene, light: np.ndarray, order: int, visible: np.ndarray, ids=None) -> np.ndarray:
    """float64 (K, order^2) unit-intensity SH coefficients of Phong radiance over view directions (SPEC 4).

    Grey materials only (channel 0 of kd); the closed form: diffuse in y_0, specular lobe zonal rotated to R (P-6).
    """
    ids = np.arange(scene.num_vertices) if ids is None else ids
    p, n = scene.positions[ids], scene.normals[ids]
    to = light[None, :] - p
    d = np.linalg.norm(to, axis=1)
    l = np.where(d[:, None] > 0, to / np.where(d > 0, d, 1)[:, None], n)
    e = 1.0 / np.maximum(d, scene.lights.radius) ** 2 if scene.lights.falloff == "inverse-square" else np.ones(len(d))
    ndotl = (n * l).sum(1)
    r = 2 * ndotl[:, None] * n - l
    out = np.zeros((len(ids), order * order))
    mat = scene.material_id[ids]
    for mi, m in enumerate(scene.materials):
        sel = mat == mi
        out[sel, 0] = e[sel] * np.clip(ndotl[sel], 0, None) * m.kd[0] * np.sqrt(4 * np.pi)  # T-6 of a constant
        if m.ks > 0:
            out[sel] += (e[sel] * m.ks)[:, None] * sh.cosine_power_lobe(r[sel], m.shininess, order)
    out[visible != LIT] = 0
    return out
