"""Per-node bounds the view cut reads every frame, made once per light sample (as ``lodprt.runtime.samples.
SampleCache`` completes it) and white point: the T-14 coefficient boxes (e_lumi) and the S-2 detail bounds (the
screen criterion), bottom-up over the vertex hierarchy (docs/RUNTIME.md)."""

from __future__ import annotations

import numpy as np

from lodprt.model.completion import CHUNK
from lodprt.model.hierarchy import node_heights


def radiance_bound(r: np.ndarray, C: int, n: int) -> np.ndarray:
    """S-2: for rows of ``C`` x ``n`` SH coefficient differences (K, C * n), with n = order^2 (or 1), a bound of the
    radiance difference toward any view direction, per channel (K, C): sum_l sqrt((2l + 1) / 4 pi) |r_l|, by
    Cauchy-Schwarz per band and the addition theorem (sum_m y_lm(s)^2 = (2l + 1) / 4 pi for every s)."""
    r = r.reshape(len(r), C, n)
    out = np.zeros((len(r), C), np.float32)
    l = 0
    while l * l < n:
        lo, hi = l * l, min((l + 1) ** 2, n)
        out += np.float32(np.sqrt((2 * l + 1) / (4 * np.pi))) * np.sqrt((r[:, :, lo:hi] ** 2).sum(-1))
        l += 1
    return out


def detail_bounds(h, c: np.ndarray, white: float, plan, rings: tuple, levels: list) -> np.ndarray:
    """S-2 for one light sample's completed coefficients ``c`` (V, C, ncoef): for each internal node, the largest
    radiance difference toward any view direction (``radiance_bound``) of (a) C(v) - sum_j w_j C(q_j) over the
    collapses in its subtree (T-15 weights over the ring the collapse removed v from) and (b) C(v) - C(q) over its
    leaves v and their original neighbours q (``rings = leaf_rings(faces)``), in units of ``white``: (N - V, C)
    float32. (a) is zero where the completed field is linear (T-15 has linear precision); (b) is one edge's step,
    small on smooth fields and large at a shadow or highlight boundary that runs next to the subtree (between two
    subtrees, where neither's own collapses see it). One number per channel keeps the per-frame read to a few
    values a node."""
    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    if N == V:
        return np.zeros((0, C), np.float32)
    c0, c1 = h.children[:, 0], h.children[:, 1]
    ring_v, ring_q, starts = rings
    c = c.reshape(V, C * n) / np.float32(white)
    d = np.zeros((N, C), np.float32)
    if len(ring_v):  # leaves: the largest step to an original neighbour (a shadow edge between subtrees)
        d[ring_v[starts]] = np.maximum.reduceat(radiance_bound(c[ring_v] - c[ring_q], C, n), starts, axis=0)
    for start in range(0, N - V, CHUNK):  # plan row m is the collapse of node V + m
        rows = slice(start, min(start + CHUNK, N - V))
        r = max(int(plan.ring_len[rows].max()), 1)
        interp = np.einsum("mr,mrk->mk", plan.weights[rows, :r].astype(np.float32), c[plan.neighbours[rows, :r]])
        d[V + rows.start:V + rows.stop] = radiance_bound(c[plan.vertex[rows]] - interp, C, n)  # T-15 residual
    for nodes in levels:
        d[nodes] = np.maximum(d[nodes], np.maximum(d[c0[nodes]], d[c1[nodes]]))
    return d[V:]


