"""Diffuse interreflection inside the point-light bake (docs/GI.md; THEORY.md G-1..G-7): per light sample, the direct
term of :mod:`lodprt.precompute.bake` plus ``bounces`` passes of gathered diffuse radiance (``kernels.gi``).

Full resolution (``Interreflection.full``): bounce 0 is the direct diffuse radiance of every referenced vertex; each
pass gathers the previous one at every referenced vertex. On the light cut (``Interreflection.sample_cut``): bounce 0
is still computed at every vertex (one shadow ray each, which the cut needs anyway), passes gather only at the
vertices of the *indirect cut* (G-5, light-independent, built once per bake from harmonic mean hit distances and
normal cones) and T-15 completes the rest; the stored cut is the common refinement (G-6) of the light cut, the
indirect cut and the ring-purity front (collapses whose T-15 rings mix directly lit and unlit vertices are split),
and no node is dark unless its radiance is exactly zero (G-7). With ``indirect_tolerance`` the indirect cut is
error-driven instead (G-9, :mod:`lodprt.precompute.indirect_cut`): per sample and pass, refined from a coarse level
where the gathered irradiance departs from its T-15 prediction, within a stated error budget per pass.
"""

from __future__ import annotations

import dataclasses
import math
import threading

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError, is_whole
from lodprt.kernels.visibility import BACK_FACING, LIT
from lodprt.launches import launch_ranges
from lodprt.model import sh
from lodprt.model.hierarchy import active_ancestors, node_heights

#: rays per vertex of the one-off harmonic-distance pass of the indirect cut (G-5)
DISTANCE_RAYS = 16


def vertex_areas(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V,) float64 a third of the area of the faces around each vertex (0 for unreferenced ones)."""
    p = np.asarray(positions, np.float64)
    f = np.asarray(faces, np.int64)
    a = 0.5 * np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1)
    return np.bincount(f.ravel(), weights=np.repeat(a / 3.0, 3), minlength=len(p))


def cosine_fibonacci(count: int) -> np.ndarray:
    """(count, 3) float64 cosine-weighted unit directions about +z (G-3): the spherical-Fibonacci disk points
    ``r_k = sqrt((k + 1/2)/count)``, ``phi_k = 2 pi frac(k / golden^2)`` lifted onto the hemisphere (Malley's method),
    so each direction stands for the same share of the projected solid angle (pdf ``cos / pi``)."""
    count = int(count)
    if count < 1:
        raise LodprtError(f"gi rays {count}: need at least one direction")
    k = np.arange(count, dtype=np.float64)
    r = np.sqrt((k + 0.5) / count)
    phi = 2.0 * np.pi * np.mod(k * (3.0 - np.sqrt(5.0)) / 2.0, 1.0)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.clip(1.0 - r * r, 0.0, None))], axis=1)


def constant_coefficient() -> float:
    """The y_0 coefficient of the constant function 1 (T-6): sqrt(4 pi), by the project's SH projection."""
    dirs, weights = sh.quadrature_for_order(1)
    return float(sh.project(np.ones(len(weights)), dirs, weights, 1)[0])


@dataclasses.dataclass(frozen=True)
class GISettings:
    """Interreflection options of a point-light bake.

    bounces: diffuse passes after the direct term (0: the direct-only bake); threshold: stop early once a pass'
    mean radiance is below ``threshold`` times the direct term's; rays: gathering rays per vertex and pass;
    indirect_threshold_deg: angle of the indirect cut (G-5; None gathers at every vertex the light cut keeps);
    seed: of the per-vertex rotations of the ray set; indirect_tolerance: when set, the error-driven indirect cut
    (G-9) replaces G-5: the RMS error each pass' estimates may leave over the vertices, relative to the RMS direct
    radiance (the actual error is larger: docs/GI.md).
    """

    bounces: int = 0
    threshold: float = 1e-3
    rays: int = 64
    indirect_threshold_deg: float | None = 10.0
    seed: int = 0
    indirect_tolerance: float | None = None

    def __post_init__(self):
        if not is_whole(self.bounces, 0, 64):
            raise LodprtError(f"bounces {self.bounces!r}: must be an integer in 0..64")
        if not (math.isfinite(self.threshold) and self.threshold >= 0):
            raise LodprtError(f"bounce_threshold {self.threshold!r}: must be finite and >= 0")
        if not is_whole(self.rays, 1, 1 << 16):
            raise LodprtError(f"gi_rays {self.rays!r}: must be an integer in 1..65536")
        t = self.indirect_threshold_deg
        if t is not None and not (math.isfinite(t) and 0 <= t <= 180):
            raise LodprtError(f"indirect_threshold_deg {t!r}: must lie in [0, 180] degrees")
        tol = self.indirect_tolerance
        if tol is not None and (isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol)
                                or not 0 < tol <= 1):
            raise LodprtError(f"indirect_tolerance {tol!r}: must be a number in (0, 1] (a relative RMS error of "
                              "the indirect radiance, G-9) or None for the geometric indirect cut (G-5)")

    def attributes(self) -> dict:
        """The store's root attributes of these settings (docs/FORMAT.md); ``indirect_tolerance`` only when set
        (G-9), so stores of the geometric cut keep the attributes they had (and resume as before)."""
        out = {"bounces": int(self.bounces), "bounce_threshold": float(self.threshold), "gi_rays": int(self.rays),
               "gi_directions": "cosine-spherical-fibonacci", "gi_seed": int(self.seed),
               "indirect_threshold_deg": None if self.indirect_threshold_deg is None
               else float(self.indirect_threshold_deg)}
        if self.indirect_tolerance is not None:
            out["indirect_tolerance"] = float(self.indirect_tolerance)
        return out


