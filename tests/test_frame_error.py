"""The frame's error estimate and the target it steers toward (E-1..E-4, ``lodprt.runtime.frame_error``): the
estimate tracks the PSNR the renderer measures against the full mesh (on every pixel, it is that error), and a
target_psnr is met by the measured frame to within the estimate's error."""

import numpy as np
import pytest

from lodprt.errors import LodprtError

pytestmark = pytest.mark.usefixtures("gl")


@pytest.fixture(scope="module")
def bunny_store(bunny_bake):
    from lodprt.store.bake_store import open_store

    return open_store(bunny_bake)


def covered(rt, frame) -> int:
    """The pixels ``frame`` (or the full mesh's frame) covers non-black, as the renderer draws them."""
    from lodprt.display.render import Renderer

    with Renderer() as r:
        return int((r.image(frame, linear=True).max(-1) > 0).sum())


def measured(rt, frame):
    """PSNR of ``frame`` against the full mesh under the same camera and lights, drawn by the renderer."""
    from lodprt.display.compare import frame_error
    from lodprt.display.render import Renderer

    rt.set_lod(False)
    full = rt.update()
    rt.set_lod(True)
    with Renderer() as r:
        return frame_error(r, frame, full, rt.white)[0]["psnr_db"]


@pytest.mark.warp_debug
@pytest.mark.parametrize("close", [False, True])
def test_estimate_tracks_the_measured_error(bunny_store, close):
    """Under the default target, from a far and a close view, light between samples: E-3 is within 1 dB of the
    PSNR the renderer measures (E-1 samples the frame's own error; the rest is where a ray and the rasteriser
    disagree on a pixel or two at an edge)."""
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime

    c, e = np.array(scene_centre(bunny_store)), np.array(default_eye(bunny_store))
    eye = c + (e - c) * (0.35 if close else 1.0)
    rt = Runtime(bunny_store, device="cpu")
    rt.set_lights(bunny_store.light_positions[[0, 1, 3, 4]].mean(0)[None])
    rt.set_camera(Camera(eye=tuple(eye), target=tuple(c), width=320, height=240))
    frame = rt.update(max_passes=10_000)
    rt.estimate_frame_error(frame.vertex_ids, frame.triangles)
    assert np.isfinite(rt.estimated_psnr)
    assert abs(rt.estimated_psnr - measured(rt, frame)) <= 1.0


def test_target_psnr_is_met(bunny_store):
    """With target_psnr 30 and 38 the first frame's steered cut (searched on every pixel, E-2) reaches the target
    by its estimate and the measured frame is within 0.5 dB of it or above (a ray and the rasteriser disagree on a
    pixel or two at an edge); a lower target keeps fewer triangles."""
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime

    cam = Camera(eye=default_eye(bunny_store), target=scene_centre(bunny_store), width=320, height=240)
    tris = {}
    for target in (30.0, 38.0):
        rt = Runtime(bunny_store, device="cpu", target_psnr=target)
        rt.set_lights(bunny_store.light_positions[4:5])
        rt.set_camera(cam)
        frame = rt.update()
        assert rt.estimated_psnr >= target, (target, rt.estimated_psnr)
        # the measured MSE within two pixels of a full-white difference of the target's (where a ray through a
        # pixel's centre and the rasteriser disagree at a silhouette)
        assert 10 ** (-measured(rt, frame) / 10) <= 10 ** (-target / 10) + 2 / covered(rt, frame)
        assert frame.stats["estimated_psnr_db"] == rt.estimated_psnr and frame.stats["estimate_stride_px"] == 1
        tris[target] = len(frame.triangles)
    assert tris[30.0] < tris[38.0]


