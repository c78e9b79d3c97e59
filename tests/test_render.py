"""Offscreen moderngl rendering (EGL): camera convention, colours, depth, tone mapping."""

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.render import render, tone_map

moderngl = pytest.importorskip("moderngl")


def quad(centre, size, y_offset=0.0):
    c = np.asarray(centre, float)
    h = size / 2
    pos = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]]) + c + [0, y_offset, 0]
    return pos, np.array([[0, 1, 2], [0, 2, 3]])


def try_render(*args, **kw):
    try:
        return render(*args, **kw)
    except LodprtError as exc:  # pragma: no cover - machines without EGL
        pytest.skip(str(exc))


def test_camera_convention_y_up_and_centre():
    """A red quad above the target shows in the upper half, a green one below in the lower half; right is +x."""
    red, f = quad([0, 0.5, 0], 0.4)
    green, _ = quad([0.5, -0.5, 0], 0.4)
    pos = np.vstack([red, green])
    tri = np.vstack([f, f + 4])
    col = np.vstack([np.tile([1, 0, 0], (4, 1)), np.tile([0, 1, 0], (4, 1))])
    img = try_render(pos, tri, col, eye=(0, 0, 3), target=(0, 0, 0), fov=60, size=(120, 100))
    assert img.shape == (100, 120, 3) and img.dtype == np.uint8
    ys, xs = np.nonzero(img[:, :, 0] > 200)
    assert ys.mean() < 50 and abs(xs.mean() - 60) < 3
    ys, xs = np.nonzero(img[:, :, 1] > 200)
    assert ys.mean() > 50 and xs.mean() > 60


def test_depth_test_keeps_the_nearer_surface():
    """Of two overlapping quads the one nearer the eye is visible, whatever the draw order."""
    far, f = quad([0, 0, -1], 1.0)
    near, _ = quad([0, 0, 0], 0.5)
    pos = np.vstack([near, far])
    tri = np.vstack([f, f + 4])
    col = np.vstack([np.tile([0, 0, 1], (4, 1)), np.tile([1, 1, 1], (4, 1))])
    img = try_render(pos, tri, col, eye=(0, 0, 3), target=(0, 0, 0), fov=50, size=(64, 64))
    assert tuple(img[32, 32]) == (0, 0, 255)


def test_bad_camera_is_a_clear_error():
    """Eye on the target, or up along the view direction, is refused with a message."""
    pos, f = quad([0, 0, 0], 1)
    with pytest.raises(LodprtError, match="coincide"):
        render(pos, f, np.ones((4, 3)), eye=(0, 0, 0), target=(0, 0, 0))
    with pytest.raises(LodprtError, match="parallel"):
        render(pos, f, np.ones((4, 3)), eye=(0, 3, 0), target=(0, 0, 0), up=(0, 1, 0))


def test_tone_map_srgb():
    """Tone mapping clips at white and applies the sRGB transfer curve (0.5 linear -> 0.7354)."""
    out = tone_map(np.array([[0.0, 0.5, 2.0]]), white=1.0)
    np.testing.assert_allclose(out, [[0.0, 0.735356983, 1.0]], atol=1e-6)
