"""Distant-light precomputed radiance transfer per vertex (patent sections 2-3; SPEC 6), baked with the Warp
kernels of ``lodprt.kernels.transfer``: diffuse transfer vectors, unshadowed, shadowed or interreflected (P-10),
glossy transfer matrices (P-11; used at run time with P-12), and the transfer cut of the vertex hierarchy for LOD.
Written as a ``lodprt-transfer`` store (:mod:`lodprt.store.transfer_store`). Equations, units and the stopping rule
of the bounce passes: docs/ENVIRONMENT.md, "Transfer bake".
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from lodprt.devices import load_kernels, resolve_device, warp
from lodprt.launches import launch_ranges
from lodprt.deprecation import renamed_arguments
from lodprt.errors import LodprtError, is_whole
from lodprt.model import sh
from lodprt.model.scene import bounds_offset, ray_offset, referenced_bounds
from lodprt.store.transfer_store import prepare_transfer_destination, write_transfer_store

log = logging.getLogger(__name__)

MODES = ("unshadowed", "shadowed", "interreflected")
GLOSSY_MODES = {"none": 0, "hemisphere": 1, "shadowed": 2}
#: most mirror reflections followed per path (C-1, C-2); longer chains are dropped
MAX_MIRROR = 8


def fibonacci_directions(count: int) -> np.ndarray:
    """Spherical Fibonacci set: (count, 3) float64 unit vectors, z_k = 1 - (2k+1)/count, phi_k = 2 pi k / golden^2.

    Each point stands for the same solid angle 4 pi / count (equal-area latitude bands, golden-angle longitudes).
    """
    count = int(count)
    if count < 1:
        raise LodprtError(f"rays {count}: need at least one direction")
    k = np.arange(count, dtype=np.float64)
    z = 1.0 - (2.0 * k + 1.0) / count
    phi = 2.0 * np.pi * np.mod(k * (3.0 - np.sqrt(5.0)) / 2.0, 1.0)
    s = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def transfer_kernels() -> tuple:
    """The Warp modules a transfer bake launches (for ``lodprt.devices.load_kernels``)."""
    warp()
    from lodprt.kernels import transfer as ktr

    return (ktr,)


@dataclasses.dataclass
class Geometry:
    """A triangle mesh on a Warp device, ready for transfer rays.

    positions, normals (V, 3) float64; faces (F, 3) int32; albedo (V, 3) float64 kd per vertex; referenced (V,)
    """

    positions: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    referenced: np.ndarray
    device: str
    offset: float
    mirror: np.ndarray | None = None  # (F,) mirror reflectance per face (0: not a mirror), None: no mirrors

    @classmethod
    def from_arrays(cls, positions, faces, normals, albedo=(1.0, 1.0, 1.0), *, device=None, offset=None,
                    mirror=None) -> "Geometry":
        pos = np.asarray(positions, np.float64)
        fc = np.asarray(faces, np.int64)
        nrm = np.asarray(normals, np.float64)
        if pos.ndim != 2 or pos.shape[1] != 3 or nrm.shape != pos.shape:
            raise LodprtError(f"transfer: positions and normals must both be (V, 3), got {pos.shape} and {nrm.shape}")
        if fc.ndim != 2 or fc.shape[1] != 3 or (fc.size and (fc.min() < 0 or fc.max() >= len(pos))):
            raise LodprtError(f"transfer: faces must be (F, 3) indices into {len(pos)} vertices")
        alb = np.broadcast_to(np.asarray(albedo, np.float64), pos.shape).copy()
        ref = np.zeros(len(pos), bool)
        ref[fc.ravel()] = True
        # the point-light bake's offset (lodprt.model.scene.ray_offset), over the referenced vertices
        off = bounds_offset(referenced_bounds(pos, ref)) if offset is None else float(offset)
        refl = None
        if mirror is not None:
            refl = np.broadcast_to(np.asarray(mirror, np.float64), (len(fc),)).copy()
            if not (np.isfinite(refl).all() and (refl >= 0).all() and (refl <= 1).all()):
                raise LodprtError("transfer: mirror reflectance per face must lie in [0, 1]")
            refl = refl if (refl > 0).any() else None
        return cls(pos, fc.astype(np.int32), nrm, alb, ref, resolve_device(device), off, refl)

    @classmethod
    def from_scene(cls, scene, *, device=None) -> "Geometry":
        kd = np.array([m.kd for m in scene.materials], np.float64)[scene.material_id]
        refl = np.array([m.ks if getattr(m, "mirror", False) else 0.0 for m in scene.materials])
        mirror = refl[scene.material_id[scene.faces[:, 0]]] if len(scene.faces) else None
        g = cls.from_arrays(scene.positions, scene.faces, scene.normals, kd, device=device, mirror=mirror,
                            offset=ray_offset(scene))
        g.referenced = scene.referenced.copy()
        return g

    def _warp(self):
        if not hasattr(self, "_wp_cache"):
            wp = warp()
            load_kernels(self.device, *transfer_kernels())
            pts = wp.array(self.positions.astype(np.float32), dtype=wp.vec3, device=self.device)
            nrm = wp.array(self.normals.astype(np.float32), dtype=wp.vec3, device=self.device)
            idx = wp.array(self.faces.ravel().astype(np.int32), dtype=wp.int32, device=self.device)
            mesh = wp.Mesh(points=pts, indices=idx)
            faces2d = wp.array(self.faces.astype(np.int32), dtype=wp.int32, device=self.device)
            self._wp_cache = (mesh, pts, nrm, faces2d)
        return self._wp_cache

    @property
    def max_dist(self) -> float:
        return 4.0 * float(np.linalg.norm(self.positions.max(0) - self.positions.min(0))) + 1.0


def _dirs(rays: int, device: str):
    wp = warp()
    return wp.array(fibonacci_directions(rays).astype(np.float32), dtype=wp.vec3, device=device)


def geometric_transfer(geom: Geometry, *, order: int, rays: int = 256, shadowed: bool = True, rotate: bool = False,
                       seed: int = 0, jobs: int | None = None) -> np.ndarray:
    """integral max(n.s, 0) V(s) y_i(s) ds per vertex by rays (no albedo): (V, order^2) float32.

    ``shadowed=False`` drops V (the quadrature of the unshadowed transfer). ``jobs``: CPU threads (default: all
    cores); the result does not depend on it.
    """
    from lodprt.kernels import transfer as ktr

    wp = warp()
    mesh, pts, nrm, _ = geom._warp()
    n = len(geom.positions)
    out = wp.zeros((n, order * order), dtype=wp.float32, device=geom.device)
    scratch = wp.zeros((n, order * order), dtype=wp.float32, device=geom.device)
    dirs = _dirs(rays, geom.device)
    launch_ranges(ktr.diffuse_direct, n, geom.device, lambda first: [
        mesh.id, pts, nrm, dirs, int(rotate), int(seed), int(order), float(geom.offset), int(shadowed), geom.max_dist,
        int(first), scratch, out], jobs)
    return out.numpy()


def mirror_transfer(geom: Geometry, *, order: int, rays: int = 256, rotate: bool = False, seed: int = 0,
                    max_mirror: int = MAX_MIRROR, jobs: int | None = None) -> np.ndarray:
    """C-1, the direct pass with mirror paths (L S* D): integral max(n.s, 0) rho(s) y_i(s_out) ds per vertex, where
    a ray meeting mirrors is reflected (at most ``max_mirror`` times, rho the product of their reflectances) until
    it escapes along s_out or is blocked (0): (V, order^2) float32, no albedo. Without mirrors it is the shadowed
    transfer of :func:`geometric_transfer`."""
    from lodprt.kernels import transfer as ktr

    wp = warp()
    mesh, pts, nrm, faces2d = geom._warp()
    n = len(geom.positions)
    refl = np.zeros(len(geom.faces)) if geom.mirror is None else geom.mirror
    refl = wp.array(refl.astype(np.float32), dtype=wp.float32, device=geom.device)
    out = wp.zeros((n, order * order), dtype=wp.float32, device=geom.device)
    scratch = wp.zeros((n, order * order), dtype=wp.float32, device=geom.device)
    dirs = _dirs(rays, geom.device)
    launch_ranges(ktr.mirror_direct, n, geom.device, lambda first: [
        mesh.id, pts, nrm, faces2d, refl, dirs, int(rotate), int(seed), int(order), float(geom.offset), geom.max_dist,
        int(max_mirror), int(first), scratch, out], jobs)
    return out.numpy()


def unshadowed_transfer_closed_form(geom: Geometry, *, order: int) -> np.ndarray:
    """integral max(n.s, 0) y_i(s) ds per vertex, evaluated in the kernel from the zonal cosine lobe: (V, order^2)."""
    from lodprt.kernels import transfer as ktr

    wp = warp()
    _, _, nrm, _ = geom._warp()
    n = len(geom.positions)
    scale = sh.zonal_scale(sh.cosine_power_zonal(1.0, order)).astype(np.float32)
    out = wp.zeros((n, order * order), dtype=wp.float32, device=geom.device)
    wp.launch(ktr.unshadowed_closed_form, dim=n, device=geom.device,
              inputs=[nrm, int(order), wp.array(scale, dtype=wp.float32, device=geom.device)], outputs=[out])
    return out.numpy()


def _energy(t: np.ndarray, referenced: np.ndarray) -> float:
    """Mean radiance of a pass under a unit white sky: sqrt(4 pi) T_0, over referenced vertices and channels."""
    if not referenced.any():
        return 0.0
    return float(np.sqrt(4 * np.pi) * t[referenced, :, 0].mean())


@dataclasses.dataclass
class DiffuseTransfer:
    """Diffuse transfer vectors and how they were made.

    transfer : (V, 3, order^2) float32, kd/pi included, every pass summed
    passes   : per pass (direct first) its (V, 3, order^2) array when ``keep_passes``, else empty
    energy   : per pass its energy (mean response to a unit white sky)
    """

    transfer: np.ndarray
    mode: str
    order: int
    rays: int
    energy: list[float]
    passes: list[np.ndarray]
    seconds: float
    threshold: float


def diffuse_transfer(geom: Geometry, *, order: int = 3, mode: str = "shadowed", rays: int = 256, bounces: int = 4,
                     threshold: float = 1e-3, rotate: bool = False, seed: int = 0, keep_passes: bool = False,
                     progress=None, jobs: int | None = None, max_mirror: int = MAX_MIRROR) -> DiffuseTransfer:
    """Per-vertex diffuse transfer vectors (P-10 and the interreflection passes; docs/ENVIRONMENT.md).

    ``mode``: unshadowed (closed form), shadowed or interreflected (``bounces`` passes at most after the direct
    one, stopping once a pass' energy is below ``threshold`` times the direct energy; with mirror faces,
    ``geom.mirror``, every pass follows up to ``max_mirror`` specular reflections, C-1 and C-2). ``progress(done, total)``
    is called after each pass; ``jobs`` CPU threads launch vertex ranges (default: all cores).
    """
    if mode not in MODES:
        raise LodprtError(f"transfer mode {mode!r}: choose one of {', '.join(MODES)}")
    if not is_whole(order, 1, 8):
        raise LodprtError(f"sh order {order!r}: the transfer kernels offer orders 1..8")
    if bounces < 0 or not np.isfinite(threshold) or threshold < 0 or max_mirror < 0:
        raise LodprtError(f"bounces {bounces}, threshold {threshold} and max_mirror {max_mirror} must be >= 0")
    from lodprt.kernels import transfer as ktr

    wp = warp()
    t0 = time.perf_counter()
    scale = (geom.albedo / np.pi)[:, :, None]  # (V, 3, 1)
    mirrors = mode == "interreflected" and geom.mirror is not None
    if mode == "unshadowed":
        g = unshadowed_transfer_closed_form(geom, order=order)
    elif mirrors:
        g = mirror_transfer(geom, order=order, rays=rays, rotate=rotate, seed=seed, max_mirror=max_mirror, jobs=jobs)
    else:
        g = geometric_transfer(geom, order=order, rays=rays, shadowed=True, rotate=rotate, seed=seed, jobs=jobs)
    cur = (scale * g[:, None, :]).astype(np.float32)
    cur[~geom.referenced] = 0
    total = cur.astype(np.float64)
    passes = [cur] if keep_passes else []
    energy = [_energy(cur, geom.referenced)]
    if progress:
        progress(1, 1 + (bounces if mode == "interreflected" else 0))
    if mode == "interreflected" and energy[0] > 0:
        mesh, pts, nrm, faces2d = geom._warp()
        n = len(geom.positions)
        k = 3 * order * order
        dirs = _dirs(rays, geom.device)
        for b in range(bounces):
            prev = wp.array(cur.reshape(n, k), dtype=wp.float32, device=geom.device)
            out = wp.zeros((n, k), dtype=wp.float32, device=geom.device)
            if mirrors:
                refl = wp.array(geom.mirror.astype(np.float32), dtype=wp.float32, device=geom.device)
                launch_ranges(ktr.mirror_bounce, n, geom.device, lambda first: [
                    mesh.id, pts, nrm, faces2d, refl, dirs, int(rotate), int(seed) + b + 1, float(geom.offset),
                    geom.max_dist, int(max_mirror), int(first), prev, out], jobs)
            else:
                launch_ranges(ktr.diffuse_bounce, n, geom.device, lambda first: [
                    mesh.id, pts, nrm, faces2d, dirs, int(rotate), int(seed) + b + 1, float(geom.offset),
                    geom.max_dist, int(first), prev, out], jobs)
            cur = (scale * out.numpy().reshape(n, 3, order * order)).astype(np.float32)
            cur[~geom.referenced] = 0
            total += cur
            e = _energy(cur, geom.referenced)
            energy.append(e)
            if keep_passes:
                passes.append(cur)
            if progress:
                progress(b + 2, 1 + bounces)
            log.info("bounce %d: energy %.4g (%.3g of direct)", b + 1, e, e / energy[0])
            if e < threshold * energy[0]:
                break
    return DiffuseTransfer(total.astype(np.float32), mode, order, rays, energy, passes, time.perf_counter() - t0, threshold)


def check_glossy_order(order) -> None:
    """LodprtError unless ``order`` is a whole number in 1..8 (the glossy matrices' orders the kernels offer)."""
    if not is_whole(order, 1, 8):
        raise LodprtError(f"glossy order {order!r}: the transfer kernels offer orders 1..8")


def glossy_transfer(geom: Geometry, ids=None, *, order: int = 3, lighting_order: int | None = None, rays: int = 256,
                    mode: str = "shadowed", rotate: bool = False, seed: int = 0, chunk: int = 1 << 14,
                    jobs: int | None = None) -> np.ndarray:
    """Glossy transfer matrices M_ij = integral V(s) H(n.s) y_i(s) y_j(s) ds (P-11) for vertices ``ids``.

    Returns (G, order^2, lighting_order^2) float32 (square unless ``lighting_order`` differs). ``mode``:
    ``shadowed`` (P-11), ``hemisphere`` (no occlusion), ``none`` (the full sphere: M tends to the identity).
    """
    from lodprt.kernels import transfer as ktr

    if mode not in GLOSSY_MODES:
        raise LodprtError(f"glossy mode {mode!r}: choose one of {', '.join(GLOSSY_MODES)}")
    lighting_order = order if lighting_order is None else int(lighting_order)
    for o in (order, lighting_order):
        check_glossy_order(o)
    wp = warp()
    mesh, pts, nrm, _ = geom._warp()
    ids = np.nonzero(geom.referenced)[0] if ids is None else np.asarray(ids)
    ids = ids.astype(np.int32)
    no, ni = order * order, lighting_order * lighting_order
    big = max(order, lighting_order) ** 2
    out = np.zeros((len(ids), no, ni), np.float32)
    dirs = _dirs(rays, geom.device)
    for s in range(0, len(ids), chunk):
        sub = ids[s : s + chunk]
        res = wp.zeros((len(sub), no, ni), dtype=wp.float32, device=geom.device)
        scratch = wp.zeros((len(sub), big), dtype=wp.float32, device=geom.device)
        wsub = wp.array(sub, dtype=wp.int32, device=geom.device)
        launch_ranges(ktr.glossy_transfer, len(sub), geom.device, lambda first: [
            mesh.id, pts, nrm, wsub, dirs, int(rotate), int(seed), int(order), int(lighting_order), float(geom.offset),
            GLOSSY_MODES[mode], geom.max_dist, int(first), scratch, res], jobs)
        out[s : s + len(sub)] = res.numpy()
    return out


def closest_hits(geom: Geometry, origins, directions) -> tuple[np.ndarray, np.ndarray]:
    """The closest-hit query ``diffuse_bounce`` uses: (face (N,) int32, -1 on a miss; barycentric weights (N, 3))."""
    from lodprt.kernels import transfer as ktr

    wp = warp()
    mesh, _, _, _ = geom._warp()
    o = wp.array(np.asarray(origins, np.float32), dtype=wp.vec3, device=geom.device)
    d = wp.array(np.asarray(directions, np.float32), dtype=wp.vec3, device=geom.device)
    face = wp.zeros(len(o), dtype=wp.int32, device=geom.device)
    bary = wp.zeros(len(o), dtype=wp.vec3, device=geom.device)
    wp.launch(ktr.closest_hits, dim=len(o), device=geom.device, inputs=[mesh.id, o, d, geom.max_dist], outputs=[face, bary])
    return face.numpy(), bary.numpy()


# -- level of detail: keep vertices where transfer vectors differ (thesis 3.3 with transfer in place of the light) --


def transfer_cut(h, transfer, threshold: float, *, floor_fraction: float = 0.05) -> np.ndarray:
    """Bottom-up cut of the vertex hierarchy ``h`` for transfer vectors: (K,) int32 active nodes (a front).

    A node replaces its two children when both did so all the way down and every leaf below it has a transfer
    vector within ``threshold`` (relative) of the node vertex's own: ``max_leaf |T_leaf - T_v| <= threshold
    (|T_v| + floor)``, with ``floor = floor_fraction`` x the mean |T| (dark vertices collapse on an absolute
    scale rather than never). The leaf spread is bounded conservatively by the per-coefficient box of the leaves'
    vectors, built bottom-up a height level at a time. ``threshold`` 0 collapses only identical vectors.
    """
    from lodprt.model.hierarchy import node_heights

    if not np.isfinite(threshold) or threshold < 0:
        raise LodprtError(f"lod threshold {threshold!r}: must be finite and >= 0")
    V, N = h.num_vertices, h.num_nodes
    t = np.asarray(transfer, np.float64).reshape(V, -1)
    norms = np.linalg.norm(t, axis=1)
    floor = floor_fraction * float(norms[norms > 0].mean()) if (norms > 0).any() else 0.0
    lo = np.empty((N, t.shape[1]))
    hi = np.empty((N, t.shape[1]))
    lo[:V] = hi[:V] = t
    ok = np.zeros(N, bool)
    ok[:V] = True
    hk = node_heights(h)
    order = np.argsort(hk, kind="stable")
    bounds = np.searchsorted(hk[order], np.arange(1, hk.max(initial=0) + 2))
    for a, b in zip(bounds[:-1], bounds[1:]):
        nodes = order[a:b]
        c0, c1 = h.children[nodes, 0], h.children[nodes, 1]
        lo[nodes] = np.minimum(lo[c0], lo[c1])
        hi[nodes] = np.maximum(hi[c0], hi[c1])
        tv = t[h.vertex[nodes]]
        spread = np.linalg.norm(np.maximum(hi[nodes] - tv, tv - lo[nodes]), axis=1)
        ok[nodes] = ok[c0] & ok[c1] & (spread <= threshold * (np.linalg.norm(tv, axis=1) + floor))
    parent_ok = np.where(h.parent >= 0, ok[np.maximum(h.parent, 0)], False)
    return np.flatnonzero(ok & ~parent_ok).astype(np.int32)


# -- bake and store ---------------------------------------------------------------------------------------------


@dataclasses.dataclass
class TransferBake:
    """What :func:`bake_transfer` made: ``diffuse`` (every vertex), the glossy vertices ``glossy_ids`` and the
    matrices ``glossy`` of ``glossy_kept_ids`` (all of them without LOD), and with LOD the hierarchy ``tree`` and the
    ``cut_nodes`` whose vertices the store keeps."""

    path: Path | None
    diffuse: DiffuseTransfer
    glossy_ids: np.ndarray
    glossy: np.ndarray | None
    seconds: float
    load_seconds: float
    device: str
    cut_nodes: np.ndarray | None = None
    tree: object = None
    glossy_kept_ids: np.ndarray | None = None


@renamed_arguments(order="sh_order", threshold="bounce_threshold")
def bake_transfer(scene, out, *, sh_order: int = 3, mode: str = "interreflected", rays: int = 256, bounces: int = 4,
                  bounce_threshold: float = 1e-3, glossy: bool = True, glossy_order: int | None = None,
                  glossy_mode: str = "shadowed", rotate: bool = False, seed: int = 0, environment=None,
                  lod_threshold: float | None = None, tree=None, device: str | None = None, overwrite: bool = False,
                  progress=None, jobs: int | None = None) -> TransferBake:
    """Bake diffuse transfer vectors for every vertex and glossy matrices for vertices whose material has ks > 0.

    Writes a ``lodprt-transfer`` store (docs/FORMAT.md, "Environment transfer store") to ``out`` unless it is
    None. ``environment`` (an :class:`lodprt.environment.Environment`) is optional: its coefficients are stored
    as the default lighting for rendering. The transfer itself does not depend on the lighting.
    With ``lod_threshold`` the vertex hierarchy is built (or ``tree`` used) and only the vertices of
    :func:`transfer_cut` keep their diffuse transfer vectors and glossy matrices (only those are baked) in the
    store; the rest are completed on reading (T-15).
    """
    device = resolve_device(device)
    if glossy_order is not None:  # before any work, glossy or not
        check_glossy_order(glossy_order)
    if out is not None:
        prepare_transfer_destination(out, overwrite=overwrite)
    t_load = load_kernels(device, *transfer_kernels())
    t0 = time.perf_counter()
    geom = Geometry.from_scene(scene, device=device)
    diffuse = diffuse_transfer(geom, order=sh_order, mode=mode, rays=rays, bounces=bounces, threshold=bounce_threshold,
                               rotate=rotate, seed=seed, progress=progress, jobs=jobs)
    ks = np.array([m.ks for m in scene.materials])
    gids = np.nonzero(geom.referenced & (ks[scene.material_id] > 0))[0].astype(np.int32) if glossy else np.zeros(0, np.int32)
    gorder = sh_order if glossy_order is None else glossy_order  # a 0 was refused above, not replaced
    cut_nodes = None
    hierarchy_seconds = None
    gkept = gids  # the glossy vertices whose matrices are baked and stored
    if lod_threshold is not None:
        t_h = time.perf_counter()
        if tree is None:
            from lodprt.model.hierarchy_build import build_hierarchy

            tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
        hierarchy_seconds = time.perf_counter() - t_h
        cut_nodes = transfer_cut(tree, diffuse.transfer, lod_threshold)
        gkept = np.intersect1d(gids, tree.vertex[cut_nodes]).astype(np.int32)  # the rest is completed (T-15)
    gmat = glossy_transfer(geom, gkept, order=gorder, lighting_order=sh_order, rays=rays, mode=glossy_mode,
                           rotate=rotate, seed=seed, jobs=jobs) if len(gkept) else None
    seconds = time.perf_counter() - t0 - (hierarchy_seconds or 0.0)
    result = TransferBake(None, diffuse, gids, gmat, seconds, t_load, device, cut_nodes, tree, gkept)
    if out is None:
        return result
    env = None if environment is None else environment.stored(sh_order)
    result.path = write_transfer_store(
        Path(out), scene, overwrite=overwrite, diffuse=diffuse.transfer, glossy_ids=gids, glossy=gmat,
        glossy_kept_ids=gkept if cut_nodes is not None else None, cut_nodes=cut_nodes, tree=tree, hierarchy_seconds=hierarchy_seconds, environment=env,
        attrs=dict(
            source=str(scene.source),
            sh_order=int(sh_order),
            mode=mode,
            rays=int(rays),
            directions="spherical-fibonacci",
            rotate_per_vertex=bool(rotate),
            seed=int(seed),
            bounces=len(diffuse.energy) - 1,
            bounce_threshold=float(bounce_threshold),
            pass_energy=[float(e) for e in diffuse.energy],
            glossy_order=int(gorder) if gmat is not None else None,
            glossy_mode=glossy_mode if gmat is not None else None,
            ray_offset=float(geom.offset),
            lod_threshold=None if cut_nodes is None else float(lod_threshold),
            vertices_kept=int(geom.referenced.sum() if cut_nodes is None else len(cut_nodes)),
            glossy_kept=int(len(gkept)),
            mirror_paths=bool(mode == "interreflected" and geom.mirror is not None),
            max_mirror=MAX_MIRROR if mode == "interreflected" and geom.mirror is not None else None,
            hierarchy_seconds=hierarchy_seconds,
            bake_seconds=float(seconds),
            load_seconds=float(t_load),
            device=device,
        ),
    )
    return result