@pytest.mark.parametrize("bound", [0.8, 3.0])
def test_sampled_error_on_every_pixel_is_the_measured_error(bunny_store, bound, monkeypatch):
    """E-1 with one ray per pixel (``COVERAGE_RAYS`` raised) is the renderer's measured error of the frame against
    the full mesh, within 0.3 dB, light between samples, at two fixed bounds; on the default grid (a ray per
    cell) within 1 dB."""
    from lodprt.runtime import frame_error
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime

    rt = Runtime(bunny_store, device="cpu", error_bound=bound)
    rt.set_lights(bunny_store.light_positions[[0, 1, 3, 4]].mean(0)[None])
    rt.set_camera(Camera(eye=default_eye(bunny_store), target=scene_centre(bunny_store), width=200, height=150))
    frame = rt.update(max_passes=10_000)
    want = measured(rt, frame)
    assert 20.0 < want < 60.0  # an error to measure
    est, _, _ = frame_error.estimate(rt, frame.vertex_ids, frame.triangles)
    assert abs(est - want) < 1.0, (est, want)
    monkeypatch.setattr(frame_error, "COVERAGE_RAYS", 10**9)
    assert frame_error.coverage_stride(200, 150) == 1
    ref = frame_error.reference(rt, frame_error.coverage_stride(200, 150))
    assert ref.cell == 1.0 and ref is frame_error.reference(rt, 1)  # made once for this camera and lights
    s = frame_error.sampled_error(rt, frame.vertex_ids, frame.triangles, ref)
    assert s == frame_error.sampled_error(rt, frame.vertex_ids, frame.triangles, ref, frame.coefficients)
    assert s.covered > 0.2 * 200 * 150 and s.mean > 0
    assert abs(-10 * np.log10(s.mean) - want) < 0.3, (-10 * np.log10(s.mean), want)


def test_ray_stride_bounds_the_rays():
    """E-2's cells: every pixel when asked (1) up to MAX_RAYS rays, the grid by default, and never more than
    MAX_RAYS rays however large the frame (a frame too large for every pixel takes a ray every few pixels)."""
    import math

    from lodprt.runtime.frame_error import MAX_RAYS, coverage_stride, ray_stride

    assert ray_stride(640, 480, 1) == 1 and ray_stride(4096, 4096, 1) == 1
    assert ray_stride(640, 480) == coverage_stride(640, 480) == 3
    for w, h in ((4097, 4096), (100_000, 100_000), (1, 10**9)):
        k = ray_stride(w, h, 1)
        assert math.ceil(w / k) * math.ceil(h / k) <= 1.01 * MAX_RAYS + w + h and k > 1


def test_estimate_schedule():
    """The estimates' schedule: the first frame estimates; a still frame after it does not (the first frame's
    pins hold); frames in motion estimate every ESTIMATE_FRAMES frames (on the grid), a bracket kept but for a
    jump; the first still frame after a move estimates once more (E-5 on every pixel), then none."""
    from lodprt.runtime.frame_error import ESTIMATE_FRAMES, EstimateSchedule, Steering

    s, st = EstimateSchedule(), Steering(36.0)
    assert s.begin(1, True, False, st) == (True, False)
    s.confirmed = True  # the first frame's pin rounds ran
    assert s.begin(2, False, False, st) == (False, True)
    st.meets = 1.0
    moving = []
    for frame in range(3, 3 + 2 * ESTIMATE_FRAMES):
        s.moved = True
        due, still = s.begin(frame, False, False, st)
        assert not still and not s.confirmed
        moving.append(due)
    assert sum(moving) == 2 and st.meets == 1.0  # a bracket kept in motion (no jump)
    assert s.begin(20, False, False, st) == (True, True)  # stopped: E-5 once
    s.confirmed = True
    assert s.begin(21, False, False, st) == (False, True)
    s.moved = True
    s.begin(22, False, True, st)  # a jump forgets the bracket
    assert st.meets is None


