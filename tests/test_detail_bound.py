"""The S-2 detail bound against brute force (``lodprt.runtime.node_bounds.detail_bounds``): for sampled internal
nodes of the bunny bake, the largest radiance difference toward 4,000 view directions (scipy's SH basis, not the
project's) of every completion residual in the node's subtree (found by walking the subtree in the test) and of
every leaf's step to an original neighbour stays under the node's bound, and the bound is within the
Cauchy-Schwarz factor of that maximum (not loose)."""

import numpy as np
import pytest

from test_sh import scipy_real_basis


def fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z * z)
    return np.c_[r * np.cos(phi), r * np.sin(phi), z]


@pytest.fixture(scope="module")
def case(bunny_bake):
    from lodprt.runtime import node_bounds
    from lodprt.store.bake_store import open_store

    store = open_store(bunny_bake)
    h = store.hierarchy()
    c = store.complete(4).astype(np.float32)
    white = 2.0
    plan = store.completion_plan()
    d = node_bounds.detail_bounds(h, c, white, plan, node_bounds.vertex_adjacency(store.faces),
                                  node_bounds.height_levels(h))
    return store, h, c, white, plan, d


def subtree(h, node: int) -> list[int]:
    out, todo = [], [node]
    while todo:
        k = todo.pop()
        out.append(k)
        if h.children[k, 1] >= 0:
            todo += [int(h.children[k, 0]), int(h.children[k, 1])]
    return out


def test_detail_bound_holds_the_brute_force_maximum(case):
    store, h, c, white, plan, d = case
    V = h.num_vertices
    n = c.shape[2]
    y = scipy_real_basis(fibonacci(4000), int(round(np.sqrt(n))))[:, :n]  # (Q, n)
    faces = store.faces
    neighbours = [set() for _ in range(V)]
    for a, b in np.r_[faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]:
        neighbours[a].add(b)
        neighbours[b].add(a)
    rng = np.random.default_rng(7)
    internal = np.arange(V, h.num_nodes)
    sizes = h.leaf_range[internal, 1] - h.leaf_range[internal, 0]
    picks = np.r_[rng.choice(internal[sizes <= 40], 60, replace=False), rng.choice(internal[sizes > 40], 15)]
    tight = 0
    for node in picks:
        worst = 0.0
        for k in subtree(h, int(node)):
            if k >= V:  # the collapse of node k: T-15's residual at the vertex it removed
                m = k - V
                ring, weights = plan.ring(m)
                res = c[plan.vertex[m]].astype(np.float64) - (weights[:, None, None].astype(np.float64)
                                                               * c[ring]).sum(0)
                worst = max(worst, float(np.abs(res @ y.T).max()))
            else:  # a leaf: its step to each original neighbour
                for q in neighbours[k]:
                    worst = max(worst, float(np.abs((c[k] - c[q]).astype(np.float64) @ y.T).max()))
        bound = float(d[node - V].max()) * white
        assert worst <= bound * (1 + 1e-4) + 1e-6, (node, worst, bound)
        tight += bound <= np.sqrt(n) * worst + 1e-6
    assert tight == len(picks)  # Cauchy-Schwarz over at most sqrt(n) bands: never looser than that


def float16_grid() -> np.ndarray:
    """Every finite non-negative float16, as float64 (the oracle's table)."""
    every = np.arange(1 << 16, dtype=np.uint16).view(np.float16)
    return np.unique(every[np.isfinite(every) & (every >= 0)].astype(np.float64))


def test_float16_up_is_the_smallest_float16_at_or_above_each_value():
    from hypothesis import given, settings, strategies as st

    from lodprt.runtime import node_bounds

    grid = float16_grid()
    edges = np.float32([0.0, 6e-8, 5.96e-8, 6.1e-5, 6.1035156e-05, 1e-30, 1.0, 1.0004883, 1.0001, 65504.0, 65519.0,
                        65520.0, 3e38])

    def check(x: np.ndarray) -> None:
        with np.errstate(over="raise"):  # values past float16's range are capped, never cast to inf (a warning)
            got = node_bounds.float16_up(x)
        assert got.dtype == np.float16 and got.shape == x.shape
        xs = x.astype(np.float64).ravel()
        want = grid[np.minimum(np.searchsorted(grid, xs), len(grid) - 1)]  # smallest float16 >= x, capped at 65504
        np.testing.assert_array_equal(got.astype(np.float64).ravel(), want)

    check(edges)
    check(edges.reshape(-1, 1)[:12].reshape(4, 3))
    check(np.zeros(0, np.float32))
    check(np.float32(1.0001))  # a single value (0-d) as well

    @settings(max_examples=200, deadline=None)
    @given(st.lists(st.floats(0, 1e6, width=32), min_size=1, max_size=50))
    def fuzz(values):
        check(np.float32(values))

    fuzz()
