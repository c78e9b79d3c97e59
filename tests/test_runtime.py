"""Run time (SPEC 5): light interpolation on a bake, the view-dependent cut, incremental refinement, relighting."""

import time

import numpy as np
import pytest

from errors_reference import node_errors_reference

from lodprt.model import sh
from lodprt.errors import LodprtError
from lodprt.model.hierarchy import active_ancestors, dependency_violations
from lodprt.runtime.camera import Camera, clip_planes, view_projection
from lodprt.runtime.session import HYSTERESIS, Runtime
from lodprt.store.bake_store import open_store


@pytest.fixture(scope="module")
def store(bunny_bake):
    return open_store(bunny_bake)


@pytest.fixture(scope="module")
def rt(store):
    return Runtime(store, device="cpu")


def centre_and_size(rt):
    c = 0.5 * (rt.bounds[0] + rt.bounds[1])
    return c, float((rt.bounds[1] - rt.bounds[0]).max())


def orbit_camera(rt, angle, *, dist=0.9, height=0.45, **kw):
    c, ext = centre_and_size(rt)
    eye = c + ext * np.array([dist * np.sin(angle), height, dist * np.cos(angle)])
    return Camera(eye=tuple(eye), target=tuple(c), **{"width": 320, "height": 240, **kw})


def rows(t: np.ndarray) -> np.ndarray:
    """A triangle list in a canonical order: corners sorted, then the rows (two lists of the same faces compare
    equal)."""
    t = np.sort(t, axis=1)
    return t[np.lexsort(t.T[::-1])]


def assert_legal(rt):
    cut = rt.cut
    np.testing.assert_array_equal(cut.anc, active_ancestors(rt.h, cut.active))  # a front
    assert len(dependency_violations(rt.h, rt.faces, cut.anc)) == 0


def converge(rt, camera, lights=None):
    rt.set_camera(camera)
    if lights is not None:
        rt.set_lights(lights)
    return rt.update(max_passes=10_000)


def test_light_on_sample_reproduces_the_stored_sample(store, rt):
    """A light exactly on sample k gives sample k's completed coefficients times the light's intensity (the thesis
    interpolation; the default one gives the exact direct light there, tests/test_moving_lights.py)."""
    rt = Runtime(store, device="cpu", interpolation="thesis")
    for k in (0, 4, store.num_samples - 1):
        rt.set_lights(store.light_positions[k], colors=[(0.5, 1.0, 2.0)])
        got = rt.coefficients()
        want = store.coefficients(k)[:, :1] * np.array([0.5, 1.0, 2.0])[None, :, None]
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())


@pytest.mark.parametrize("interpolation", ["direct", "thesis"])
def test_radiance_continuous_across_a_cell_boundary(store, interpolation):
    """Radiance changes by a small amount for a small light step through the middle between two samples, where
    the 8 nearest samples change, except (direct path: exact hard shadows) at vertices whose exact shadow state
    changes with the step (Embree's visibility at both lights)."""
    from lodprt.precompute import reference

    rt = Runtime(store, device="cpu", interpolation=interpolation)
    scene = store.scene()
    caster = reference.EmbreeCaster(scene)
    a, b = store.light_positions[3], store.light_positions[4]
    eye = (0.0, 0.4, 0.9)
    mid = 0.5 * (a + b)
    step = 1e-4 * np.linalg.norm(b - a)
    rad, vis = [], []
    for s in (-step, 0.0, step):
        light = mid + s * (b - a) / np.linalg.norm(b - a) + np.array([0.0, 0.0, 1e-3])
        rt.set_lights(light)
        rad.append(rt.radiance(eye))
        vis.append(reference.visibility(caster, scene, light.astype(np.float64), float(store.attrs["ray_offset"])))
    scale = np.abs(rad[1]).max()
    for k in (0, 2):
        keep = vis[k] == vis[1] if interpolation == "direct" else np.ones(len(vis[1]), bool)
        assert np.abs(rad[k] - rad[1])[keep].max() < 1e-2 * scale
        assert (~keep).sum() <= 5  # a step of 1e-4 of the spacing moves the shadow edge over a few vertices


def test_two_lights_at_one_spot_add(store, rt):
    """Two lights at the same place equal one light of twice the intensity; several lights add (thesis 3.4.1)."""
    x = 0.3 * store.light_positions[1] + 0.7 * store.light_positions[5]
    rt.set_lights([x, x])
    two = rt.coefficients()
    rt.set_lights([x], colors=[2.0 * store.intensity])
    np.testing.assert_allclose(two, rt.coefficients(), rtol=1e-6, atol=1e-7)
    y = store.light_positions[7]
    rt.set_lights([x, y])
    both = rt.coefficients()
    rt.set_lights([x])
    one = rt.coefficients()
    rt.set_lights([y])
    np.testing.assert_allclose(both, one + rt.coefficients(), rtol=1e-5, atol=1e-6)


def test_lights_outside_the_region(store):
    """Outside the light box: clamped with lights_clamped counted, or refused with outside='error'."""
    r = Runtime(store, outside="clamp")
    hi = np.asarray(store.root["lights"].attrs["box"])[3:]
    r.set_lights([hi + 1.0])
    assert r.lights_clamped == 1
    np.testing.assert_allclose(r.light_positions[0], hi)
    r2 = Runtime(store, outside="error")
    with pytest.raises(LodprtError, match="outside the sampled region"):
        r2.set_lights([hi + 1.0])
    r2.set_lights([hi])  # on the boundary is inside


