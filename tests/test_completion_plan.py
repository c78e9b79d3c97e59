"""The CSR completion plan (``lodprt.model.completion.CompletionPlan``) and the chunked per-node bounds
(``lodprt.runtime.node_bounds``) against straightforward references written here: dense rings padded to the
largest, float64 T-15 weights from ``ring_weights``, waves from a Python loop over the collapses, and the
unchunked bound formulas; the plan's memory follows the real ring sizes (issue 25)."""

import dataclasses

import numpy as np
import pytest

from lodprt.model.completion import CompletionPlan, ring_weights


def python_waves(h, plan) -> np.ndarray:
    """Each row's wave as the original loop made it: rows from the last collapse to the first, a vertex's wave one
    more than the highest wave among its ring (0 for vertices not yet given one)."""
    wave = [0] * h.num_vertices
    vertex = plan.vertex.tolist()
    for m in range(len(vertex) - 1, -1, -1):
        ring, _ = plan.ring(m)
        wave[vertex[m]] = 1 + max((wave[q] for q in ring.tolist()), default=0)
    return np.asarray(wave)[plan.vertex]


def dense_rings(h, positions, normals):
    """Reference T-15 weights, float64, in dense (M, R) rows padded to the largest ring: (ids, weights, lengths)."""
    V, N = h.num_vertices, h.num_nodes
    vertex = h.vertex[h.children[V:N, 1]]
    offs = h.neighbour_offsets
    lens = np.diff(offs[V:])
    R = int(lens.max())
    mask = np.arange(R)[None, :] < lens[:, None]
    ids = np.repeat(vertex[:, None], R, axis=1)
    ids[mask] = h.neighbours[(offs[V:N, None] + np.arange(R)[None, :])[mask]]
    p, n = np.asarray(positions, np.float64), np.asarray(normals, np.float64)
    w, order, _ = ring_weights(p[vertex], p[ids], mask, n[vertex])
    return np.take_along_axis(ids, order, axis=1), w, lens


def reference_complete(h, plan, dense, ids, coeffs, cut_nodes, dark):
    """T-15 completion in float64 over the dense rings, one whole wave at a time (the original algorithm)."""
    from lodprt.model.hierarchy import active_ancestors

    V = h.num_vertices
    nb, weights, lens = dense
    out = np.zeros((V,) + coeffs.shape[1:])
    out[ids] = coeffs
    have = np.zeros(V, bool)
    have[ids] = True
    active = np.zeros(h.num_nodes, bool)
    active[cut_nodes] = True
    active[:V] |= h.parent[:V] < 0
    is_dark = np.zeros(h.num_nodes, bool)
    is_dark[cut_nodes[dark]] = True
    dark_v = is_dark[active_ancestors(h, active)]
    out[dark_v & ~have] = 0.0
    have |= dark_v
    for w in range(1, plan.wave.max() + 1):
        rows = np.flatnonzero(plan.wave == w)
        rows = rows[~have[plan.vertex[rows]]]
        lit = weights[rows] * ~dark_v[nb[rows]]
        total = lit.sum(1, keepdims=True)
        use = np.where(total > 0, lit / np.where(total > 0, total, 1.0), weights[rows])
        out[plan.vertex[rows]] = np.einsum("mr,mr...->m...", use, out[nb[rows]])
        have[plan.vertex[rows]] = True
    return out


@pytest.fixture(scope="module")
def bunny_store(bunny_bake):
    from lodprt.store.bake_store import open_store

    return open_store(bunny_bake)


def test_waves_equal_the_python_loop(bunny_floor, bunny_hierarchy):
    plan = CompletionPlan(bunny_hierarchy, bunny_floor.positions, bunny_floor.normals)
    np.testing.assert_array_equal(plan.wave, python_waves(bunny_hierarchy, plan))
    assert plan.wave.min() == 1 and plan.wave.max() > 10
    np.testing.assert_array_equal(plan.by_wave, np.argsort(plan.wave, kind="stable"))


