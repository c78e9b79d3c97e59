"""Camera maths for every stage that looks at the scene: the ``Camera`` record, view and projection matrices (the
renderer's and the view cut's are the same), frustum planes, default views and camera paths around a store's
objects."""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from lodprt.errors import LodprtError, is_number, is_whole, shown
from lodprt.model.scene import referenced_bounds

log = logging.getLogger(__name__)

#: the camera paths ``camera_path`` knows (``lodprt frames --path``, ``lodprt view --path``)
PATHS = ("orbit", "dolly")
#: frames along a path when the user does not say: ``lodprt frames --frames``, one lap of ``lodprt view --path``
PATH_FRAMES = 120


@dataclasses.dataclass(frozen=True)
class Camera:
    """Perspective camera: right-handed, looks from ``eye`` at ``target``, ``up`` (default y) is up on screen,
    ``fov`` the vertical field of view in degrees, ``width`` x ``height`` pixels. ``near``/``far`` None: chosen
    from the scene's bounds."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 40.0
    width: int = 800
    height: int = 600
    near: float | None = None
    far: float | None = None

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            given = getattr(self, name)
            try:
                v = np.asarray(given, object)
            except ValueError:  # ragged
                v = np.empty(0, object)
            if v.shape != (3,) or not all(is_number(x) and math.isfinite(x) for x in v):
                raise LodprtError(f"camera {name}: expected 3 finite numbers, got {shown(given)}")
            v = v.astype(np.float64)
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if not np.linalg.norm(self.up) > 0:  # no direction: refused, not replaced as a parallel one is (view_up)
            raise LodprtError(f"camera up: {list(self.up)} has no direction; give a non-zero vector (default 0 1 0)")
        if not (is_number(self.fov) and 0.0 < float(self.fov) < 180.0):  # "45" or True is no angle
            raise LodprtError(f"camera fov: {shown(self.fov)} degrees; must be a number strictly between 0 and 180")
        object.__setattr__(self, "fov", float(self.fov))
        size = []
        for name in ("width", "height"):  # whole pixels: 320.0 is 320, 320.5 or "320" is refused
            v = getattr(self, name)
            if not is_whole(v, 1):
                raise LodprtError(f"camera size: {shown(self.width)} x {shown(self.height)}; width and height must be whole "
                                  "numbers >= 1")
            size.append(int(v))
        object.__setattr__(self, "width", size[0])
        object.__setattr__(self, "height", size[1])
        for name in ("near", "far"):  # each alone too: a near of 0 or a NaN far leaves no finite projection
            v = getattr(self, name)
            if v is not None and not (is_number(v) and math.isfinite(v) and v > 0):
                raise LodprtError(f"camera {name}: {shown(v)}; must be a finite number > 0 (None: from the scene's bounds)")
            if v is not None:
                object.__setattr__(self, name, float(v))
        if self.near is not None and self.far is not None and not self.near < self.far:
            raise LodprtError(f"camera near/far: {self.near}, {self.far}; need 0 < near < far")


def clip_planes(view_proj: np.ndarray) -> np.ndarray:
    """(6, 4) inward frustum planes (a, b, c, d) with unit (a, b, c) from a 4x4 view-projection matrix
    (Gribb-Hartmann): a point x is inside when ``a x + b y + c z + d >= 0`` for all six."""
    m = np.asarray(view_proj, np.float64)
    planes = np.array([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]])
    n = np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    # a far plane at infinity in float64 (far / near past ~1e16: m[2][2] is -1 exactly) has no normal: it culls nothing
    return np.where(n > 0, planes / np.where(n > 0, n, 1.0), np.array([0.0, 0.0, 0.0, 1.0]))


def camera_for(camera=None, *, eye=None, target=None, default_target=None, **fields) -> Camera:
    """What ``set_camera`` takes: a ``Camera``, or its fields with the eye positional (``camera``) or ``eye=``;
    ``target`` None is ``default_target`` (the scene's centre, as on the command line). Fields None are
    ``Camera``'s defaults; beside a ``Camera``, the fields given replace its own (its eye and target stay)."""
    fields = {k: v for k, v in fields.items() if v is not None}
    if isinstance(camera, Camera):
        if eye is not None or target is not None:
            raise LodprtError("set_camera: pass either a Camera or its eye and target, not both")
        eye, make = camera, dataclasses.replace  # the fields given replace its own (width=64 was dropped)
    elif camera is not None and eye is not None:
        raise LodprtError("set_camera: the eye given twice (positional and eye=)")
    else:
        eye, target, make = camera if eye is None else eye, default_target if target is None else target, Camera
        if eye is None:
            raise LodprtError("set_camera: give the eye (set_camera(eye=(x, y, z))) or a Camera")
        if target is None:
            raise LodprtError("set_camera: give the target (no scene centre to default to)")
        fields["target"] = target
    try:
        return make(eye, **fields)
    except TypeError as exc:  # a field Camera has not
        raise LodprtError(f"set_camera: {exc}") from exc


def view_projection(camera: Camera, bounds: np.ndarray) -> np.ndarray:
    """4x4 projection @ view of ``camera`` (OpenGL clip space), with the renderer's near and far planes
    (``lodprt.render.camera_matrices``) for the scene's bounds (2, 3): the cut culls with the planes that draw."""
    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    view, proj = camera_matrices(camera, corners)
    return proj @ view


def object_bounds(store) -> np.ndarray:
    """(2, 3) bounds of the scene's objects without the floor (all referenced vertices when only a floor)."""
    pos = np.asarray(store.positions)
    oid = np.asarray(store.read("scene/object_id"))
    names = list(store.root["scene"].attrs.get("object_names", []))
    used = store.referenced
    keep = used.copy()
    if "floor" in names:
        keep &= oid != names.index("floor")
    p = pos[keep] if keep.any() else pos[used] if used.any() else pos
    return np.array([p.min(0), p.max(0)]) if len(p) else np.zeros((2, 3))


def camera_path(rt, path: str, frames: int, *, size=(800, 600), fov: float = 40.0, light_turns: float = 2.0):
    """Yields ``frames`` (Camera, lights (1, 3)) pairs: ``orbit`` circles the objects at 2.2 object sizes, 25
    degrees above them; ``dolly`` moves from 3 object sizes to 0.8 straight toward them; the light circles inside
    the sampled light box ``light_turns`` times over the path."""
    if path not in PATHS:
        raise LodprtError(f"camera path {path!r}: choose one of {', '.join(PATHS)}")
    b = object_bounds(rt.store)
    c = 0.5 * (b[0] + b[1])
    size_ = float(np.linalg.norm(b[1] - b[0])) or 1.0
    box = np.asarray(rt.store.root["lights"].attrs["box"], np.float64)
    lc, lh = 0.5 * (box[:3] + box[3:]), 0.5 * (box[3:] - box[:3])
    elev = math.radians(25.0)
    for k in range(int(frames)):
        t = k / max(int(frames), 1)
        if path == "orbit":
            a = 2.0 * math.pi * t
            dist = 2.2 * size_
        else:
            a = 0.6
            dist = size_ * (3.0 - 2.2 * t)
        eye = c + dist * np.array([math.cos(elev) * math.sin(a), math.sin(elev), math.cos(elev) * math.cos(a)])
        la = 2.0 * math.pi * light_turns * t
        light = lc + 0.8 * lh * np.array([math.cos(la), 0.0, math.sin(la)])
        yield Camera(eye=tuple(eye), target=tuple(c), fov=fov, width=int(size[0]), height=int(size[1])), light[None, :]


def view_up(forward, up) -> np.ndarray:
    """``up`` unless it is (nearly) parallel to the unit viewing direction ``forward``: then the world axis least
    aligned with ``forward`` (looking straight down with up = +y gives -z up on screen), as viewers do; logged."""
    up = np.asarray(up, np.float64)
    n = np.linalg.norm(up)
    if n > 0 and np.linalg.norm(np.cross(forward, up / n)) > 1e-6:
        return up
    axes = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    pick = axes[int(np.argmin(np.abs(axes @ forward)))]
    log.info("camera: up %s is parallel to the viewing direction %s; using up %s", up.tolist(),
             np.round(forward, 6).tolist(), pick.tolist())
    return pick


def look_at(eye, target, up) -> np.ndarray:
    """4x4 view matrix (right-handed, camera looks down -z); an ``up`` along the view is replaced (``view_up``)."""
    eye, target, up = (np.asarray(x, np.float64) for x in (eye, target, up))
    f = target - eye
    if not np.linalg.norm(f) > 0:
        raise LodprtError("camera: eye and target coincide")
    f /= np.linalg.norm(f)
    s = np.cross(f, view_up(f, up))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    t = 1.0 / np.tan(np.radians(fov_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = t / aspect, t
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def camera_matrices(camera, points=None) -> tuple[np.ndarray, np.ndarray]:
    """View and projection matrices (4x4 float64) of a ``lodprt.runtime.Camera``; near/far None are chosen so
    that ``points`` (N, 3) lie between them (a thousandth of far at the closest)."""
    view = look_at(camera.eye, camera.target, camera.up)
    near, far = camera.near, camera.far
    if near is None or far is None:
        pts = np.asarray(points if points is not None and len(points) else [camera.target], np.float64)
        lo, hi = pts.min(0), pts.max(0)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        depth = -(corners @ view[:3, :3].T + view[:3, 3])[:, 2]
        scene_far = max(float(depth.max()) * 1.01, 1e-6)
        f = scene_far if far is None else far
        # the precision floor reads the scene's depth, not a far given alone: a far of 10,000 put near past the scene
        near = max(float(depth.min()) * 0.99, scene_far * 1e-3) if near is None else near
        far = max(f, near * 1.0001)
    return view, perspective(camera.fov, camera.width / camera.height, near, far)


def orbit(camera, angle: float):
    """``camera`` turned by ``angle`` radians about the vertical (``up``) axis through its target."""
    return dataclasses.replace(camera, eye=tuple(rotate_about(camera.eye, camera.target, camera.up, angle)))


def rotate_about(point, centre, axis, angle: float) -> np.ndarray:
    """Rodrigues rotation of ``point`` about the line through ``centre`` along ``axis``."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    v = np.asarray(point, np.float64) - np.asarray(centre, np.float64)
    c, s = np.cos(angle), np.sin(angle)
    return np.asarray(centre, np.float64) + v * c + np.cross(k, v) * s + k * np.dot(k, v) * (1 - c)


def default_eye(store) -> tuple[float, float, float]:
    """A three-quarter view from the front (+z) and above that frames the scene at a 40-degree field of view."""
    lo, hi = referenced_bounds(store.positions, store.referenced)  # the vertices the faces use
    c = 0.5 * (lo + hi)
    r = 0.5 * float(np.linalg.norm(hi - lo)) or 1.0
    return tuple(float(x) for x in c + r * np.array([0.5, 0.9, 1.9]))


def scene_centre(store) -> tuple[float, float, float]:
    """Centre of the bounding box of the vertices the faces use (the default look-at point)."""
    lo, hi = referenced_bounds(store.positions, store.referenced)
    return tuple(float(x) for x in 0.5 * (lo + hi))


def camera_jump(a: Camera, b: Camera, jump: float) -> bool:
    """More than a small step from camera ``a`` to ``b``: the eye or the target moved by more than ``jump`` of the
    viewing distance, or the lens, screen or up vector changed."""
    dist = max(float(np.linalg.norm(np.subtract(a.eye, a.target))), 1e-12)
    step = max(float(np.linalg.norm(np.subtract(a.eye, b.eye))), float(np.linalg.norm(np.subtract(a.target, b.target))))
    return step > jump * dist or (a.fov, a.width, a.height, a.up, a.near, a.far) != (b.fov, b.width, b.height, b.up,
                                                                                     b.near, b.far)