@pytest.mark.parametrize("seed", [0, 1])
def test_kernel_errors_match_float64_reference(rt, device, seed):
    """view_errors (float32 Warp kernel) agrees with the float64 numpy reference on every internal node."""
    r = Runtime(rt.store, device=device)
    rng = np.random.default_rng(seed)
    box = np.asarray(r.store.root["lights"].attrs["box"])
    r.set_camera(orbit_camera(r, rng.uniform(0, 6.28), fov=rng.uniform(20, 90)))
    r.set_lights(box[:3] + rng.random((2, 3)) * (box[3:] - box[:3]), colors=rng.random((2, 3)))
    nodes = np.arange(r.h.num_vertices, r.h.num_nodes)
    c1, e1, g1, l1, f1, d1 = r.node_errors(nodes)
    c2, e2, g2, l2, f2, d2 = node_errors_reference(r, nodes)
    assert (c1 != c2).mean() < 1e-4  # float32 ties at a plane or a cone boundary only
    ok = c1 == c2
    np.testing.assert_allclose(g1[ok], g2[ok], atol=2e-5)
    np.testing.assert_allclose(l1[ok], l2[ok], atol=2e-4)
    np.testing.assert_allclose(d1[ok], d2[ok], atol=2e-4)
    np.testing.assert_allclose(e1[ok], e2[ok], atol=2e-4)
    np.testing.assert_allclose(f1[ok], f2[ok], rtol=1e-4)
    fast = r.node_errors(nodes, exact=False)  # early exits: the same refine/coarsen decision for every node
    np.testing.assert_array_equal(fast.culled, c1)
    np.testing.assert_array_equal(fast.error > r.error_bound, e1 > r.error_bound)


def test_frame_relighting_matches_reference(rt, device):
    """A frame's coefficients and radiance equal the float64 evaluation at the frame's vertices."""
    r = Runtime(rt.store, device=device)
    r.set_lights([r.store.light_positions[2] * 0.5 + r.store.light_positions[6] * 0.5])
    f = converge(r, orbit_camera(r, 0.7))
    ref = r.coefficients(f.vertex_ids)
    np.testing.assert_allclose(f.coefficients, ref, rtol=1e-5, atol=1e-5 * np.abs(ref).max())
    eye = np.asarray(f.camera.eye)
    d = eye - r.positions[f.vertex_ids]
    rad = np.einsum("vci,vi->vc", ref.astype(np.float64), sh.basis(d, r.order))
    np.testing.assert_allclose(f.radiance, rad, rtol=1e-4, atol=1e-5 * np.abs(rad).max())
    assert f.triangles.min() >= 0 and f.triangles.max() < len(f.vertex_ids)
    np.testing.assert_array_equal(f.positions, r.positions[f.vertex_ids].astype(np.float32))


def test_cut_is_legal_after_every_update(store):
    """Along an orbit with a moving light the cut stays a legal front after every frame (and is incremental)."""
    r = Runtime(store)
    box = np.asarray(store.root["lights"].attrs["box"])
    touched = []
    for i in range(12):
        r.set_camera(orbit_camera(r, 0.02 * i))  # small steps: frame-to-frame coherence
        t = 0.05 * i
        r.set_lights([box[:3] + (box[3:] - box[:3]) * np.array([0.5 + 0.4 * np.cos(t), 0.5, 0.5 + 0.4 * np.sin(t)])])
        f = r.update()
        assert_legal(r)
        assert f.stats["triangles"] < len(store.faces)
        touched.append(f.stats["nodes_touched"])
    assert touched[0] > 5 * np.median(touched[1:])  # later frames touch what changed, not the whole cut


def test_frame_mesh_follows_the_cut_and_is_the_callers(store):
    """A frame's mesh is the cut's, from the reference triangulation, whether the cut moved (camera steps) or not
    (LOD off, lights moving: the mesh made once is kept); a frame's arrays are the caller's own (changing one changes
    no later frame)."""
    from lodprt.model.hierarchy import triangulate

    def reference(r):
        vid = np.sort(r.h.vertex[r.cut.nodes])
        return vid[r.store.referenced[vid]], rows(triangulate(r.h, r.faces, r.cut.anc))

    box = np.asarray(store.root["lights"].attrs["box"])
    for lod in (True, False):
        r = Runtime(store, lod=lod)
        frames = []
        for i in range(4):
            r.set_camera(orbit_camera(r, 0.3 * (i % 3) if lod else 0.1))  # the cut moves, and comes back
            r.set_lights([box[:3] + (box[3:] - box[:3]) * np.array([0.3 + 0.1 * i, 0.5, 0.5])])
            f = r.update(max_passes=10_000)
            vid, tri = reference(r)
            np.testing.assert_array_equal(f.vertex_ids, vid)
            np.testing.assert_array_equal(rows(f.vertex_ids[f.triangles]), tri)
            frames.append(f)
        first = frames[0].vertex_ids.copy()
        frames[0].vertex_ids[:] = 0
        frames[0].triangles[:] = 0
        again = r.update()  # a still frame (LOD on: E-5 refines it)
        vid, tri = reference(r)
        np.testing.assert_array_equal(again.vertex_ids, vid)
        np.testing.assert_array_equal(rows(again.vertex_ids[again.triangles]), tri)
        if not lod:
            np.testing.assert_array_equal(again.vertex_ids, first)
            np.testing.assert_array_equal(again.triangles, frames[-1].triangles)


