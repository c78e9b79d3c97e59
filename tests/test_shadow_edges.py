"""The actual light's shadow edges in the view cut (M-6, ``lodprt.runtime.shadow_edges``): the direct kernel's
``lit`` bits against a second ray caster (Embree, float64), the straddling steps and per-node errors against
brute-force loops, the footprint against the kernel's, and, end to end, thin bars whose shadows between two light
samples lie where no sample's shadow does: the cut follows them (and without M-6 it does not)."""

import numpy as np
import pytest
import trimesh

from test_moving_lights import bake_grid
from test_view_cut import grid_plane

pytestmark = pytest.mark.usefixtures("gl")


@pytest.fixture(scope="module")
def bars(tmp_path_factory):
    """Four thin bars (0.02 wide) floating 0.8 over a 121 x 121 plane, under a 3 x 1 x 3 light grid with 0.3
    between samples: moving the light by one spacing moves each bar's shadow by about 0.34, eight shadow widths."""
    parts = {"plane": grid_plane(121, 2.0)}
    for i, x in enumerate((-0.3, -0.1, 0.1, 0.3)):
        bar = trimesh.creation.box((0.02, 0.02, 1.2))
        bar.apply_translation((x, 0.8, 0.0))
        parts[f"bar{i}"] = bar
    return bake_grid(tmp_path_factory.mktemp("bars"), parts)


def top_camera():
    from lodprt.runtime.camera import Camera

    return Camera(eye=(0.0, 1.9, 0.9), target=(0.0, 0.0, 0.0), width=240, height=180)


def between(store) -> np.ndarray:
    """A light halfway between the centre sample and the next along x (on no sample's shadow)."""
    p = store.light_positions
    centre = np.argmin(np.linalg.norm(p - p.mean(0), axis=1))
    dx = np.where((np.abs(p[:, 1:] - p[centre, 1:]).max(1) < 1e-9) & (p[:, 0] > p[centre, 0] + 1e-9))[0]
    return 0.5 * (p[centre] + p[dx[0]])


def converged(store, light, **options):
    """A Runtime at ``light`` from the top camera after a few still frames (the steering and M-6 settle)."""
    from lodprt.runtime.session import Runtime

    rt = Runtime(store, device="cpu", **options)
    rt.set_lights(light[None])
    rt.set_camera(top_camera())
    for _ in range(12):
        lod = rt.update(max_passes=10_000)
    return rt, lod


@pytest.mark.warp_debug
def test_lit_bits_match_a_second_ray_caster(bars):
    """The direct kernel's ``lit`` output (M-6) is the visibility of the actual light: Embree's float64 shadow rays
    from the same offset agree on every drawn vertex (bit 0 for back-facing and shadowed vertices)."""
    from lodprt.precompute import reference

    scene, store = bars
    light = between(store)
    rt, lod = converged(store, light)
    lit = rt.lighting.lit_rows(len(lod.vertex_ids))
    assert lit is not None and lit.shape == (len(lod.vertex_ids),)
    state = reference.visibility(reference.EmbreeCaster(scene), scene, light, float(store.attrs["ray_offset"]),
                                 ids=np.asarray(lod.vertex_ids))
    want = (state == reference.LIT).astype(np.int32)
    assert 0 < want.sum() < len(want)  # some drawn vertices in the bars' shadows
    assert (lit != want).mean() < 0.002, np.flatnonzero(lit != want)[:10]  # float32 against float64 rays
    kept = lit.copy()
    rt.coefficients(np.arange(len(kept)))  # other vertices, as many: the frame's bits stay the frame's
    assert np.array_equal(rt.lighting.lit_rows(len(kept)), kept)


@pytest.mark.parametrize("dtypes", [(np.int64, np.float64), (np.int32, np.float32)])  # the run time's: int32, f32
def test_straddling_steps_against_loops(dtypes):
    from lodprt.runtime.shadow_edges import straddling_steps

    rng = np.random.default_rng(3)
    A, T = 60, 150
    tri = rng.integers(0, A, (T, 3)).astype(dtypes[0])
    lit = rng.integers(0, 4, A).astype(np.int32)  # two lights: bits 0 and 1
    rad = (rng.random((A, 3)) * 5.0).astype(dtypes[1])
    got = straddling_steps(tri, lit, rad, white=2.5)
    want = np.zeros(A)
    for t in tri:
        if len({int(lit[i]) for i in t}) > 1:
            d = max(np.abs(rad[a].astype(np.float64) - rad[b]).max() / 2.5 for a in t for b in t)  # float64
            for i in t:
                want[i] = max(want[i], d)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert not straddling_steps(tri, np.zeros(A, np.int32), rad, 1.0).any()  # nothing straddles: no step


