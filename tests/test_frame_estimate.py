"""The parts of the frame estimate (E-1..E-4, docs/RUNTIME.md) and of the view cut's default, each against its own
oracle: E-2's primary rays (``kernels.runtime.first_hits``) against a float64 Moller-Trumbore caster written here,
their coverage against the renderer's, S-3's subtree deviation against a walk of the hierarchy, the field the view
cut bounds on a direct-only store (``DirectLight.direct_field``) against the bake's own rows, and the default target:
on unless a bound or a triangle budget is given alone."""

import numpy as np
import pytest

from lodprt.errors import LodprtError


def moller_trumbore(eye: np.ndarray, dirs: np.ndarray, tri: np.ndarray, with_t: bool = False):
    """float64: the nearest triangle each ray (eye + t dirs, t > 0) meets, -1 where none (and its t, inf where
    none, with ``with_t``)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = b - a, c - a
    best = np.full(len(dirs), np.inf)
    out = np.full(len(dirs), -1)
    for k in range(len(tri)):
        p = np.cross(dirs, e2[k])
        det = p @ e1[k]
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = eye - a[k]
        u = (p @ s) * inv
        q = np.cross(s, e1[k])
        v = (dirs @ q) * inv
        t = (q @ e2[k]) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < best)
        best[hit], out[hit] = t[hit], k
    return (out, best) if with_t else out


@pytest.mark.warp_debug
def test_first_hits_agree_with_a_second_ray_caster(device):
    """Three overlapping quads at different depths, one tilted: the face each grid ray meets first equals the
    float64 caster's, on every device (rays within 1e-4 of an edge are not compared), and its barycentric weights
    put the hit where the caster's ray parameter does (E-1 interpolates the corners' radiance with them)."""
    import warp as wp

    from lodprt.kernels import runtime as kr

    wp.init()
    quads = [(-1.0, -1.0, 0.6, 0.4, -3.0), (-0.2, -0.7, 1.1, 0.9, -4.0), (-0.8, 0.1, 0.3, 1.2, -2.0)]
    pts, faces = [], []
    for i, (x0, y0, x1, y1, z) in enumerate(quads):
        tilt = 0.3 * i
        corners = [(x0, y0, z + tilt * y0), (x1, y0, z + tilt * y0), (x1, y1, z + tilt * y1), (x0, y1, z + tilt * y1)]
        base = len(pts)
        pts += corners
        faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    pts, faces = np.array(pts), np.array(faces)
    cols, rows = 37, 23
    eye = np.array([0.05, 0.02, 0.0])
    corner, du, dv = np.array([-0.6, 0.45, -1.0]), np.array([1.2 / cols, 0, 0]), np.array([0, -0.9 / rows, 0])
    mesh = wp.Mesh(points=wp.array(pts.astype(np.float32), dtype=wp.vec3, device=device),
                   indices=wp.array(faces.astype(np.int32).ravel(), dtype=wp.int32, device=device))
    face = wp.zeros(cols * rows, dtype=wp.int32, device=device)
    bary = wp.zeros(cols * rows, dtype=wp.vec3, device=device)
    vec = lambda a: wp.vec3(*map(float, a))  # noqa: E731
    half = cols * rows // 2 + 5  # two launches, as the run time slices them over the cores: the offset places them
    for a, b in ((0, half), (half, cols * rows)):
        wp.launch(kr.first_hits, dim=b - a, inputs=[a, mesh.id, vec(eye), vec(corner), vec(du), vec(dv), cols],
                  outputs=[face, bary], device=device)
    i, j = np.meshgrid(np.arange(cols), np.arange(rows))
    dirs = corner + (i.ravel()[:, None] + 0.5) * du + (j.ravel()[:, None] + 0.5) * dv
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    ref, t = moller_trumbore(eye, dirs, pts[faces], with_t=True)
    got, w = face.numpy(), bary.numpy().astype(np.float64)
    assert (ref >= 0).sum() > 0.3 * len(ref) and (ref < 0).any() and len(set(ref[ref >= 0])) >= 4
    # a ray near a shared edge may be given to either face: compare the quads there, the faces elsewhere
    assert np.array_equal(np.where(got >= 0, got // 2, -1), np.where(ref >= 0, ref // 2, -1))
    assert (got == ref).mean() > 0.95
    hit = got >= 0
    assert np.all(w[~hit] == 0)
    np.testing.assert_allclose(w[hit].sum(1), 1.0, atol=1e-5)
    assert (w[hit] >= -1e-5).all() and (w[hit] > 0.05).all(1).any()  # inside the face, and not only its corners
    at = (w[hit][:, :, None] * pts[faces[got[hit]]]).sum(1)  # the weights' point on the face the kernel met
    np.testing.assert_allclose(at, eye + t[hit, None] * dirs[hit], atol=1e-4)


@pytest.mark.warp_debug
@pytest.mark.parametrize("ncoef", [1, 16])
def test_hit_radiance_is_the_interpolated_fragment(device, ncoef):
    """E-1's fragment at a hit (``kernels.runtime.hit_radiance``) equals the float64 reference: the corners'
    positions, normals and coefficients interpolated with the hit's weights, then T-7 toward the eye
    (``radiance_toward``, scipy-checked SH); rays that met nothing read 0. Both SH widths a relit store gives (y_0
    of a diffuse-only store, order 4), in two launches (the offset), bounds-checked."""
    import warp as wp

    from lodprt.kernels import runtime as kr
    from lodprt.store.bake_store import radiance_toward

    wp.init()
    rng = np.random.default_rng(7)
    A, R = 40, 300
    pos = rng.normal(size=(A, 3))
    nrm = rng.normal(size=(A, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    coef = rng.normal(size=(A, 3, ncoef))
    rows = np.stack([rng.choice(A, 3, replace=False) for _ in range(R)]).astype(np.int32)
    rows[::7] = -1  # rays that met nothing
    w = rng.dirichlet(np.ones(3), R)
    eye = np.array([0.3, 4.0, -2.5])
    out = wp.zeros((R, 3), dtype=wp.float32, device=device)
    args = [wp.array(rows, dtype=wp.int32, device=device), wp.array(w.astype(np.float32), dtype=wp.vec3,
                                                                     device=device),
            wp.array(pos.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(nrm.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(coef.astype(np.float32), dtype=wp.float32, device=device), wp.vec3(*map(float, eye)),
            wp.empty((R, ncoef), dtype=wp.float32, device=device)]
    for a, b in ((0, 123), (123, R)):
        wp.launch(kr.hit_radiance, dim=b - a, inputs=[a] + args, outputs=[out], device=device)
    got = out.numpy()
    hit = rows[:, 0] >= 0
    at = lambda x: np.einsum("rk,rk...->r...", w[hit], x[rows[hit]])  # noqa: E731
    want = radiance_toward(at(pos), at(nrm), at(coef), eye, np.ones(3))
    np.testing.assert_allclose(got[hit], want, rtol=1e-4, atol=1e-4 * np.abs(want).max())
    assert np.all(got[~hit] == 0)


@pytest.mark.usefixtures("gl")
def test_screen_hits_cover_what_the_renderer_covers(bunny_bake):
    """E-2's count: the cells whose ray meets the scene, times the pixels a cell stands for, equals the pixels the
    renderer covers drawing the full mesh (lit white), within 3% (the rays sample the cell centres)."""
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.frame_error import screen_hits
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    store = open_store(bunny_bake)
    rt = Runtime(store, device="cpu", lod=False)
    rt.set_lights(store.light_positions[4:5])
    c, e = np.array(scene_centre(store)), np.array(default_eye(store))
    for k, scale in enumerate((1.0, 0.3)):
        rt.set_camera(Camera(eye=tuple(c + (e - c) * scale), target=tuple(c + [0.3 * k, 0, 0]), width=320,
                             height=240))
        face, _, cell = screen_hits(rt)
        frame = rt.update()
        frame.radiance[:] = 1.0  # every pixel the mesh covers lit, whether drawn per vertex or per pixel (SH)
        frame.coefficients[:] = 0.0
        frame.coefficients[:, :, 0] = 4.0
        with Renderer() as r:
            img = r.image(frame, linear=True)
        covered = float((np.abs(img).sum(-1) > 0).sum())
        assert 0.97 * covered <= (face >= 0).sum() * cell <= 1.03 * covered + cell


def test_subtree_deviation_is_the_walk_of_the_hierarchy(bunny_hierarchy):
    """S-3: for every node, |e_k| plus the largest deviation of a child, recursively from the leaves, capped at the
    node's radius: the vectorised bottom-up pass equals an explicit post-order walk in float64."""
    from lodprt.runtime import node_bounds

    h = bunny_hierarchy
    got = node_bounds.subtree_deviation(h, node_bounds.height_levels(h))
    e = np.linalg.norm(np.asarray(h.error_vector, np.float64), axis=1)
    V, N = h.num_vertices, h.num_nodes
    raw = np.zeros(N)
    raw[:V] = e[:V]
    for k in range(V, N):  # children precede their parent in node order
        a, b = h.children[k]
        assert a < k and b < k
        raw[k] = e[k] + max(raw[a], raw[b])
    ref = np.minimum(raw, np.asarray(h.radius, np.float64))
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0)
    assert (got[V:] > 0).mean() > 0.9  # not vacuous: internal nodes deviate