def interrupted(*args, **kwargs):
    """Stands in for a call that Ctrl-C interrupts (KeyboardInterrupt)."""
    raise KeyboardInterrupt


def test_an_interrupted_frame_leaves_no_stale_mesh(store, monkeypatch):
    """A frame interrupted while it makes the cut's mesh (KeyboardInterrupt: Ctrl-C in the viewer or a notebook),
    after the triangulation took in the cut's move: the next frame of the same cut draws the cut's mesh, not the one
    before the move (which ``Runtime._cut_mesh`` kept as current while nothing moved after). A fixed bound: no E-5
    on the still frame, so the cut does not move again and only the cache could tell."""
    from lodprt.model.hierarchy import triangulate
    from lodprt.runtime.triangulation import IncrementalTriangulation

    r = Runtime(store, criterion="screen", error_bound=0.8)
    r.set_lights([store.light_positions[0]])
    r.set_camera(orbit_camera(r, 0.0))
    before = r.update(max_passes=10_000)
    r.set_camera(orbit_camera(r, 0.8, dist=0.6))

    monkeypatch.setattr(IncrementalTriangulation, "faces", interrupted)  # after update() took in the move
    with pytest.raises(KeyboardInterrupt):
        r.update(max_passes=10_000)
    monkeypatch.undo()
    after = r.update(max_passes=10_000)
    assert after.stats["refined"] + after.stats["coarsened"] == 0  # the cut had moved in the interrupted frame
    np.testing.assert_array_equal(rows(after.vertex_ids[after.triangles]), rows(triangulate(r.h, r.faces, r.cut.anc)))
    assert len(after.triangles) != len(before.triangles)


def test_frames_in_motion_equal_with_the_triangles_made_meanwhile(store, monkeypatch):
    """On the CPU a frame in motion makes its triangles on a worker thread while it relights the cut's vertices
    (``CutMesh``; they need the cut's nodes only). Every frame of a moving camera and light (E-4 estimates, the
    first frame's E-5, a frame interrupted while it relit) equals, array for array, the frame of a Runtime that
    makes the triangles first: vertices, triangles, coefficients, radiance, and the cut's counts."""
    from lodprt.runtime import session
    from lodprt.runtime.triangulation import CutMesh

    class Serial(CutMesh):
        def __init__(self, *args, background=False, **kwargs):
            super().__init__(*args, background=False, **kwargs)

    monkeypatch.setattr(session, "CutMesh", Serial)
    serial = Runtime(store)
    monkeypatch.undo()
    worker = Runtime(store)
    started = []
    start = CutMesh.start
    monkeypatch.setattr(CutMesh, "start", lambda self, cut: (started.append(self.background), start(self, cut))[1])
    lights = store.light_positions

    for k in range(12):
        for rt in (serial, worker):
            rt.set_camera(orbit_camera(rt, 0.15 * k, dist=0.9 - 0.02 * k))
            rt.set_lights([lights[0] + (lights[-1] - lights[0]) * (k / 11)])
            if k == 6:  # interrupted while it relights: the worker's mesh is left in the making
                with monkeypatch.context() as m:
                    m.setattr(Runtime, "_relight", interrupted)
                    with pytest.raises(KeyboardInterrupt):
                        rt.update()
        a, b = serial.update(), worker.update()
        for name in ("vertex_ids", "triangles", "coefficients", "radiance"):
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=f"frame {k}: {name}")
        for name in ("triangles", "vertices", "refined", "coarsened", "passes", "estimated_psnr_db"):
            assert b.stats[name] == a.stats[name], (k, name)
    assert started and all(started)  # frames in motion used the worker (the serial Runtime never starts one)


def test_still_frames_hold_geometry_at_the_default_rate(store):
    """S-1's geometric term as the run time evaluates it: on E-5's still frame (every pixel measured) at the default
    bound's rate, SCREEN_BOUND / pixel_tolerance per pixel, not the coarsest bound's (ten times it); in motion at the
    steered bound's, so that the geometric error stays at pixel_tolerance pixels. The kernel's error is the largest
    of the geometric term and S-2's, so it is at least the term at the rate in force, and below it at the other for
    some nodes."""
    import math

    from lodprt.runtime.criteria import PIXEL_TOLERANCE, SCREEN_BOUND

    r = Runtime(store)
    r.set_camera(orbit_camera(r, 0.4))
    r.update()  # the first frame: E-5, a still frame

    def terms(rate):
        act = np.flatnonzero(r.cut.active)
        nodes = act[act >= r.h.num_vertices]
        ne = r.node_errors(nodes, exact=True)
        seen = ~ne.culled & (ne.e_geo > 0)
        geo = ne.e_geo[seen] * math.hypot(r.camera.width, r.camera.height) * rate / PIXEL_TOLERANCE
        return ne.error[seen], geo

    assert r.motion_bound is not None
    err, geo = terms(SCREEN_BOUND)
    assert len(err) and np.all(err >= geo * (1 - 1e-4))
    err, geo = terms(r.error_bound)  # the coarsest bound E-5 draws at: a rate ten times the default's
    assert r.error_bound > 2 * SCREEN_BOUND and np.any(err < geo * 0.99)
    r.set_camera(orbit_camera(r, 0.5))
    r.update()  # in motion: E-4's bound back, geometry at its rate
    assert r.motion_bound is None
    err, geo = terms(r.error_bound)
    assert len(err) and np.all(err >= geo * (1 - 1e-4))


