"""Coefficient completion (SPEC 5; thesis 3.4.3, eq. 15): a vertex a light cut did not keep gets its coefficients
from the neighbours it had just before its collapse (``Hierarchy.collapsed_neighbours``), which existed earlier
in the simplification and so are either kept or completed first.

Weights, per collapsed vertex ``p`` with ring ``q_1..q_n`` (sorted around ``p``'s normal, then projected onto the
plane through ``p`` whose normal is the area-weighted normal of the fan ``(p, q_j, q_j+1)``):

    T-15  w_j = (cot gamma_j + cot delta_j) / |p - q_j|^2      (Meyer et al. generalised barycentric coordinates)

with gamma_j, delta_j the angles at ``q_j`` between ``p - q_j`` and the ring edges to ``q_j-1`` and ``q_j+1``.
They have linear precision on convex rings. Where the ring is degenerate for them (fewer than 3 neighbours, an open
boundary ring, coincident or collinear points, obtuse angles making a weight <= 0), a documented, bounded rule
takes over, in this order:

    boundary    on an open ring (a gap of at least 180 degrees between neighbours sorted around p: a vertex of an
                open boundary, which ``build_hierarchy`` collapses along the boundary by default), p is
                interpolated along the segment between the two neighbours on either side of the gap (weights
                1 - t and t, t the clamped projection of p on it): linear precision along a straight boundary
    mean value  w_j = (tan(alpha_j-1 / 2) + tan(alpha_j / 2)) / |p - q_j|  (Floater; alpha_j the angle at p between
                q_j and q_j+1; positive and linearly precise on star-shaped rings)
    Shepard     w_j = 1 / max(|p - q_j|, tiny)^2  (always positive; a single neighbour is copied)

Weights are normalised to sum 1, so a ring of equal coefficients completes to exactly those. Nothing here is NaN.
The weights depend on geometry only: ``CompletionPlan`` computes them once per hierarchy; ``complete`` then fills
one sample in "waves" (a vertex's wave is one more than the highest wave among its neighbours), vectorised per
wave.
"""

from __future__ import annotations

import numpy as np

from lodprt.model.hierarchy import Hierarchy

RULE_T15, RULE_MEAN_VALUE, RULE_SHEPARD, RULE_BOUNDARY = 0, 1, 2, 3
#: rows of rings weighed at once (memory is CHUNK x the chunk's largest ring)
CHUNK = 8192
RULE_NAMES = ("T-15 cotangent", "mean value", "Shepard", "boundary")
#: an angular gap in a sorted ring at least this close to 180 degrees (radians) makes it an open boundary ring
GAP_SLACK = 1e-6


def _cot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """cot of the angle between vectors a and b (..., 3); +inf-free: NaN where they are parallel (caught later)."""
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (a * b).sum(-1) / cross


def _boundary_weights(ang, d, nxt, mask, n_real):
    """The boundary rule (module docstring) for rings sorted by angle ``ang`` (M, R) (inf on the padding), offsets
    ``d = q - p`` (M, R, 3) in that order: weights (M, R) and which rings are open (a gap >= 180 degrees, at least
    2 neighbours)."""
    M, R = ang.shape
    two_pi = 2 * np.pi
    with np.errstate(invalid="ignore"):
        gap = np.where(mask, np.mod(np.take_along_axis(ang, nxt, axis=1) - ang, two_pi), -1.0)
    a = np.argmax(gap, axis=1)
    open_ring = (n_real >= 2) & (gap[np.arange(M), a] >= np.pi - GAP_SLACK)
    b = nxt[np.arange(M), a]
    da, db = d[np.arange(M), a], d[np.arange(M), b]
    seg = db - da
    L2 = (seg * seg).sum(1)
    t = np.clip(np.divide(-(da * seg).sum(1), L2, out=np.full(M, 0.5), where=L2 > 0), 0.0, 1.0)
    w = np.zeros((M, R))
    w[np.arange(M), a] = 1.0 - t
    w[np.arange(M), b] += t
    return w, open_ring