def test_extra_holds_this_frames_errors_only(bunny_floor, bunny_hierarchy):
    """``CutRefinement.set_extra`` clears only the last frame's nodes: after several frames the M-6 errors are
    this frame's alone, as a fresh array would hold them."""
    from lodprt.runtime.refinement import CutRefinement
    from lodprt.runtime.view_cut import Cut

    h = bunny_hierarchy
    ref = CutRefinement(h, Cut.base(h, bunny_floor.faces), "cpu", 1)
    rng = np.random.default_rng(4)
    for _ in range(4):
        nodes = np.unique(rng.integers(h.num_vertices, h.num_nodes, 50))
        err = rng.random(len(nodes))
        ref.set_extra(nodes, err)
        want = np.zeros(h.num_nodes, np.float32)
        want[nodes] = err
        np.testing.assert_array_equal(ref.extra, want)
    ref.extra = None  # as the run time drops it (another criterion, LOD off): made again
    ref.set_extra(nodes[:3], err[:3])
    assert np.count_nonzero(ref.extra) == 3


def test_area_weight_closed_form():
    from lodprt.runtime.shadow_edges import area_weight

    np.testing.assert_allclose(area_weight(np.array([0.0, 0.5, 3.0, 4.0, 16.0, 400.0]), 4.0),
                               [1.0, 1.0, 1.0, 1.0, 2.0, 10.0])


def test_footprint_matches_the_kernel(bars):
    """``sphere_pixels`` is pi r_px^2 of the footprint ``kernels.runtime.view_errors`` measures."""
    from lodprt.runtime.shadow_edges import sphere_pixels

    _, store = bars
    rt, _ = converged(store, store.light_positions[4])
    nodes = np.flatnonzero(rt.cut.active)
    nodes = nodes[nodes >= rt.h.num_vertices][:500]
    ne = rt.node_errors(nodes)
    seen = ~ne.culled
    got = sphere_pixels(rt.node_pos(nodes), rt.radius[nodes], rt.vp, rt.focal_px())
    np.testing.assert_allclose(got[seen], np.pi * ne.footprint[seen] ** 2, rtol=2e-4)


def test_node_errors_against_a_walk(bars):
    """Each flagged drawn vertex's active node (when internal) and that node's parent get the largest step among
    the flagged vertices under them, times the weight; nothing else is returned."""
    from lodprt.runtime.shadow_edges import shadow_edge_errors

    _, store = bars
    rt, lod = converged(store, store.light_positions[4])
    h, vid = rt.h, np.asarray(lod.vertex_ids)
    rng = np.random.default_rng(5)
    step = np.where(rng.random(len(vid)) < 0.05, rng.random(len(vid)), 0.0)
    nodes, err = shadow_edge_errors(h, rt.cut.anc, vid, step, lambda n: 1.0 + n % 3)
    want = {}
    for v, s in zip(vid, step):
        if s <= 0:
            continue
        node = int(rt.cut.anc[v])
        assert h.vertex[node] == v and rt.cut.active[node]  # a drawn vertex is its active node's vertex
        for n in ([node] if node >= h.num_vertices else []) + ([int(h.parent[node])] if h.parent[node] >= 0 else []):
            want[n] = max(want.get(n, 0.0), s)
    assert sorted(want) == nodes.tolist()
    np.testing.assert_allclose(err, [want[n] * (1.0 + n % 3) for n in nodes.tolist()])


def test_thin_shadows_between_samples_are_kept(bars, monkeypatch):
    """With the light between samples, the bars' shadows on the plane lie where no sample's do. At a fixed bound
    (the per-node bounds alone, no frame target) the cut follows them from its own shadow rays and reaches 35 dB
    against the full mesh; with M-6 switched off the samples' bounds leave them coarse (lower PSNR), so the test
    sees the difference. The default (the frame target, whose E-1 samples the actual shadows) reaches 35 dB
    either way, with fewer triangles than the full mesh."""
    from lodprt.display.compare import frame_error
    from lodprt.display.render import Renderer
    from lodprt.runtime.frames import full_frame
    from lodprt.runtime.session import Runtime

    _, store = bars
    light = between(store)
    rt, lod = converged(store, light, error_bound=0.8)
    _, steered = converged(store, light)
    full = full_frame(store, top_camera(), lights=light[None])
    monkeypatch.setattr(Runtime, "_shadow_edges", lambda self, *a: False)
    _, without = converged(store, light, error_bound=0.8)
    _, steered_without = converged(store, light)
    with Renderer() as r:
        psnr, psnr_without, psnr_steered, psnr_steered_without = (frame_error(r, f, full, rt.white)[0]["psnr_db"]
                                                                   for f in (lod, without, steered, steered_without))
    assert psnr >= 35.0, (psnr, psnr_without)
    assert psnr > psnr_without + 3.0, (psnr, psnr_without)
    assert min(psnr_steered, psnr_steered_without) >= 35.0, (psnr_steered, psnr_steered_without)
    for f in (lod, steered):
        assert len(f.triangles) < 0.8 * len(full.triangles), (len(f.triangles), psnr, psnr_without)  # a cut
