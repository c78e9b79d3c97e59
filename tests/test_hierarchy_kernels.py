"""The hierarchy build's round kernels (``lodprt.kernels.hierarchy``) on every Warp device, against numpy."""

import numpy as np
import pytest

from lodprt.devices import warp
from lodprt.model.hierarchy_attributes import error_vectors
from lodprt.model.hierarchy_build import build_hierarchy
from lodprt.model.hierarchy_rounds import EDGE_WEIGHT, FOLD_COS, MAX_VALENCE, SLIVER
from test_hierarchy import wavy_grid


def numpy_adjacency(faces, n):
    """Sorted one-rings with the faces on each edge, by one sort of the directed edge keys (the reference)."""
    a, b = faces.ravel().astype(np.int64), faces[:, [1, 2, 0]].ravel().astype(np.int64)
    keys, count = np.unique(np.r_[a * n + b, b * n + a], return_counts=True)
    start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(keys // n, minlength=n), out=start[1:])
    return (keys % n).astype(np.int32), count.astype(np.int32), start


@pytest.mark.warp_debug
def test_round_kernels_match_numpy(device):
    """On a wavy grid: the corners and one-rings equal numpy's; every best move is a candidate edge whose cost is
    the QEM formula's (float64 numpy) and the same as on the CPU; the selected collapses are pairwise
    non-conflicting; the error vectors equal numpy's closest-point reference (figure 10)."""
    from lodprt.kernels import hierarchy as kh

    wp = warp()
    pos, faces = wavy_grid(12)
    faces = faces.astype(np.int32)
    n, flat = len(pos), faces.ravel()
    arr = lambda a, t: wp.array(np.ascontiguousarray(a), dtype=t, device=device)  # noqa: E731
    fstart = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=n), out=fstart[1:])
    corner = wp.zeros(len(flat), dtype=wp.int32, device=device)
    wp.launch(kh.fill_corners, dim=len(flat), device=device, inputs=[
        arr(flat, wp.int32), arr(fstart, wp.int64), wp.zeros(n, dtype=wp.int32, device=device), corner])
    got = corner.numpy()
    for v in range(n):  # any order within a vertex on a GPU
        np.testing.assert_array_equal(np.sort(got[fstart[v] : fstart[v + 1]]), np.flatnonzero(flat == v))
    ring = wp.zeros(2 * len(flat), dtype=wp.int32, device=device)
    distinct = wp.zeros(n, dtype=wp.int32, device=device)
    wp.launch(kh.gather_rings, dim=n, device=device, inputs=[arr(faces, wp.int32), arr(fstart, wp.int64), corner,
                                                              ring, distinct])
    dst, count, start = numpy_adjacency(faces, n)
    np.testing.assert_array_equal(np.diff(start), distinct.numpy())
    wdst = wp.zeros(len(dst), dtype=wp.int32, device=device)
    wcount = wp.zeros(len(dst), dtype=wp.int32, device=device)
    wp.launch(kh.write_rings, dim=n, device=device, inputs=[arr(fstart, wp.int64), ring, arr(start, wp.int64),
                                                             wdst, wcount])
    np.testing.assert_array_equal(wdst.numpy(), dst)
    np.testing.assert_array_equal(wcount.numpy(), count)

    rng = np.random.default_rng(3)
    quadric = rng.random((n, 10)) * 1e-3
    boundary = (np.bincount(np.r_[dst[count == 1]], minlength=n) > 0).astype(np.uint8)
    zeros8 = np.zeros(n, np.uint8)
    best = wp.zeros(n, dtype=wp.int64, device=device)
    cost = wp.zeros(n, dtype=wp.float64, device=device)
    wp.launch(kh.best_moves, dim=n, device=device, inputs=[
        arr(pos, wp.float64), arr(quadric, wp.float64), arr(faces, wp.int32), arr(np.ones(n, np.uint8), wp.uint8),
        arr(zeros8, wp.uint8), arr(boundary, wp.uint8), arr(np.zeros(n, np.int32), wp.int32),
        arr(np.zeros(n, np.int32), wp.int32), -1, 0, arr(start, wp.int64), wdst, wcount, arr(fstart, wp.int64),
        corner, EDGE_WEIGHT, FOLD_COS, SLIVER, MAX_VALENCE, wp.zeros(len(dst), dtype=wp.float64, device=device),
        best, cost])
    e, c = best.numpy(), cost.numpy()
    src = np.repeat(np.arange(n), np.diff(start))
    has = np.flatnonzero(e >= 0)
    assert len(has) > n // 2
    v, u = src[e[has]], dst[e[has]]
    assert (v == has).all() and (count[e[has]] == 2 - boundary[v]).all()
    x = np.c_[pos[u], np.ones(len(u))]
    Q = lambda q: np.einsum("ki,kij,kj->k", x, q, x)  # noqa: E731
    full = np.zeros((len(u), 4, 4))
    from lodprt.model.hierarchy_rounds import QUADRIC_ENTRIES

    for k, (r, s) in enumerate(QUADRIC_ENTRIES):
        full[:, r, s] = full[:, s, r] = quadric[v, k] + quadric[u, k]
    d2 = ((pos[u] - pos[v]) ** 2).sum(1)
    np.testing.assert_allclose(c[has], Q(full) + EDGE_WEIGHT * d2 * d2, rtol=1e-9, atol=1e-12)

    order = has[np.argsort(c[has], kind="stable")].astype(np.int32)
    target = np.full(n, -1, np.int32)
    target[has] = u
    made = wp.zeros(len(order), dtype=wp.uint8, device=device)
    inf = np.full(n, np.inf)
    wp.launch(kh.greedy_select, dim=1, device=device, inputs=[
        arr(order, wp.int32), arr(target, wp.int32), arr(np.floor(np.log2(np.maximum(c, 1e-300))), wp.float64),
        arr(start, wp.int64), wdst, arr(zeros8, wp.uint8), arr(zeros8, wp.uint8), arr(inf, wp.float64),
        arr(inf, wp.float64), made])
    cv = order[made.numpy() == 1]
    cu = target[cv]
    assert len(cv) > 0 and len(np.unique(np.r_[cv, cu])) == 2 * len(cv)
    closed = lambda a: np.r_[a, dst[start[a] : start[a + 1]]]  # noqa: E731
    in_v = np.zeros(n, int)
    in_u = np.zeros(n, int)
    for a, b in zip(cv, cu):
        in_v[closed(a)] += 1
        in_u[closed(b)] += 1
    assert (in_v[cv] == 1).all() and (in_v[cu] == 1).all() and (in_u[cv] == 1).all()

    err = wp.zeros((len(cv), 3), dtype=wp.float64, device=device)
    wp.launch(kh.collapse_errors, dim=len(cv), device=device, inputs=[
        arr(pos, wp.float64), arr(faces, wp.int32), arr(fstart, wp.int64), corner, arr(cv, wp.int32),
        arr(cu, wp.int32), err])
    tris, counts = [], []
    for a, b in zip(cv, cu):  # the faces around u after the collapse a -> b
        f = np.where(faces == a, b, faces)
        f = f[((f == b).any(1)) & (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        tris.append(f)
        counts.append(len(f))
    ref = error_vectors(pos, cv, np.array(counts), np.concatenate(tris))
    np.testing.assert_allclose(np.linalg.norm(err.numpy(), axis=1), np.linalg.norm(ref, axis=1), atol=1e-9)


def test_build_runs_the_kernels_on_a_grid():
    """A whole build through the kernels on a flat grid reaches its base and keeps one root per base vertex."""
    pos, faces = wavy_grid(16)
    h = build_hierarchy(pos, faces, np.tile([0, 1.0, 0], (len(pos), 1)), target_base=8)
    assert h.num_nodes > len(pos) and len(h.roots) < 40
