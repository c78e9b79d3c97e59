"""The sequential hierarchy build (``lodprt.model.hierarchy_greedy``, rule H-G): every collapse legal on the mesh as
it stands (the rounds build's replay oracle), the same node attributes, one collapse per vertex and round, the
same hierarchy on any number of threads, and the rounds build's base sizes and rules on awkward meshes."""

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.model.hierarchy_build import build_hierarchy
from lodprt.model.hierarchy_greedy import build_greedy
from lodprt.model.scene import vertex_normals
from lodprt.runtime.view_cut import Cut
from test_hierarchy import check_cones, check_forest, check_radii, face_normals, flat_grid, replay_collapses, wavy_grid


def greedy(pos, faces, **kw):
    pos = np.asarray(pos, float)
    return build_greedy(pos, faces, vertex_normals(pos, np.asarray(faces)), **kw)


def two_grids():
    pa, fa = wavy_grid(20, seed=1)
    pb, fb = wavy_grid(14, lift=5.0, seed=2)
    return np.r_[pa, pb], np.r_[fa, fb + len(pa)]


@pytest.mark.warp_debug
@pytest.mark.parametrize("mesh", ["wavy12", "wavy24", "two"])
def test_every_collapse_is_legal_on_the_mesh_as_it_stands(mesh):
    """Replayed one by one in creation order on a plain Python mesh, every collapse is a legal half-edge collapse
    of the mesh as it stands then, its recorded neighbours are v's and its error vector v's offset from the closest
    point of the faces around u (``replay_collapses``, float64 brute force); the nodes form a binary forest of
    half-edge collapses."""
    pos, faces = two_grids() if mesh == "two" else wavy_grid(int(mesh[4:]))
    h = greedy(pos, faces)
    replay_collapses(pos, faces, h)
    check_forest(h, len(pos), np.isin(np.arange(len(pos)), faces))
    assert h.method == "sequential" and h.num_nodes > len(pos)


def test_one_collapse_per_vertex_and_round():
    """Rule H-G: a vertex is an endpoint of at most one collapse per round, so a node is at most one level above
    its children per round: the depth is at most the rounds made (``levels``)."""
    pos, faces = wavy_grid(30)
    h = greedy(pos, faces)
    assert 0 < h.depth <= h.levels, (h.depth, h.levels)


def test_the_same_hierarchy_on_any_number_of_threads():
    """Parts are whole groups, dealt the same way whatever the threads, and share nothing: bit for bit."""
    pos, faces = two_grids()
    one, two = greedy(pos, faces, workers=1), greedy(pos, faces, workers=2)
    for name in one.ARRAYS:
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), err_msg=name)


def test_components_never_merge_and_component_splits():
    """No collapse joins two connected components, nor two values of ``component`` within one."""
    pos, faces = two_grids()
    na = 20 * 20
    h = greedy(pos, faces)
    internal = np.arange(len(pos), h.num_nodes)
    side = h.vertex[internal] < na
    assert (side == (h.vertex[h.children[internal, 1]] < na)).all()
    comp = (pos[:, 0] > 9.5).astype(np.int64)  # cut the first grid in two along x
    h = greedy(pos, faces, component=comp)
    internal = np.arange(len(pos), h.num_nodes)
    assert (comp[h.vertex[internal]] == comp[h.vertex[h.children[internal, 1]]]).all()


@pytest.mark.parametrize("n, target", [(61, 64), (41, 16)])
def test_flat_grid_reaches_its_target_base_and_keeps_its_outline(n, target):
    """As the rounds build (``test_hierarchy``): at most target + 2 roots, the four corners among them, the base
    covering the whole square with no face turned over; with ``keep_boundary`` the whole rim stays."""
    pos, faces, normals, rim = flat_grid(n)
    h = build_greedy(pos, faces, normals, target_base=target)
    assert len(h.roots) <= target + 2, len(h.roots)
    assert np.isin(rim[:4], h.vertex[h.roots]).all()
    tri = Cut.base(h, faces).triangles()
    cross = face_normals(pos, tri)
    assert len(tri) <= target and (cross[:, 1] > 0).all()
    assert np.linalg.norm(cross, axis=1).sum() / 2 == pytest.approx(4.0, rel=1e-9)
    kept = build_greedy(pos, faces, normals, target_base=target, keep_boundary=True)
    assert np.isin(rim, kept.vertex[kept.roots]).all() and len(kept.roots) < len(rim) + 64