def test_csr_rings_are_the_float64_rings_rounded(bunny_floor, bunny_hierarchy):
    h = bunny_hierarchy
    plan = CompletionPlan(h, bunny_floor.positions, bunny_floor.normals)
    nb, w, lens = dense_rings(h, bunny_floor.positions, bunny_floor.normals)
    np.testing.assert_array_equal(plan.ring_len, lens)
    assert plan.ring_ids.dtype == np.int32 and plan.ring_w.dtype == np.float32
    for m in range(0, len(lens), 97):
        ring, weights = plan.ring(m)
        np.testing.assert_array_equal(ring, nb[m, : lens[m]])
        np.testing.assert_allclose(weights, w[m, : lens[m]], rtol=1e-6)  # rounded to float32
    c = np.random.default_rng(3).standard_normal((h.num_vertices, 5)).astype(np.float32)
    rows = slice(100, 9000)
    want = np.einsum("mr,mrk->mk", w[rows], c[nb[rows]].astype(np.float64))
    got = np.stack([plan.ring(m)[1].astype(np.float64) @ c[plan.ring(m)[0]].astype(np.float64)
                    for m in range(100, 9000)])  # the CSR rows as the kernels read them
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


def plan_as_dense(plan, R: int):
    """The plan's CSR rings as dense (M, R) ids and weights (0 on the padding)."""
    M = len(plan.vertex)
    lens = np.diff(plan.ring_ptr)
    mask = np.arange(R)[None, :] < lens[:, None]
    ids, w = np.zeros((M, R), np.int64), np.zeros((M, R))
    ids[mask], w[mask] = plan.ring_ids, plan.ring_w
    return ids, w, mask


def assert_plan_is_the_reference(h, pos, nrm) -> np.ndarray:
    """The plan's rule, sorted ring and weights of every row against ``ring_weights`` (float64 numpy): the same
    rule and ring, the weights to float32 rounding. Returns the rules."""
    plan = CompletionPlan(h, pos, nrm)
    V, N = h.num_vertices, h.num_nodes
    vertex = h.vertex[h.children[V:N, 1]]
    ref_ids, ref_w, lens = dense_rings(h, pos, nrm)
    R = ref_ids.shape[1]
    mask = np.arange(R)[None, :] < lens[:, None]
    p64, n64 = pos.astype(np.float64), nrm.astype(np.float64)
    _, _, ref_rule = ring_weights(p64[vertex], p64[ref_ids], mask, n64[vertex])
    np.testing.assert_array_equal(plan.rule, ref_rule)
    ids, w, _ = plan_as_dense(plan, R)
    np.testing.assert_array_equal(np.where(mask, ids, 0), np.where(mask, ref_ids, 0))
    assert np.abs(w - np.where(mask, ref_w, 0)).max() <= 1e-6
    np.testing.assert_allclose(w.sum(1)[lens > 0], 1.0, atol=1e-6)
    return ref_rule


@pytest.mark.warp_debug
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_weight_kernel_equals_the_numpy_rules(bunny_floor, bunny_hierarchy, dtype):
    """``kernels.completion.ring_weights`` (through ``CompletionPlan``) against ``ring_weights``, the float64 numpy
    reference, on every collapse of the bunny + floor: the same rule on every row (all four rules occur: T-15 inside,
    boundary along the floor's edge, mean value and Shepard on the odd rings), the same sorted ring, the same
    weights to float32 rounding; positions given in float32 or float64."""
    rules = assert_plan_is_the_reference(bunny_hierarchy, bunny_floor.positions.astype(dtype),
                                         bunny_floor.normals.astype(dtype))
    assert set(np.unique(rules)) == {0, 1, 2, 3}


