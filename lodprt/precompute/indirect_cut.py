"""The error-driven indirect cut of a light-cut GI bake (G-9; docs/GI.md, THEORY.md): per light sample and pass,
where the gathering rays of :mod:`lodprt.precompute.gi` are cast, chosen by the indirect field itself rather than
by geometry alone (G-5).

The hierarchy's fronts by leaf count, ``F_0`` (subtrees of at most ``4^START_LEVEL`` leaves) to ``F_L`` (the
leaves), each about 4 times finer than the last, are the levels of a coarse-to-fine refinement. A pass gathers at
the vertices of ``F_0``; then, level by level, at the new vertices of ``F_k`` under every region (node of
``F_{k-1}``) still open, and compares each new vertex's gathered irradiance ``E_j`` with ``E~_j``, the T-15
completion of what was gathered before it. A region ``p`` that stops at level ``k`` leaves at most

    G-9  SSE_p = n_p mean_{j new under p} |kd_j (E_j - E~_j)|^2          (n_p: referenced leaves under p)

of squared error in the pass' outgoing radiance against gathering at every vertex (its vertices are completed from
level ``k``, at least as fine as the level that predicted the ``E~_j``). The pass' budget is ``(tau L_rms)^2 N``:
``tau`` the stated tolerance (``indirect_tolerance``), ``L_rms`` the root mean square of the sample's direct diffuse
radiance (bounce 0, channels averaged) over the ``N`` referenced vertices. At level ``k`` the open regions stop in
ascending order of ``SSE_p / n_p`` while their sum stays within half of the budget still unspent; the others are
refined; at the finest level every vertex is gathered (no error). So the stopped regions' estimated errors sum to at
most the budget: each pass' completed radiance is within ``tau L_rms`` RMS of the full-resolution pass from the
same previous field, as far as the test vertices represent their regions (a feature no test vertex of a level
sees is not found). ``E_j`` and the full-resolution pass cast the same rays at ``j``, so the ray noise is part of
that error: a noisy region refines as a detailed one does. Smooth indirect light (most of a large floor) stops at
the first levels, at almost no cost of the budget; gradients, contact shadows and creases refine to the leaves.
"""

from __future__ import annotations

import numpy as np

from lodprt.model.hierarchy import active_ancestors

#: F_0 holds subtrees of at most 4**START_LEVEL leaves (G-9's coarsest level); each level is 4 times finer
START_LEVEL = 5


class IndirectLevels:
    """The fronts ``F_0..F_L`` of hierarchy ``h`` by leaf count (G-9), for each node of ``F_k`` (k >= 1) the index
    of its ancestor in ``F_{k-1}``, and each node's count of referenced leaves. Light-independent: built once."""

    def __init__(self, h, referenced: np.ndarray, start_level: int = START_LEVEL):
        self.h = h
        self.referenced = np.asarray(referenced, bool)
        cum = np.concatenate([[0], np.cumsum(self.referenced[h.leaf_order])])
        self.leaves = cum[h.leaf_range[:, 1]] - cum[h.leaf_range[:, 0]]  # (N,) referenced leaves under each node
        count = h.leaf_range[:, 1] - h.leaf_range[:, 0]
        self.fronts: list[np.ndarray] = []  # (n_k,) node ids, ascending
        self.parents: list[np.ndarray] = []  # (n_k,) index into fronts[k - 1] (empty for k = 0)
        previous = None
        for size in [4**k for k in range(int(start_level), -1, -1)]:
            ok = count <= size
            mask = ok & ~np.where(h.parent >= 0, ok[np.maximum(h.parent, 0)], False)  # highest nodes of <= size
            nodes = np.flatnonzero(mask)
            if previous is None:
                self.parents.append(np.zeros(0, np.int64))
            else:  # F_k is nested in F_{k-1}: h.vertex[q] is a leaf of q, its F_{k-1} ancestor is q's
                up = active_ancestors(h, previous)[h.vertex[nodes]]
                self.parents.append(np.searchsorted(self.fronts[-1], up))
            self.fronts.append(nodes)
            previous = mask


def stop_within_budget(sse: np.ndarray, leaves: np.ndarray, tested: np.ndarray, budget: float) -> np.ndarray:
    """(R,) bool: the regions that stop (G-9): among the ``tested`` ones, in ascending order of ``sse / leaves``,
    as many as keep the sum of their ``sse`` within ``budget``."""
    idx = np.flatnonzero(tested)
    stop = np.zeros(len(sse), bool)
    if not len(idx) or budget < 0:
        return stop
    density = sse[idx] / np.maximum(leaves[idx], 1)
    order = idx[np.argsort(density, kind="stable")]
    stop[order[np.cumsum(sse[order]) <= budget]] = True
    return stop