class Interreflection:
    """Device-side interreflection state of one bake, shared read-only by the sample threads (each call allocates
    its own work arrays). ``baker`` is the bake's :class:`lodprt.precompute.baker.Baker`; ``tree`` the hierarchy
    when the bake uses light cuts (then :meth:`prepare_cut` builds the indirect cut and completion plan)."""

    def __init__(self, baker, scene, settings: GISettings):
        wp = warp()
        self.wp, self.baker, self.settings = wp, baker, settings
        dev = baker.device
        self.V = scene.num_vertices
        self.faces = wp.array(scene.faces.astype(np.int32), dtype=wp.int32, device=dev)
        dirs = cosine_fibonacci(settings.rays).astype(np.float32)
        self.dirs = wp.array(dirs, dtype=wp.vec3, device=dev)
        self.spec_scale = float(2.0 / np.mean(1.0 / np.maximum(dirs[:, 2].astype(np.float64), 1e-6)))  # G-4
        self.area = vertex_areas(scene.positions, scene.faces)  # G-8 energy weights
        kd = np.array([m.kd[: baker.channels] for m in scene.materials], np.float64)
        self.kd_v = kd[scene.material_id]  # (V, C)
        # G-4: view-dependent indirect light only where some material reflects specularly (ks > 0)
        self.specular = baker.ncoef > 1 and any(float(m.ks) > 0.0 for m in scene.materials)
        self.referenced = scene.referenced.copy()
        self.y0 = constant_coefficient()
        self.max_dist = 4.0 * float(scene.diagonal) + 1.0
        self.positions, self.normals = scene.positions, scene.normals
        self.energy: dict[int, list[float]] = {}  # per light sample, the passes' mean radiance (direct first)
        self.gathered: dict[tuple, list[int]] = {}  # per light sample, each pass' gathering vertices (G-9)
        self._lock = threading.Lock()
        self.cut_state = None

    # -- passes --------------------------------------------------------------------------------------------------

    def _direct(self, light, ids, visible):
        """Bounce 0 (G-1): (V, C) device array of the direct diffuse radiance, rows ``ids``; 0 elsewhere."""
        from lodprt.kernels import gi as kgi

        wp, b = self.wp, self.baker
        out = wp.zeros((self.V, b.channels), dtype=wp.float32, device=b.device)
        wp.launch(kgi.direct_diffuse, dim=ids.shape[0], device=b.device,
                  inputs=[b.points, b.normals, b.material_id, ids, visible, b.kd, wp.vec3(*map(float, light)),
                          b.falloff, b.radius], outputs=[out])
        return out

    def _gather(self, ids, previous, bounce: int, specular):
        """One pass (G-2, G-4) at vertices ``ids`` (device): (G, C) mean incident radiance; ``specular`` += ."""
        from lodprt.kernels import gi as kgi

        wp, b = self.wp, self.baker
        g = ids.shape[0]
        gathered = wp.zeros((g, b.channels), dtype=wp.float32, device=b.device)
        basis = wp.zeros((g, b.sh_order * b.sh_order if b.ncoef > 1 else 1), dtype=wp.float32, device=b.device)
        wp.launch(kgi.gather_bounce, dim=g, device=b.device,
                  inputs=[b.mesh.id, b.points, b.normals, self.faces, b.material_id, ids, b.ks, b.zonal, self.dirs,
                          previous, int(self.settings.seed) + bounce, float(b.offset), self.max_dist,
                          self.spec_scale, basis],
                  outputs=[gathered, specular])
        return gathered.numpy().astype(np.float64)

    def _energy(self, radiance: np.ndarray) -> float:
        """Area-weighted mean outgoing diffuse radiance over the surface, channels averaged (G-8): exitant power
        over pi times the area, the measure of the stopping rule and of the energy bound of each pass."""
        total = float(self.area.sum())
        return float((self.area[:, None] * radiance).sum() / (total * radiance.shape[1])) if total > 0 else 0.0

    def _passes(self, light, visible_all, gather_ids: np.ndarray, complete, keep: list | None = None):
        """Bounce 0 at every referenced vertex, then the passes at ``gather_ids`` (host (G,) int32);
        ``complete(values (G, ...))`` -> (V, ...) fills the other vertices (identity scatter at full resolution).
        Returns (sum of E_b over the passes (V, C), specular coefficients (V, C, ncoef) or None, energies);
        ``keep`` (a list) receives each pass' outgoing diffuse radiance (V, C), bounce 0 first."""
        wp, b, st = self.wp, self.baker, self.settings
        ids_all = b.ids
        rad = self._direct(light, ids_all, visible_all)
        energies = [self._energy(rad.numpy())]
        if keep is not None:
            keep.append(rad.numpy().astype(np.float64))
        total = np.zeros((self.V, b.channels))
        spec_on = self.specular
        ids = wp.array(gather_ids, dtype=wp.int32, device=b.device)
        specular = wp.zeros((len(gather_ids), b.channels, b.ncoef if spec_on else 1), dtype=wp.float32, device=b.device)
        for bounce in range(st.bounces):
            if energies[0] <= 0.0:
                break  # nothing is lit: no light to reflect
            e_full = complete(self._gather(ids, rad, bounce, specular))  # G-2, then T-15 off the gathering set
            total += e_full
            radiance = self.kd_v * e_full  # G-1: Lambert kd / pi times pi E_b
            energies.append(self._energy(radiance))
            if keep is not None:
                keep.append(radiance)
            if energies[-1] < st.threshold * energies[0] or bounce == st.bounces - 1:
                break
            rad = wp.array(radiance.astype(np.float32), dtype=wp.float32, device=b.device)
        spec = complete(specular.numpy().astype(np.float64)) if spec_on and len(energies) > 1 else None
        return total, spec, energies

    def _passes_refined(self, light, visible_all):
        """Bounce 0 at every referenced vertex, then each pass on its own error-driven indirect cut (G-9).
        Returns (sum of E_b over the passes (V, C), specular coefficients (V, C, ncoef) or None, energies, the
        active ancestor (V,) of each vertex on the deepest of the passes' fronts or None without passes, the
        number of gathering vertices of each pass)."""
        from lodprt.precompute.indirect_cut import refine_pass

        wp, b, st, cs = self.wp, self.baker, self.settings, self.cut_state
        rad = self._direct(light, b.ids, visible_all)
        direct = rad.numpy().astype(np.float64)
        energies = [self._energy(direct)]
        ref = self.referenced
        l_rms = math.sqrt(float(np.mean(direct[ref].mean(1) ** 2))) if ref.any() else 0.0
        tol = st.indirect_tolerance * l_rms  # G-9: the RMS error a pass may leave, tau L_rms
        total = np.zeros((self.V, b.channels))
        spec_on = self.specular
        spec_total, anc, counts = None, None, []

        def complete(ids, values):
            return cs.plan.complete(ids, values, self.V)  # T-15 from the gathering vertices

        def predict(k, ids, values):  # T-15 of level k's vertices alone: the rows they read (G-9)
            return cs.plan.complete(ids, values, self.V, rows=cs.level_rows[k])

        for bounce in range(st.bounces):
            if energies[0] <= 0.0:
                break  # nothing is lit: no light to reflect

            def gather(ids, previous=rad, bounce=bounce):
                specular = wp.zeros((len(ids), b.channels, b.ncoef if spec_on else 1), dtype=wp.float32,
                                    device=b.device)
                e = self._gather(wp.array(ids, dtype=wp.int32, device=b.device), previous, bounce, specular)
                return e, specular.numpy().astype(np.float64) if spec_on else None

            ids, e, spec, front, _ = refine_pass(cs.levels, gather, complete, self.kd_v, tol, predict)  # G-9
            counts.append(len(ids))
            e_full = complete(ids, e)
            total += e_full
            if spec is not None:
                spec_total = complete(ids, spec) + (0.0 if spec_total is None else spec_total)
            a = active_ancestors(cs.h, front)
            anc = a if anc is None else np.minimum(anc, a)  # the deepest front of the passes (G-6)
            radiance = self.kd_v * e_full  # G-1
            energies.append(self._energy(radiance))
            if energies[-1] < st.threshold * energies[0] or bounce == st.bounces - 1:
                break
            rad = wp.array(radiance.astype(np.float32), dtype=wp.float32, device=b.device)
        return total, spec_total, energies, anc, counts

    def _coefficients(self, ids: np.ndarray, total: np.ndarray, spec) -> np.ndarray:
        """(K, C, ncoef) float32 indirect SH coefficients of vertices ``ids`` (G-4: diffuse in y_0 alone)."""
        b = self.baker
        out = np.zeros((len(ids), b.channels, b.ncoef))
        if spec is not None:
            out += spec[ids]
        out[:, :, 0] += self.y0 * self.kd_v[ids] * total[ids]
        return out.astype(np.float32)

    def _remember(self, light, energies, gathered=None) -> None:
        with self._lock:
            self.energy[tuple(float(x) for x in light)] = energies
            if gathered is not None:
                self.gathered[tuple(float(x) for x in light)] = gathered

    def sample_attributes(self, light) -> dict:
        """What a light sample's group records of its interreflection: each pass' mean radiance (bounce 0 first)
        and the vertices the indirect cut gathers at (``gi_attributes`` assembles the root's from them, so a
        sample baked on a dask worker or in an earlier, resumed run counts the same)."""
        key = tuple(float(x) for x in light)
        energy = self.energy.get(key, [])
        if self.cut_state is None:
            gather = None
        elif self.cut_state.gather_ids is None:  # G-9: the mean over the sample's passes
            passes = self.gathered.get(key, [])
            gather = int(round(float(np.mean(passes)))) if passes else 0
        else:
            gather = int(len(self.cut_state.gather_ids))
        return {"bounce_energy": [float(e) for e in energy], "indirect_gather_vertices": gather}

    def pass_radiance(self, light) -> list[np.ndarray]:
        """Each pass' outgoing diffuse radiance (V, C) float64 at full resolution, bounce 0 first (references)."""
        ids = self.baker.ids_host
        keep: list[np.ndarray] = []

        def scatter(values):
            out = np.zeros((self.V,) + values.shape[1:])
            out[ids] = values
            return out

        self._passes(light, self.baker.visibility(light), ids, scatter, keep)
        return keep

    def full(self, light, visible) -> np.ndarray:
        """Indirect coefficients (K, C, ncoef) float32 of every baked vertex (``baker.ids``) for one light sample,
        ``visible`` the device visibility states aligned with them. Adds to the direct coefficients."""
        ids = self.baker.ids_host

        def scatter(values):
            out = np.zeros((self.V,) + values.shape[1:])
            out[ids] = values
            return out

        total, spec, energies = self._passes(light, visible, ids, scatter)
        self._remember(light, energies)
        return self._coefficients(ids, total, spec)

    # -- light cuts ---------------------------------------------------------------------------------------------

    def prepare_cut(self, tree) -> None:
        """Once per bake: the completion plan, the indirect cut (G-5) and the ring tables of G-6 for ``tree``."""
        from lodprt.devices import load_kernels
        from lodprt.kernels import completion as kc
        from lodprt.model.completion import CompletionPlan

        load_kernels("cpu", kc)  # T-15 completion runs on the CPU: loaded before the sample threads launch it
        self.cut_state = CutState(tree, self, CompletionPlan(tree, self.positions, self.normals))

    def sample_cut(self, light, lightcut, threshold_deg: float):
        """One light sample on its cut with interreflection; returns what ``Baker.sample_cut`` returns."""
        wp, b, cs = self.wp, self.baker, self.cut_state
        vis = b.visibility(light).numpy().copy()
        full = np.full(self.V, BACK_FACING, np.uint8)
        full[b.ids_host] = vis
        active, dark = lightcut.cut(b.normals, wp.array(full, dtype=wp.uint8, device=b.device), light, threshold_deg)
        visible = wp.array(vis, dtype=wp.uint8, device=b.device)

        def complete(values):
            return cs.plan.complete(cs.gather_ids, values, self.V)  # T-15 from the indirect cut's vertices

        if cs.levels is None:
            total, spec, energies = self._passes(light, visible, cs.gather_ids, complete)
            self._remember(light, energies)
            anc = None
        else:
            total, spec, energies, anc, counts = self._passes_refined(light, visible)
            self._remember(light, energies, counts)
        nodes, ids, node_dark = cs.refine(active, dark, full == LIT, total, spec, anc)
        k = len(ids)
        basis = wp.zeros((k, b.sh_order * b.sh_order), dtype=wp.float32, device=b.device)
        coeffs = wp.zeros((k, b.channels, b.ncoef), dtype=wp.float32, device=b.device)
        b.shade(light, wp.array(ids, dtype=wp.int32, device=b.device),
                wp.array(full[ids], dtype=wp.uint8, device=b.device), basis, coeffs)
        out = coeffs.numpy() + self._coefficients(ids, total, spec)
        return ids, nodes, node_dark, out.astype(np.float32), vis


