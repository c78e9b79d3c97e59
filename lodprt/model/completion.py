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
The weights depend on geometry only: ``CompletionPlan`` computes them once per hierarchy (float64 maths, stored as
float32 in CSR rings with int32 neighbour ids: memory follows the real ring sizes), in a Warp kernel over the cores
(``lodprt.kernels.completion.ring_weights``; ``ring_weights`` here is its numpy reference, which the tests hold it
to); ``complete`` then fills one sample in "waves" (a vertex's wave is one more than the highest wave among its
neighbours), the rows in wave order in one kernel launch (``complete_in_order``), in float64 or float32.
"""

from __future__ import annotations

import numpy as np

from lodprt.devices import warp
from lodprt.model.hierarchy import Hierarchy

RULE_T15, RULE_MEAN_VALUE, RULE_SHEPARD, RULE_BOUNDARY = 0, 1, 2, 3
#: rows at once in ``wave_numbers`` and in the chunked bounds of ``lodprt.runtime.node_bounds``
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


def as_rows(rows, M: int) -> np.ndarray:
    """Row ids from a slice of M rows (no (M,) array made) or ids."""
    return np.arange(*rows.indices(M)) if isinstance(rows, slice) else np.asarray(rows)


def ring_rows(ptr: np.ndarray, rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For CSR row offsets ``ptr`` (M+1,) and some rows (a slice or (K,) ids): the flat indices of those rows'
    entries (in row order), the rows that have any entry (their positions in ``rows``) and where each of those
    starts in the flat indices (for ``np.<ufunc>.reduceat``)."""
    rows = as_rows(rows, len(ptr) - 1)
    first, lens = ptr[rows], ptr[rows + 1] - ptr[rows]
    filled = np.flatnonzero(lens > 0)
    seg = np.cumsum(lens) - lens
    flat = np.arange(int(lens.sum()), dtype=np.int64) + np.repeat(first - seg, lens)
    return flat, filled, seg[filled]


def wave_numbers(vertex: np.ndarray, ptr: np.ndarray, ids: np.ndarray, num_vertices: int) -> np.ndarray:
    """The wave of every collapse row (M,) int32: 1 + the highest wave among the ring vertices of row m that a
    later row removed (vertices never removed, or removed by row m or before, count 0), as a loop over the rows
    from the last to the first would give. A ring holds the vertices alive just before its collapse, so rows
    depend on later rows only (a DAG): blocks of ``CHUNK`` rows, from the last back, each iterated Jacobi-style
    (``np.maximum.reduceat`` over its CSR rings) until nothing changes, the later blocks' waves already final;
    as many sweeps as the longest chain of dependent rows inside a block, and memory for one block only."""
    M = len(vertex)
    removed = np.full(num_vertices, M, np.int32)  # the row that removed each vertex; M: never
    removed[vertex] = np.arange(M, dtype=np.int32)
    wave_v = np.zeros(num_vertices + 1, np.int32)  # per vertex, 0 until its row is settled; the last one stays 0
    for hi in range(M, 0, -CHUNK):
        lo = max(hi - CHUNK, 0)
        flat, filled, seg = ring_rows(ptr, slice(lo, hi))
        q = ids[flat]
        row = np.repeat(np.arange(lo, hi, dtype=np.int32), np.diff(ptr[lo:hi + 1]))
        q = np.where(removed[q] > row, q, num_vertices)  # read as 0: not removed by a later row
        v, new = vertex[lo:hi], np.ones(hi - lo, np.int32)
        while len(flat):
            new[filled] = 1 + np.maximum.reduceat(wave_v[q], seg)
            if np.array_equal(new, wave_v[v]):
                break
            wave_v[v] = new
        wave_v[v] = new
    return wave_v[vertex]


