"""Per-node bounds the view cut reads every frame, made once per light sample (as ``lodprt.runtime.samples.
SampleCache`` completes it) and white point: the T-14 coefficient boxes (e_lumi) and the S-2 detail bounds (the
screen criterion), bottom-up over the vertex hierarchy (docs/RUNTIME.md); the S-3 error vectors; and
``NodeErrors``, what the view cut's kernel gives per candidate node."""

from __future__ import annotations

import typing
import weakref

import numpy as np

from lodprt.devices import warp
from lodprt.model.completion import CHUNK
from lodprt.model.hierarchy import node_heights
from lodprt.launches import KernelThreads, warp_view


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


def float16_up(x: np.ndarray) -> np.ndarray:
    """``x`` (float32) as float16 rounded up: the smallest float16 at or above each value, at
    most float16's largest finite value (65504). The sample cache keeps the S-2 bounds and E-1 mean squares in
    this form (half the bytes of float32, twice the samples held in the same ``cache_bytes``): a rounded-up bound
    is still a bound, larger by at most one float16 step (a factor 1 + 2^-10 above 6.1e-5, 6e-8 below it)."""
    x = np.asarray(np.minimum(np.asarray(x, np.float32), np.finfo(np.float16).max), np.float32)  # capped: no overflow
    h = x.astype(np.float16)
    low = h.astype(np.float32) < x
    h[low] = np.nextafter(h[low], np.float16(np.inf))
    return h


def detail_bounds(h, c: np.ndarray, white: float, plan, adjacency: tuple, levels: list) -> np.ndarray:
    """S-2 for one light sample's completed coefficients ``c`` (V, C, ncoef): for each internal node, the largest
    radiance difference toward any view direction (``radiance_bound``) of (a) C(v) - sum_j w_j C(q_j) over the
    collapses in its subtree (T-15 weights over the ring the collapse removed v from) and (b) C(v) - C(q) over its
    leaves v and their original neighbours q (``adjacency``: ``vertex_adjacency(faces)``, or the Cut's
    ``leaf_adjacency``, the same edges in leaf order), in units of ``white``: (N - V, C)
    float32. (a) is zero where the completed field is linear (T-15 has linear precision); (b) is one edge's step,
    small on smooth fields and large at a shadow or highlight boundary that runs next to the subtree (between two
    subtrees, where neither's own collapses see it). One number per channel keeps the per-frame read to a few
    values a node. Both terms are Warp kernels (``lodprt.kernels.node_bounds``) sliced over the cores, with no copy
    of a float32 ``c``."""
    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    if N == V:
        return np.zeros((0, C), np.float32)
    c0, c1 = h.children[:, 0], h.children[:, 1]
    d = np.zeros((N, C), np.float32)
    with KernelThreads(None) as threads:
        leaf_steps(d, coefficient_rows(c), white, adjacency, threads)
    d[V:] = collapse_residuals(plan, c, white)  # plan row m is the collapse of node V + m (leaf_steps: d[:V])
    for nodes in levels:
        d[nodes] = np.maximum(d[nodes], np.maximum(d[c0[nodes]], d[c1[nodes]]))
    return d[V:]


#: the last field's ``collapse_residuals``: (weak reference to the field, weak reference to the plan, white, bounds)
_LAST_RESIDUALS: list = []


def collapse_residuals(plan, c: np.ndarray, white: float) -> np.ndarray:
    """S-2 (a) of every plan row for one sample's field ``c`` (V, C, ncoef), (M, C) float32 (``residual_bounds``),
    kept for the last field given (held weakly, compared by identity): ``detail_bounds`` and
    ``detail_mean_square`` of the same sample share one pass of the kernel. Read only."""
    if _LAST_RESIDUALS:
        ref_c, ref_plan, w, r = _LAST_RESIDUALS[0]
        if ref_c() is c and ref_plan() is plan and w == white:
            return r
    r = np.empty((len(plan.vertex), c.shape[1]), np.float32)
    with KernelThreads(None) as threads:
        residual_bounds(plan, coefficient_rows(c), white, r, threads)
    r.flags.writeable = False
    _LAST_RESIDUALS[:] = [(weakref.ref(c), weakref.ref(plan), white, r)]
    return r


