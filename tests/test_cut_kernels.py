"""The view cut's sequential kernels (``lodprt.kernels.view_cut``) against the one-step-at-a-time Python rules of
``lodprt.runtime.view_cut.Cut`` (``try_coarsen``, ``force_refine``): the same moves in the same order give the same
cut, bit for bit, and every cut they leave is legal (El-Sana & Varshney dependencies, a valid front)."""

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.model.hierarchy import active_ancestors, dependency_violations
from lodprt.runtime.view_cut import Cut

pytestmark = pytest.mark.warp_debug


def copy(cut: Cut) -> Cut:
    return Cut(cut.h, cut.faces, cut.active.copy())


def legal(cut: Cut) -> None:
    np.testing.assert_array_equal(cut.anc, active_ancestors(cut.h, cut.active))
    assert len(dependency_violations(cut.h, cut.faces, cut.anc)) == 0


def random_cut(h, faces, device, seed: int) -> Cut:
    """A legal cut some way down the hierarchy: forced splits of random active nodes from the base."""
    rng = np.random.default_rng(seed)
    cut = Cut.base(h, faces)
    for _ in range(4):
        act = np.flatnonzero(cut.active)
        inner = act[act >= h.num_vertices]
        cut.force_refine_list(rng.permutation(inner)[: max(len(inner) // 3, 1)], device=device)
    return cut


def test_force_refine_list_matches_the_python_rule(bunny_floor, bunny_hierarchy, device):
    h, faces = bunny_hierarchy, bunny_floor.faces
    rng = np.random.default_rng(5)
    cut = random_cut(h, faces, device, 1)
    legal(cut)
    act = np.flatnonzero(cut.active)
    nodes = rng.permutation(act[act >= h.num_vertices])[:150]
    ref = copy(cut)
    before = int(cut.active.sum())
    n = cut.force_refine_list(nodes, device=device)
    want = sum(ref.force_refine(int(k)) for k in nodes if ref.active[k])
    assert n == want == int(cut.active.sum()) - before  # every split adds one active node
    assert not cut.active[nodes].any()  # each asked-for node is split
    np.testing.assert_array_equal(cut.active, ref.active)
    legal(cut)


def test_force_refine_list_budget_stops_between_nodes(bunny_floor, bunny_hierarchy, device):
    h, faces = bunny_hierarchy, bunny_floor.faces
    cut = Cut.base(h, faces)
    roots = h.roots[h.children[h.roots, 0] >= 0]
    n = cut.force_refine_list(roots, max_splits=3, device=device)
    assert n >= 3 and cut.active[roots].any()  # stopped early; the chain it started was finished
    legal(cut)
    assert cut.force_refine_list(roots, max_splits=0, device=device) == 0
    assert cut.force_refine_list(np.zeros(0, np.int64), device=device) == 0


def test_coarsen_list_matches_the_python_rule(bunny_floor, bunny_hierarchy, device):
    h, faces = bunny_hierarchy, bunny_floor.faces
    rng = np.random.default_rng(9)
    cut = random_cut(h, faces, device, 2)
    for _ in range(3):
        act = np.flatnonzero(cut.active)
        par = np.unique(h.parent[act][h.parent[act] >= 0])
        nodes = rng.permutation(np.concatenate([par, act[:50]]))[:400]  # leaves and inactive pairs too
        ref = copy(cut)
        done, blocker = cut.coarsen_list(nodes, device=device)
        for k, d, b in zip(nodes, done, blocker):
            c0, c1 = h.children[k]
            both = c0 >= 0 and ref.active[c0] and ref.active[c1]
            blockers = ref.try_coarsen(int(k))
            assert d == (both and not len(blockers)), k
            assert (b in blockers) if (both and len(blockers)) else b == -1, (k, b, blockers)
        np.testing.assert_array_equal(cut.active, ref.active)
        legal(cut)
        assert done.any()


def test_bad_nodes_are_refused(bunny_floor, bunny_hierarchy):
    cut = Cut.base(bunny_hierarchy, bunny_floor.faces)
    with pytest.raises(LodprtError, match="does not exist"):
        cut.coarsen_list([bunny_hierarchy.num_nodes])
    with pytest.raises(LodprtError, match="does not exist"):
        cut.force_refine_list([-1])


def test_nodes_follow_every_move(bunny_floor, bunny_hierarchy, device):
    """``Cut.nodes`` is kept between moves (a frame asks for it several times): after every kind of move, the
    Python rules and the sequential kernels alike, it is the active nodes again, and callers cannot write it."""
    h = bunny_hierarchy
    cut = random_cut(h, bunny_floor.faces, device, 3)
    rng = np.random.default_rng(11)

    def check():
        nodes = cut.nodes
        np.testing.assert_array_equal(nodes, np.flatnonzero(cut.active))
        assert nodes is cut.nodes and not nodes.flags.writeable  # kept until the next move

    def inner():
        act = cut.nodes
        return rng.permutation(act[act >= h.num_vertices])

    def parents():  # the coarsen candidates: both children active
        act = cut.nodes
        p = np.unique(h.parent[act][h.parent[act] >= 0])
        return rng.permutation(p[cut.active[h.children[p, 0]] & cut.active[h.children[p, 1]]])

    moves = [
        lambda: [cut.refine(int(k)) for k in inner()[:200]],
        lambda: [cut.coarsen(int(k)) for k in parents()[:200]],
        lambda: [cut.try_coarsen(int(k)) for k in parents()[:200]],
        lambda: [cut.force_refine(int(k)) for k in inner()[:5]],
        lambda: cut.refine_many(inner()[:40]),
        lambda: cut.coarsen_many(parents()[:40]),
        lambda: cut.force_refine_many(inner()[:10], max_rounds=2),
        lambda: cut.force_refine_list(inner()[:40], device=device),
        lambda: cut.coarsen_list(parents()[:40], device=device),
    ]
    check()
    for i, move in enumerate(moves):
        before = cut.active.copy()
        move()
        assert not np.array_equal(before, cut.active), i  # the move moved the cut
        check()
    legal(cut)