@pytest.mark.warp_debug
def test_drawn_field_is_the_bake_where_the_light_cut_kept_vertices(bunny_bake):
    """On a direct-only light-cut store the field the view cut bounds is the exact direct light (D_j V_j): at the
    vertices the bake kept it equals the stored rows, and elsewhere it departs from the cut's linear completion
    (shadow edges the completion smooths)."""
    from lodprt.runtime.direct_light import DirectLight
    from lodprt.store.bake_store import open_store

    store = open_store(bunny_bake)
    d = DirectLight(store, "cpu")
    assert not d.residual
    for sample in (0, 4):
        ids, rows = store.sample(sample)
        done = store.complete(sample).astype(np.float32)
        states, drawn = d.direct_field(sample)  # made without completing the sample
        assert drawn.shape == done.shape and states.shape == (store.num_vertices,)
        scale = float(np.abs(rows).max())
        np.testing.assert_allclose(drawn[ids], rows, atol=2e-3 * scale)
        other = store.referenced.copy()
        other[ids] = False
        assert np.abs(drawn[other] - done[other]).max() > 0.05 * scale
        assert np.array_equal(drawn[~store.referenced], done[~store.referenced])


def test_the_default_is_a_frame_target():
    """The screen criterion steers toward DEFAULT_TARGET_PSNR unless a bound is given alone (a fixed bound) or the
    target is 'off'; a target with a bound starts the steering there; a bad target names the field."""
    from lodprt.runtime.criteria import DEFAULT_TARGET_PSNR, make_criterion

    assert make_criterion().target_psnr == DEFAULT_TARGET_PSNR and make_criterion().steered()
    assert make_criterion(error_bound=0.3).target_psnr is None
    assert make_criterion(error_bound=0.3, target_psnr=30).target_psnr == 30.0
    assert make_criterion(target_psnr="off").target_psnr is None
    assert make_criterion(target_psnr="OFF", error_bound=0.2).error_bound == 0.2
    assert not make_criterion("thesis").steered()
    for bad in ("loud", -3.0, float("nan"), 500):
        with pytest.raises(LodprtError, match="target_psnr"):
            make_criterion(target_psnr=bad)