def detail_mean_square(h, c: np.ndarray, white: float, plan, levels: list) -> np.ndarray:
    """E-1 for one light sample's completed coefficients ``c`` (V, C, ncoef): for each internal node, the mean over
    its leaves of the squared T-15 residual (``radiance_bound`` of C(v) - sum_j w_j C(q_j), the same per-collapse
    term as ``detail_bounds`` (a)) of the collapses in its subtree, in units of ``white`` squared: (N - V, C)
    float32. Where ``detail_bounds`` keeps the largest, this keeps the mean, so that a node's E-1 term (mean
    square times the pixels it covers) estimates rather than bounds the squared error it adds to a frame."""
    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    if N == V:
        return np.zeros((0, C), np.float32)
    c0, c1 = h.children[:, 0], h.children[:, 1]
    c = c.reshape(V, C * n) / np.float32(white)
    s = np.zeros((N, C), np.float64)
    for start in range(0, N - V, CHUNK):  # plan row m is the collapse of node V + m
        rows = slice(start, min(start + CHUNK, N - V))
        r = max(int(plan.ring_len[rows].max()), 1)
        interp = np.einsum("mr,mrk->mk", plan.weights[rows, :r].astype(np.float32), c[plan.neighbours[rows, :r]])
        s[V + rows.start:V + rows.stop] = radiance_bound(c[plan.vertex[rows]] - interp, C, n) ** 2
    for nodes in levels:
        s[nodes] += s[c0[nodes]] + s[c1[nodes]]
    leaves = np.maximum(h.leaf_range[V:, 1] - h.leaf_range[V:, 0], 1)
    return (s[V:] / leaves[:, None]).astype(np.float32)


def subtree_deviation(h, levels: list) -> np.ndarray:
    """S-3 for every node (N,) float64: a bound on how far the coarse surface around a node may lie from the
    leaves under it, ``|e_k| + max(dev(c0), dev(c1))`` bottom-up (0 for leaves; e_k the error vector of the node's
    own collapse, which measures one step only: the collapsed vertex against the surface of the step before),
    capped at the node's bounding radius (no leaf lies farther than that from the node's vertex)."""
    e = np.linalg.norm(np.asarray(h.error_vector, np.float64), axis=1)
    dev = e.copy()
    c0, c1 = h.children[:, 0], h.children[:, 1]
    for nodes in levels:
        dev[nodes] = e[nodes] + np.maximum(dev[c0[nodes]], dev[c1[nodes]])
    return np.minimum(dev, np.asarray(h.radius, np.float64))


def leaf_rings(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every original edge in both directions, sorted by its first vertex: (v, q, start of each v's run)."""
    f = faces
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    e = e[e[:, 0] != e[:, 1]]
    e = e[np.argsort(e[:, 0], kind="stable")]
    starts = np.flatnonzero(np.r_[True, e[1:, 0] != e[:-1, 0]]) if len(e) else np.zeros(0, np.int64)
    return e[:, 0], e[:, 1], starts


def height_levels(h) -> list[np.ndarray]:
    """Internal nodes grouped by height (children always on lower levels), lowest first."""
    hk = node_heights(h)
    order = np.argsort(hk, kind="stable")
    bounds = np.searchsorted(hk[order], np.arange(1, hk.max() + 2)) if len(hk) else np.zeros(1, np.int64)
    return [order[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)]


def coefficient_boxes(h, c: np.ndarray, white: float, levels: list) -> np.ndarray:
    """T-14 for one light sample's completed coefficients ``c`` (V, C, ncoef): the box of every coefficient over
    each internal node's leaves, in units of ``white``: (N - V, 2, C, ncoef) float16, centre then half-width
    (clipped to float16's range), made bottom-up one height level at a time (children always sit on lower
    levels)."""
    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    out = np.zeros((N - V, 2, C, n), np.float16)
    if N == V:
        return out
    c0, c1 = h.children[:, 0], h.children[:, 1]
    big = float(np.finfo(np.float16).max)
    mn = np.empty((N, C * n), np.float32)
    mn[:V] = c.reshape(V, C * n) / np.float32(white)
    mx = mn.copy()
    for nodes in levels:
        mn[nodes] = np.minimum(mn[c0[nodes]], mn[c1[nodes]])
        mx[nodes] = np.maximum(mx[c0[nodes]], mx[c1[nodes]])
    out[:, 0] = np.clip(0.5 * (mx[V:] + mn[V:]), -big, big).reshape(N - V, C, n)
    out[:, 1] = np.clip(0.5 * (mx[V:] - mn[V:]), 0, big).reshape(N - V, C, n)
    return out
