"""Offscreen rendering with moderngl (headless EGL: Mesa llvmpipe on CPU machines, the driver on GPUs).

Camera convention: perspective, vertical field of view in degrees, right-handed, y up by default; the image's
first row is its top. Colours are per vertex, interpolated across triangles, written as given (display space).
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError

_VERTEX = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec3 in_col;
out vec3 v_col;
void main() { gl_Position = mvp * vec4(in_pos, 1.0); v_col = in_col; }
"""
_FRAGMENT = """
#version 330
in vec3 v_col;
out vec4 f_col;
void main() { f_col = vec4(v_col, 1.0); }
"""


def look_at(eye, target, up) -> np.ndarray:
    """4x4 view matrix (right-handed, camera looks down -z)."""
    eye, target, up = (np.asarray(x, np.float64) for x in (eye, target, up))
    f = target - eye
    if np.linalg.norm(f) == 0:
        raise LodprtError("camera: eye and target coincide")
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-12:
        raise LodprtError("camera: the up vector is parallel to the viewing direction")
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


def render(positions, triangles, colors, *, eye, target, up=(0.0, 1.0, 0.0), fov=40.0, size=(800, 600),
           background=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Render triangles (M, 3) over positions (V, 3) with per-vertex colours (V, 3) in [0, 1]: (H, W, 3) uint8."""
    import moderngl

    width, height = (int(x) for x in size)
    if width < 1 or height < 1:
        raise LodprtError(f"size {size}: width and height must be >= 1")
    pos = np.asarray(positions, np.float32)
    tri = np.asarray(triangles, np.int32)
    col = np.clip(np.asarray(colors, np.float32), 0, 1)
    radius = float(np.linalg.norm(pos.max(0) - pos.min(0))) or 1.0
    dist = float(np.linalg.norm(np.asarray(eye, float) - np.asarray(target, float)))
    mvp = perspective(fov, width / height, max(dist - 2 * radius, dist * 1e-3), dist + 2 * radius) @ look_at(eye, target, up)
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as exc:  # no EGL display: say so instead of a deep traceback
        raise LodprtError(f"cannot create an offscreen OpenGL context (EGL): {exc}") from exc
    try:
        prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        prog["mvp"].write(mvp.T.astype(np.float32).tobytes())  # column-major
        vbo = ctx.buffer(np.hstack([pos, col]).astype(np.float32).tobytes())
        ibo = ctx.buffer(tri.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "in_pos", "in_col")], index_buffer=ibo)
        fbo = ctx.simple_framebuffer((width, height), components=3)
        fbo.use()
        ctx.enable(moderngl.DEPTH_TEST)
        fbo.clear(*background, depth=1.0)
        vao.render(moderngl.TRIANGLES)
        img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(height, width, 3)
        return img[::-1].copy()  # OpenGL's first row is the bottom
    finally:
        ctx.release()


def tone_map(radiance: np.ndarray, white: float | None = None) -> np.ndarray:
    """Linear radiance (..., 3) -> display [0, 1]: divide by ``white`` (default: 99th percentile), clip, sRGB."""
    r = np.asarray(radiance, np.float64)
    if white is None:
        pos = r[r > 0]
        white = float(np.percentile(pos, 99)) if pos.size else 1.0
    x = np.clip(r / white, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