def attach(baker, scene, settings: GISettings, tree=None) -> Interreflection:
    """Give ``baker`` (``lodprt.precompute.baker.Baker``) its interreflection state; with ``tree`` (a light-cut bake)
    also the indirect cut and completion plan. Returns the state."""
    baker.gi = Interreflection(baker, scene, settings)
    if tree is not None:
        baker.gi.prepare_cut(tree)
    return baker.gi


class CutState:
    """What the cuts of a GI bake share across samples: the indirect cut and the ring tables of the purity test."""

    def __init__(self, h, gi: Interreflection, plan):
        self.h, self.plan = h, plan
        V, N = h.num_vertices, h.num_nodes
        hk = node_heights(h)
        order = np.argsort(hk, kind="stable")
        bounds = np.searchsorted(hk[order], np.arange(1, hk.max(initial=0) + 2))
        self.height_levels = [order[a:c] for a, c in zip(bounds[:-1], bounds[1:]) if c > a]
        internal = np.arange(V, N)
        offs = h.neighbour_offsets
        counts = (offs[internal + 1] - offs[internal]).astype(np.int64)
        self.ring_row = np.repeat(np.arange(len(internal)), counts)
        self.ring_nb = h.neighbours[offs[V] : offs[N]].astype(np.int64)
        self.ring_u = np.repeat(h.vertex[h.children[internal, 1]].astype(np.int64), counts)
        self.referenced = gi.referenced
        if gi.settings.indirect_tolerance is not None:  # G-9: the cut is chosen per sample and pass
            from lodprt.precompute.indirect_cut import IndirectLevels

            self.levels = IndirectLevels(h, self.referenced)
            self.level_rows = [plan.rows_for(h.vertex[f]) for f in self.levels.fronts]  # what each level reads
            self.indirect_nodes = self.indirect_anc = self.gather_ids = None
            return
        self.levels = None
        inverse = self._inverse_distances(gi)
        self.indirect_nodes = indirect_cut(h, inverse, gi.settings.indirect_threshold_deg, self.height_levels)
        mask = np.zeros(N, bool)
        mask[self.indirect_nodes] = True
        self.indirect_anc = active_ancestors(h, mask)
        verts = h.vertex[self.indirect_nodes]
        self.gather_ids = np.sort(verts[gi.referenced[verts]]).astype(np.int32)

    def _inverse_distances(self, gi: Interreflection) -> np.ndarray:
        """(V,) 1 / harmonic mean hit distance of every referenced vertex (G-5), 0 elsewhere."""
        from lodprt.kernels import gi as kgi

        wp, b = gi.wp, gi.baker
        dirs = wp.array(cosine_fibonacci(min(DISTANCE_RAYS, gi.settings.rays)).astype(np.float32), dtype=wp.vec3,
                        device=b.device)
        n = len(b.ids_host)
        out = wp.zeros(n, dtype=wp.float32, device=b.device)
        launch_ranges(kgi.hit_distance, n, b.device, lambda first: [  # a range per core on the CPU
            b.mesh.id, b.points, b.normals, b.ids[first:], dirs, int(gi.settings.seed), float(b.offset), gi.max_dist,
            out[first:]], None)
        inv = np.zeros(self.h.num_vertices)
        inv[b.ids_host] = out.numpy()
        return inv

    def pure_front(self, lit: np.ndarray) -> np.ndarray:
        """(N,) bool front of the highest nodes whose every collapse below has a T-15 ring of the collapsed
        vertex's own direct class (lit or not; G-6)."""
        h = self.h
        V, N = h.num_vertices, h.num_nodes
        mixed = lit[self.ring_nb] != lit[self.ring_u]
        bad = np.bincount(self.ring_row, weights=mixed, minlength=N - V) > 0
        good = np.ones(N, bool)
        good[V:] = ~bad
        for nodes in self.height_levels:
            c0, c1 = h.children[nodes, 0], h.children[nodes, 1]
            good[nodes] &= good[c0] & good[c1]
        return good & ~np.where(h.parent >= 0, good[np.maximum(h.parent, 0)], False)

    def refine(self, active, dark, lit, total, spec, indirect_anc=None):
        """The stored cut (G-6, G-7): (nodes (K,) int32, vertex ids (K,) int32 ascending, dark (K,) uint8);
        ``indirect_anc`` (V,) the sample's own indirect front (G-9) in place of the bake's (G-5)."""
        h = self.h
        anc = np.minimum(active_ancestors(h, active), active_ancestors(h, self.pure_front(lit)))
        indirect = self.indirect_anc if indirect_anc is None else indirect_anc
        if indirect is not None:
            anc = np.minimum(anc, indirect)  # the deepest of the three fronts: ids grow toward the roots
        nodes = np.unique(anc)
        verts = h.vertex[nodes]
        keep = self.referenced[verts]
        order = np.argsort(verts[keep])
        nodes, verts = nodes[keep][order], verts[keep][order]
        direct_dark = dark[active_ancestors(h, active)[verts]]
        energy = np.abs(total).sum(1) + (np.abs(spec).sum((1, 2)) if spec is not None else 0.0)
        lit_leaves = np.concatenate([[0], np.cumsum(energy[h.leaf_order] > 0)])
        rng = h.leaf_range[nodes]
        zero = lit_leaves[rng[:, 1]] == lit_leaves[rng[:, 0]]
        return nodes.astype(np.int32), verts.astype(np.int32), (direct_dark & zero).astype(np.uint8)