def test_complete_matches_the_float64_reference(bunny_store):
    s = bunny_store
    h, plan = s.hierarchy(), s.completion_plan()
    dense = dense_rings(h, s.positions, s.normals)
    for k in (0, 4, s.num_samples - 1):
        ids, coeffs = s.sample(k)
        cut = s.cut_arrays(k)
        assert len(cut["cut_nodes"]) and (s.referenced & ~np.isin(np.arange(s.num_vertices), ids)).any()
        ref = reference_complete(h, plan, dense, ids, coeffs.astype(np.float64), np.asarray(cut["cut_nodes"]),
                                 np.asarray(cut["dark"], bool))
        scale = np.abs(ref).max()
        got = s.complete(k)
        assert got.dtype == np.float64
        assert np.abs(got - ref).max() <= 1e-6 * scale  # float32 weights, renormalised in float64
        got32 = s.complete(k, dtype=np.float32)
        assert got32.dtype == np.float32
        assert np.abs(got32 - got).max() <= 1e-5 * scale
        np.testing.assert_array_equal(got32, plan.complete(ids, coeffs, s.num_vertices, dtype=np.float32, **cut))


@pytest.mark.warp_debug
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(), (1, 1), (3, 1), (1, 16), (3, 9)])
@pytest.mark.parametrize("with_cut", [False, True])
def test_wave_kernel_equals_the_dense_reference_on_every_store_kind(bunny_store, shape, dtype, with_cut):
    """``kernels.completion.complete_in_order`` (through ``CompletionPlan.complete``) against the dense float64
    reference: 1 or 3 channels, 1 or n^2 coefficients, float32 or float64, with the sample's cut (dark nodes
    dropped from the rings) and without one; the plan's own inputs are left as they were."""
    s = bunny_store
    h, plan = s.hierarchy(), s.completion_plan()
    dense = dense_rings(h, s.positions, s.normals)
    ids, _ = s.sample(4)
    cut = s.cut_arrays(4)
    coeffs = np.random.default_rng(len(shape)).normal(size=(len(ids),) + shape)
    nodes, dark = np.asarray(cut["cut_nodes"]), np.asarray(cut["dark"], bool)
    if not with_cut:  # no node dark: every ring neighbour counts
        dark = np.zeros_like(dark)
    before = [a.copy() for a in (plan.ring_ids, plan.ring_w, plan.vertex, plan.by_wave)]
    ref = reference_complete(h, plan, dense, ids, coeffs, nodes, dark)
    kw = {"cut_nodes": nodes, "dark": dark} if with_cut else {}
    got = plan.complete(ids, coeffs.astype(dtype), s.num_vertices, dtype=dtype, **kw)
    assert got.dtype == dtype and got.shape == (s.num_vertices,) + shape
    tol = (1e-6 if dtype == np.float64 else 1e-5) * np.abs(ref).max()
    assert np.abs(got - ref).max() <= tol
    assert dark.any() == with_cut and (got[ref == 0] == 0).all()
    for a, b in zip(before, (plan.ring_ids, plan.ring_w, plan.vertex, plan.by_wave)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("with_cut", [False, True])
def test_rows_for_complete_their_targets_as_a_whole_completion_does(bunny_store, with_cut):
    """Completing only ``rows_for(targets)`` gives the targets exactly the values of a whole completion (the rows
    a ring reads are all there, in wave order), touches fewer rows for coarse targets, and leaves the vertices it
    does not need at 0."""
    s = bunny_store
    h, plan = s.hierarchy(), s.completion_plan()
    ids, coeffs = s.sample(4)
    kw = s.cut_arrays(4) if with_cut else {}
    whole = plan.complete(ids, coeffs, s.num_vertices, **kw)
    rng = np.random.default_rng(7)
    for targets in (h.vertex[h.roots], rng.choice(s.num_vertices, 50, replace=False), np.arange(s.num_vertices)):
        rows = plan.rows_for(targets)
        assert np.all(np.diff(plan.wave[rows]) >= 0)  # wave order
        part = plan.complete(ids, coeffs, s.num_vertices, rows=rows, **kw)
        np.testing.assert_array_equal(part[targets], whole[targets])
        touched = np.zeros(s.num_vertices, bool)
        touched[ids] = True
        touched[plan.vertex[rows]] = True
        assert (part[~touched] == 0).all()
    assert len(plan.rows_for(h.vertex[h.roots])) < len(plan.vertex) // 10
    assert len(plan.rows_for(np.arange(s.num_vertices))) == len(plan.vertex)
    with pytest.raises(ValueError, match="outside the plan"):
        plan.complete(ids, coeffs, s.num_vertices, rows=np.array([len(plan.vertex)]))


def test_wave_kernel_refuses_what_it_would_index_past():
    """The host checks shapes before a launch: an output of fewer rows than the hierarchy's vertices, or a mask
    too short, is a clear error, not a write past an array's end."""
    from lodprt.model.hierarchy_build import build_hierarchy

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 0, 0], [2, 1, 0]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2], [1, 4, 3], [4, 5, 3]], np.int32)
    normals = np.tile([0.0, 0.0, 1.0], (6, 1))
    h = build_hierarchy(pos, faces, normals)
    plan = CompletionPlan(h, pos, normals)
    with pytest.raises(ValueError, match="at least the hierarchy's 6 vertices"):
        plan.fill_waves(np.zeros((5, 1)), np.zeros(6, bool), np.zeros(6, bool))
    with pytest.raises(ValueError, match="need 6"):
        plan.fill_waves(np.zeros((6, 1)), np.zeros(5, bool), np.zeros(6, bool))
    with pytest.raises(ValueError, match="float32 or float64"):
        plan.fill_waves(np.zeros((6, 1), np.int32), np.zeros(6, bool), np.zeros(6, bool))