def test_still_frames_refine_where_the_error_is(bunny_store, monkeypatch):
    """``Runtime.update``: the first frame searches E-4's bound on E-2's grid (for the frames in motion), then
    measures its error on every pixel and pins nodes from the coarsest bound until it meets the target (E-5); a
    still camera estimates no more; a moving one returns to E-4's bound, drops the pins and estimates on the grid
    every few frames; when it stops, E-5 on every pixel again."""
    from lodprt.runtime import frame_error
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime

    calls = []
    real_estimate, real_pin = frame_error.estimate, frame_error.pin
    monkeypatch.setattr(frame_error, "estimate", lambda *a, **k: calls.append(k["stride"]) or real_estimate(*a, **k))
    monkeypatch.setattr(frame_error, "pin", lambda *a, **k: calls.append("pin") or real_pin(*a, **k))
    rt = Runtime(bunny_store, device="cpu")
    rt.set_lights(bunny_store.light_positions[4:5])
    c, e = np.array(scene_centre(bunny_store)), np.array(default_eye(bunny_store))
    cam = lambda k: Camera(eye=tuple(c + (e - c) * (1 - 0.01 * k)), target=tuple(c), width=640, height=480)  # noqa
    grid = frame_error.coverage_stride(640, 480)
    assert grid > 1
    rt.set_camera(cam(0))
    first = rt.update()
    assert calls[0] == grid and "pin" in calls and set(calls) <= {"pin", 1, grid}
    motion = rt.motion_bound  # E-4's bound, searched first, kept aside while the frame is pinned
    assert motion is not None and rt.steering.meets is not None
    assert first.stats["pinned_nodes"] > 0 and first.stats["estimate_stride_px"] == 1
    assert rt.estimated_psnr >= rt.target_psnr and rt.error_bound == frame_error.BOUND_RANGE[1]
    calls.clear()
    for _ in range(3):  # still: no estimate, the same cut
        frame = rt.update()
    assert calls == [] and len(frame.triangles) == len(first.triangles)
    for k in range(1, 1 + 2 * frame_error.ESTIMATE_FRAMES):
        rt.set_camera(cam(k))
        frame = rt.update()
    assert calls and set(calls) == {grid} and frame.stats["pinned_nodes"] == 0
    assert rt.motion_bound is None and rt.error_bound < frame_error.BOUND_RANGE[1]
    calls.clear()
    assert rt.update().stats["pinned_nodes"] > 0  # stopped
    assert calls[0] == "pin" and set(calls) <= {"pin", 1}


def test_a_pinned_node_stays_split_even_culled(bunny_store):
    """E-5: a pinned node splits even when T-13 culls it (its pixels were seen) and is not collapsed again for
    being culled: the cut settles in a few passes instead of flipping it back and forth."""
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime

    rt = Runtime(bunny_store, device="cpu", error_bound=0.8)  # a fixed bound: no pins of its own
    rt.set_lights(bunny_store.light_positions[4:5])
    rt.set_camera(Camera(eye=default_eye(bunny_store), target=scene_centre(bunny_store), width=320, height=240))
    rt.update()
    act = np.flatnonzero(rt.cut.active)
    internal = act[act >= rt.h.num_vertices]
    culled = internal[rt.node_errors(internal).culled]
    assert len(culled)
    rt.refinement.pin(culled[:5])
    frame = rt.update(max_passes=10_000)
    assert not rt.cut.active[culled[:5]].any() and frame.stats["passes"] < 50
    again = rt.update(max_passes=10_000)
    assert again.stats["passes"] < 50 and not rt.cut.active[culled[:5]].any()