def test_zero_error_bound_refines_everything_visible(store):
    """With error bound 0 every active internal node is culled or has zero error (to float32 rounding): the visible
    mesh is at full resolution."""
    r = Runtime(store, error_bound=0.0)
    converge(r, orbit_camera(r, 0.3, dist=1.2, height=0.8))
    assert_legal(r)
    act = np.flatnonzero(r.cut.active)
    internal = act[act >= r.h.num_vertices]
    culled, err = node_errors_reference(r, internal)[:2]
    assert (culled | (err < 1e-6)).all()  # float32 rounding of a sub-nanopixel geometric error
    big = Runtime(store, error_bound=1.0, criterion="thesis")  # T-14 at the top of its scale: nothing refines
    f = converge(big, orbit_camera(big, 0.3, dist=1.2, height=0.8))
    assert f.stats["refined"] == 0 and f.stats["active_nodes"] == len(r.h.roots)


def test_camera_looking_away_gives_the_coarsest_cut(store):
    """When nothing is in view, a detailed cut coarsens back to the base mesh (the coarsest legal cut)."""
    r = Runtime(store, error_bound=0.05)
    cam = orbit_camera(r, 0.0)
    f = converge(r, cam)
    assert f.stats["active_nodes"] > 2 * len(r.h.roots)
    eye = np.asarray(cam.eye)
    away = Camera(eye=cam.eye, target=tuple(eye + (eye - np.asarray(cam.target))), width=320, height=240)
    converge(r, away)
    assert_legal(r)
    np.testing.assert_array_equal(np.flatnonzero(r.cut.active), np.sort(r.h.roots))


def test_incremental_reaches_a_converged_cut(store):
    """Reaching a view incrementally from another view gives a converged cut for it: legal, no active node over the
    bound, every collapse the bound allows (error at most bound / HYSTERESIS) blocked by a finer neighbour (the
    El-Sana & Varshney rule); and it is the cut converged from the base up to such blocks and the hysteresis band
    (under 5% of the nodes differ). Cuts are fixed points of the rules, not unique: a node with an error between
    bound / HYSTERESIS and the bound stays as it was, and two collapses blocking each other may stay split on one
    path and never be split on another."""
    lights = [store.light_positions[4] + np.array([0.01, 0.0, -0.02])]
    inc = Runtime(store, error_bound=0.1)
    converge(inc, orbit_camera(inc, 2.0), lights)
    converge(inc, orbit_camera(inc, 0.5), lights)
    assert_legal(inc)
    h, cut = inc.h, inc.cut
    act = np.flatnonzero(cut.active)
    inner = act[act >= h.num_vertices]
    culled, err = inc.node_errors(inner)[:2]
    assert (culled | (err <= inc.error_bound)).all()
    par = np.unique(h.parent[act])
    cand = par[(par >= 0) & cut.active[h.children[np.maximum(par, 0), 0]] & cut.active[h.children[np.maximum(par, 0), 1]]]
    culled, err = inc.node_errors(cand)[:2]
    if inc.refinement.extra is not None:  # M-6: a collapse across the actual light's shadow edge is not allowed
        err = np.maximum(err, inc.refinement.extra[cand])
    loose = culled | (err * HYSTERESIS <= inc.error_bound)  # collapses the bound allows (with the hysteresis)
    assert all(len(cut.blockers_of_coarsen(int(k))) for k in cand[loose])
    fresh = Runtime(store, error_bound=0.1)
    converge(fresh, orbit_camera(fresh, 0.5), lights)
    differ = np.count_nonzero(inc.cut.active != fresh.cut.active)
    assert differ <= 0.05 * len(act), (differ, len(act))


def test_culling_is_conservative(store):
    """Every node culled as outside the frustum has all its leaves outside; every back-facing one has all its
    leaves' normals facing away from the eye."""
    r = Runtime(store)
    r.set_camera(orbit_camera(r, 1.1, dist=0.5, height=0.3, fov=30))
    nodes = np.arange(r.h.num_vertices, r.h.num_nodes)
    culled = node_errors_reference(r, nodes).culled
    planes = clip_planes(view_projection(r.camera, r.bounds))
    eye = np.asarray(r.camera.eye)
    rng = np.random.default_rng(3)
    for k in rng.choice(nodes[culled], 300, replace=False):
        leaves = r.h.leaves(k)
        p = r.positions[leaves]
        inside = (p @ planes[:, :3].T + planes[:, 3] >= 0).all(1)
        facing = ((eye - p) * r.normals[leaves]).sum(1) > 0
        assert not (inside & facing).any(), k