def old_detail_bounds(h, c, white, plan, faces, levels):
    """S-2 as first written: every array at once, rings padded to the largest, each edge as often as faces list it."""
    from lodprt.runtime.node_bounds import radiance_bound

    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    nb, w = padded_plan(plan)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    e = e[e[:, 0] != e[:, 1]]
    e = e[np.argsort(e[:, 0], kind="stable")]
    starts = np.flatnonzero(np.r_[True, e[1:, 0] != e[:-1, 0]])
    c = c.reshape(V, C * n) / np.float32(white)
    d = np.zeros((N, C), np.float32)
    d[e[starts, 0]] = np.maximum.reduceat(radiance_bound(c[e[:, 0]] - c[e[:, 1]], C, n), starts, axis=0)
    interp = np.einsum("mr,mrk->mk", w, c[nb])
    d[V:] = radiance_bound(c[plan.vertex] - interp, C, n)
    s = np.zeros((N, C))
    s[V:] = d[V:].astype(np.float64) ** 2
    for nodes in levels:
        d[nodes] = np.maximum(d[nodes], np.maximum(d[h.children[nodes, 0]], d[h.children[nodes, 1]]))
        s[nodes] += s[h.children[nodes, 0]] + s[h.children[nodes, 1]]
    leaves = np.maximum(h.leaf_range[V:, 1] - h.leaf_range[V:, 0], 1)
    return d[V:], (s[V:] / leaves[:, None]).astype(np.float32)


def padded_plan(plan):
    R = int(plan.ring_len.max())
    nb = np.repeat(plan.vertex[:, None], R, axis=1)
    w = np.zeros(nb.shape, np.float32)
    mask = np.arange(R)[None, :] < plan.ring_len[:, None]
    nb[mask], w[mask] = plan.ring_ids, plan.ring_w
    return nb, w


def old_boxes(h, c, white, levels):
    V, N = h.num_vertices, h.num_nodes
    _, C, n = c.shape
    big = float(np.finfo(np.float16).max)
    mn = np.empty((N, C * n), np.float32)
    mn[:V] = c.reshape(V, C * n) / np.float32(white)
    mx = mn.copy()
    for nodes in levels:
        mn[nodes] = np.minimum(mn[h.children[nodes, 0]], mn[h.children[nodes, 1]])
        mx[nodes] = np.maximum(mx[h.children[nodes, 0]], mx[h.children[nodes, 1]])
    out = np.zeros((N - V, 2, C, n), np.float16)
    out[:, 0] = np.clip(0.5 * (mx[V:] + mn[V:]), -big, big).reshape(N - V, C, n)
    out[:, 1] = np.clip(0.5 * (mx[V:] - mn[V:]), 0, big).reshape(N - V, C, n)
    return out