def test_pins_cover_the_excess():
    """E-5's choice on a hand-made frame: each ray's error goes to the mesh it meets first (the cut's or the full
    one), shared by the coarse active nodes at the corners of the face it met there, and the nodes with the largest
    shares are taken until they cover the excess over the budget; none when the frame meets it; a node pinned
    already is not taken again."""
    from types import SimpleNamespace

    from lodprt.runtime.frame_error import Reference, pinned_nodes

    V = 6  # leaves 0..5 (0..4 at depth 1, 5 at depth 3 from the eye); nodes 6, 7, 8 coarse
    anc = np.array([6, 6, 7, 7, 8, 5])
    positions = np.zeros((V, 3))
    positions[:, 2] = [1, 1, 1, 1, 1, 3]
    rt = SimpleNamespace(h=SimpleNamespace(num_nodes=9, num_vertices=V), cut=SimpleNamespace(anc=anc),
                         faces=np.array([[0, 2, 4], [1, 3, 5], [5, 5, 5]]), positions=positions,
                         camera=SimpleNamespace(eye=(0.0, 0.0, 0.0)),
                         refinement=SimpleNamespace(pinned=np.zeros(9, bool)))
    vid = np.arange(V)
    triangles = np.array([[0, 2, 5], [4, 5, 5]])  # the cut's faces
    third = np.full((4, 3), 1 / 3)
    ref = Reference(1, np.array([0, 2, -1, 1]), third, np.zeros((4, 3)), 1.0)
    cut_hits = (np.array([0, 1, 1, -1]), third)
    d2 = np.array([0.4, 0.2, 0.1, 0.3])
    # ray 0: full face 0 (depth 1) before cut face 0 (5/3): {6, 7, 8} 0.4/3 each; ray 1: cut face 1 (7/3) before
    # full face 2 (3): {8} 0.2; ray 2: the cut only: {8} 0.1; ray 3: the full mesh only, face 1: {6, 7} 0.15 each
    err = {6: 0.4 / 3 + 0.15, 7: 0.4 / 3 + 0.15, 8: 0.4 / 3 + 0.2 + 0.1}
    assert abs(sum(err.values()) - d2.sum()) < 1e-12
    total = d2.sum()
    assert len(pinned_nodes(rt, vid, triangles, ref, d2, cut_hits, total)) == 0
    assert list(pinned_nodes(rt, vid, triangles, ref, d2, cut_hits, total - 0.2)) == [8]
    assert list(pinned_nodes(rt, vid, triangles, ref, d2, cut_hits, total - err[8] - 0.01)) == [8, 6]  # 6, 7 tie
    rt.refinement.pinned[8] = True  # pinned already (and still active: it could not split): the next one
    assert list(pinned_nodes(rt, vid, triangles, ref, d2, cut_hits, total - 0.2)) == [6]


def test_bad_target_is_a_clear_error(bunny_store):
    from lodprt.runtime.session import Runtime

    with pytest.raises(LodprtError, match="target_psnr -3"):
        Runtime(bunny_store, device="cpu", target_psnr=-3)
    with pytest.raises(LodprtError, match="not with criterion 'thesis'"):
        Runtime(bunny_store, device="cpu", target_psnr=38, criterion="thesis")


def closed_form_psnr(bound):
    """A frame whose PSNR falls as 20 log10 of the bound (E-1 grows as the bound squared): 40 dB at bound 0.5."""
    return 40.0 - 20.0 * np.log10(bound / 0.5)


@pytest.mark.parametrize("start", [1e-3, 0.05, 0.8, 6.0])
@pytest.mark.parametrize("target", [30.0, 38.0, 45.0])
def test_steering_settles_on_the_largest_bound_that_meets_the_target(start, target):
    """E-4's search on a closed-form frame: from any start it ends on a bound whose PSNR meets the target, within
    one step of the exact answer 0.5 * 10^((40 - target) / 20), and stays there."""
    from lodprt.runtime.frame_error import BOUND_RANGE, REPROBE, Steering

    exact = 0.5 * 10 ** ((40.0 - target) / 20.0)
    s, b = Steering(target, step=0.1), start
    for rounds in range(40):
        est = closed_form_psnr(b)
        b = s.next_bound(b, est, np.array([b]), np.array([10 ** (-est / 10)]), 1.0)  # E-1 = 10^(-E-3 / 10) N
        assert BOUND_RANGE[0] <= b <= BOUND_RANGE[1]
        if s.settled():
            break
    assert s.settled() and rounds < 25
    assert closed_form_psnr(b) >= target
    assert exact / 1.1 <= b <= exact * (1 + 1e-9)
    for _ in range(REPROBE - 1):  # settled: it keeps the bound for REPROBE rounds, then probes upward once
        assert s.next_bound(b, closed_form_psnr(b), np.array([b]), np.array([10 ** (-closed_form_psnr(b) / 10)]),
                            1.0) == b


def test_steering_follows_a_frame_that_changes():
    """A bracket the frame no longer obeys gives way: after the scene gets 6 dB worse at every bound, the search
    settles again on a bound that meets the target."""
    from lodprt.runtime.frame_error import Steering

    s, b = Steering(38.0), 0.8
    for shift in (0.0, -6.0):
        for _ in range(40):
            est = closed_form_psnr(b) + shift
            b = s.next_bound(b, est, np.array([b]), np.array([10 ** (-est / 10)]), 1.0)
            if s.settled() and closed_form_psnr(b) + shift >= 38.0:
                break
        assert s.settled() and closed_form_psnr(b) + shift >= 38.0
