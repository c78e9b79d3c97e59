"""The interactive viewer: its controls without a window, a clear error without a display, the real viewer loop
on a headless EGL context (its picture against `lodprt render`'s, its keys, its overlay), and a real window under a
virtual X server (Xvfb) when one is installed."""

import dataclasses
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lodprt.runtime.camera import Camera
from lodprt.display.overlay import SLIDER_ROW, Slider, slider_layout
from lodprt.display.viewer import Viewer, ViewerState


def state():
    cam = Camera(eye=(0.0, 0.5, 2.0), target=(0.0, 0.5, 0.0), width=200, height=100)
    return ViewerState(camera=cam, lights=np.array([[0.0, 2.0, 0.0]]), colors=None, error_bound=0.25, alpha=0.6,
                       criterion="thesis")


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


def slider(s, name):
    return next(sl for sl in s.sliders() if sl.name == name)


def at(sl, t):
    """The point a fraction t along the slider's track, halfway down it."""
    x, y, w, h = sl.rect
    return x + t * w, y + h / 2


def test_slider_maps_x_to_its_range_and_clamps_outside_the_track():
    """value_at gives lo and hi at the track's ends, is linear between, and clamps beyond them; contains is the rect."""
    sl = Slider("alpha", "alpha", (10.0, 20.0, 100.0, 12.0))
    assert sl.value_at(10.0) == 0.0 and sl.value_at(110.0) == 1.0 and sl.value_at(35.0) == 0.25
    assert sl.value_at(-50.0) == 0.0 and sl.value_at(500.0) == 1.0
    assert Slider("e", "e", (0.0, 0.0, 10.0, 1.0), lo=2.0, hi=4.0).value_at(5.0) == 3.0
    assert sl.contains(10.0, 20.0) and sl.contains(110.0, 32.0) and sl.contains(60.0, 26.0)
    assert not sl.contains(9.0, 26.0) and not sl.contains(111.0, 26.0) and not sl.contains(60.0, 33.0)
    assert sl.fraction(-1.0) == 0.0 and sl.fraction(0.4) == 0.4 and sl.fraction(1.25) == 1.0


def test_sliders_sit_in_the_bottom_left_corner_inside_the_window():
    """Both sliders (error bound above alpha) lie inside the window's lower-left part and do not overlap."""
    for width, height in [(200, 100), (240, 180), (1280, 720)]:
        eb, al = slider_layout(width, height)
        assert (eb.name, al.name) == ("error_bound", "alpha") and (eb.lo, eb.hi, al.lo, al.hi) == (0, 1, 0, 1)
        for sl in (eb, al):
            x, y, w, h = sl.rect
            assert x >= 0 and x + w <= width / 2 + 100 and y >= height / 2 and y + h <= height and w >= 40
        assert eb.rect[1] + eb.rect[3] <= al.rect[1]


def test_screen_criterion_shows_no_alpha():
    """Under the screen criterion (which reads no alpha) there is one slider, the alpha keys change nothing, and the
    overlay names the criterion without an alpha; under "thesis" it shows alpha."""
    s = state()
    assert "alpha 0.60" in s.knobs() and s.knobs().startswith("thesis criterion")
    s = dataclasses.replace(state(), criterion="screen", error_bound=0.8)
    assert [sl.name for sl in s.sliders()] == ["error_bound"]
    s.dirty = False
    s.step_alpha(True)
    assert s.alpha == 0.6 and not s.dirty
    assert s.knobs() == "screen criterion, error bound 0.8"