def test_lumi_error_bounds_the_leaf_spread(store):
    """e_lumi is at least the true display spread (max - min of clip(L / white, 0, 1)) of the leaves' radiance toward
    the node's view direction, and it is 0 for a node whose leaves all read the same (T-14's boxes hold the
    samples' radiance: the T-12 blend of the thesis interpolation)."""
    from lodprt.runtime.frames import display

    r = Runtime(store, interpolation="thesis")
    r.set_camera(orbit_camera(r, 0.4))
    r.set_lights([store.light_positions[1] * 0.6 + store.light_positions[4] * 0.4])
    nodes = np.random.default_rng(1).choice(np.arange(r.h.num_vertices, r.h.num_nodes), 400, replace=False)
    ne = node_errors_reference(r, nodes)
    culled, lumi = ne.culled, ne.e_lumi
    nodes, lumi = nodes[~culled], lumi[~culled]  # culled nodes get no error (they are coarsened regardless)
    assert len(nodes) > 100
    coef = r.coefficients()
    tight = 0
    for k, e in zip(nodes, lumi):
        v = np.asarray(r.camera.eye) - r.positions[r.h.vertex[k]]
        rad = np.einsum("vci,i->vc", coef[r.h.leaves(k)].astype(np.float64), sh.basis(v, r.order)) / r.white
        spread = float((display(rad.max(0)) - display(rad.min(0))).max())
        assert e >= spread - 2e-3, (k, e, spread)
        tight += e < spread + 0.05
    assert tight > len(nodes) // 4  # a bound, but not a loose one: within 0.05 for many nodes
    dark = np.flatnonzero(np.abs(r.box_centre).max((1, 2, 3)) + np.abs(r.box_half).max((1, 2, 3)) == 0)
    if len(dark):
        assert (node_errors_reference(r, dark[:50] + r.h.num_vertices)[3] == 0).all()


@pytest.mark.parametrize("cam", [
    dict(fov=0.01), dict(fov=179.0), dict(near=1e-9), dict(dist=0.01, height=0.05),
])
def test_stiff_cameras_stay_finite_and_legal(store, cam):
    """Fov near 0 and 179 degrees, a near plane almost 0, a camera inside the scene: finite frames, legal cuts."""
    r = Runtime(store)
    kw = {k: v for k, v in cam.items() if k in ("fov", "near")}
    geo = {k: v for k, v in cam.items() if k in ("dist", "height")}
    f = converge(r, orbit_camera(r, 0.9, **geo, **kw))
    assert np.isfinite(f.radiance).all() and np.isfinite(f.coefficients).all()
    assert_legal(r)


def test_triangle_budget_steers_the_count(store):
    """With a triangle budget the count settles at or under the budget within a few frames, the bound under the
    steering's highest (8; budgets past it: tests/test_budgets.py)."""
    r = Runtime(store, error_bound=0.01, triangle_budget=4000)
    cam = orbit_camera(r, 0.2)
    counts = []
    for _ in range(60):  # coarsening from ~46k triangles runs a few hundred collapses a frame
        r.set_camera(cam)
        counts.append(r.update().stats["triangles"])
    assert counts[0] > 4000 and counts[-1] <= 4000 and r.error_bound < 8


def test_bad_settings_are_refused(store, rt):
    """Bad error bounds, alpha, cameras, lights and colours raise LodprtError naming the field."""
    with pytest.raises(LodprtError, match="alpha"):
        rt.set_error_bound(0.2, alpha=1.5)
    with pytest.raises(LodprtError, match="error_bound"):
        rt.set_error_bound(-1)
    with pytest.raises(LodprtError, match="fov"):
        Camera(eye=(0, 0, 1), target=(0, 0, 0), fov=180)
    with pytest.raises(LodprtError, match="eye"):
        Camera(eye=(0, np.nan, 1), target=(0, 0, 0))
    for eye in ("abc", (0, "1", 2), [[0, 0], [1]], (0, True, 1)):  # "abc" raised a bare ValueError
        with pytest.raises(LodprtError, match=r"^camera eye: expected 3 finite numbers"):
            Camera(eye=eye, target=(0, 0, 0))
    with pytest.raises(LodprtError, match="lights"):
        rt.set_lights(np.zeros((2, 2)))
    with pytest.raises(LodprtError, match="colors"):
        rt.set_lights([[0, 0.3, 0]], colors=[[-1, 0, 0]])
    with pytest.raises(LodprtError, match="no camera"):
        Runtime(store).update()


@pytest.mark.parametrize("field, bad", [
    ("near", 0.0), ("near", -1.0), ("near", float("nan")), ("near", "0.1"), ("far", float("nan")),
    ("far", float("inf")), ("far", 0.0), ("fov", "45"), ("fov", True), ("fov", None),
])
def test_bad_camera_planes_and_fov_are_refused(rt, field, bad):
    """A lone near of 0, below 0 or NaN, a non-finite far and a fov that is no number (a string, a bool) are
    refused where Camera checks its fields, naming the field; Runtime.set_camera the same (where a field None is
    Camera's default)."""
    with pytest.raises(LodprtError, match=f"camera {field}"):
        Camera(eye=(0, 0, 1), target=(0, 0, 0), **{field: bad})
    if bad is None:
        assert rt.set_camera((0, 0.3, 0.6), (0, 0.1, 0), **{field: bad}).fov == Camera((0, 0, 1), (0, 0, 0)).fov
        return
    with pytest.raises(LodprtError, match=f"camera {field}"):
        rt.set_camera((0, 0.3, 0.6), (0, 0.1, 0), **{field: bad})


