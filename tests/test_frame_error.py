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
        assert rt.estimated_psnr >= target - 0.5, (target, rt.estimated_psnr)
        assert measured(rt, frame) >= target - 0.5
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
    est, _ = frame_error.estimate(rt, frame.vertex_ids, frame.triangles)
    assert abs(est - want) < 1.0, (est, want)
    monkeypatch.setattr(frame_error, "COVERAGE_RAYS", 10**9)
    assert frame_error.coverage_stride(200, 150) == 1
    ref = frame_error.reference(rt, frame_error.coverage_stride(200, 150))
    assert ref.cell == 1.0 and ref is frame_error.reference(rt, 1)  # made once for this camera and lights
    s = frame_error.sampled_error(rt, frame.vertex_ids, frame.triangles, ref)
    assert s == frame_error.sampled_error(rt, frame.vertex_ids, frame.triangles, ref, frame.coefficients)
    assert s.covered > 0.2 * 200 * 150 and s.mean > 0
    assert abs(-10 * np.log10(s.mean) - want) < 0.3, (-10 * np.log10(s.mean), want)


def test_estimate_schedule():
    """E-4's schedule: the first frame estimates; a still frame after it estimates on every pixel until an estimate
    confirms the settled bound, then no more, and keeps the bracket the first frame confirmed; frames in motion
    estimate every ESTIMATE_FRAMES frames (on the grid); the first still frame after a move forgets the bracket."""
    from lodprt.runtime.frame_error import ESTIMATE_FRAMES, EstimateSchedule, Steering

    s, st = EstimateSchedule(), Steering(36.0)
    assert s.begin(1, True, False, st) == (True, False)
    st.meets, s.confirmed = 1.0, True  # the first frame's search settled and confirmed its bound
    assert s.begin(2, False, False, st) == (False, True) and st.meets == 1.0
    moving = []
    for frame in range(3, 3 + 2 * ESTIMATE_FRAMES):
        s.moved = True
        due, still = s.begin(frame, False, False, st)
        assert not still and not s.confirmed
        moving.append(due)
    assert sum(moving) == 2 and st.meets == 1.0  # a bracket kept in motion (no jump)
    assert s.begin(20, False, False, st) == (True, True) and st.meets is None  # still again: searched afresh
    assert s.begin(21, False, False, st) == (True, True)
    s.confirmed = True
    assert s.begin(22, False, False, st) == (False, True)
    s.begin(23, False, True, st)  # a jump forgets the bracket
    assert st.meets is None


def test_still_frames_steer_on_every_pixel(bunny_store, monkeypatch):
    """``Runtime.update``: the first frame's estimates are on every pixel; a still camera estimates no more once
    the search has settled; a moving camera estimates on E-2's grid every few frames; when it stops, on every
    pixel again."""
    from lodprt.runtime import frame_error
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.session import Runtime

    strides = []
    real = frame_error.estimate
    monkeypatch.setattr(frame_error, "estimate", lambda *a, **k: strides.append(k["stride"]) or real(*a, **k))
    rt = Runtime(bunny_store, device="cpu")
    rt.set_lights(bunny_store.light_positions[4:5])
    c, e = np.array(scene_centre(bunny_store)), np.array(default_eye(bunny_store))
    cam = lambda k: Camera(eye=tuple(c + (e - c) * (1 - 0.01 * k)), target=tuple(c), width=640, height=480)  # noqa
    rt.set_camera(cam(0))
    rt.update()
    assert strides and set(strides) == {1}
    for _ in range(6):  # still: steered on every pixel until settled, then no estimate
        strides.clear()
        rt.update()
    assert strides == [] and rt.steering.settled()
    grid = frame_error.coverage_stride(640, 480)
    assert grid > 1
    for k in range(1, 1 + 2 * frame_error.ESTIMATE_FRAMES):
        rt.set_camera(cam(k))
        rt.update()
    assert strides and set(strides) == {grid}
    strides.clear()
    rt.update()  # stopped
    assert strides == [1]


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