def test_cli_target_off_and_budget(bunny_bake):
    """``--target-psnr off`` and ``--triangle-budget`` alone give a fixed-bound criterion; the default CLI steers;
    a Runtime with a budget alone runs under the budget, not the target."""
    import argparse

    from lodprt.cli import args as cli_args
    from lodprt.runtime.criteria import criterion_of
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    p = argparse.ArgumentParser()
    cli_args.add_view_cut(p)
    p.add_argument("--triangle-budget", type=int, default=None)
    assert criterion_of(p.parse_args([])).steered()
    assert not criterion_of(p.parse_args(["--target-psnr", "off"])).steered()
    assert not criterion_of(p.parse_args(["--triangle-budget", "5000"])).steered()
    assert criterion_of(p.parse_args(["--target-psnr", "31"])).target_psnr == 31.0
    with pytest.raises(SystemExit):
        p.parse_args(["--target-psnr", "loud"])
    rt = Runtime(open_store(bunny_bake), device="cpu", triangle_budget=4000)
    assert rt.steering is None and rt.triangle_budget == 4000
    with pytest.raises(LodprtError, match="triangle_budget"):
        Runtime(open_store(bunny_bake), device="cpu", triangle_budget=4000, target_psnr=30)


@pytest.mark.parametrize("interpolation", ["direct", "thesis"])
def test_a_black_light_is_a_black_frame_at_the_target(bunny_bake, interpolation):
    """Every light black (colour 0, legal): no sample carries weight, yet the default (steered to its target) and
    a moving frame make a black frame that meets any target (E-3 inf) on the base cut, with the full mesh black too;
    E-4's per-node shares (``node_mean_square``) used to reduce over no sample and raise."""
    from lodprt.runtime import frame_error
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    store = open_store(bunny_bake)
    light, black = store.light_positions[[0, 1, 3, 4]].mean(0)[None], np.zeros((1, 3))
    rt = Runtime(store, device="cpu", interpolation=interpolation)
    assert rt.steering is not None
    rt.set_lights(light, black)
    for k in range(3):  # the first frame (E-5), then frames in motion with E-4 due on the first of them
        rt.set_camera(Camera(eye=tuple(np.asarray(default_eye(store)) * (1.0 + 0.05 * k)),
                             target=scene_centre(store), width=160, height=120))
        frame = rt.update()
        assert not np.any(frame.radiance) and not np.any(frame.coefficients)
        assert frame.stats["triangles"] > 0
    assert rt.estimated_psnr == float("inf")
    coarse = np.flatnonzero(rt.cut.active)
    coarse = coarse[coarse >= store.num_vertices]
    assert len(rt.used_samples) == 0 and len(coarse)
    assert not np.any(frame_error.node_mean_square(rt, coarse))


