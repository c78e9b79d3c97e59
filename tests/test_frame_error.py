"""The frame's error estimate and the target it steers toward (E-1..E-4, ``lodprt.runtime.frame_error``): the
estimate is never above the PSNR the renderer measures against the full mesh, and a target_psnr is met by the
measured frame; the covered-pixel count equals the renderer's coverage on a plane seen straight on."""

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


@pytest.mark.parametrize("close", [False, True])
def test_estimate_is_not_optimistic(bunny_store, close):
    """At the default fixed bound, from a far and a close view, light between samples: E-3 <= measured PSNR."""
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
    assert rt.estimated_psnr <= measured(rt, frame) + 0.5


def test_target_psnr_is_met(bunny_store):
    """With target_psnr 38 the steered cut's estimate reaches the target and the measured frame exceeds it; a
    lower target keeps fewer triangles."""
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
        assert measured(rt, frame) >= target
        assert frame.stats["estimated_psnr_db"] == rt.estimated_psnr
        tris[target] = len(frame.triangles)
    assert tris[30.0] < tris[38.0]


def test_covered_pixels_of_a_square_seen_straight_on():
    """E-2: a unit square filling a known part of the screen covers exactly that many pixels; seen from behind,
    none."""
    from lodprt.runtime.camera import Camera, view_projection
    from lodprt.runtime.frame_error import covered_pixels

    pos = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    cam = Camera(eye=(0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0), fov=60.0, width=200, height=100)
    vp = view_projection(cam, np.array([[-1.0, -1, -1], [1, 1, 1]]))
    half = np.tan(np.radians(30.0)) * 2.0  # half the screen's height at the square's depth, scene units
    want = (0.5 / half * 50) * 2 * (0.5 / half * 50) * 2  # side in pixels, squared
    np.testing.assert_allclose(covered_pixels(pos, tri, vp, cam.eye, 200, 100), want, rtol=1e-6)
    assert covered_pixels(pos, tri[:, ::-1], vp, cam.eye, 200, 100) == 0.0


def test_bad_target_is_a_clear_error(bunny_store):
    from lodprt.runtime.session import Runtime

    with pytest.raises(LodprtError, match="target_psnr -3"):
        Runtime(bunny_store, device="cpu", target_psnr=-3)
    with pytest.raises(LodprtError, match="not with criterion 'thesis'"):
        Runtime(bunny_store, device="cpu", target_psnr=38, criterion="thesis")