@pytest.mark.warp_debug
def test_awkward_meshes_build_and_non_manifold_vertices_stay():
    """A single triangle, a duplicated vertex, an unreferenced vertex, a repeated corner and a fin (three faces on
    one edge): the build finishes, the fin's edge ends take part in no collapse, the full cut gives back the
    faces (less the one with a repeated corner)."""
    h = greedy([[0, 0, 0], [1, 0, 0], [0, 0, 1]], [[0, 2, 1]])
    assert h.num_nodes >= 3
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0), indexing="ij"), -1).reshape(-1, 2)
    pos = np.c_[g[:, 0], 0.1 * np.sin(g[:, 0] * g[:, 1]), g[:, 1]]
    i, j = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
    a = (i * 6 + j).ravel()
    quad = np.r_[np.c_[a, a + 1, a + 6], np.c_[a + 1, a + 7, a + 6]]
    pos = np.r_[pos, pos[[7]], [[1, 1, 1]], [[9, 9, 9]]]  # 36: duplicate of 7, 37: fin tip, 38: unreferenced
    faces = np.r_[quad, [[36, 8, 14]], [[7, 8, 37]], [[3, 3, 4]]]
    h = greedy(pos, faces)
    movers = np.r_[h.vertex[h.children[36:][h.children[36:, 1] >= 0, 1]]] if h.num_nodes > 39 else np.zeros(0, int)
    assert not np.isin([7, 8], movers).any()  # the fin's edge (three faces) ends never collapse
    assert h.parent[38] == -1
    assert np.isfinite(h.cone_axis).all() and np.isfinite(h.error_vector).all()
    good = faces[:-1]
    np.testing.assert_array_equal(Cut.full(h, good).triangles(), good)


@pytest.mark.warp_debug
def test_bunny_floor_attributes_and_base_match_the_rounds_build(bunny_floor):
    """On the bunny and its floor: a forest of half-edge collapses, every leaf normal inside its ancestors' cones,
    every radius holding its leaves (a sample of nodes), zero error vectors on the flat floor and not on the
    bunny, and a base within 5% (or 8 roots) of the rounds build's."""
    s = bunny_floor
    h = build_greedy(s.positions, s.faces, s.normals, component=s.object_id)
    V = s.num_vertices
    check_forest(h, V, np.isin(np.arange(V), s.faces))
    check_cones(h, s.normals)
    rng = np.random.default_rng(0)
    check_radii(h, s.positions, rng.choice(np.arange(V, h.num_nodes), 40, replace=False))
    internal = np.arange(V, h.num_nodes)
    on_floor = s.object_id[h.vertex[internal]] == s.object_id[-1]
    err = np.linalg.norm(h.error_vector[internal], axis=1)
    assert err[on_floor].max() < 1e-6 and err[~on_floor].max() > 1e-5
    rounds = build_hierarchy(s.positions, s.faces, s.normals, component=s.object_id, method="rounds")
    assert abs(len(h.roots) - len(rounds.roots)) <= max(0.05 * len(rounds.roots), 8)


def test_bad_input_is_refused_naming_the_field():
    with pytest.raises(LodprtError, match="faces"):
        build_greedy(np.zeros((3, 3)), np.array([[0, 1, 5]]), np.zeros((3, 3)))
    with pytest.raises(LodprtError, match="non-finite"):
        build_greedy(np.full((3, 3), np.nan), np.array([[0, 1, 2]]), np.zeros((3, 3)))
    with pytest.raises(LodprtError, match="normals"):
        build_greedy(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.zeros((2, 3)))
    with pytest.raises(LodprtError, match="component"):
        build_greedy(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.zeros((3, 3)), component=np.zeros(2, int))


def test_leaf_layout_kernel_matches_the_numpy_layout():
    """The build's one-thread leaf layout (children before parents) equals ``lodprt.model.hierarchy.leaf_layout``."""
    from lodprt.model.hierarchy import leaf_layout

    pos, faces = two_grids()
    h = greedy(pos, faces)
    order, rng = leaf_layout(h.parent, h.children, h.num_vertices)
    np.testing.assert_array_equal(h.leaf_order, order)
    np.testing.assert_array_equal(h.leaf_range, rng)