class _Gathered:
    """The vertices a pass has gathered at so far, with their values (G, C) and specular (G, C, n) or None."""

    def __init__(self, num_vertices: int, referenced: np.ndarray, gather):
        self.done = np.zeros(num_vertices, bool)
        self.referenced, self.gather = referenced, gather
        self.ids, self.e, self.spec = [], [], []

    def take(self, verts: np.ndarray):
        """Gather at the referenced vertices of ``verts`` not gathered yet: (them (G,) int32, E (G, C) or None)."""
        verts = np.unique(verts[self.referenced[verts] & ~self.done[verts]]).astype(np.int32)
        if not len(verts):
            return verts, None
        e, spec = self.gather(verts)
        self.done[verts] = True
        self.ids.append(verts)
        self.e.append(e)
        self.spec.append(spec)
        return verts, e

    def arrays(self):
        specs = [s for s in self.spec if s is not None]
        spec = np.concatenate(specs) if specs and len(specs) == len(self.spec) else None
        return np.concatenate(self.ids), np.concatenate(self.e), spec


def refine_pass(levels: IndirectLevels, gather, complete, kd: np.ndarray, tolerance: float, predict=None):
    """One pass of G-9.

    gather(ids (G,) int32) -> (E (G, C), specular (G, C, n) or None) gathers at ``ids``; complete(ids (G,),
    values (G, ...)) -> (V, ...) is T-15 from those vertices; kd (V, C) the diffuse albedo; tolerance the absolute
    RMS radiance ``tau L_rms`` of G-9; predict(k, ids, values) -> (V, ...), when given, is ``complete`` right at
    least at the vertices of level ``F_k`` (the only ones level k reads). Returns (gathered ids (G,) int32, E (G, C),
    specular (G, C, n) or None, the pass' front (N,) bool: the nodes under which it stopped, and the estimated
    squared error it left (G-9)).
    """
    if predict is None:
        predict = lambda k, ids, values: complete(ids, values)  # noqa: E731
    h = levels.h
    got = _Gathered(h.num_vertices, levels.referenced, gather)
    got.take(h.vertex[levels.fronts[0]])
    budget = tolerance**2 * float(levels.referenced.sum())  # G-9: the pass' sum of squared errors
    spent = 0.0
    front = np.zeros(h.num_nodes, bool)
    open_ = np.ones(len(levels.fronts[0]), bool)  # every region of F_0 is tested at level 1
    last = len(levels.fronts) - 1
    for k in range(1, last + 1):
        par = levels.parents[k]
        cand = open_[par]  # the nodes of F_k under a region still open
        if not cand.any():
            break
        field = predict(k, *got.arrays()[:2]) if k < last else None  # T-15 from the coarser levels
        verts = h.vertex[levels.fronts[k][cand]]
        new, e = got.take(verts)
        prev = levels.fronts[k - 1]
        if k == last:  # the leaves: every vertex is gathered, no error left
            stop = open_.copy()
        else:
            n, sse = np.zeros(len(prev), np.int64), np.zeros(len(prev))
            if len(new):
                region = regions_of(verts, par[cand], new)
                d2 = ((kd[new] * (e - field[new])) ** 2).mean(1)  # G-9: squared error of the prediction
                n = np.bincount(region, minlength=len(prev))
                sse = np.bincount(region, weights=d2, minlength=len(prev)) / np.maximum(n, 1) * levels.leaves[prev]
            stop = stop_within_budget(sse, levels.leaves[prev], open_ & (n > 0), 0.5 * (budget - spent))
            spent += float(sse[stop].sum())
        front[levels.fronts[k][cand & stop[par]]] = True  # a stopped region is completed from level k
        open_ = cand & ~stop[par]
    ids, e, spec = got.arrays()
    return ids, e, spec, front, spent


def regions_of(verts: np.ndarray, regions: np.ndarray, new: np.ndarray) -> np.ndarray:
    """The region of each vertex of ``new`` from the pairs (``verts``, ``regions``), ``verts`` unsorted."""
    order = np.argsort(verts, kind="stable")
    return regions[order][np.searchsorted(verts[order], new)]