def test_press_on_a_slider_sets_its_value_and_drags_it_without_orbiting():
    """A left press on the error-bound / alpha track sets that value from x, drags follow x (clamped); no orbit."""
    s = state()
    cam = s.camera
    s.dirty = False
    assert s.press(*at(slider(s, "error_bound"), 0.75)) is True
    assert np.isclose(s.error_bound, 0.75) and s.alpha == 0.6 and s.dirty
    x, y = at(slider(s, "error_bound"), 0.5)
    s.drag(x, y - 40, 5.0, -40.0)  # the drag may leave the track vertically: the grabbed slider keeps following x
    assert np.isclose(s.error_bound, 0.5)
    s.drag(*at(slider(s, "error_bound"), 3.0), 200.0, 0.0)
    assert s.error_bound == 1.0 and s.camera == cam
    s.release()
    assert s.press(*at(slider(s, "alpha"), 0.2)) is True
    assert np.isclose(s.alpha, 0.2) and s.error_bound == 1.0
    s.drag(*at(slider(s, "alpha"), -1.0), -100.0, 0.0)
    assert s.alpha == 0.0 and s.camera == cam
    s.release()
    s.drag(50.0, 50.0, 10.0, 0.0)  # after the release a drag orbits again
    assert s.camera.eye != cam.eye and s.alpha == 0.0


def test_press_outside_the_sliders_orbits_as_before():
    """A left press off the sliders (or a right press on one) leaves the values alone: the drag orbits (pans)."""
    s = state()
    assert s.press(100.0, 30.0) is False
    s.drag(110.0, 30.0, 10.0, 0.0)
    ref = state()
    ref.orbit(10.0 * 3 / 100, 0.0)  # the old rule: 3 radians per window height
    np.testing.assert_allclose(s.camera.eye, ref.camera.eye)
    assert (s.error_bound, s.alpha) == (0.25, 0.6)
    s = state()
    assert s.press(*at(slider(s, "alpha"), 0.9), left=False) is False
    s.drag(*at(slider(s, "alpha"), 0.95), 5.0, 0.0, left=False)
    assert s.alpha == 0.6 and s.camera.target != state().camera.target


class _Names:
    """Stands in for moderngl-window's keys / buttons: every attribute is its own name."""

    def __getattr__(self, name):
        return name