@pytest.mark.warp_debug
def test_tiles_then_their_borders_stay_legal(monkeypatch):
    """A component over ``TILE`` movable vertices is built in tiles first (their borders waiting), then whole: every
    collapse still replays legally, the same on one thread and two, and the tiles' borders do collapse in the end
    (the base as small as without tiles, within a few roots)."""
    import lodprt.model.hierarchy_greedy as hg

    pos, faces = two_grids()
    whole = greedy(pos, faces)
    monkeypatch.setattr(hg, "TILE", 60)
    one, two = greedy(pos, faces, workers=1), greedy(pos, faces, workers=2)
    replay_collapses(pos, faces, two)
    check_forest(two, len(pos), np.ones(len(pos), bool))  # the compacted phases leave no stale parent behind
    for name in one.ARRAYS:
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), err_msg=name)
    assert abs(len(two.roots) - len(whole.roots)) <= 6, (len(two.roots), len(whole.roots))


def test_the_same_hierarchy_whatever_order_the_jobs_run_in(monkeypatch):
    """The tiles and each component's second phase are jobs (``run_jobs``): run one at a time in the reverse of any
    order the pool would pick (the last ready job first), the hierarchy is the pool's, array for array; and each
    component's second phase ran before the other component's tiles were all done."""
    import lodprt.model.hierarchy_greedy as hg

    pos, faces = two_grids()
    monkeypatch.setattr(hg, "TILE", 60)
    pooled = greedy(pos, faces, workers=2)
    ran = []

    def reverse(jobs, workers, after=lambda: None):
        waits = [j.waits for j in jobs]
        ready = [k for k, w in enumerate(waits) if w == 0]
        while ready:
            k = ready.pop()  # the last ready job first
            jobs[k].run({})
            ran.append(k)
            for d in jobs[k].then:
                waits[d] -= 1
                if not waits[d]:
                    ready.append(d)
        assert len(ran) == len(jobs)
        after()

    monkeypatch.setattr(hg, "run_jobs", reverse)
    other = greedy(pos, faces, workers=2)
    for name in pooled.ARRAYS:
        np.testing.assert_array_equal(getattr(pooled, name), getattr(other, name), err_msg=name)
    assert other.levels == pooled.levels
    tiles = [i for i, k in enumerate(ran) if k < len(ran) - 2]  # the tiles' jobs come first, then the 2 components'
    rests = [i for i, k in enumerate(ran) if k >= len(ran) - 2]
    assert len(rests) == 2 and min(rests) < max(tiles)


def radius_cut(h, faces, r):
    """From the base, split (forced) every active node wider than ``r`` until none is: one level of detail over the
    whole mesh, as a distant view asks for."""
    cut = Cut.base(h, faces)
    while True:
        n = cut.nodes
        wide = n[(h.radius[n] > r) & (h.children[n, 0] >= 0)]
        if not len(wide):
            return cut
        cut.force_refine_many(wide)


def test_tiles_stop_early_so_a_coarse_cut_costs_no_more_where_they_meet(monkeypatch):
    """The first phase takes each tile to 1/REDUCE of its faces only, and the rest is built whole: the borders
    collapse among the coarse levels, not after them. So a coarse cut of one level everywhere keeps about the
    triangles of an untiled build. Built down to the base in the tiles instead (the former build, REDUCE huge),
    the borders come last in creation order; splitting any tile node then needs its border neighbours split,
    and the same cut keeps twice the triangles or more, along the borders."""
    import lodprt.model.hierarchy_greedy as hg

    pos, faces = wavy_grid(128)
    whole = greedy(pos, faces)
    monkeypatch.setattr(hg, "TILE", 2000)  # 9 tiles
    tiled = greedy(pos, faces)
    monkeypatch.setattr(hg, "REDUCE", 10**9)
    former = greedy(pos, faces)
    for r in (12.0, 16.0):
        a, b, c = (len(radius_cut(h, faces, r).triangles()) for h in (whole, tiled, former))
        assert b <= 1.3 * a and c >= 2 * a, (r, a, b, c)