def coefficient_rows(c: np.ndarray):
    """A Warp view of ``c`` (V, C, n) as (V, C * n) float32 rows (no copy when it is float32 and contiguous)."""
    V = c.shape[0]
    return warp_view(np.asarray(c, np.float32).reshape(V, -1), warp().float32)


def residual_bounds(plan, c, white: float, out: np.ndarray, threads: KernelThreads) -> None:
    """S-2 (a) into ``out`` (M, C) float32: ``radiance_bound`` of the T-15 residual C(v) - sum_j w_j C(q_j) of
    every plan row, in units of ``white``, for coefficient rows ``c`` (``coefficient_rows``)."""
    from lodprt.kernels import node_bounds as kb

    wp = warp()
    M = len(plan.vertex)
    if out.shape[0] != M or c.shape[1] % max(out.shape[1], 1):
        raise ValueError(f"residual_bounds: out {out.shape} does not fit {M} plan rows of {c.shape[1]} coefficients")
    threads.launch(kb.residual_bounds, M, [warp_view(plan.vertex, wp.int32), warp_view(plan.ring_ptr, wp.int64),
                                            warp_view(plan.ring_ids, wp.int32), warp_view(plan.ring_w, wp.float32),
                                            c, np.float32(1.0 / white), warp_view(out, wp.float32)],
                   work=plan.ring_ptr)


def leaf_steps(d: np.ndarray, c, white: float, adjacency: tuple, threads: KernelThreads) -> None:
    """S-2 (b) into ``d`` (N, C) at the leaves: the largest ``radiance_bound`` of (C(v) - C(q)) / white over the
    original neighbours q of each leaf v, for ``adjacency = (vertex of each row (R,) int32, CSR offsets (R + 1,)
    int64, neighbours (E,) int32)`` and ``c`` from ``coefficient_rows``."""
    from lodprt.kernels import node_bounds as kb

    wp = warp()
    rows, ptr, nbr = adjacency
    if len(ptr) != len(rows) + 1 or (len(ptr) and ptr[-1] != len(nbr)):
        raise ValueError(f"leaf_steps: {len(rows)} rows, {len(ptr)} offsets and {len(nbr)} neighbours do not fit")
    ptr = np.asarray(ptr, np.int64)
    threads.launch(kb.leaf_step_bounds, len(rows), [warp_view(rows, wp.int32), warp_view(ptr, wp.int64),
                                                    warp_view(nbr, wp.int32), c, np.float32(1.0 / white),
                                                    warp_view(d, wp.float32)], work=ptr)