@pytest.mark.warp_debug
def test_relit_any_vertex_is_what_the_full_mesh_frame_draws(bunny_bake):
    """E-1 relights any vertex (``Runtime.relit``): at the cut's vertices it is the frame's own coefficients and
    radiance, at every vertex the full-mesh frame's (LOD off, same camera and lights), and the frame's relighting
    state (M-6's lit lights) is left as it was."""
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    store = open_store(bunny_bake)
    cam = Camera(eye=default_eye(store), target=scene_centre(store), width=160, height=120)
    light = store.light_positions[[0, 1, 3, 4]].mean(0)[None]  # between samples: the direct path (M-1)
    full = Runtime(store, device="cpu", lod=False)
    full.set_lights(light)
    full.set_camera(cam)
    ref = np.zeros((store.num_vertices, 3), np.float32)
    f = full.update()
    ref[f.vertex_ids] = f.radiance
    ref_c = np.zeros((store.num_vertices,) + f.coefficients.shape[1:], np.float32)
    ref_c[f.vertex_ids] = f.coefficients
    rt = Runtime(store, device="cpu", error_bound=0.8)
    rt.set_lights(light)
    rt.set_camera(cam)
    frame = rt.update(max_passes=10_000)
    assert len(frame.vertex_ids) < 0.7 * len(f.vertex_ids)  # a coarse cut: most vertices are not drawn
    lit = rt.lighting.frame_lit.copy()
    coef, rad = rt.relit(frame.vertex_ids)
    np.testing.assert_allclose(rad, frame.radiance, rtol=0, atol=1e-6)
    np.testing.assert_allclose(coef, frame.coefficients, rtol=0, atol=1e-6)
    other = np.setdiff1d(f.vertex_ids, frame.vertex_ids)
    coef, rad = rt.relit(other)
    np.testing.assert_allclose(rad, ref[other], rtol=0, atol=1e-5 * float(np.abs(ref).max()))
    np.testing.assert_allclose(coef, ref_c[other], rtol=0, atol=1e-5 * float(np.abs(ref_c).max()))
    assert np.array_equal(rt.lighting.frame_lit, lit)


@pytest.mark.parametrize("n, size", [(1, 0), (1, 5), (50, 300), (100_000, 90_000), (1_000_000, 1_000)])
def test_distinct_ids_is_numpy_unique(n, size):
    """``distinct_ids`` marks a table instead of sorting (or sorts, for few values of many ids): the same ids and
    inverse as ``np.unique`` (the oracle)."""
    from lodprt.runtime.frame_error import distinct_ids

    values = np.random.default_rng(size).integers(0, n, (size, 3)) if size else np.zeros((0, 3), np.int64)
    ids, inverse = distinct_ids(values, n)
    want_ids, want_inverse = np.unique(values, return_inverse=True)
    np.testing.assert_array_equal(ids, want_ids)
    np.testing.assert_array_equal(inverse, want_inverse.ravel())
    np.testing.assert_array_equal(ids[inverse].reshape(values.shape), values)


def test_a_scene_small_on_screen_is_estimated_on_a_finer_grid(bunny_bake):
    """Seen from 25x the default distance the scene covers a few hundred pixels of 400 x 300: on E-2's default
    grid (coverage_stride) fewer than MIN_COVERED rays meet it, so the grid is halved until enough do or it is
    every pixel; the estimate is then the one made on that grid directly (it was made on the default grid: inf
    when no ray met the scene, far too optimistic when few did)."""
    from lodprt.runtime import frame_error
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    store = open_store(bunny_bake)
    centre = np.asarray(scene_centre(store))
    eye = centre + 25.0 * (np.asarray(default_eye(store)) - centre)
    rt = Runtime(store, device="cpu")
    rt.set_lights(store.light_positions[[0, 1, 3, 4]].mean(0)[None])
    rt.set_camera(Camera(eye=tuple(eye), target=tuple(centre), width=400, height=300))
    frame = rt.update()
    coarse = frame_error.coverage_stride(400, 300)
    few = frame_error.sampled_error(rt, frame.vertex_ids, frame.triangles, frame_error.reference(rt, coarse))
    assert few.covered < frame_error.MIN_COVERED  # the precondition
    est, _, stride = frame_error.estimate(rt, frame.vertex_ids, frame.triangles)
    assert stride < coarse
    fine = frame_error.sampled_error(rt, frame.vertex_ids, frame.triangles, frame_error.reference(rt, stride))
    assert fine.covered >= frame_error.MIN_COVERED or stride == 1
    assert est == fine.psnr() and np.isfinite(est)