def ring_weights(p: np.ndarray, ring: np.ndarray, mask: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Completion weights for M vertices at once.

    p (M, 3), ring (M, R, 3) neighbour positions padded to R, mask (M, R) True for real neighbours (a prefix),
    normal (M, 3) the vertices' own normals (to sort the ring). Returns (weights (M, R) summing to 1 on the
    mask, sorted ring index order (M, R), rule (M,) int8) -- weights are in the sorted order.
    """
    M, R, _ = ring.shape
    n_real = mask.sum(1)
    # sort each ring by angle around the normal (tangent frame from the normal)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normal, t1)
    d = ring - p[:, None, :]
    ang = np.arctan2((d * t2[:, None]).sum(-1), (d * t1[:, None]).sum(-1))
    ang = np.where(mask, ang, np.inf)
    order = np.argsort(ang, axis=1, kind="stable")
    d = np.take_along_axis(d, order[:, :, None], axis=1)
    # cyclic successor / predecessor within each ring's real length
    j = np.arange(R)[None, :]
    nxt = np.where(j + 1 < n_real[:, None], j + 1, 0)
    prv = np.where(j > 0, j - 1, np.maximum(n_real[:, None] - 1, 0))
    w_bd, open_ring = _boundary_weights(np.take_along_axis(ang, order, axis=1), d, nxt, mask, n_real)
    d_next = np.take_along_axis(d, nxt[:, :, None], axis=1)
    d_prev = np.take_along_axis(d, prv[:, :, None], axis=1)
    # area-weighted normal of the fan (p, q_j, q_j+1), and projection onto its plane
    fan = np.where(mask[:, :, None], np.cross(d, d_next), 0.0).sum(1)
    fl = np.linalg.norm(fan, axis=1, keepdims=True)
    nf = np.where(fl > 0, fan / np.where(fl > 0, fl, 1.0), normal)
    proj = lambda x: x - (x * nf[:, None]).sum(-1, keepdims=True) * nf[:, None]  # noqa: E731
    d, d_next, d_prev = proj(d), proj(d_next), proj(d_prev)
    dist2 = (d * d).sum(-1)
    scale2 = np.where(mask, dist2, 0).max(1, keepdims=True)
    tiny = 1e-24 * np.maximum(scale2, 1e-300)

    with np.errstate(divide="ignore", invalid="ignore"):
        # T-15: at q_j, angles between (p - q_j) and the edges to q_j-1 and q_j+1
        gamma = _cot(-d, d_prev - d)
        delta = _cot(-d, d_next - d)
        w_t15 = (gamma + delta) / dist2
        # mean value: alpha_j = angle at p between q_j and q_j+1
        cos_a = (d * d_next).sum(-1) / np.sqrt(dist2 * (d_next * d_next).sum(-1))
        sin_a = (np.cross(d, d_next) * nf[:, None]).sum(-1) / np.sqrt(dist2 * (d_next * d_next).sum(-1))
        tan_half = sin_a / (1.0 + cos_a)  # tan(alpha/2), signed: negative where the ring folds back
        tan_prev = np.take_along_axis(tan_half, prv, axis=1)
        w_mv = (tan_prev + tan_half) / np.sqrt(dist2)
    w_shep = 1.0 / np.maximum(dist2, tiny)

    def ok(w):
        good = np.where(mask, np.isfinite(w) & (w > 0), True).all(1)
        return good & (n_real >= 3)

    rule = np.full(M, RULE_SHEPARD, np.int8)
    w = np.where(mask, w_shep, 0.0)
    mv_ok = ok(w_mv)
    rule[mv_ok] = RULE_MEAN_VALUE
    w[mv_ok] = np.where(mask[mv_ok], w_mv[mv_ok], 0.0)
    rule[open_ring] = RULE_BOUNDARY
    w[open_ring] = w_bd[open_ring]
    t_ok = ok(w_t15)
    rule[t_ok] = RULE_T15
    w[t_ok] = np.where(mask[t_ok], w_t15[t_ok], 0.0)
    w = w / w.sum(1, keepdims=True)
    return w, order, rule


class CompletionPlan:
    """Geometry-only part of completion for one hierarchy: who completes whom, with which weights, in which wave."""

    def __init__(self, h: Hierarchy, positions: np.ndarray, normals: np.ndarray):
        self.h = h
        V = h.num_vertices
        internal = np.arange(V, h.num_nodes)
        self.vertex = h.vertex[h.children[internal, 1]].astype(np.int64)  # the vertex each collapse removed
        offs = h.neighbour_offsets
        counts = (offs[internal + 1] - offs[internal]).astype(np.int64)
        R = int(counts.max()) if len(counts) else 1
        M = len(internal)
        p = np.asarray(positions, np.float64)
        nrm = np.asarray(normals, np.float64)
        self.neighbours = np.repeat(self.vertex[:, None], R, axis=1)
        self.weights = np.zeros((M, R))
        self.rule = np.zeros(M, np.int8)
        # rings padded to the largest ring of their chunk (rows sorted by ring size): bounded memory
        by_size = np.argsort(counts, kind="stable")
        for start in range(0, M, CHUNK):
            rows = by_size[start : start + CHUNK]
            r = int(counts[rows].max())
            mask = np.arange(r)[None, :] < counts[rows, None]
            idx = np.repeat(self.vertex[rows, None], r, axis=1)
            first = offs[internal[rows]]
            take = first[:, None] + np.arange(r)[None, :]
            idx[mask] = h.neighbours[take[mask]]
            w, order, rule = ring_weights(p[self.vertex[rows]], p[idx], mask, nrm[self.vertex[rows]])
            self.neighbours[rows, :r] = np.take_along_axis(idx, order, axis=1)
            self.weights[rows, :r] = w
            self.rule[rows] = rule
        self.neighbours = self.neighbours[:, : max(R, 1)]
        self.ring_len = counts  # real neighbours per row: sorted rows keep them first
        # waves: neighbours of a collapsed vertex were removed later (or never); coarse first
        wave = [0] * V
        lens = counts.tolist()
        nb = self.neighbours.tolist()
        vlist = self.vertex.tolist()
        for m in range(M - 1, -1, -1):
            wave[vlist[m]] = 1 + max((wave[q] for q in nb[m][: lens[m]]), default=0)
        wave = np.asarray(wave, np.int64)
        self.wave = wave[self.vertex]
        self.by_wave = np.argsort(self.wave, kind="stable")
        self.wave_ptr = np.searchsorted(self.wave[self.by_wave], np.arange(self.wave.max() + 2 if M else 1))

    def rule_fractions(self) -> dict[str, float]:
        counts = np.bincount(self.rule, minlength=len(RULE_NAMES)) / max(len(self.rule), 1)
        return {name: float(c) for name, c in zip(RULE_NAMES, counts)}

    def complete(self, ids: np.ndarray, coeffs: np.ndarray, num_vertices: int, *, cut_nodes=None, dark=None) -> np.ndarray:
        """(V, ...) float64 coefficients of every vertex from the kept ``ids`` (K,) and their ``coeffs`` (K, ...).

        With the sample's cut (``cut_nodes`` (K,) and their ``dark`` flags), every vertex under a dark node is
        exactly 0 (all its leaves face away or lie in shadow: no radiance), and the others are completed from
        ring neighbours that are not dark (weights renormalised; all of them when every neighbour is dark).
        """
        out = np.zeros((num_vertices,) + coeffs.shape[1:], np.float64)
        out[ids] = coeffs
        have = np.zeros(num_vertices, bool)
        have[ids] = True
        dark_v = np.zeros(num_vertices, bool)
        if cut_nodes is not None:
            from lodprt.model.hierarchy import active_ancestors

            active = np.zeros(self.h.num_nodes, bool)
            active[cut_nodes] = True
            leaves = self.h.parent[:num_vertices] < 0
            active[:num_vertices] |= leaves  # isolated vertices: roots that are never baked
            is_dark = np.zeros(self.h.num_nodes, bool)
            is_dark[np.asarray(cut_nodes)[np.asarray(dark, bool)]] = True
            dark_v = is_dark[active_ancestors(self.h, active)]
            out[dark_v & ~have] = 0.0
            have |= dark_v
        for w in range(1, len(self.wave_ptr) - 1):
            rows = self.by_wave[self.wave_ptr[w] : self.wave_ptr[w + 1]]
            rows = rows[~have[self.vertex[rows]]]
            if not len(rows):
                continue
            r = max(int(self.ring_len[rows].max()), 1)  # no work on the padding of larger rings
            nb = self.neighbours[rows, :r]
            weights = self.weights[rows, :r] * ~dark_v[nb]
            total = weights.sum(1, keepdims=True)
            weights = np.where(total > 0, weights / np.where(total > 0, total, 1.0), self.weights[rows, :r])
            out[self.vertex[rows]] = np.einsum("mr,mr...->m...", weights, out[nb])  # T-15
            have[self.vertex[rows]] = True
        return out