@pytest.mark.parametrize("white", [2.0, 0.37])
def test_chunked_bounds_equal_the_unchunked_formulas(bunny_store, white):
    from lodprt.runtime import node_bounds
    from lodprt.runtime.view_cut import Cut

    s = bunny_store
    h, plan = s.hierarchy(), s.completion_plan()
    levels = node_bounds.height_levels(h)
    c = s.complete(4, dtype=np.float32)
    rings = node_bounds.leaf_rings(s.faces)
    v, q, starts = rings
    assert v.dtype == q.dtype == np.int32
    old_pairs = np.unique(np.r_[s.faces[:, [0, 1]], s.faces[:, [1, 2]], s.faces[:, [2, 0]],
                                s.faces[:, [1, 0]], s.faces[:, [2, 1]], s.faces[:, [0, 2]]], axis=0)
    np.testing.assert_array_equal(np.c_[v, q], old_pairs[old_pairs[:, 0] != old_pairs[:, 1]])
    np.testing.assert_array_equal(v[starts], np.unique(v))
    d = node_bounds.detail_bounds(h, c, white, plan, node_bounds.vertex_adjacency(s.faces), levels)
    np.testing.assert_array_equal(d, node_bounds.detail_bounds(h, c, white, plan, Cut.base(h, s.faces).leaf_adjacency,
                                                               levels))  # the same edges in leaf order
    ms = node_bounds.detail_mean_square(h, c, white, plan, levels)
    d_ref, ms_ref = old_detail_bounds(h, c, white, plan, s.faces, levels)
    assert d.shape == d_ref.shape and d.dtype == np.float32
    np.testing.assert_allclose(d, d_ref, rtol=1e-5, atol=1e-6 * d_ref.max())
    np.testing.assert_allclose(ms, ms_ref, rtol=1e-4, atol=1e-10 * ms_ref.max())
    np.testing.assert_array_equal(node_bounds.coefficient_boxes(h, c, white, levels), old_boxes(h, c, white, levels))


@pytest.mark.warp_debug
@pytest.mark.parametrize("C,n", [(1, 1), (3, 1), (1, 16), (3, 9)])
def test_bound_kernels_equal_the_numpy_formulas_on_every_store_kind(bunny_store, C, n):
    """``lodprt.kernels.node_bounds`` (both kernels, sliced over threads) against the numpy formulas above, on 1 or
    3 channels and 1 or n^2 coefficients (a smooth field plus a step, so that both S-2 terms are nonzero)."""
    from lodprt.runtime import node_bounds

    s = bunny_store
    h, plan = s.hierarchy(), s.completion_plan()
    levels = node_bounds.height_levels(h)
    rng = np.random.default_rng(C * 100 + n)
    p = s.positions.astype(np.float32)
    c = (p[:, :1, None] * rng.normal(size=(1, C, n)) + (p[:, 1:2, None] > 0.1) * rng.normal(size=(1, C, n)))
    c = c.astype(np.float32)
    d = node_bounds.detail_bounds(h, c, 0.7, plan, node_bounds.vertex_adjacency(s.faces), levels)
    ms = node_bounds.detail_mean_square(h, c, 0.7, plan, levels)
    d_ref, ms_ref = old_detail_bounds(h, c, 0.7, plan, s.faces, levels)
    assert d.shape == d_ref.shape == (h.num_nodes - h.num_vertices, C) and (d_ref > 0).any()
    np.testing.assert_allclose(d, d_ref, rtol=1e-5, atol=1e-6 * d_ref.max())
    np.testing.assert_allclose(ms, ms_ref, rtol=1e-4, atol=1e-8 * ms_ref.max())  # float32 sums in another order


