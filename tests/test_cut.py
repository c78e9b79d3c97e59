"""Light-dependent cut and coefficient completion (thesis 3.3, figure 8; 3.4.3, T-15)."""

import numpy as np
import pytest

from lodprt.precompute.bake import bake
from lodprt.devices import load_kernels
from lodprt.precompute.baker import Baker, bake_kernels
from lodprt.model.completion import RULE_BOUNDARY, RULE_T15, CompletionPlan, ring_weights
from lodprt.precompute.light_cut import LightCut
from lodprt.model.hierarchy import active_ancestors
from lodprt.model.hierarchy_build import build_hierarchy
from lodprt.kernels.visibility import LIT
from lodprt.model.scene import Material, assemble_scene, floor_mesh


def light_cut(scene, h, device, light, threshold):
    load_kernels(device, *bake_kernels())
    ids = np.flatnonzero(scene.referenced).astype(np.int32)
    baker = Baker(scene, 2, device, ids)
    kept, nodes, dark, coeffs, vis = baker.sample_cut(light, LightCut(h, baker.points, device), threshold)
    return baker, kept, nodes, dark, coeffs, vis


@pytest.mark.parametrize("threshold", [0.0, 5.0, 30.0, 100.0])
def test_cuts_are_valid_fronts(device, bunny_floor, bunny_hierarchy, threshold):
    """Every light cut is a legal front of the hierarchy: each vertex has exactly one active ancestor."""
    h = bunny_hierarchy
    ids = np.flatnonzero(bunny_floor.referenced).astype(np.int32)
    load_kernels(device, *bake_kernels())
    baker = Baker(bunny_floor, 2, device, ids)
    lc = LightCut(h, baker.points, device)
    import warp as wp

    for light in bunny_floor.lights.positions[[0, 4]]:
        vis = np.full(bunny_floor.num_vertices, 2, np.uint8)
        vis[ids] = baker.visibility(light).numpy()
        active, dark = lc.cut(baker.normals, wp.array(vis, dtype=wp.uint8, device=device), light, threshold)
        anc = active_ancestors(h, active)  # raises if a vertex has no or two active ancestors
        np.testing.assert_array_equal(np.unique(anc), np.flatnonzero(active))  # and no active node is idle
        # a dark node's leaves are dark (shadowed or back-facing); the cone test (T-11) judges with the light
        # direction at the node, so a leaf or two at the terminator may still see it
        under = np.zeros(bunny_floor.num_vertices, bool)
        under[np.flatnonzero(dark[anc])] = True
        lit_under_dark = np.mean(vis[under] == LIT) if under.any() else 0.0
        assert lit_under_dark < 0.01


@pytest.mark.warp_debug
def test_threshold_monotone_and_eps0_keeps_lit(device, bunny_floor, bunny_hierarchy):
    """epsilon = 0 keeps every lit, front-facing vertex; larger thresholds keep fewer vertices."""
    light = bunny_floor.lights.positions[4]
    counts = []
    for th in (0.0, 5.0, 30.0):
        _, kept, _, _, _, vis = light_cut(bunny_floor, bunny_hierarchy, device, light, th)
        counts.append(len(kept))
        if th == 0.0:
            lit = np.flatnonzero(bunny_floor.referenced)[vis == LIT]
            assert np.isin(lit, kept).all()
    assert counts[0] > counts[1] >= counts[2]


@pytest.mark.warp_debug
def test_uniform_incidence_collapses_to_the_base(device):
    """A plane under a very distant light (nothing shadowed, all angles equal within 5 deg) keeps only the base."""
    pos, faces = floor_mesh(np.array([[0, 0, 0], [1, 0, 1.0]]), 30, 0.0, 1.0)
    scene = assemble_scene([("plane", pos, faces, Material((0.8,) * 3, 0.0, 1.0))], None,
                      {"box": [0.4, 1e6, 0.4, 0.6, 1e6 + 1, 0.6], "grid": [1, 1, 1], "falloff": "none"}, "l", "plane")
    h = build_hierarchy(scene.positions, scene.faces, scene.normals)
    _, kept, _, _, _, vis = light_cut(scene, h, device, scene.lights.positions[0], 5.0)
    assert (vis == LIT).all()
    np.testing.assert_array_equal(np.sort(kept), np.sort(h.vertex[h.roots]))
    # and with a close light the angles vary: more is kept, and where the angle varies most (under the light)
    _, kept_near, _, _, _, _ = light_cut(scene, h, device, np.array([0.5, 0.3, 0.5]), 5.0)
    assert len(kept_near) > len(kept)


def test_cut_bake_coefficients_identical_to_full(tmp_path, device, bunny_floor, bunny_hierarchy):
    """Vertices the cut keeps carry bit-identical coefficients to the full bake; info reports per-sample counts."""
    from lodprt.store.bake_store import open_store

    full = bake(bunny_floor, tmp_path / "full.zarr", sh_order=3, device=device, tree=bunny_hierarchy, full=True)
    cut = bake(bunny_floor, tmp_path / "cut.zarr", sh_order=3, device=device, tree=bunny_hierarchy, threshold_deg=5.0)
    sf, sc = open_store(tmp_path / "full.zarr"), open_store(tmp_path / "cut.zarr")
    for k in range(sf.num_samples):
        fid, fc = sf.sample(k)
        cid, cc = sc.sample(k)
        pos = np.searchsorted(fid, cid)
        np.testing.assert_array_equal(fc[pos], cc)
        assert len(cid) < len(fid) / 2
    info = sc.info()
    assert info["mode"] == "cut" and info["threshold_deg"] == 5.0
    assert [s["vertices_kept"] for s in info["samples"]] == [len(sc.sample(k)[0]) for k in range(sc.num_samples)]
    # payload: vertex id, 9 coefficients, cut node id and its dark flag
    assert all(s["bytes"] == s["vertices_kept"] * (4 + 9 * 4 + 4 + 1) for s in info["samples"])
    # completed radiance is close to the full bake's where it matters (lit, facing the eye)
    eye = np.array([0.0, 0.25, 0.45])
    rf, rc = sf.radiance(4, eye), sc.radiance(4, eye)
    assert np.isfinite(rc).all()
    rel = np.sqrt(np.mean((rc - rf) ** 2)) / np.sqrt(np.mean(rf**2))
    assert rel < 0.2, rel
    assert len(full.samples) == len(cut.samples)