def fake_viewer(s):
    """A Viewer's event handlers on a window stand-in (framebuffer twice the window size, as on a HiDPI screen)."""
    window = SimpleNamespace(keys=_Names(), mouse=_Names(), size=(s.camera.width // 2, s.camera.height // 2),
                             buffer_size=(s.camera.width, s.camera.height), modifiers=SimpleNamespace(shift=False),
                             mouse_states=SimpleNamespace(left=True))
    v = SimpleNamespace(state=s, window=window, source=None, player=None)
    for name in ("_key", "_press", "_drag", "_pixels", "_pause"):
        setattr(v, name, getattr(Viewer, name).__get__(v))
    return v


def test_keys_and_sliders_change_the_same_values():
    """The window's [ ] , . keys and its mouse presses on the sliders change one error bound and alpha, each from where
    the other left it; the sliders' fill follows the keys (full past 1), and ] gets the error bound off 0."""
    s = state()
    v = fake_viewer(s)
    x, y = at(slider(s, "error_bound"), 0.5)
    v._press(x / 2, y / 2, "left")  # window coordinates: half the framebuffer's
    assert np.isclose(s.error_bound, 0.5)
    v._key("RIGHT_BRACKET", "ACTION_PRESS", None)
    assert np.isclose(s.error_bound, 0.625) and np.isclose(slider(s, "error_bound").fraction(s.error_bound), 0.625)
    x, y = at(slider(s, "alpha"), 0.3)
    v._press(x / 2, y / 2, "left")
    v._key("PERIOD", "ACTION_PRESS", None)
    assert np.isclose(s.alpha, 0.35) and np.isclose(s.error_bound, 0.625)
    v._key("COMMA", "ACTION_PRESS", None)
    v._key("COMMA", "ACTION_PRESS", None)
    assert np.isclose(s.alpha, 0.25)
    v._drag(*(c / 2 for c in at(slider(s, "alpha"), 1.0)), 10.0, 0.0)
    assert s.alpha == 1.0
    v._key("PERIOD", "ACTION_PRESS", None)
    assert s.alpha == 1.0
    for _ in range(3):
        v._key("RIGHT_BRACKET", "ACTION_PRESS", None)
    assert np.isclose(s.error_bound, 0.625 * 1.25 ** 3) and slider(s, "error_bound").fraction(s.error_bound) == 1.0
    x, y = at(slider(s, "error_bound"), 0.0)
    v._press(x / 2, y / 2, "left")
    assert s.error_bound == 0.0
    v._key("LEFT_BRACKET", "ACTION_PRESS", None)
    assert s.error_bound == 0.0
    v._key("RIGHT_BRACKET", "ACTION_PRESS", None)
    assert s.error_bound == 0.01


def test_window_drags_off_the_sliders_orbit_pan_and_move_lights():
    """Through the window's handlers a left drag off the sliders orbits, shift + drag moves the light, right pans."""
    s = state()
    v = fake_viewer(s)
    v._press(50.0, 10.0, "left")
    v._drag(55.0, 10.0, 5.0, 0.0)  # 5 window pixels = 10 framebuffer pixels
    ref = state()
    ref.orbit(10.0 * 3 / 100, 0.0)
    np.testing.assert_allclose(s.camera.eye, ref.camera.eye)
    light = s.lights[0].copy()
    v.window.modifiers.shift = True
    v._drag(60.0, 10.0, 5.0, 0.0)
    assert not np.allclose(s.lights[0], light)
    v.window.modifiers.shift, v.window.mouse_states.left = False, False
    target = s.camera.target
    v._press(50.0, 10.0, "right")
    v._drag(55.0, 10.0, 5.0, 0.0)
    assert s.camera.target != target and (s.error_bound, s.alpha) == (0.25, 0.6)


@pytest.fixture(scope="module")
def cut_store(bunny_floor, bunny_hierarchy, tmp_path_factory):
    """The bunny on a 40 x 40 floor, light cut at 5 degrees, with the hierarchy."""
    from lodprt.precompute.bake import bake

    path = tmp_path_factory.mktemp("viewer") / "cut.zarr"
    bake(bunny_floor, path, sh_order=4, device="cpu", tree=bunny_hierarchy, threshold_deg=5.0)
    return path


def test_no_display_is_a_one_line_error(cut_store, monkeypatch, capsys):
    """Without DISPLAY `lodprt view` says what is missing in one line and exits with code 2."""
    from lodprt.cli.main import main

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
    res = subprocess.run([sys.executable, "-m", "lodprt.cli.main", "view", str(cut_store), "--light", "0.05", "0.3", "0.1",
                          "--size", "240", "180", "--frames", "3", "--screenshot", str(shot)],
                         env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "closed after 3 frames" in res.stdout
    img = np.asarray(Image.open(shot))
    assert img.shape == (180, 240, 3)
    assert (img[100:, :].max(2) > 60).mean() > 0.2  # the lit floor and bunny fill the lower part
    corner = img[:30, :120]
    assert (corner > 240).all(2).any() and (corner < 60).all(2).mean() > 0.5  # white text on its dark box
    # the default screen criterion steers its one knob, the error bound, toward the frame target (E-4): the bottom
    # row's slider shows the bound it settled on (0..1 track), which the closing line prints with the estimate
    said = re.search(r"closed after 3 frames \(screen criterion, error bound ([0-9.e+-]+), estimated ([0-9.]+) dB\)",
                     res.stdout)
    assert said, res.stdout
    bound = float(said.group(1))
    assert bound > 0.0 and float(said.group(2)) > 20.0
    (eb,) = slider_layout(240, 180, alpha=False)
    x, y, w, h = (int(c) for c in eb.rect)
    track = img[y + 4:y + h - 4, x + 2:x + w - 2].astype(int)
    filled = (track[..., 0] > 230) & (track[..., 1] > 180) & (track[..., 2] < 90)  # the slider's amber fill
    share = filled.mean(0).astype(bool).mean()
    assert abs(share - eb.fraction(min(bound, 1.0))) < 0.05, (share, bound)
    above = img[y - SLIDER_ROW + 4:y - 4, x + 2:x + w - 2].astype(int)  # no alpha slider above it
    assert not ((above[..., 0] > 230) & (above[..., 1] > 180) & (above[..., 2] < 90)).any()


def headless(store, **options):
    """The real ``Viewer`` on moderngl-window's headless window (an EGL context: no DISPLAY, no events)."""
    from lodprt.store.bake_store import open_store

    cam = Camera(eye=(0.35, 0.45, 0.9), target=(0.0, 0.05, 0.0), width=240, height=180)
    return Viewer(open_store(store), lights=[[0.05, 0.3, 0.1]], camera=cam, headless=True, **options)


def window_image(viewer) -> np.ndarray:
    w, h = viewer.window.buffer_size
    return np.frombuffer(viewer.window.fbo.read(components=3), np.uint8).reshape(h, w, 3)[::-1]


def test_headless_viewer_draws_the_frame_lodprt_render_draws(cut_store, tmp_path, monkeypatch):
    """The viewer's loop (its own run-time source, lights, camera, white and overlay) on an EGL context, without
    DISPLAY: outside the overlay's text and sliders its first frame is `lodprt render`'s picture of the same lights
    and camera (a second Runtime, the offscreen renderer), pixel for pixel; the overlay is drawn over it."""
    from PIL import Image

    from lodprt.display.pictures import render_to_file
    from lodprt.store.bake_store import open_store

    monkeypatch.delenv("DISPLAY", raising=False)
    v = headless(cut_store)
    try:
        v.window.use()
        v.step()
        img = window_image(v).astype(int)
        cam, lights = v.state.camera, v.state.lights
    finally:
        v.renderer.release()
        v.window.destroy()
    out = tmp_path / "render.png"
    render_to_file(open_store(cut_store), out, lights=lights, camera=cam)
    ref = np.asarray(Image.open(out)).astype(int)
    assert img.shape == ref.shape == (180, 240, 3)
    (eb,) = slider_layout(240, 180, alpha=False)
    scene = np.ones((180, 240), bool)
    scene[:80, :] = False  # the text box (five lines at most)
    scene[int(eb.rect[1]) - 4:, :] = False  # the slider row
    assert (ref[scene].max(1) > 60).mean() > 0.2  # the lit floor and bunny, not a blank picture
    assert np.abs(img - ref)[scene].max() <= 1  # the same frame (1: the two contexts' rounding, at most)
    box = img[:30, :120]
    assert (box > 240).all(-1).any() and not np.array_equal(box, ref[:30, :120])  # white text drawn over it


def test_headless_viewer_keys_reach_the_run_time(cut_store, monkeypatch):
    """The real viewer's key handler (the headless window has no key codes of its own: each key stands in as its
    name): ] raises the bound the run time gets (x 1.25), L switches the run time to the full mesh (every face
    drawn, the overlay says so), Q ends the loop."""
    from lodprt.store.bake_store import open_store

    monkeypatch.delenv("DISPLAY", raising=False)
    faces = len(open_store(cut_store).faces)
    v = headless(cut_store, error_bound=0.5)  # a bound alone: fixed, not steered
    keys = v.window.keys = _Names()
    try:
        v.window.use()
        v.step()
        lod_triangles = len(v.frame.triangles)
        assert 0 < lod_triangles < faces and v.source.error_bound == 0.5
        v._key(keys.RIGHT_BRACKET, keys.ACTION_PRESS, None)
        v.state.orbit(0.05, 0.0)  # a new frame
        v.step()
        assert v.source.error_bound == 0.625 and len(v.frame.triangles) <= lod_triangles
        v._key(keys.L, keys.ACTION_PRESS, None)
        v.step()
        assert len(v.frame.triangles) == faces
        assert "full resolution" in v.overlay_text(len(v.frame.triangles)).splitlines()[0]
        v._key(keys.Q, keys.ACTION_PRESS, None)
        assert v.window.is_closing
    finally:
        v.renderer.release()
        v.window.destroy()


def test_headless_viewer_shows_the_frame_time_budget_and_its_floor(cut_store, monkeypatch):
    """Under a frame-time budget no frame meets (1e-3 ms) the overlay shows the budget and the floor B-2 raised
    over the frames in motion (x 1.25 a timed frame, from the bound it found); without a budget there is no such
    line."""
    monkeypatch.delenv("DISPLAY", raising=False)
    for budget in (None, 1e-3):
        v = headless(cut_store, frame_ms=budget)
        try:
            v.window.use()
            for k in range(6):
                if k:
                    v.state.orbit(0.05, 0.0)  # in motion: B-2 times these frames
                v.step()
            text = v.overlay_text(len(v.frame.triangles))
            floor = v.frame.stats["bound_floor"]
        finally:
            v.renderer.release()
            v.window.destroy()
        if budget is None:
            assert "budget" not in text and floor is None
        else:
            assert floor > 0 and v.state.error_bound >= floor
            assert f"budget 0.001 ms, bound floor {floor:.3g}" in text.splitlines()[2]


def test_view_headless_command_writes_its_screenshot_without_a_display(cut_store, tmp_path, monkeypatch, capsys):
    """`lodprt view --headless --frames 2 --screenshot` runs without DISPLAY and writes the last frame;
    --headless without --frames and --frames 0 are one-line errors with exit code 2."""
    from PIL import Image

    from lodprt.cli.main import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    shot = tmp_path / "shot.png"
    assert main(["view", str(cut_store), "--headless", "--frames", "2", "--size", "160", "120",
                 "--screenshot", str(shot)]) == 0
    assert "closed after 2 frames" in capsys.readouterr().out
    assert np.asarray(Image.open(shot)).shape == (120, 160, 3)
    for extra, said in ((["--headless"], "--headless needs --frames N"), (["--frames", "0"], "--frames 0")):
        assert main(["view", str(cut_store)] + extra) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and said in err, err


def test_headless_viewer_shows_a_bar_while_a_moved_light_completes_samples(cut_store, monkeypatch, capsys):
    """With the CLI's ``set_lights`` (`lodprt view`), a light moved onto a sample the run time does not hold yet
    completes it with a transient bar on stderr; a frame that completes nothing prints none, and the sample
    cache's own progress callback is back afterwards."""
    from lodprt.cli.progress import set_lights_with_progress

    monkeypatch.delenv("DISPLAY", raising=False)
    v = headless(cut_store, set_lights=set_lights_with_progress)
    try:
        v.window.use()
        v.step()
        cache = v.source.samples
        held, done = cache.progress, cache.completed
        capsys.readouterr()
        v.state.orbit(0.05, 0.0)  # the same lights: nothing to complete
        v.step()
        assert cache.completed == done and "completing light samples" not in capsys.readouterr().err
        far = np.argmax(np.linalg.norm(v.source.store.light_positions - v.state.lights[0], axis=1))
        assert far not in cache.slot_sample
        shown = []  # the overlay's text at each swap while the frame is made

        def swap():
            shown.append(v.overlay.tex["text"][0])
            if len(shown) == 1:  # a control moved during the wait: kept, and it asks for the next frame
                v.state.orbit(0.1, 0.0)

        monkeypatch.setattr(v.window, "swap_buffers", swap)
        v.state.lights[0] = v.source.store.light_positions[far]
        moved = v.state.lights.copy()
        v.state.dirty = True
        v.step()
        n = cache.completed - done
        assert n >= 1 and far in cache.slot_sample
        assert "completing light samples" in capsys.readouterr().err
        assert cache.progress is held
        # the window: the last frame with the notice, before the first sample and after each one
        assert [t.splitlines()[-1] for t in shown] == [f"completing light samples: {i} of {n} done"
                                                      for i in range(n + 1)]
        assert all(t.splitlines()[0].endswith("LOD") for t in shown)  # over the last frame's overlay
        assert v.state.dirty and np.array_equal(v.state.lights, moved)  # the orbit during the wait is not lost
        eye = v.state.camera.eye
        v.step()  # the next frame is made for the orbited camera, and says nothing more
        assert not v.state.dirty and np.allclose(v.frame.camera.eye, eye) and len(shown) == n + 1
    finally:
        v.renderer.release()
        v.window.destroy()


def test_headless_viewer_plays_the_path_of_frames_and_pauses(cut_store, monkeypatch):
    """``path="orbit"``: each frame takes the next camera and light of ``camera_path`` (looped), and makes the same
    frames as a second Runtime stepped along that path as ``lodprt frames`` steps it; what each frame cost is kept
    (the light samples completed counted by the cache); P and a drag pause it, P plays on from where it stopped."""
    from lodprt.runtime.camera import camera_path
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    monkeypatch.delenv("DISPLAY", raising=False)
    v = headless(cut_store, path="orbit", path_frames=4)
    try:
        v.window.use()
        cam = v.state.camera
        steps = list(camera_path(v.source, "orbit", 4, size=(cam.width, cam.height), fov=cam.fov))
        twin = Runtime(open_store(cut_store))  # the path as `lodprt frames` steps it
        done = v.samples.completed
        for k in range(6):
            v.step()
            eye, lights = steps[k % 4][0].eye, steps[k % 4][1]
            assert np.allclose(v.state.camera.eye, eye) and np.array_equal(v.frame.lights, lights)
            twin.set_camera(steps[k % 4][0])
            twin.set_lights(lights)
            ref = twin.update()
            assert np.array_equal(v.frame.triangles, ref.triangles)
            status = v.overlay_text(len(v.frame.triangles)).splitlines()[-2]
            assert status == f"path orbit, frame {k % 4 + 1} of 4 (P pauses)"
        played = v.player.played
        assert len(played) == 6 and sum(r["samples_completed"] for r in played) == v.samples.completed - done
        assert all(r["ms_update"] > 0 and r["ms_lights"] >= 0 for r in played)
        keys = v.window.keys = _Names()  # the headless window has no key codes: each key stands in as its name
        v._key(keys.P, keys.ACTION_PRESS, None)
        eye = v.state.camera.eye
        v.step()
        assert v.state.camera.eye == eye and len(v.player.played) == 6  # paused: nothing moves, nothing recorded
        assert v.overlay_text(1).splitlines()[-2].endswith("(paused: P plays)")
        v._key(keys.P, keys.ACTION_PRESS, None)
        v.step()
        assert np.allclose(v.state.camera.eye, steps[6 % 4][0].eye) and len(v.player.played) == 7
        v.state.orbit(0.3, 0.0)  # what a drag does; the window's handler pauses the path first
        v._pause()
        v.state.dirty = True
        moved = v.state.camera.eye
        v.step()
        assert np.allclose(v.frame.camera.eye, moved) and len(v.player.played) == 7
    finally:
        v.renderer.release()
        v.window.destroy()


def test_a_lap_is_path_frames_long_and_pause_stops_where_it_is(cut_store, monkeypatch):
    """Without ``path_frames`` a lap of the path is ``lodprt frames``' default run (``PATH_FRAMES`` frames);
    ``pause`` stops the path where it is (nothing advances) and ``toggle`` plays on from there."""
    from types import SimpleNamespace

    from lodprt.runtime.camera import PATH_FRAMES

    monkeypatch.delenv("DISPLAY", raising=False)
    v = headless(cut_store, path="dolly")
    try:
        player = v.player
        assert len(player.steps) == PATH_FRAMES
        state = SimpleNamespace(camera=v.state.camera, lights=None, selected=None, dirty=False)
        assert player.advance(state) and player.index == 1
        player.pause()
        state.dirty = False
        assert not player.advance(state) and player.index == 1 and not state.dirty
        player.pause()  # pausing a paused path keeps it paused
        assert player.paused
        player.toggle()
        assert player.advance(state) and player.index == 2
        assert np.allclose(state.camera.eye, player.steps[1][0].eye)
    finally:
        v.renderer.release()
        v.window.destroy()


def test_path_summary_is_the_records_median_and_sums():
    """The closing summary of a played path: medians after the first frame, sums and the longest wait, exactly."""
    from lodprt.display.playback import PathPlayer, summary_line

    player = PathPlayer.__new__(PathPlayer)  # the records alone: no run time needed
    player.path, player.played = "dolly", []
    assert summary_line(player.summary()) == "path dolly: no frame played"
    player.record(900.0, 1500.0, 20.0, 3)  # one frame: no median after it (the first frame's was given as one)
    one = player.summary()
    assert one["median_ms_update"] is None and one["median_ms_draw"] is None
    assert summary_line(one).startswith("path dolly: 1 frame, first frame 1500 ms, no frame after it to time; ")
    player.played = []
    for rec in [(900.0, 1500.0, 20.0, 3), (0.0, 10.0, 4.0, 0), (2500.0, 30.0, 8.0, 2), (0.0, 20.0, 6.0, 0)]:
        player.record(*rec)
    s = player.summary()
    assert s == {"path": "dolly", "frames": 4, "first_frame_ms": 1500.0, "median_ms_update": 20.0,
                 "median_ms_draw": 6.0, "samples_completed": 5, "lights_seconds": 3.4, "max_ms_lights": 2500.0}
    line = summary_line(s)
    assert line == ("path dolly: 4 frames, median update 20 ms and draw 6 ms after the first (1500 ms); "
                    "setting the lights completed 5 light samples in 3.4 s (longest frame's 2.5 s)")
    # benchmarks/ten_million.py reads the numbers back from the line `lodprt view` prints
    bench = str(Path(__file__).resolve().parents[1] / "benchmarks")
    if bench not in sys.path:
        sys.path.insert(0, bench)
    from ten_million import view_path

    opened = "lodprt view: out.zarr opened in 61.5 s - H prints the controls, Q quits\n"
    assert view_path(f"{opened}lodprt view: closed after 4 frames\nlodprt view: {line}\n") == {
        "path": "dolly", "frames": 4.0, "median_ms_update": 20.0, "median_ms_draw": 6.0, "first_frame_ms": 1500.0,
        "samples_completed": 5.0, "lights_seconds": 3.4, "max_seconds_lights": 2.5, "open_seconds": 61.5}
    with pytest.raises(SystemExit, match="no path summary"):
        view_path(f"{opened}lodprt view: closed after 4 frames\n")
    with pytest.raises(SystemExit, match="no opening time"):
        view_path(f"lodprt view: {line}\n")


def test_view_command_plays_a_path_and_prints_its_summary(cut_store, monkeypatch, capsys):
    """``lodprt view --path orbit --frames N --headless``: N frames of the path, its summary line on closing; with
    ``--light`` the light stays where it was put while the camera moves."""
    from lodprt.cli.main import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(cut_store), "--headless", "--frames", "3", "--size", "160", "120", "--path", "orbit"]) == 0
    out = capsys.readouterr().out
    assert "closed after 3 frames" in out
    assert re.search(r"lodprt view: \S*cut\.zarr opened in [0-9.]+ s - headless, 3 frames", out)
    assert re.search(r"path orbit: 3 frames, median update \d+ ms and draw \d+ ms after the first \(\d+ ms\); "
                     r"setting the lights completed \d+ light samples in [0-9.]+ s", out)
    assert main(["view", str(cut_store), "--headless", "--frames", "2", "--size", "160", "120", "--path", "dolly",
                 "--light", "0.05", "0.3", "0.1"]) == 0
    out = capsys.readouterr().out
    assert "path dolly: 2 frames" in out and "light 1 of 1" not in out
    with pytest.raises(SystemExit) as exc:
        main(["view", str(cut_store), "--path", "spiral", "--headless", "--frames", "1"])
    assert exc.value.code == 2
    assert "invalid choice: 'spiral'" in capsys.readouterr().err