def vertex_adjacency(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``leaf_rings(faces)`` as an adjacency CSR: (the vertex of each row (R,) int32, offsets (R + 1,) int64,
    neighbours (E,) int32), one row per vertex that has a neighbour."""
    v, q, starts = leaf_rings(faces)
    return v[starts], np.r_[starts, len(v)].astype(np.int64), q


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
    s = np.zeros((N, C), np.float64)
    s[V:] = collapse_residuals(plan, c, white)  # plan row m is the collapse of node V + m
    s[V:] **= 2
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
    """Every original edge in both directions, once each, sorted by its first vertex then its second: int32
    (v, q, start of each v's run). Made from one int64 key per directed face edge, sorted in place."""
    f = np.asarray(faces)
    V = int(f.max()) + 1 if f.size else 0
    key = np.empty(6 * len(f), np.int64)
    for i, (a, b) in enumerate(((0, 1), (1, 2), (2, 0), (1, 0), (2, 1), (0, 2))):
        key[i * len(f):(i + 1) * len(f)] = f[:, a].astype(np.int64) * V + f[:, b]
    key.sort()
    keep = np.ones(len(key), bool)
    keep[1:] = key[1:] != key[:-1]
    key = key[keep]
    del keep
    v, q = (key // max(V, 1)).astype(np.int32), (key % max(V, 1)).astype(np.int32)
    del key
    loop = v == q
    if loop.any():  # degenerate faces
        v, q = v[~loop], q[~loop]
    idx = np.int32 if len(v) < 2**31 else np.int64
    starts = np.flatnonzero(np.r_[True, v[1:] != v[:-1]]).astype(idx) if len(v) else np.zeros(0, idx)
    return v, q, starts


def height_levels(h) -> list[np.ndarray]:
    """Internal nodes grouped by height (children always on lower levels), lowest first (int32 ids)."""
    hk = node_heights(h)
    order = np.argsort(hk, kind="stable").astype(np.int32 if len(hk) < 2**31 else np.int64)
    bounds = np.searchsorted(hk[order], np.arange(1, hk.max() + 2)) if len(hk) else np.zeros(1, np.int64)
    return [order[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)]


def coefficient_boxes(h, c: np.ndarray, white: float, levels: list) -> np.ndarray:
    """T-14 for one light sample's completed coefficients ``c`` (V, C, ncoef): the box of every coefficient over
    each internal node's leaves, in units of ``white``: (N - V, 2, C, ncoef) float16, centre then half-width
    (clipped to float16's range), made bottom-up one height level at a time (children always sit on lower
    levels), ``CHUNK`` nodes at a time; the float32 minimum and maximum are kept for internal nodes only (a leaf's
    are its own coefficients)."""
    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    out = np.zeros((N - V, 2, C, n), np.float16)
    if N == V:
        return out
    c0, c1 = h.children[:, 0], h.children[:, 1]
    big = float(np.finfo(np.float16).max)
    c, white = c.reshape(V, C * n), np.float32(white)
    mn = np.empty((N - V, C * n), np.float32)
    mx = np.empty_like(mn)

    def box(ch):  # (min, max) of nodes ch, leaves or internal
        leaf = ch < V
        lo, hi = np.empty((len(ch), C * n), np.float32), np.empty((len(ch), C * n), np.float32)
        lo[leaf] = hi[leaf] = c[ch[leaf]] / white
        lo[~leaf], hi[~leaf] = mn[ch[~leaf] - V], mx[ch[~leaf] - V]
        return lo, hi

    for level in levels:
        for start in range(0, len(level), CHUNK):
            nodes = level[start:start + CHUNK]
            (lo0, hi0), (lo1, hi1) = box(c0[nodes]), box(c1[nodes])
            mn[nodes - V], mx[nodes - V] = np.minimum(lo0, lo1), np.maximum(hi0, hi1)
    for start in range(0, N - V, CHUNK):
        rows = slice(start, min(start + CHUNK, N - V))
        out[rows, 0] = np.clip(0.5 * (mx[rows] + mn[rows]), -big, big).reshape(-1, C, n)
        out[rows, 1] = np.clip(0.5 * (mx[rows] - mn[rows]), 0, big).reshape(-1, C, n)
    return out


class NodeErrors(typing.NamedTuple):
    """Per candidate node (K,): culled (T-13 or outside the frustum), error (the criterion's, compared with the
    bound), e_geo (error vector on screen over the diagonal, T-14), e_lumi (display spread of the leaves' radiance,
    T-14), footprint (bounding-sphere radius on screen, pixels), e_detail (S-2: the radiance toward the eye that
    completing the subtree from coarser vertices could miss, units of white). All 0 where culled."""

    culled: np.ndarray
    error: np.ndarray
    e_geo: np.ndarray
    e_lumi: np.ndarray
    footprint: np.ndarray
    e_detail: np.ndarray


def scaled_error_vectors(h, deviation: np.ndarray) -> np.ndarray:
    """S-3: (N, 3) float32 each node's error vector direction (its cone axis where the node's own vector is 0) at
    length ``deviation`` (the subtree's accumulated deviation, ``node_bounds.subtree_deviation``)."""
    own = np.asarray(h.error_vector, np.float64)
    length = np.linalg.norm(own, axis=1)
    unit = np.where(length[:, None] > 0, own / np.maximum(length, 1e-300)[:, None], h.cone_axis)
    return np.ascontiguousarray(unit * deviation[:, None], np.float32)
