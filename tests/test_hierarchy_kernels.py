"""The hierarchy build's round kernels (``lodprt.kernels.hierarchy``) on every Warp device, against numpy."""

import numpy as np
import pytest

from lodprt.devices import warp
from lodprt.model.hierarchy import concat_ranges
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
    wdst = wp.zeros(2 * len(flat), dtype=wp.int32, device=device)
    wcount = wp.zeros(2 * len(flat), dtype=wp.int32, device=device)
    wend = wp.zeros(n, dtype=wp.int64, device=device)
    half = n // 2  # two slices (``first``), as the host's threads launch them
    for first, dim in ((0, half), (half, n - half)):
        wp.launch(kh.gather_rings, dim=dim, device=device, inputs=[first, arr(faces, wp.int32), arr(fstart, wp.int64),
                                                                    corner, wdst, wcount, wend])
    dst, count, start = numpy_adjacency(faces, n)
    pstart, pend = 2 * fstart, wend.numpy()  # the padded CSR: v's ring at pstart[v]:pend[v]
    np.testing.assert_array_equal(pend - pstart[:-1], np.diff(start))
    at = concat_ranges(pstart[:-1], pend)
    np.testing.assert_array_equal(wdst.numpy()[at], dst)
    np.testing.assert_array_equal(wcount.numpy()[at], count)
    dst, count, start = wdst.numpy(), wcount.numpy(), pstart  # the kernels below read the padded CSR

    rng = np.random.default_rng(3)
    quadric = rng.random((n, 10)) * 1e-3
    boundary = (np.bincount(dst[at][count[at] == 1], minlength=n) > 0).astype(np.uint8)
    zeros8 = np.zeros(n, np.uint8)
    best = wp.zeros(n, dtype=wp.int64, device=device)
    cost = wp.zeros(n, dtype=wp.float64, device=device)
    edge_cost = wp.zeros(len(dst), dtype=wp.float64, device=device)
    for first, dim in ((0, half), (half, n - half)):
        wp.launch(kh.best_moves, dim=dim, device=device, inputs=[
            first, arr(pos, wp.float64), arr(quadric, wp.float64), arr(faces, wp.int32),
            arr(np.ones(n, np.uint8), wp.uint8), arr(zeros8, wp.uint8), arr(boundary, wp.uint8),
            arr(np.zeros(n, np.int32), wp.int32), arr(np.zeros(n, np.int32), wp.int32), -1, 0, arr(start, wp.int64),
            wend, wdst, wcount, arr(fstart, wp.int64), corner, EDGE_WEIGHT, FOLD_COS, SLIVER, MAX_VALENCE, edge_cost,
            best, cost])
    e, c = best.numpy(), cost.numpy()
    src = np.zeros(len(dst), np.int64)
    src[at] = np.repeat(np.arange(n), pend - pstart[:-1])
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
        arr(start, wp.int64), wend, wdst, arr(zeros8, wp.uint8), arr(zeros8, wp.uint8), arr(inf, wp.float64),
        arr(inf, wp.float64), made])
    cv = order[made.numpy() == 1]
    cu = target[cv]
    assert len(cv) > 0 and len(np.unique(np.r_[cv, cu])) == 2 * len(cv)
    closed = lambda a: np.r_[a, dst[start[a] : pend[a]]]  # noqa: E731
    in_v = np.zeros(n, int)
    in_u = np.zeros(n, int)
    for a, b in zip(cv, cu):
        in_v[closed(a)] += 1
        in_u[closed(b)] += 1
    assert (in_v[cv] == 1).all() and (in_v[cu] == 1).all() and (in_u[cv] == 1).all()

    err = wp.zeros((len(cv), 3), dtype=wp.float64, device=device)
    wp.launch(kh.collapse_errors, dim=len(cv), device=device, inputs=[
        0, arr(pos, wp.float64), arr(faces, wp.int32), arr(fstart, wp.int64), corner, arr(cv, wp.int32),
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
    """A whole rounds build through the kernels on a flat grid reaches its base and keeps one root per base vertex."""
    pos, faces = wavy_grid(16)
    h = build_hierarchy(pos, faces, np.tile([0, 1.0, 0], (len(pos), 1)), target_base=8, method="rounds")
    assert h.num_nodes > len(pos) and len(h.roots) < 40


@pytest.mark.warp_debug
def test_quadric_kernels_match_numpy(device):
    """``plane_sums`` adds each face's quadric entries at its corners exactly as numpy's per-corner-slot bincounts
    do (the same float sums, bit for bit on the CPU), in two slices; ``merge_quadrics`` adds Q_v into Q_u."""
    from lodprt.kernels import hierarchy as kh
    from lodprt.model.hierarchy_rounds import QUADRIC_ENTRIES

    wp = warp()
    pos, faces = wavy_grid(9)
    faces = faces.astype(np.int32)
    n, flat = len(pos), faces.ravel()
    rng = np.random.default_rng(5)
    plane, weight = rng.standard_normal((len(faces), 4)), rng.random(len(faces))
    ref = np.zeros((n, 10))
    for k, (r, s) in enumerate(QUADRIC_ENTRIES):  # numpy's sums (hierarchy_build._plane_quadrics)
        w = weight * plane[:, r] * plane[:, s]
        for slot in range(3):
            ref[:, k] += np.bincount(faces[:, slot], weights=w, minlength=n)
    fstart = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=n), out=fstart[1:])
    corner = np.argsort(flat, kind="stable").astype(np.int32)  # ascending within each vertex
    arr = lambda a, t: wp.array(np.ascontiguousarray(a), dtype=t, device=device)  # noqa: E731
    q = wp.zeros((n, 10), dtype=wp.float64, device=device)
    for first, dim in ((0, n // 3), (n // 3, n - n // 3)):
        wp.launch(kh.plane_sums, dim=dim, device=device, inputs=[first, arr(fstart, wp.int64), arr(corner, wp.int32),
                                                                  arr(plane, wp.float64), arr(weight, wp.float64), q])
    if device == "cpu":  # the build's device: no fused multiply-add, the same bits
        np.testing.assert_array_equal(q.numpy(), ref)
    else:
        np.testing.assert_allclose(q.numpy(), ref, rtol=1e-12, atol=1e-12)
    ref = q.numpy()

    v = np.array([0, 5, 9], np.int32)
    u = np.array([1, 4, 20], np.int32)
    want = ref.copy()
    want[u] += want[v]
    wp.launch(kh.merge_quadrics, dim=2, device=device, inputs=[1, arr(v, wp.int32), arr(u, wp.int32), q])
    wp.launch(kh.merge_quadrics, dim=1, device=device, inputs=[0, arr(v, wp.int32), arr(u, wp.int32), q])
    np.testing.assert_array_equal(q.numpy(), want)


@pytest.mark.warp_debug
def test_threads_build_the_same_hierarchy(monkeypatch):
    """The round kernels sliced over several threads (``KernelThreads``; every pass split, down to tiny ones) build
    the node arrays one thread builds, bit for bit."""
    import lodprt.launches as launches

    pos, faces = wavy_grid(24)
    normals = np.tile([0, 1.0, 0], (len(pos), 1))
    one = build_hierarchy(pos, faces, normals, target_base=8, workers=1, method="rounds")
    monkeypatch.setattr(launches, "SPLIT_MIN", 2)
    for workers in (2, 3):
        many = build_hierarchy(pos, faces, normals, target_base=8, workers=workers, method="rounds")
        for name in ("parent", "children", "vertex", "creation", "cone_axis", "cone_half_angle", "radius",
                     "error_vector", "neighbours", "neighbour_offsets", "leaf_order", "leaf_range"):
            np.testing.assert_array_equal(getattr(many, name), getattr(one, name), err_msg=name)