def test_the_window_says_the_store_is_opening_and_counts_the_samples_it_completes(cut_store, monkeypatch):
    """While the run time opens (a minute at 10M vertices) the window shows a notice naming the store and its
    vertices, then how many of the light samples the opening completes are done, each reported to ``progress``
    as well (the CLI's bar), then that the first frame is being made; once open, later completions report through
    the frame that needs them only."""
    from lodprt.display.overlay import Overlay
    from lodprt.store.bake_store import open_store

    monkeypatch.delenv("DISPLAY", raising=False)
    shown, told = [], []
    draw = Overlay.draw

    def record(self, text, size, sliders=(), values=None):
        shown.append(text)
        draw(self, text, size, sliders, values)

    monkeypatch.setattr(Overlay, "draw", record)
    v = headless(cut_store, progress=lambda done, total: told.append((done, total)))
    try:
        V = open_store(cut_store).num_vertices
        opening = f"opening cut.zarr: {V:,} vertices"
        n = v.samples.completed
        assert n >= 1 and told == [(i, n) for i in range(n + 1)]
        assert shown == [opening] + [f"{opening}\ncompleting light samples: {i} of {n} done" for i in range(n + 1)]
        assert v.samples.progress is None
        v.window.use()
        v.step()  # the first frame: a notice while it is made, then the overlay alone
        assert shown[-2] == f"{opening}\nmaking the first frame"
        assert not shown[-1].startswith("opening") and "completing" not in shown[-1]
        v.state.orbit(0.05, 0.0)
        v.step()  # later frames say nothing of the kind
        assert "making the first frame" not in shown[-2]
    finally:
        v.renderer.release()
        v.window.destroy()