def test_residuals_are_shared_per_field_and_never_stale(bunny_store, monkeypatch):
    """S-2 and E-1 of one field share one pass of the residual kernel; another field (even one made at the freed
    field's address, or the same one at another white) gets its own."""
    from lodprt.runtime import node_bounds

    s = bunny_store
    plan = s.completion_plan()
    calls = []
    original = node_bounds.residual_bounds
    monkeypatch.setattr(node_bounds, "residual_bounds", lambda *a: calls.append(1) or original(*a))
    c = s.complete(4, dtype=np.float32)
    r = node_bounds.collapse_residuals(plan, c, 1.0)
    assert node_bounds.collapse_residuals(plan, c, 1.0) is r and len(calls) == 1
    assert not r.flags.writeable
    np.testing.assert_allclose(node_bounds.collapse_residuals(plan, c, 2.0), r / 2, rtol=1e-6)
    for k in (5, 6, 7):  # fields made and freed in turn: each compared with a fresh pass of the kernel
        c = s.complete(k, dtype=np.float32)
        got = node_bounds.collapse_residuals(plan, c, 1.0)
        fresh = np.empty_like(got)
        with node_bounds.KernelThreads(1) as threads:
            original(plan, node_bounds.coefficient_rows(c), 1.0, fresh, threads)
        np.testing.assert_array_equal(got, fresh)
        del c


def grid_with_a_large_ring(n: int = 50):
    """An n x n grid's hierarchy (rim kept), with one collapse's ring widened to every vertex no collapse removes
    (the rim's 4 n - 4 and the base mesh's): the builder caps valences (``MAX_VALENCE``), so rings this large come
    from elsewhere (a scanned mesh, another build). The ring stays legal for completion: its vertices outlive the
    collapse."""
    from lodprt.model.hierarchy_build import build_hierarchy

    g = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2) / (n - 1)
    pos = np.c_[g, 0.01 * np.sin(7 * g[:, 0]) * np.cos(5 * g[:, 1])]
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    faces = np.r_[np.c_[i, i + n, i + 1], np.c_[i + 1, i + n, i + n + 1]]
    normals = np.tile([0.0, 0.0, 1.0], (len(pos), 1))
    h = build_hierarchy(pos, faces, normals, keep_boundary=True)
    V, N = h.num_vertices, h.num_nodes
    offs, nbrs = h.neighbour_offsets, h.neighbours
    big = V + (N - V) // 2
    kept = np.setdiff1d(np.arange(V), h.vertex[h.children[V:, 1]])
    ring = np.union1d(nbrs[offs[big]:offs[big + 1]], kept).astype(np.int32)
    nbrs = np.r_[nbrs[:offs[big]], ring, nbrs[offs[big + 1]:]].astype(np.int32)
    offs = offs.copy()
    offs[big + 1:] += len(ring) - (h.neighbour_offsets[big + 1] - h.neighbour_offsets[big])
    return dataclasses.replace(h, neighbour_offsets=offs, neighbours=nbrs), pos, normals, big - V


def test_plan_memory_follows_the_ring_sizes():
    h, pos, normals, row = grid_with_a_large_ring()
    plan = CompletionPlan(h, pos, normals)
    M, entries, R = len(plan.vertex), int(plan.ring_len.sum()), int(plan.ring_len.max())
    assert plan.ring_len[row] == R and R > 150 and R > 20 * entries / M
    # 8 bytes a ring entry (int32 id, float32 weight) and 32 a row (offset, vertex, length, rule, wave, order)
    assert plan.nbytes <= 8 * entries + 32 * M + 8 * (plan.wave.max() + 2), plan.nbytes
    assert plan.nbytes < M * R  # a padded (M, R) table of ids alone would take 4 M R
    ids, w = plan.ring(row)
    assert len(ids) == R and abs(float(w.astype(np.float64).sum()) - 1.0) < 1e-6
    np.testing.assert_array_equal(plan.wave, python_waves(h, plan))
    kept = np.setdiff1d(np.arange(h.num_vertices), plan.vertex)
    out = plan.complete(kept, np.full(len(kept), 0.25), h.num_vertices, dtype=np.float32)
    np.testing.assert_allclose(out, 0.25, rtol=1e-6)