def test_good_camera_planes_give_a_finite_frustum(rt):
    """A lone near or far, and numpy numbers for the fov, near and far (0-d arrays too, which the first check of
    a number refused), give finite clip planes (the frustum the cut culls with), kept as floats."""
    for kw in (dict(near=1e-3), dict(far=50.0), dict(near=0.01, far=2.0), dict(fov=np.float32(45.0)),
               dict(fov=np.int64(60)), dict(fov=np.array(45.0), near=np.array(0.01), far=np.float32(2.0)),
               dict(far=1e160), dict(near=1e-6, far=1e20)):  # the last two: a far plane at infinity (NaN before)
        cam = Camera(eye=(0, 0.3, 0.6), target=(0, 0.1, 0), **kw)
        vp = view_projection(cam, rt.bounds)
        planes = clip_planes(vp)
        assert np.isfinite(vp).all() and np.isfinite(planes).all(), kw
        ahead = np.array([0.0, 0.1, 0.0, 1.0])  # the target: inside every plane
        assert (planes @ ahead >= 0).all(), kw
        assert all(type(v) is float for v in (cam.fov, cam.near, cam.far) if v is not None), kw


@pytest.mark.parametrize("bad", [0, -3, 1.9, float("nan"), "2", True])
def test_bad_max_passes_is_refused_at_construction_and_update(store, rt, bad):
    """max_passes is a whole number >= 1 both where the Runtime is made and per update (nothing truncated)."""
    from lodprt.runtime.settings import check_max_passes

    with pytest.raises(LodprtError, match="max_passes"):
        Runtime(store, device="cpu", max_passes=bad)
    rt.set_camera(orbit_camera(rt, 0.3))
    frame = rt.errors.frame
    with pytest.raises(LodprtError, match="max_passes"):
        rt.update(max_passes=bad)
    assert rt.errors.frame == frame  # refused before the frame began
    assert check_max_passes(3.0) == 3 and type(check_max_passes(np.int64(2))) is int


def test_cli_radiance_with_lights(store, bunny_bake, tmp_path, capsys):
    """`lodprt radiance --light` writes the interpolated, completed radiance; bad lights give one-line errors."""
    from lodprt.cli.main import main

    x = 0.5 * (store.light_positions[0] + store.light_positions[4])
    out = tmp_path / "rad.npy"
    args = ["radiance", str(bunny_bake), "--light", *map(str, x), "--color", "1", "0.5", "0.25", "--eye", "0", "0.3", "0.6"]
    assert main(args + ["-o", str(out)]) == 0
    r = Runtime(store, lod=False)
    r.set_lights([x], colors=[(1, 0.5, 0.25)])
    want = r.radiance((0, 0.3, 0.6))
    np.testing.assert_allclose(np.load(out), want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    assert main(args + ["-o", str(out)]) == 2  # exists, no --overwrite
    hi = np.asarray(store.root["lights"].attrs["box"])[3:] + 1
    assert main(["radiance", str(bunny_bake), "--light", *map(str, hi), "--outside", "error", "--eye", "0", "0", "1",
                 "-o", str(tmp_path / "x.npy")]) == 2
    assert "outside the sampled region" in capsys.readouterr().err
    assert main(["radiance", str(bunny_bake), "--light", "0", "0.3", "0", "--color", "1", "1", "1", "--color", "1", "1",
                 "1", "--eye", "0", "0", "1", "-o", str(tmp_path / "y.npy")]) == 2
    assert "one per light" in capsys.readouterr().err


def test_cli_frames_json(bunny_bake, capsys):
    """`lodprt frames --json` reports every frame with fewer triangles than the full mesh and a summary."""
    import json

    from lodprt.cli.main import main

    t = time.perf_counter()
    assert main(["frames", str(bunny_bake), "--frames", "6", "--path", "dolly", "--json"]) == 0
    wall = time.perf_counter() - t
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["frames"]) == 6
    # the store's opening (its run time, the samples completed at open) is part of the command, before any frame
    assert 0 < doc["summary"]["open_seconds"] < wall - 1e-3 * sum(f["ms_total"] + f["ms_lights"] for f in doc["frames"])
    assert all(0 < f["triangles"] < doc["summary"]["full_triangles"] for f in doc["frames"])
    assert doc["summary"]["median_ms"] > 0
    later = [f["ms_total"] for f in doc["frames"][1:]]  # the mean counts every frame after the first
    assert doc["summary"]["mean_ms"] == pytest.approx(sum(later) / len(later))
    assert main(["frames", str(bunny_bake), "--frames", "0"]) == 2