def test_transient_bar_closes_once_its_total_is_reached(monkeypatch):
    """``cli.progress.transient_bar``: made at the first report, advanced to each ``done``, closed at the total."""
    from lodprt.cli import progress as cli_progress

    made = []

    class Bar:
        def __init__(self, **options):
            self.n, self.options, self.closed = 0, options, False
            made.append(self)

        def update(self, k):
            self.n += k

        def close(self):
            self.closed = True

    monkeypatch.setattr(cli_progress, "new_bar", lambda **options: Bar(**options))
    update = cli_progress.transient_bar("opening: completing light samples", "sample")
    assert made == []
    update(0, 3)
    update(2, 3)
    assert len(made) == 1 and made[0].n == 2 and not made[0].closed
    assert made[0].options == {"total": 3, "unit": "sample", "desc": "opening: completing light samples",
                               "leave": False}
    update(3, 3)
    assert made[0].n == 3 and made[0].closed


def test_a_source_without_a_sample_cache_sets_its_lights_with_no_bar(capsys):
    """``runtime.sources.reporting`` and the CLI's ``set_lights_with_progress`` on a source with no sample cache
    (full-resolution ``StoreFrames``): the lights are set once, nothing is reported, no bar is drawn."""
    from lodprt.cli.progress import set_lights_with_progress
    from lodprt.runtime.sources import reporting, sample_cache

    calls, told = [], []
    source = SimpleNamespace(set_lights=lambda lights, colors: calls.append((lights, colors)))
    assert sample_cache(source) is None
    with reporting(source, lambda done, total: told.append((done, total))):
        source.set_lights([[0.0, 1.0, 0.0]], None)
    set_lights_with_progress(source, [[0.0, 2.0, 0.0]])
    assert calls == [([[0.0, 1.0, 0.0]], None), ([[0.0, 2.0, 0.0]], None)] and told == []
    assert capsys.readouterr().err == ""