@pytest.mark.warp_debug
def test_a_unit_out_of_neighbour_room_stops_with_a_clear_error(monkeypatch):
    """Each unit records neighbours in its own range; were the host's sizing ever short, the kernel writes nothing
    past it (a neighbour of another unit, or past the array) and the build raises."""
    import lodprt.model.hierarchy_greedy as hg

    sizes = hg._sizes
    monkeypatch.setattr(hg, "_sizes", lambda *a: (lambda m, e: (m, e // 50))(*sizes(*a)))
    pos, faces = two_grids()
    with pytest.raises(LodprtError, match="neighbour"):
        greedy(pos, faces)


def test_a_bake_with_it_stores_it_whole(tmp_path):
    """``bake(scene, path, tree=build_greedy(...))`` stores the sequential build's arrays unchanged, with its method and
    rounds, and its light cuts keep fewer vertices than the full mesh (the documented way to use it today)."""
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene
    from lodprt.precompute.bake import bake
    from lodprt.store.bake_store import open_store

    pos, faces = wavy_grid(24)
    scene = assemble_scene([("grid", pos, faces, THESIS_MATERIAL)], None, {}, "lights", "grid")
    h = build_greedy(scene.positions, scene.faces, scene.normals)
    res = bake(scene, tmp_path / "s.zarr", sh_order=2, threshold_deg=30.0, tree=h)
    stored = open_store(tmp_path / "s.zarr").hierarchy()
    assert stored.method == "sequential" and stored.levels == h.levels
    for name in h.ARRAYS:
        np.testing.assert_array_equal(getattr(stored, name), getattr(h, name), err_msg=name)
    assert 0 < min(s["vertices_kept"] for s in res.samples) < scene.num_vertices


@pytest.mark.parametrize("workers", [1, 2])
def test_the_default_build_reports_progress_in_the_calling_thread(monkeypatch, workers):
    """``build_hierarchy`` (its default method is this build) reports ``progress(collapses, total)`` from the
    calling thread as units finish, over tiles and whole components: never decreasing, never past the total
    (the movable vertices), ending at exactly the collapses made."""
    import threading

    import lodprt.model.hierarchy_greedy as hg

    monkeypatch.setattr(hg, "TILE", 60)
    pos, faces = two_grids()
    calls = []
    h = build_hierarchy(pos, faces, vertex_normals(pos, faces), workers=workers,
                        progress=lambda done, total: calls.append((done, total, threading.get_ident())))
    assert h.method == "sequential"
    done = [c[0] for c in calls]
    # after each unit on one thread; with two, after each unit the calling thread ran and at the end: on this
    # small build under load the other thread can run every unit (CI once saw one call), so only the end is sure
    assert len(calls) > (4 if workers == 1 else 0)
    assert {c[1] for c in calls} == {len(pos)}  # every vertex of the open grids may move
    assert done == sorted(done) and done[-1] == h.num_nodes - len(pos) <= len(pos)
    assert {c[2] for c in calls} == {threading.get_ident()}


def scipy_groups(V, faces, component=None):
    """The oracle: scipy's connected components of the face edges (those within one ``component`` value)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if component is not None:
        e = e[component[e[:, 0]] == component[e[:, 1]]]
    g = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(V, V))
    return connected_components(g, directed=False)[1]


@pytest.mark.warp_debug
def test_mesh_groups_union_find_matches_scipy_connected_components():
    """``mesh_groups`` (the ``components`` union-find kernel) gives scipy's labels exactly, numbered by smallest
    vertex: random meshes with isolated vertices, repeated corners and a ``component`` split (small labels, labels
    past int32, negative ones); no faces; and a refused face index past the vertices."""
    from hypothesis import given, settings, strategies as st

    from lodprt.model.hierarchy_levels import mesh_groups

    @settings(max_examples=60, deadline=None)
    @given(st.integers(1, 40), st.integers(0, 50), st.sampled_from([None, 3, 2**40, -5]), st.integers(0, 2**31))
    def check(V, F, labels, seed):
        rng = np.random.default_rng(seed)
        faces = rng.integers(0, V, (F, 3))
        comp = None if labels is None else rng.integers(0, 3, V) * (labels if labels != 3 else 1)
        got = mesh_groups(V, faces, comp)
        np.testing.assert_array_equal(got, scipy_groups(V, faces.reshape(-1, 3), comp))

    check()
    pos, faces = two_grids()
    np.testing.assert_array_equal(mesh_groups(len(pos), faces), scipy_groups(len(pos), faces))
    with pytest.raises(LodprtError, match="outside"):
        mesh_groups(3, np.array([[0, 1, 3]]))