def test_completion_of_constant_and_linear_fields(bunny_floor, bunny_hierarchy):
    """Equal neighbour coefficients complete to exactly those; on the flat floor a linear field is reproduced,
    on its rim too (the build collapses rim vertices along the rim: the boundary rule)."""
    from lodprt.runtime.view_cut import Cut

    h = bunny_hierarchy
    plan = CompletionPlan(h, bunny_floor.positions, bunny_floor.normals)
    sums = np.add.reduceat(plan.ring_w.astype(np.float64), plan.ring_ptr[:-1])  # every ring has a neighbour
    np.testing.assert_allclose(sums, 1.0, atol=1e-6)  # float32 weights
    assert (plan.ring_w >= 0).all() and np.isfinite(plan.ring_w).all()
    base = Cut.base(h, bunny_floor.faces)
    ids = np.unique(h.vertex[base.active])
    const = plan.complete(ids, np.full((len(ids), 1, 4), 0.37), bunny_floor.num_vertices)
    ref = bunny_floor.referenced
    np.testing.assert_allclose(const[ref], 0.37, rtol=1e-13)
    lin = bunny_floor.positions @ np.array([0.3, 0.0, -1.2]) + 0.5
    got = plan.complete(ids, lin[ids, None], bunny_floor.num_vertices)[:, 0]
    floor = (bunny_floor.object_id == 1) & ref
    np.testing.assert_allclose(got[floor], lin[floor], atol=1e-12)
    assert plan.rule_fractions()["T-15 cotangent"] > 0.5


def test_ring_weights_linear_precision_and_degenerate_rings():
    """T-15 on a convex ring reproduces p; collinear, coincident, obtuse and single-neighbour rings stay bounded."""
    ang = np.linspace(0, 2 * np.pi, 7)[:-1] + 0.1
    ring = np.c_[np.cos(ang), np.sin(ang), np.zeros(6)] * [[1.0], [0.8], [1.2], [0.9], [1.1], [1.0]]
    p = np.array([[0.1, -0.05, 0.0]])
    w, order, rule = ring_weights(p, ring[None], np.ones((1, 6), bool), np.array([[0, 0, 1.0]]))
    assert rule[0] == RULE_T15
    np.testing.assert_allclose(w[0] @ ring[order[0]], p[0], atol=1e-14)
    cases = [
        np.array([[1, 0, 0], [2, 0, 0], [3, 0, 0.0]]),  # collinear, all on one side
        np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0.0]]),  # coincident neighbours
        np.array([[1, 0, 0], [-1, 0.01, 0], [-1, -0.01, 0.0]]),  # obtuse: p near an edge
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]),  # a neighbour on p itself
    ]
    for ring in cases:
        w, _, _ = ring_weights(np.zeros((1, 3)), ring[None], np.ones((1, 3), bool), np.array([[0, 0, 1.0]]))
        assert np.isfinite(w).all() and (w >= 0).all() and w.sum() == pytest.approx(1.0)
    w, _, _ = ring_weights(np.zeros((1, 3)), np.array([[[1.0, 0, 0], [0, 0, 0]]]), np.array([[True, False]]),
                           np.array([[0, 0, 1.0]]))
    np.testing.assert_allclose(w, [[1.0, 0.0]])


def test_ring_weights_boundary_rule_on_open_rings():
    """A vertex on a straight open boundary (its ring a half fan, a gap of 180 degrees) takes the boundary rule and
    reproduces p from the two neighbours along the boundary; at a convex bend of the boundary (a gap over 180
    degrees) the weights stay positive and complete to p's closest point on the segment between them."""
    ang = np.array([0.0, 0.6, 1.5, 2.4, np.pi])
    ring = np.c_[np.cos(ang), np.sin(ang), np.zeros(5)] * [[1.0], [0.7], [1.3], [0.8], [2.0]]
    up = np.array([[0, 0, 1.0]])
    w, order, rule = ring_weights(np.zeros((1, 3)), ring[None], np.ones((1, 5), bool), up)
    assert rule[0] == RULE_BOUNDARY
    np.testing.assert_allclose(w[0] @ ring[order[0]], 0.0, atol=1e-14)
    bent = ring.copy()
    bent[4] = [-1.0, 0.3, 0.0]
    w, order, rule = ring_weights(np.zeros((1, 3)), bent[None], np.ones((1, 5), bool), up)
    assert rule[0] == RULE_BOUNDARY and (w >= 0).all() and w.sum() == pytest.approx(1.0)
    a, b = bent[0], bent[4]
    t = -a @ (b - a) / ((b - a) @ (b - a))
    np.testing.assert_allclose(w[0] @ bent[order[0]], a + t * (b - a), atol=1e-14)