class CompletionPlan:
    """Geometry-only part of completion for one hierarchy: who completes whom, with which weights, in which wave.

    Row m is the collapse of node ``V + m``: it removed ``vertex[m]``, whose ring (sorted as ``ring_weights``
    returns it) is ``ring_ids[ring_ptr[m]:ring_ptr[m + 1]]`` (int32) with the T-15 weights ``ring_w`` (float32)
    at the same places: memory follows the real ring sizes (CSR), not the largest ring.
    """

    def __init__(self, h: Hierarchy, positions: np.ndarray, normals: np.ndarray):
        self.h = h
        V = h.num_vertices
        internal = np.arange(V, h.num_nodes)
        self.vertex = h.vertex[h.children[internal, 1]].astype(np.int32)  # the vertex each collapse removed
        offs = h.neighbour_offsets
        counts = np.diff(offs[V:]).astype(np.int64)
        M = len(internal)
        self.ring_len = counts.astype(np.int32)  # real neighbours per row
        self.ring_ptr = np.r_[0, np.cumsum(counts)].astype(np.int64)
        self.ring_ids = h.neighbours[offs[V] : offs[h.num_nodes]].astype(np.int32)  # each ring, sorted by ``weigh``
        self.ring_w = np.empty(len(self.ring_ids), np.float32)
        self.rule = np.zeros(M, np.int8)
        if M:
            self.weigh(positions, normals)
        # waves: neighbours of a collapsed vertex were removed later (or never); coarse first
        self.wave = wave_numbers(self.vertex, self.ring_ptr, self.ring_ids, V)
        self.by_wave = np.argsort(self.wave, kind="stable").astype(np.int32)
        self.wave_ptr = np.searchsorted(self.wave[self.by_wave], np.arange(self.wave.max() + 2 if M else 1))

    def weigh(self, positions: np.ndarray, normals: np.ndarray) -> None:
        """Sort every ring by angle and give it its weights and rule (``lodprt.kernels.completion.ring_weights``:
        ``ring_weights`` above, row by row, in float64), sliced over every core."""
        from lodprt.kernels import completion as kc
        from lodprt.launches import KernelThreads, warp_view

        wp = warp()
        V = self.h.num_vertices
        wide = np.float64 if np.float64 in (np.asarray(positions).dtype, np.asarray(normals).dtype) else np.float32
        p, n = (np.ascontiguousarray(a, wide) for a in (positions, normals))  # float32 read as it is, no copy
        if p.shape != (V, 3) or n.shape != (V, 3):
            raise ValueError(f"completion plan: positions {p.shape} and normals {n.shape}, need ({V}, 3)")
        vec = wp.vec3d if wide == np.float64 else wp.vec3
        inputs = [warp_view(self.vertex, wp.int32), warp_view(self.ring_ptr, wp.int64), warp_view(p, vec),
                  warp_view(n, vec), warp_view(self.ring_ids, wp.int32), warp_view(self.ring_w, wp.float32),
                  warp_view(self.rule, wp.int8)]
        with KernelThreads(None) as threads:
            threads.launch(kc.ring_weights, len(self.vertex), inputs, work=self.ring_ptr)

    @property
    def nbytes(self) -> int:
        """Bytes held by the plan's own arrays (the hierarchy it refers to not counted)."""
        return sum(a.nbytes for a in vars(self).values() if isinstance(a, np.ndarray))

    def ring(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """Row m's ring: neighbour ids (int32) and their T-15 weights (float32), in ``ring_weights``' order."""
        lo, hi = self.ring_ptr[m], self.ring_ptr[m + 1]
        return self.ring_ids[lo:hi], self.ring_w[lo:hi]

    def rule_fractions(self) -> dict[str, float]:
        counts = np.bincount(self.rule, minlength=len(RULE_NAMES)) / max(len(self.rule), 1)
        return {name: float(c) for name, c in zip(RULE_NAMES, counts)}

    def rows_for(self, targets: np.ndarray) -> np.ndarray:
        """The plan rows, in wave order, whose values completing the vertices ``targets`` reads: their own rows and,
        from the finest wave back, the rows of every ring vertex a needed row reads (a ring holds vertices of
        earlier waves only). ``complete(..., rows=rows_for(t))`` gives ``t`` the values a whole completion gives."""
        need = np.zeros(self.h.num_vertices, bool)
        need[np.asarray(targets)] = True
        keep = np.zeros(len(self.vertex), bool)
        for w in range(len(self.wave_ptr) - 2, 0, -1):
            rows = self.by_wave[self.wave_ptr[w] : self.wave_ptr[w + 1]]
            rows = rows[need[self.vertex[rows]]]
            keep[rows] = True
            flat, _, _ = ring_rows(self.ring_ptr, rows)
            need[self.ring_ids[flat]] = True
        return self.by_wave[keep[self.by_wave]]

    def complete(self, ids: np.ndarray, coeffs: np.ndarray, num_vertices: int, *, cut_nodes=None, dark=None,
                 dtype=np.float64, rows: np.ndarray | None = None) -> np.ndarray:
        """(V, ...) coefficients of every vertex in ``dtype`` (float64 by default; the weights and every gather
        in it too) from the kept ``ids`` (K,) and their ``coeffs`` (K, ...).

        With the sample's cut (``cut_nodes`` (K,) and their ``dark`` flags), every vertex under a dark node is
        exactly 0 (all its leaves face away or lie in shadow: no radiance), and the others are completed from
        ring neighbours that are not dark (weights renormalised; all of them when every neighbour is dark).
        The weights of a ring are renormalised to sum 1 in ``dtype``, so equal neighbours complete exactly.
        ``rows`` (from :meth:`rows_for`) completes only the vertices those rows read; the others stay 0.
        """
        coeffs = np.asarray(coeffs)
        out = np.zeros((num_vertices,) + coeffs.shape[1:], dtype)
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
        self.fill_waves(out.reshape(num_vertices, -1), have, dark_v, rows)
        return out

    def fill_waves(self, out: np.ndarray, have: np.ndarray, dark_v: np.ndarray, rows=None) -> None:
        """T-15 into the rows of ``out`` (V, K) float32 or float64, C-contiguous, of every plan row's vertex not in
        ``have`` (V,) bool, wave after wave (``lodprt.kernels.completion.complete_in_order``, one launch on the
        CPU): each from its ring's values, dark neighbours (``dark_v`` (V,) bool) dropped and the rest renormalised
        (all of them when all are dark); only plan ``rows`` (in wave order) when given. ``have`` is updated."""
        from lodprt.kernels import completion as kc
        from lodprt.launches import warp_view

        wp = warp()
        V = self.h.num_vertices
        if out.ndim != 2 or out.shape[0] < V or not out.flags.c_contiguous or out.dtype not in (np.float32,
                                                                                               np.float64):
            raise ValueError(f"completion output {out.dtype} {out.shape}: need C-contiguous float32 or float64 "
                             f"rows for at least the hierarchy's {V} vertices")
        if len(have) < V or len(dark_v) < V:
            raise ValueError(f"completion masks of {len(have)} and {len(dark_v)} vertices: need {V}")
        vert_dt = wp.float64 if out.dtype == np.float64 else wp.float32
        fixed = [warp_view(self.vertex, wp.int32), warp_view(self.ring_ptr, wp.int64),
                 warp_view(self.ring_ids, wp.int32), warp_view(self.ring_w, wp.float32),
                 warp_view(dark_v, wp.uint8), warp_view(have, wp.uint8), warp_view(out, vert_dt)]
        rows = self.by_wave if rows is None else np.asarray(rows, np.int32)
        if len(rows) and (rows.min() < 0 or rows.max() >= len(self.vertex)):
            raise ValueError(f"completion rows outside the plan's {len(self.vertex)} rows")
        if len(rows):  # T-15 (kernels.completion), wave after wave
            wp.launch(kc.complete_in_order, dim=1, device="cpu", inputs=[warp_view(rows, wp.int32)] + fixed)
        have[self.vertex[rows]] = True