def indirect_cut(h, inverse: np.ndarray, threshold_deg: float | None, levels) -> np.ndarray:
    """(K,) int32 front of the indirect cut (G-5): a node replaces its children when both did and
    ``atan(r / d_min) + theta <= threshold`` (r its bounding radius, d_min the least harmonic mean hit distance
    of the leaves below, theta its normal-cone half-angle). ``threshold_deg`` None keeps every leaf."""
    V, N = h.num_vertices, h.num_nodes
    ok = np.zeros(N, bool)
    ok[:V] = True
    if threshold_deg is not None:
        inv = np.zeros(N)
        inv[:V] = inverse
        eps = math.radians(float(threshold_deg))
        for nodes in levels:
            c0, c1 = h.children[nodes, 0], h.children[nodes, 1]
            inv[nodes] = np.maximum(inv[c0], inv[c1])
            spread = np.arctan(h.radius[nodes] * inv[nodes]) + h.cone_half_angle[nodes]
            ok[nodes] = ok[c0] & ok[c1] & (spread <= eps)
    parent_ok = np.where(h.parent >= 0, ok[np.maximum(h.parent, 0)], False)
    return np.flatnonzero(ok & ~parent_ok).astype(np.int32)


def gi_attributes(settings, samples: list[dict]) -> dict:
    """Root attributes of a store baked with bounces: the settings, each sample's pass energies (from the
    statistics its group records) and the vertices the indirect cut gathers at."""
    counts = [s["indirect_gather_vertices"] for s in samples if s.get("indirect_gather_vertices") is not None]
    gather = int(round(float(np.mean(counts)))) if counts else None  # G-9 varies by sample; G-5 does not
    return {**settings.attributes(), "bounce_energy": [list(s.get("bounce_energy", [])) for s in samples],
            "indirect_gather_vertices": gather}
