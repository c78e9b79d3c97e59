"""Interactive viewer (``lodprt view``): moderngl-window (pyglet) around the same ``Renderer`` the offscreen
commands use, driving the run time (moving lights, view-dependent cut) every frame something changed.

Controls (also printed by H):

    left drag          orbit the camera about its target        right / middle drag   pan
    wheel              zoom (move the eye toward the target)    R                     reset the camera
    shift + left drag  move the selected light in the screen plane; shift + wheel moves it toward/away from you
    Tab                select the next light                    A / Delete            add / remove a light
    [ / ]              error bound / 1.25, x 1.25               , / .                 alpha - / + 0.05 (thesis)
    left press / drag on a slider (bottom left): set the error bound or alpha (0 to 1) from the x position
    W wireframe        L LOD on/off                             V per-vertex / per-fragment radiance
    M light markers    - / =  exposure - / + 1/2 stop            H help     Q / Escape quit
    P                  pause / play the camera path (``--path``; a drag or the wheel pauses it too)

The overlay (top left) shows triangles, vertices, the active criterion with its knobs (the error bound; alpha only
for "thesis", the only criterion that reads it; under a target PSNR the frame's estimated PSNR, E-3), under a
frame-time budget the budget and the bound's floor (B-2), lights and the frame time (run-time update and draw); the
sliders (bottom left) show the same knobs and follow the keys. While a moved light completes light samples
(seconds each on millions of vertices), the last frame stays up with a line saying how many are done; while the
store opens (a minute at 10M vertices), the window says so, and how many light samples the opening completed.
Without a display it raises LodprtError saying what is missing (no DISPLAY, or no moderngl-window).

``path="orbit"|"dolly"`` (``lodprt view --path``) plays the camera path of ``lodprt frames``, the light circling with
it (``lodprt.display.playback``), and ``lodprt view`` prints what its frames cost when it closes.

``headless=True`` (``lodprt view --headless --frames N``) runs the same loop, overlay and screenshot on an EGL
context (moderngl-window's headless window: no events, no DISPLAY needed), for servers and the tests.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import logging
import os
import time

import numpy as np

from lodprt.errors import LodprtError
from lodprt.display.overlay import Overlay, Slider, slider_layout
from lodprt.display.playback import PathPlayer, summary_line
from lodprt.display.render import Renderer
from lodprt.runtime.camera import PATH_FRAMES, rotate_about
from lodprt.runtime.frames import auto_white
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.criteria import CRITERIA, make_criterion, resolve_criterion
from lodprt.runtime.settings import check_frame_ms
from lodprt.runtime.sources import frame_source, reporting, sample_cache

log = logging.getLogger(__name__)

HELP = __doc__.split("Controls (also printed by H):")[1].split("The overlay")[0].rstrip()

def _check_display(headless: bool) -> None:
    if not headless and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise LodprtError("no display: DISPLAY is not set (run it on a desktop, over ssh -X, or under a virtual "
                          "X server: xvfb-run -a lodprt view ...); without a window: lodprt view --headless "
                          "--frames N --screenshot PNG; offscreen pictures: lodprt render")
    missing = [name for name in ("moderngl_window",) + (() if headless else ("pyglet",))
               if importlib.util.find_spec(name) is None]
    if missing:
        raise LodprtError(f"the viewer needs {' and '.join(missing)}: pip install moderngl-window")


@dataclasses.dataclass
class ViewerState:
    """What the controls change; kept apart from the window so it can be driven (and tested) without one."""

    camera: object
    lights: np.ndarray
    colors: np.ndarray | None
    error_bound: float
    alpha: float
    criterion: str = "screen"  # the view cut's name (``lodprt.runtime.criteria.CRITERIA``); alpha is "thesis"'s
    lod: bool = True
    wireframe: bool = False
    per_vertex: bool = False
    markers: bool = True
    exposure: float = 0.0
    selected: int = 0
    dirty: bool = True  # the run time must make a new frame
    grabbed: Slider | None = None  # the slider a left press started on, until the button is released

    # -- sliders and the keys that change the same values -------------------------------------------------------
    def sliders(self) -> tuple[Slider, ...]:
        """The sliders laid out for the current window (camera) size, in its pixels."""
        return slider_layout(self.camera.width, self.camera.height, knobs=CRITERIA[self.criterion].KNOBS)

    def has_knob(self, name: str) -> bool:
        """Whether the active criterion has the knob ``name`` (its ``KNOBS``; alpha only for "thesis")."""
        return name in {k.name for k in CRITERIA[self.criterion].KNOBS}

    def knobs(self) -> str:
        """The active criterion and its knobs, as the overlay prints them (``Criterion.describe``)."""
        return make_criterion(self.criterion, error_bound=self.error_bound, alpha=self.alpha).describe()

    def set_value(self, name: str, value: float) -> None:
        """Error bound (>= 0) or alpha (clamped to [0, 1]); what the sliders and the keys both go through."""
        value = max(float(value), 0.0) if name == "error_bound" else min(max(float(value), 0.0), 1.0)
        if value != getattr(self, name):
            setattr(self, name, value)
            self.dirty = True

    def step_error_bound(self, up: bool) -> None:
        """``]`` / ``[``: error bound x 1.25 or / 1.25 (up from 0, where scaling is stuck, goes to 0.01)."""
        e = self.error_bound
        self.set_value("error_bound", (e * 1.25 if e > 0 else 0.01) if up else e / 1.25)

    def step_alpha(self, up: bool) -> None:
        """``.`` / ``,``: alpha + or - 0.05 within [0, 1] (the thesis criterion only: the others have no alpha)."""
        if not self.has_knob("alpha"):
            return
        self.set_value("alpha", round(self.alpha + (0.05 if up else -0.05), 10))

    # -- the mouse (pixels of the window's framebuffer, origin top left) -------------------------------------------
    def press(self, x: float, y: float, left: bool = True) -> bool:
        """A button went down at (x, y): a left press on a slider grabs it and sets its value from x (True);
        anything else leaves the drag to the camera and lights (False)."""
        self.grabbed = None
        if left:
            for slider in self.sliders():
                if slider.contains(x, y):
                    self.grabbed = slider
                    self.set_value(slider.name, slider.value_at(x))
                    return True
        return False

    def release(self) -> None:
        self.grabbed = None

    def drag(self, x: float, y: float, dx: float, dy: float, *, left: bool = True, shift: bool = False) -> None:
        """The mouse moved by (dx, dy) to (x, y) with a button down: the grabbed slider follows x; otherwise shift
        moves the selected light, left orbits, right / middle pans (as fractions of the window height)."""
        if self.grabbed is not None:
            self.set_value(self.grabbed.name, self.grabbed.value_at(x))
            return
        scale = 1.0 / max(self.camera.height, 1)
        if shift:
            self.move_light(dx * scale, -dy * scale)
        elif left:
            self.orbit(dx * 3 * scale, dy * 3 * scale)
        else:
            self.pan(dx * scale, dy * scale)

    def orbit(self, dx: float, dy: float) -> None:
        """Turn the eye about the target: dx radians about up, dy radians about the camera's right axis."""
        cam = self.camera
        eye = rotate_about(cam.eye, cam.target, cam.up, -dx)
        f = np.subtract(cam.target, eye)
        right = np.cross(f, cam.up)
        new = rotate_about(eye, cam.target, right, -dy)
        v = new - np.asarray(cam.target)
        if abs(np.dot(v / np.linalg.norm(v), np.asarray(cam.up) / np.linalg.norm(cam.up))) < 0.995:  # stay off the pole
            eye = new
        self._camera(eye=tuple(eye))

    def pan(self, dx: float, dy: float) -> None:
        """Move eye and target together by (dx, dy) in units of the distance between them, in the screen plane."""
        cam = self.camera
        f = np.subtract(cam.target, cam.eye)
        dist = np.linalg.norm(f)
        right = np.cross(f, cam.up)
        right /= np.linalg.norm(right)
        up = np.cross(right, f / dist)
        shift = dist * (-dx * right + dy * up)
        self._camera(eye=tuple(np.add(cam.eye, shift)), target=tuple(np.add(cam.target, shift)))

    def zoom(self, factor: float) -> None:
        cam = self.camera
        v = np.subtract(cam.eye, cam.target)
        self._camera(eye=tuple(np.asarray(cam.target) + v * factor))

    def move_light(self, dx: float, dy: float, dz: float = 0.0) -> None:
        """Move the selected light by (dx, dy) screen-plane and dz toward-the-eye units of the eye distance."""
        cam = self.camera
        f = np.subtract(cam.target, cam.eye)
        f /= np.linalg.norm(f)
        right = np.cross(f, cam.up)
        right /= np.linalg.norm(right)
        up = np.cross(right, f)
        d = np.linalg.norm(self.lights[self.selected] - np.asarray(cam.eye))
        self.lights[self.selected] += d * (dx * right + dy * up - dz * f)
        self.dirty = True

    def add_light(self) -> None:
        base = self.lights[self.selected]
        self.lights = np.vstack([self.lights, base + 0.05 * np.linalg.norm(base - np.asarray(self.camera.target)) * np.array([1.0, 0.0, 0.0])])
        if self.colors is not None:
            self.colors = np.vstack([self.colors, self.colors[self.selected]])
        self.selected = len(self.lights) - 1
        self.dirty = True

    def remove_light(self) -> None:
        if len(self.lights) > 1:
            self.lights = np.delete(self.lights, self.selected, axis=0)
            if self.colors is not None:
                self.colors = np.delete(self.colors, self.selected, axis=0)
            self.selected %= len(self.lights)
            self.dirty = True

    def resize(self, width: int, height: int) -> None:
        self._camera(width=max(int(width), 1), height=max(int(height), 1))

    def _camera(self, **fields) -> None:
        self.camera = dataclasses.replace(self.camera, **fields)
        self.dirty = True


class Viewer:
    """The window loop: events change a ``ViewerState``; a changed state asks the run time for a new frame."""

    def __init__(self, store, *, lights, camera, colors=None, criterion="screen",
                 interpolation: str = DEFAULT_INTERPOLATION, error_bound: float | None = None,
                 alpha: float | None = None, target_psnr=None, frame_ms: float | None = None,
                 outside: str = "clamp",
                 lod: bool = True, wireframe: bool = False, per_vertex: bool = False, exposure: float = 0.0,
                 white: float | None = None, light_markers: bool = True, headless: bool = False,
                 set_lights=None, path: str | None = None, path_frames: int | None = None,
                 fixed_lights: bool = False, progress=None):
        #: ``set_lights(source, lights, colors)``: how a frame sets the lights (the CLI's shows a progress bar on
        #: stderr while they complete light samples, seconds each on a store of millions of vertices);
        #: ``progress(done, total)``: told of the light samples the store's opening completes (the CLI's bar)
        self.set_lights = set_lights or (lambda source, lights, colors: source.set_lights(lights, colors))
        if outside == "error":  # the starting lights; a light dragged out of the box later is clamped
            from lodprt.runtime.lights import LightInterpolator

            LightInterpolator(store.light_positions, store.light_box, outside="error").clamp(lights)
        check_frame_ms(frame_ms)  # a bad budget before the window
        _check_display(headless)
        import moderngl_window
        from moderngl_window.conf import settings

        criterion = resolve_criterion(criterion, error_bound=error_bound, alpha=alpha, target_psnr=target_psnr)
        self.state = ViewerState(camera=camera, lights=np.asarray(lights, np.float64).reshape(-1, 3).copy(),
                                 colors=None if colors is None else np.asarray(colors, np.float64).reshape(-1, 3),
                                 error_bound=criterion.error_bound, alpha=getattr(criterion, "alpha", 0.6),
                                 criterion=criterion.name, lod=lod,
                                 wireframe=wireframe,
                                 per_vertex=per_vertex, markers=light_markers, exposure=exposure)
        self.home = camera
        self.white = white
        kind = "headless" if headless else "pyglet"  # headless: an EGL context and framebuffer, no events
        settings.WINDOW.update({"class": f"moderngl_window.context.{kind}.Window", "gl_version": (3, 3),
                                "backend": "egl" if headless else None,
                                "size": (camera.width, camera.height), "title": f"lodprt view {store.path.name}",
                                "vsync": False, "resizable": not headless, "aspect_ratio": None})
        try:
            self.window = moderngl_window.create_window_from_settings()
        except Exception as exc:  # no X server behind DISPLAY, no GLX or EGL, no OpenGL 3.3
            where = "a headless EGL context" if headless else f"a window on DISPLAY={os.environ.get('DISPLAY')!r}"
            raise LodprtError(f"cannot open {where}: {exc}") from exc
        w = self.window
        self.renderer = Renderer(w.ctx)
        self.overlay = Overlay(w.ctx)
        self.frame = None
        # the run time opens after the window (fail fast), a minute at 10M vertices: the window says so meanwhile
        self.opening = opening = f"opening {store.path.name}: {store.num_vertices:,} vertices"
        self._show(opening)

        def opened(done: int, total: int) -> None:
            self._show(f"{opening}\ncompleting light samples: {done} of {total} done")
            if progress is not None:
                progress(done, total)

        t_open = time.perf_counter()
        self.source = frame_source(store, criterion=criterion, lod=lod, interpolation=interpolation,
                                   frame_ms=frame_ms, progress=opened, white=white)
        self.open_seconds = time.perf_counter() - t_open  # the run time's set-up, its samples completed at open
        self.samples = sample_cache(self.source)  # the run time's (None: full resolution)
        if self.samples is not None:  # later completions report through the frame that needs them (_completing)
            self.samples.progress = None
        #: ``--path``: the camera path played (``lodprt.display.playback``)
        self.player = None if path is None else PathPlayer(self.source, path, path_frames or PATH_FRAMES, camera=camera,
                                                           fixed_lights=fixed_lights)
        self.pushed = None  # the (error_bound, alpha) last given to the source
        self.ms_update = self.ms_draw = self.ms_lights = 0.0
        w.mouse_drag_event_func = self._drag
        w.mouse_press_event_func = self._press
        w.mouse_release_event_func = lambda x, y, button: self.state.release()
        w.mouse_scroll_event_func = self._scroll
        w.key_event_func = self._key
        w.resize_func = lambda width, height: self.state.resize(*self.window.buffer_size)
        self.state.resize(*w.buffer_size)

    # -- events ----------------------------------------------------------------------------------------------
    def _pixels(self, x, y, dx=0.0, dy=0.0):
        """Window coordinates (what pyglet reports) to framebuffer pixels (what the state and overlay use)."""
        w = self.window
        rx, ry = w.buffer_size[0] / max(w.size[0], 1), w.buffer_size[1] / max(w.size[1], 1)
        return x * rx, y * ry, dx * rx, dy * ry

    def _press(self, x, y, button):
        self.state.press(*self._pixels(x, y)[:2], left=button == self.window.mouse.left)

    def _drag(self, x, y, dx, dy):
        w = self.window
        self._pause()
        self.state.drag(*self._pixels(x, y, dx, dy), left=w.mouse_states.left, shift=w.modifiers.shift)

    def _scroll(self, x_offset, y_offset):
        self._pause()
        if self.window.modifiers.shift:
            self.state.move_light(0.0, 0.0, 0.05 * y_offset)
        else:
            self.state.zoom(0.9 ** y_offset)

    def _key(self, key, action, modifiers):
        keys, s = self.window.keys, self.state
        if action != keys.ACTION_PRESS:
            return
        if key in (keys.Q, keys.ESCAPE):
            self.window.close()
        elif key == keys.TAB:
            s.selected = (s.selected + 1) % len(s.lights)
        elif key == keys.A:
            self._pause()
            s.add_light()
        elif key in (keys.DELETE, keys.BACKSPACE):
            self._pause()
            s.remove_light()
        elif key in (keys.LEFT_BRACKET, keys.RIGHT_BRACKET):
            s.step_error_bound(key == keys.RIGHT_BRACKET)
        elif key in (keys.COMMA, keys.PERIOD):
            s.step_alpha(key == keys.PERIOD)
        elif key == keys.W:
            s.wireframe = not s.wireframe
        elif key == keys.L:
            s.lod = not s.lod
            self.source.set_lod(s.lod)
            s.dirty = True
        elif key == keys.V:
            s.per_vertex = not s.per_vertex
        elif key == keys.M:
            s.markers = not s.markers
        elif key in (keys.MINUS, keys.EQUAL):
            s.exposure += 0.5 if key == keys.EQUAL else -0.5
        elif key == keys.R:
            self._pause()
            s.camera = dataclasses.replace(self.home, width=s.camera.width, height=s.camera.height)
            s.dirty = True
        elif key == keys.P and self.player is not None:
            self.player.toggle()
        elif key == keys.H:
            print(HELP)

    def _pause(self) -> None:
        """The user takes the camera or a light: a playing path stops where it is."""
        if self.player is not None:
            self.player.pause()

    # -- loop ------------------------------------------------------------------------------------------------
    def step(self) -> None:
        """One frame: a new run-time frame if the state changed, then draw it and the overlay."""
        s = self.state
        playing = self.player is not None and self.player.advance(s)
        if s.dirty or self.frame is None:
            t0 = time.perf_counter()
            done = 0 if self.samples is None else self.samples.completed
            if (s.error_bound, s.alpha) != self.pushed:  # the user moved a knob (not every frame: a target's
                self.source.set_error_bound(s.error_bound, s.alpha)  # steering keeps the bound it found, E-4)
                self.pushed = (s.error_bound, s.alpha)
            s.dirty = False  # a control moved while the window waits for light samples asks for the next frame
            with self._completing():
                self.set_lights(self.source, s.lights, s.colors)
            self.ms_lights = 1e3 * (time.perf_counter() - t0)
            self.source.set_camera(s.camera)
            if self.frame is None:  # the first frame refines the cut to its target: seconds at 10M vertices
                self._show(f"{self.opening}\nmaking the first frame")
            self.frame = self.source.update()
            if not s.dirty:  # what the run time made of the knobs and lights (nothing moved meanwhile)
                s.error_bound = float(getattr(self.source, "error_bound", s.error_bound))  # the steered bound
                self.pushed = (s.error_bound, s.alpha)
                s.lights = np.asarray(self.frame.lights, np.float64).copy()  # as the run time clamped them
            self.ms_update = 1e3 * (time.perf_counter() - t0)
        self._draw()
        if playing:
            completed = 0 if self.samples is None else self.samples.completed - done
            self.player.record(self.ms_lights, self.ms_update - self.ms_lights, self.ms_draw, completed)

    def _draw(self, notice: str | None = None) -> None:
        """The frame and the overlay (with a ``notice`` line); before the first frame, the notice alone."""
        s, w = self.state, self.window
        t0 = time.perf_counter()
        if self.frame is None:
            w.ctx.clear(0.0, 0.0, 0.0)
            self.overlay.draw(notice or "", w.buffer_size)
            return
        white = self.white or getattr(self.source, "white", None) or auto_white(self.frame.radiance)
        info = self.renderer.draw(self.frame, target=w.fbo, camera=s.camera, per_vertex=s.per_vertex,
                                  exposure=s.exposure, white=white, wireframe=s.wireframe, light_markers=s.markers)
        text = self.overlay_text(info["triangles"]) + ("" if notice is None else f"\n{notice}")
        self.overlay.draw(text, w.buffer_size, s.sliders(), {"error_bound": s.error_bound, "alpha": s.alpha})
        self.ms_draw = 1e3 * (time.perf_counter() - t0)
        if info["gl_error"] != "GL_NO_ERROR":
            log.warning("OpenGL error: %s", info["gl_error"])

    def _completing(self):
        """While the lights complete light samples (seconds each on a store of millions of vertices): the window
        shows the last frame with how many are done, redrawn as each one is (``SampleCache.reporting``)."""
        return reporting(self.source, self._show_completion)

    def _show_completion(self, done: int, total: int) -> None:
        self._show(f"completing light samples: {done} of {total} done")

    def _show(self, notice: str) -> None:
        """The last frame (if any) with ``notice`` under its overlay, shown now (the window takes its events)."""
        w = self.window
        w.use()
        self._draw(notice)
        w.swap_buffers()

    def overlay_text(self, triangles: int) -> str:
        """The overlay's lines for the frame drawn (``triangles`` of it): the mesh, the criterion's knobs with E-3's
        estimate, the frame-time budget (B-2) with the bound's floor, the selected light, the path played, the
        times."""
        s, st = self.state, self.frame.stats
        budget = st.get("frame_ms_budget")
        floor = st.get("bound_floor") or 0.0
        return (f"{triangles:,} triangles, {len(self.frame.positions):,} vertices, "
                f"{'LOD' if getattr(self.source, 'lod', False) else 'full resolution'}\n"
                f"{s.knobs()}  exposure {s.exposure:+.1f}"
                + (f"  estimated {st['estimated_psnr_db']:.1f} dB" if st.get("estimated_psnr_db") is not None else "")
                + ("" if budget is None else f"\nbudget {budget:.3g} ms, bound floor "
                   + (f"{floor:.3g}" if floor > 0 else "off")) + "\n"
                f"light {s.selected + 1} of {len(s.lights)} at ({', '.join(f'{x:.3f}' for x in s.lights[s.selected])})\n"
                + ("" if self.player is None else f"{self.player.status()}\n") +
                f"update {self.ms_update:.0f} ms (cut {st.get('ms_cut', 0.0):.0f}), draw {self.ms_draw:.0f} ms  [H help]")

    def screenshot(self, path) -> None:
        """The window's current picture (after ``step``) as a PNG."""
        from PIL import Image

        w, h = self.window.buffer_size
        img = np.frombuffer(self.window.fbo.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
        Image.fromarray(img).save(path)

    def run(self, frames: int | None = None, *, screenshot=None) -> int:
        """Loop until the window closes (or after ``frames`` frames); returns the number of frames drawn.
        ``screenshot``: write the last frame drawn there (PNG)."""
        n = 0
        w = self.window
        try:
            while not w.is_closing and (frames is None or n < frames):
                w.use()
                self.step()
                if screenshot is not None and (frames is None or n == frames - 1):
                    self.screenshot(screenshot)
                w.swap_buffers()
                n += 1
        finally:
            self.renderer.release()
            w.destroy()
        return n


def run_viewer(store, *, frames: int | None = None, screenshot=None, **options) -> int:
    """``lodprt view``: open the window, loop, return the exit status (LodprtError when no display)."""
    viewer = Viewer(store, **options)
    print(f"lodprt view: {store.path} opened in {viewer.open_seconds:.1f} s - "
          + ("headless, " + f"{frames} frames" if options.get("headless") else "H prints the controls, Q quits"))
    n = viewer.run(frames, screenshot=screenshot)
    est = None if viewer.frame is None else viewer.frame.stats.get("estimated_psnr_db")
    print(f"lodprt view: closed after {n} frames ({viewer.state.knobs()}"
          + ("" if est is None else f", estimated {est:.1f} dB") + ")")
    if viewer.player is not None:
        print(f"lodprt view: {summary_line(viewer.player.summary())}")
    return 0
