"""The interactive viewer: its controls without a window, a clear error without a display, and a real window
under a virtual X server (Xvfb) when one is installed."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from lodprt.runtime import Camera
from lodprt.viewer import ViewerState


def state():
    cam = Camera(eye=(0.0, 0.5, 2.0), target=(0.0, 0.5, 0.0), width=200, height=100)
    return ViewerState(camera=cam, lights=np.array([[0.0, 2.0, 0.0]]), colors=None, error_bound=0.25, alpha=0.6)


def test_orbit_pan_zoom_keep_the_camera_sane():
    """Orbit keeps the distance to the target, pan moves eye and target together, zoom scales the distance."""
    s = state()
    s.orbit(0.7, 0.3)
    assert np.isclose(np.linalg.norm(np.subtract(s.camera.eye, s.camera.target)), 2.0)
    assert s.camera.eye[0] != 0.0 and s.camera.eye[1] > 0.5 and s.dirty
    before = np.subtract(s.camera.eye, s.camera.target)
    s.pan(0.1, 0.0)
    np.testing.assert_allclose(np.subtract(s.camera.eye, s.camera.target), before, atol=1e-12)
    assert s.camera.target != (0.0, 0.5, 0.0)
    s.zoom(0.5)
    assert np.isclose(np.linalg.norm(np.subtract(s.camera.eye, s.camera.target)), 1.0)
    for _ in range(40):  # never over the pole (the up vector would become parallel to the view)
        s.orbit(0.0, 0.5)
    f = np.subtract(s.camera.target, s.camera.eye)
    assert abs(f[1]) / np.linalg.norm(f) < 0.999


def test_lights_are_added_moved_and_removed():
    """Adding selects the new light, moving changes only the selected one, the last light cannot be removed."""
    s = state()
    s.add_light()
    assert len(s.lights) == 2 and s.selected == 1
    first = s.lights[0].copy()
    s.move_light(0.1, 0.0)
    assert np.array_equal(s.lights[0], first) and not np.allclose(s.lights[1], first)
    s.remove_light()
    s.remove_light()
    assert len(s.lights) == 1 and s.selected == 0


@pytest.fixture(scope="module")
def cut_store(bunny_floor, bunny_hierarchy, tmp_path_factory):
    """The bunny on a 40 x 40 floor, light cut at 5 degrees, with the hierarchy."""
    from lodprt.bake import bake

    path = tmp_path_factory.mktemp("viewer") / "cut.zarr"
    bake(bunny_floor, path, sh_order=4, device="cpu", tree=bunny_hierarchy, threshold_deg=5.0)
    return path


def test_no_display_is_a_one_line_error(cut_store, monkeypatch, capsys):
    """Without DISPLAY `lodprt view` says what is missing in one line and exits with code 2."""
    from lodprt.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(cut_store), "--frames", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no display" in err and "xvfb-run" in err


@pytest.fixture
def xvfb():
    """A virtual X server on a free display number (skips, saying why, when Xvfb is not installed)."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (Debian: apt-get install xvfb); the viewer needs an X display")
    read, write = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                            pass_fds=(write,), stderr=subprocess.DEVNULL)
    os.close(write)
    with os.fdopen(read) as f:
        number = f.readline().strip()
    if not number:
        proc.kill()
        pytest.skip("Xvfb did not start")
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=10)


def test_viewer_starts_draws_and_closes_under_xvfb(cut_store, xvfb, tmp_path):
    """`lodprt view` opens a window under Xvfb, draws the lit scene with the overlay, and closes after 3 frames."""
    from PIL import Image

    shot = tmp_path / "shot.png"
    env = dict(os.environ, DISPLAY=xvfb)
    res = subprocess.run([sys.executable, "-m", "lodprt.cli", "view", str(cut_store), "--light", "0.05", "0.3", "0.1",
                          "--size", "240", "180", "--frames", "3", "--screenshot", str(shot)],
                         env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "closed after 3 frames" in res.stdout
    img = np.asarray(Image.open(shot))
    assert img.shape == (180, 240, 3)
    assert (img[100:, :].max(2) > 60).mean() > 0.2  # the lit floor and bunny fill the lower part
    corner = img[:30, :120]
    assert (corner > 240).all(2).any() and (corner < 60).all(2).mean() > 0.5  # white text on its dark box