def test_cli_frames_one_frame_has_no_time_after_the_first(bunny_bake, capsys):
    """`frames --frames 1` printed "median 247.88 ms per frame after the first (248 ms)" and --json gave median_ms and
    p95_ms equal to the first frame: with no frame after the first they are null and the text says so."""
    import json

    from lodprt.cli.main import main

    assert main(["frames", str(bunny_bake), "--frames", "1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)["summary"]
    assert summary["first_frame_ms"] > 0
    assert (summary["median_ms"], summary["mean_ms"], summary["p95_ms"]) == (None, None, None)
    assert main(["frames", str(bunny_bake), "--frames", "1"]) == 0
    text = capsys.readouterr().out
    assert "no frame after it to time" in text and "after the first" not in text, text


def test_cli_frames_refuses_options_full_drops_and_names_bad_values_first(tmp_path, capsys):
    """`frames --full --triangle-budget 10` (or --error-bound, --target-psnr, --criterion, --alpha, --frame-ms: the
    view cut's, which --full leaves unread) ran with them ignored; `--triangle-budget 0` said "triangle_budget 0"
    after the store was opened; `--target-psnr abc` said "invalid target_arg value". Each is refused naming the
    options, before the store is read (the store here does not exist)."""
    from lodprt.cli.main import main

    missing = str(tmp_path / "none.zarr")
    for opts, msg in ((["--full", "--triangle-budget", "10"], "error: --triangle-budget and --full: --full draws the "
                                                               "full mesh, with no view cut for it to choose or steer"),
                      (["--full", "--error-bound", "0.1"], "error: --error-bound and --full"),
                      (["--full", "--criterion", "screen", "--target-psnr", "30", "--alpha", "0.5", "--frame-ms", "9"],
                       "error: --criterion, --target-psnr, --alpha, --frame-ms and --full: "),
                      (["--triangle-budget", "0"], "error: --triangle-budget 0: must be a whole number of triangles"),
                      (["--target-psnr", "0"], "error: --target-psnr 0.0: must be a PSNR in dB in (0, 200], or 'off'"),
                      (["--error-bound", "-1"], "error: --error-bound -1.0: must be a finite number >= 0"),
                      (["--criterion", "thesis", "--target-psnr", "30"],
                       "error: --target-psnr 30.0: a setting of criterion 'screen', not with criterion 'thesis'"),
                      (["--target-psnr", "abc"],
                       "error: argument --target-psnr: 'abc': must be a PSNR in dB in (0, 200], or 'off'")):
        try:
            code = main(["frames", missing, *opts])
        except SystemExit as stop:  # argparse's own refusal
            code = stop.code
        err = capsys.readouterr().err
        assert code == 2 and msg in err and "none.zarr" not in err, (opts, err)
        assert "triangle_budget" not in err and "target_psnr" not in err and "target_arg" not in err, err


def test_cli_frames_reports_the_samples_its_lights_complete(bunny_bake, capsys):
    """`lodprt frames` reports, apart from the frame times, the light samples each frame's lights completed: with a
    cache that holds every sample, each sample the path's lights reach is completed once (counted by a second
    Runtime along the same path, from the samples it uses, not from the cache's count), and a still light completes
    nothing after its first frame."""
    import json

    from lodprt.cli.main import main
    from lodprt.runtime.camera import camera_path

    assert main(["frames", str(bunny_bake), "--frames", "12", "--json"]) == 0
    out = capsys.readouterr()
    doc = json.loads(out.out)
    frames, summary = doc["frames"], doc["summary"]
    first = next(f["frame"] for f in frames if f["samples_completed"])  # a bar on stderr while a frame completes
    assert f"frame {first}: completing light samples" in out.err
    assert all(f["ms_lights"] >= 0 and f["samples_completed"] >= 0 for f in frames)
    assert summary["samples_completed"] == sum(f["samples_completed"] for f in frames)
    assert summary["lights_seconds"] == pytest.approx(sum(f["ms_lights"] for f in frames) / 1e3)
    assert summary["sample_cache_slots"] == summary["light_samples"]  # the small store's samples all fit
    rt = Runtime(open_store(bunny_bake), device="cpu")
    seen = set(rt.used_samples.tolist())
    assert summary["samples_completed_at_open"] == len(seen)
    for camera, lights in camera_path(rt, "orbit", 12):
        rt.set_lights(lights)
        seen |= set(rt.used_samples.tolist())
    assert summary["samples_completed_at_open"] + summary["samples_completed"] == len(seen) > 1
    still = open_store(bunny_bake).light_positions[0]
    assert main(["frames", str(bunny_bake), "--frames", "4", "--light", *map(str, still), "--json"]) == 0
    frames = json.loads(capsys.readouterr().out)["frames"]
    assert [f["samples_completed"] for f in frames[1:]] == [0, 0, 0]


def test_light_radiance_without_a_runtime(store, bunny_floor, tmp_path):
    """light_radiance equals Runtime.radiance, and works on a store baked without a hierarchy (full bake)."""
    from lodprt.precompute.bake import bake
    from lodprt.runtime.frames import light_radiance

    x = [0.4 * store.light_positions[2] + 0.6 * store.light_positions[7]]
    r = Runtime(store, lod=False)
    r.set_lights(x, colors=[(0.3, 0.6, 0.9)])
    want = r.radiance((0.1, 0.3, 0.7))
    got = light_radiance(store, x, (0.1, 0.3, 0.7), colors=[(0.3, 0.6, 0.9)])
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    flat = tmp_path / "flat.zarr"
    bake(bunny_floor, flat, sh_order=2, device="cpu", hierarchy=False)
    plain = open_store(flat)
    rad = light_radiance(plain, x, (0.1, 0.3, 0.7))
    assert rad.shape == (plain.num_vertices, 3) and np.isfinite(rad).all() and rad.max() > 0
    with pytest.raises(LodprtError, match="hierarchy"):
        Runtime(plain)


def test_sliced_rows_give_the_frame_of_one_launch(store, monkeypatch):
    """The run time's per-row passes (view errors, relighting, E-2's rays) split over the cores from ROWS_MIN rows,
    one slice per core, each launch writing only its own rows: a frame made with every pass split (ROWS_MIN 7) is
    the frame of single launches, bit for bit (triangles, coefficients, radiance, the estimate)."""
    from lodprt.runtime import session

    frames = []
    for least in (7, 1 << 30):
        monkeypatch.setattr(session, "ROWS_MIN", least)
        rt = Runtime(store, device="cpu", target_psnr=36.0)
        frames.append(converge(rt, orbit_camera(rt, 0.7)))
    a, b = frames
    np.testing.assert_array_equal(a.triangles, b.triangles)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    np.testing.assert_array_equal(a.radiance, b.radiance)
    assert a.stats["estimated_psnr_db"] == b.stats["estimated_psnr_db"]


def test_host_array_is_a_view_on_the_cpu(device):
    """A frame's small kernel inputs: the values in the kernel's dtype; on the CPU a view of the numpy array when it
    already has that dtype (no copy), elsewhere a copy."""
    import warp as wp

    from lodprt.runtime.device_inputs import host_array

    held = np.arange(7, dtype=np.int32)[::-1].copy()
    got = host_array(held, np.int32, wp.int32, device)
    np.testing.assert_array_equal(got.numpy(), held)
    assert np.shares_memory(got.numpy(), held) == (device == "cpu")
    cast = host_array(np.arange(5, dtype=np.int64), np.int32, wp.int32, device)  # cast: a new array either way
    assert cast.dtype == wp.int32 and cast.numpy().tolist() == [0, 1, 2, 3, 4]
    pts = host_array(np.ones((3, 3)), np.float32, wp.vec3, device)
    assert pts.shape == (3,) and np.allclose(pts.numpy(), 1.0)


def test_cli_frames_json_is_strict_json(bunny_bake, capsys):
    """`frames --full --error-every 1 --json`: the full mesh against itself has PSNR inf, written null (it was
    Infinity, which strict parsers refuse)."""
    import json

    pytest.importorskip("moderngl")
    from lodprt.cli.main import main

    assert main(["frames", str(bunny_bake), "--frames", "2", "--full", "--error-every", "1", "--size", "80", "60",
                 "--json"]) == 0

    def refuse(name):
        raise ValueError(f"not strict JSON: {name}")

    doc = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert [f["psnr_db"] for f in doc["frames"]] == [None, None]


def test_lod_off_reports_no_estimate(bunny_bake):
    """E-3 belongs to the cut: with LOD switched off the frame reports none (it reported the last cut's), and
    with LOD on again the cut's."""
    rt = Runtime(open_store(bunny_bake), device="cpu")
    rt.set_camera(eye=(0.3, 1.0, 1.8), width=80, height=60)
    assert rt.update().stats["estimated_psnr_db"] is not None
    rt.set_lod(False)
    frame = rt.update()
    assert frame.stats["estimated_psnr_db"] is None and frame.stats["estimate_stride_px"] is None
    rt.set_lod(True)
    assert rt.update().stats["estimated_psnr_db"] is not None


def test_runtime_takes_a_path_and_names_what_is_no_store(store, tmp_path):
    """``Runtime("bake.zarr")`` opens the store (it raised AttributeError 'str' object has no attribute
    'hierarchy'); a thing that is no store is a LodprtError; a volume store is named as one (it was 'not a lodprt
    store', though info reads it)."""
    from lodprt.model.volume import procedural_volume
    from lodprt.precompute.volume import bake_volume

    by_path = Runtime(str(store.path), device="cpu")
    assert by_path.h.num_nodes == store.hierarchy().num_nodes
    for bad in (None, 42):
        with pytest.raises(LodprtError, match="not a bake store; pass lodprt.open_store"):
            Runtime(bad, device="cpu")
    vol = tmp_path / "v.zarr"
    bake_volume(procedural_volume("cloud:4"), vol, sh_order=1, rays=4, bounces=0, device="cpu")
    with pytest.raises(LodprtError, match="a volume store .*render-volume, not with the point-light commands"):
        Runtime(str(vol), device="cpu")


def test_a_running_runtime_changes_only_its_criterions_bound_and_alpha(store):
    """``rt.criterion = 'thesis'`` was kept and the next update raised AttributeError; another kind or target would
    run without the per-node bounds and the steering it needs. The bound (and alpha) may change, and forget M-7's
    splits."""
    from lodprt.runtime.criteria import ScreenCriterion, ThesisCriterion

    rt = Runtime(store, device="cpu", triangle_budget=500)
    for bad in ("thesis", ThesisCriterion(), ScreenCriterion(), ScreenCriterion(0.8, target_psnr=30.0), None):
        with pytest.raises(LodprtError, match="criterion"):
            rt.criterion = bad
    rt.criterion = rt.criterion.with_bound(2.0)
    assert rt.error_bound == 2.0 and rt.target_psnr is None
    thesis = Runtime(store, device="cpu", criterion="thesis")
    thesis.criterion = thesis.criterion.with_bound(0.5).with_alpha(0.2)
    assert (thesis.error_bound, thesis.alpha) == (0.5, 0.2)


def test_fields_beside_a_camera_replace_its_own(rt):
    """``set_camera(camera, width=64)`` returned the camera at its own 320 x 240, the width dropped silently."""
    cam = orbit_camera(rt, 0.2)
    got = rt.set_camera(cam, width=64, fov=50.0, far=20.0)
    assert (got.width, got.height, got.fov, got.far, got.eye) == (64, 240, 50.0, 20.0, cam.eye)
    assert rt.set_camera(cam) == cam and rt.camera == cam
    with pytest.raises(LodprtError, match="camera size"):
        rt.set_camera(cam, height=0)


def test_a_very_distant_light_warns_once_without_numpy(rt):
    """A light at 1e300 is clamped into the box with lodprt's warning; numpy's overflow warning (np.round of the
    points) no longer leaks onto the user's screen."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rt.set_lights([(1e300, 0.3, 0.0)])
    assert np.isfinite(rt.light_positions).all()
