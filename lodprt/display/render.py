"""Rendering with moderngl (offscreen: headless EGL, Mesa llvmpipe on CPU machines, the driver on GPUs; on screen:
the viewer's window context). docs/DISPLAY.md has the whole story.

Camera convention: perspective, vertical field of view in degrees, right-handed, y up by default; the image's
first row is its top.

* ``render``: per-vertex display colours, interpolated (``lodprt diff``'s panels).
* ``Renderer``: draws run-time ``Frame``s, radiance reconstructed from SH coefficients in the shader (per fragment
  or per vertex), tone mapping, wireframe, light markers, linear float32 output.
* ``full_frame`` / ``frame_source``: frames at full resolution from a store, or from its run time (view cut).
* ``render_to_file``, ``turntable``: what ``lodprt render`` and ``lodprt turntable`` do.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from lodprt.errors import LodprtError

log = logging.getLogger(__name__)

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


def fit_mvp(positions, *, eye, target, up, fov: float, size) -> np.ndarray:
    """4x4 projection @ view for the simple mesh renders: near and far bracket the positions' bounding sphere."""
    pos = np.asarray(positions, np.float64)
    radius = float(np.linalg.norm(pos.max(0) - pos.min(0))) if len(pos) else 0.0
    radius = radius or 1.0
    dist = float(np.linalg.norm(np.asarray(eye, float) - np.asarray(target, float)))
    width, height = size
    return perspective(fov, width / height, max(dist - 2 * radius, dist * 1e-3), dist + 2 * radius) @ look_at(eye, target, up)


def draw_mesh(prog, vertices: np.ndarray, layout: tuple, triangles, mvp: np.ndarray, size, background) -> np.ndarray:
    """Draw indexed triangles with ``prog`` (its uniforms already set but ``mvp``) on ``prog.ctx`` into a new RGB8
    framebuffer with depth test: (H, W, 3) uint8, first row on top. ``vertices`` (V, k) float32 interleaved as
    ``layout`` = (format, attribute names...)."""
    import moderngl

    ctx = prog.ctx
    width, height = check_size(size, ctx)
    prog["mvp"].write(np.asarray(mvp).T.astype(np.float32).tobytes())  # column-major
    vbo = ctx.buffer(np.ascontiguousarray(vertices, np.float32).tobytes())
    ibo = ctx.buffer(np.asarray(triangles, np.int32).tobytes())
    vao = ctx.vertex_array(prog, [(vbo, *layout)], index_buffer=ibo)
    fbo = ctx.simple_framebuffer((width, height), components=3)
    fbo.use()
    ctx.enable(moderngl.DEPTH_TEST)
    fbo.clear(*background, depth=1.0)
    vao.render(moderngl.TRIANGLES)
    img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(height, width, 3)
    return img[::-1].copy()  # OpenGL's first row is the bottom


def check_size(size, ctx=None) -> tuple[int, int]:
    """(width, height) as ints, LodprtError unless both are >= 1 and, with a moderngl ``ctx``, within its largest
    renderbuffer and viewport (GL_MAX_RENDERBUFFER_SIZE, GL_MAX_VIEWPORT_DIMS)."""
    try:
        width, height = (int(x) for x in size)
    except (TypeError, ValueError) as exc:
        raise LodprtError(f"size {size!r}: expected two integers (width height)") from exc
    if width < 1 or height < 1:
        raise LodprtError(f"size {size}: width and height must be >= 1")
    if ctx is not None:
        info = ctx.info
        dims = info.get("GL_MAX_VIEWPORT_DIMS") or (1 << 30, 1 << 30)
        side = int(info.get("GL_MAX_RENDERBUFFER_SIZE") or 1 << 30)
        max_w, max_h = min(side, int(dims[0])), min(side, int(dims[1]))
        if width > max_w or height > max_h:
            raise LodprtError(f"size {width} x {height}: this OpenGL context ({info.get('GL_RENDERER', 'unknown')}) "
                              f"draws at most {max_w} x {max_h} pixels (GL_MAX_RENDERBUFFER_SIZE, "
                              f"GL_MAX_VIEWPORT_DIMS)")
    return width, height


def render(positions, triangles, colors, *, eye, target, up=(0.0, 1.0, 0.0), fov=40.0, size=(800, 600),
           background=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Render triangles (M, 3) over positions (V, 3) with per-vertex colours (V, 3) in [0, 1]: (H, W, 3) uint8."""
    size = check_size(size)
    pos = np.asarray(positions, np.float32)
    col = np.clip(np.asarray(colors, np.float32), 0, 1)
    mvp = fit_mvp(pos, eye=eye, target=target, up=up, fov=fov, size=size)
    ctx = create_context()
    try:
        prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        return draw_mesh(prog, np.hstack([pos, col]), ("3f 3f", "in_pos", "in_col"), triangles, mvp, size, background)
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


# ---------------------------------------------------------------------------------------------------------------
# Frames: the renderer draws ``lodprt.runtime.Frame`` objects.
#
# Tone mapping (display output): display = sRGB(clip(2**exposure * L / white, 0, 1)), L the linear radiance, ``white``
# the radiance that maps to display 1 (default: the 99th percentile of the frame's positive per-vertex radiance,
# the same rule as ``tone_map``), sRGB the IEC 61966-2-1 transfer curve. Linear output writes L itself (float32,
# background 0, no overlays).

_MAX_ORDER = 8  # SH bands the shader evaluates (GLSL code is generated per order, see _sh_glsl)


def _sh_glsl(order: int) -> str:
    """GLSL ``void sh_basis(vec3 d, out float y[N])``: the real SH basis of lodprt.model.sh (T-5, no Condon-Shortley
    phase), unrolled for ``order`` bands with float64-computed constants (Q recurrence of the lodprt.model.sh docstring)."""
    n = order * order

    def g(v) -> str:  # a GLSL float literal with every digit a float32 can use
        return f"{float(v):.9e}"

    lines = [f"void sh_basis(vec3 d, out float y[{n}]) {{", "    float x = d.x, yy = d.y, z = d.z;",
             "    float re0 = 1.0, im0 = 0.0;"]
    for m in range(1, order):
        lines.append(f"    float re{m} = re{m - 1} * x - im{m - 1} * yy, im{m} = re{m - 1} * yy + im{m - 1} * x;")
    qmm = 1.0 / np.sqrt(4.0 * np.pi)
    for m in range(order):
        if m > 0:
            qmm *= np.sqrt((2.0 * m + 1.0) / (2.0 * m))
        for l in range(m, order):
            if l == m:
                expr = g(qmm)
            elif l == m + 1:
                expr = f"{g(np.sqrt(2.0 * m + 3.0))} * z * q{m}_{m}"
            else:
                a = np.sqrt((4.0 * l * l - 1.0) / (l * l - m * m))
                b = np.sqrt(((l - 1.0) ** 2 - m * m) / (4.0 * (l - 1.0) ** 2 - 1.0))
                expr = f"{g(a)} * (z * q{l - 1}_{m} - {g(b)} * q{l - 2}_{m})"
            lines.append(f"    float q{l}_{m} = {expr};")
            if m == 0:
                lines.append(f"    y[{l * (l + 1)}] = q{l}_0;")
            else:
                lines.append(f"    y[{l * (l + 1) + m}] = {g(np.sqrt(2.0))} * q{l}_{m} * re{m};")
                lines.append(f"    y[{l * (l + 1) - m}] = {g(np.sqrt(2.0))} * q{l}_{m} * im{m};")
    lines.append("}")
    return "\n".join(lines)


_FRAME_COMMON = """
#version 330
uniform sampler2D coef;      // (V * NCOEF) RGB32F texels, texel v * NCOEF + i = coefficient i of vertex v
uniform int tex_width;
uniform vec3 eye;
vec3 coef_at(int v, int i) {{
    int t = v * NCOEF + i;
    return texelFetch(coef, ivec2(t % tex_width, t / tex_width), 0).rgb;
}}
{sh}
vec3 radiance(ivec3 v, vec3 w, vec3 d) {{  // T-7 for the coefficients sum_k w_k c(v_k) at direction d
    float y[NCOEF];
    sh_basis(d, y);
    vec3 L = vec3(0.0);
    for (int i = 0; i < NCOEF; ++i) L += (w.x * coef_at(v.x, i) + w.y * coef_at(v.y, i) + w.z * coef_at(v.z, i)) * y[i];
    return L;
}}
vec3 view_dir(vec3 p, vec3 n) {{
    vec3 d = eye - p;
    float len = length(d);
    return len > 0.0 ? d / len : n;  // an eye on the point looks along the normal (as lodprt.store.radiance_toward)
}}
"""

_FRAME_VERTEX = """
uniform mat4 mvp;
in vec3 in_pos;
in vec3 in_nrm;
out vec3 v_pos;
out vec3 v_rad;
flat out int v_id;
#ifdef COEF_VARYINGS
out VertexCoef { vec3 c[NCOEF]; } vs_c;  // fetched once per vertex, interpolated by the rasteriser
#endif
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_pos = in_pos;
    v_id = gl_VertexID;
#ifdef COEF_VARYINGS
    for (int i = 0; i < NCOEF; ++i) vs_c.c[i] = coef_at(gl_VertexID, i);
#endif
#ifdef PER_VERTEX
    v_rad = radiance(ivec3(gl_VertexID), vec3(1.0, 0.0, 0.0), view_dir(in_pos, in_nrm));
#else
    v_rad = in_nrm;  // the normal, for the fragment stage's degenerate view direction
#endif
}
"""

_FRAME_GEOMETRY = """
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
in vec3 v_pos[];
in vec3 v_rad[];
flat in int v_id[];
out vec3 g_pos;
out vec3 g_rad;
out vec3 g_bary;
flat out ivec3 g_ids;
#ifdef COEF_VARYINGS
in VertexCoef { vec3 c[NCOEF]; } gs_in[];
out FragmentCoef { vec3 c[NCOEF]; } gs_c;
#endif
void main() {
    for (int k = 0; k < 3; ++k) {
#ifdef COEF_VARYINGS
        for (int i = 0; i < NCOEF; ++i) gs_c.c[i] = gs_in[k].c[i];
#endif
        gl_Position = gl_in[k].gl_Position;
        g_pos = v_pos[k];
        g_rad = v_rad[k];
        g_bary = vec3(k == 0, k == 1, k == 2);
        g_ids = ivec3(v_id[0], v_id[1], v_id[2]);
        EmitVertex();
    }
    EndPrimitive();
}
"""

_FRAME_FRAGMENT = """
uniform bool linear_out;     // true: write linear radiance (float target); false: tone-mapped sRGB
uniform float scale;         // 2^exposure / white
uniform bool wireframe;
uniform vec3 wire_color;
in vec3 g_pos;
in vec3 g_rad;
in vec3 g_bary;
flat in ivec3 g_ids;
#ifdef COEF_VARYINGS
in FragmentCoef { vec3 c[NCOEF]; } fs_c;
#endif
out vec4 f_col;
vec3 srgb(vec3 x) { return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, x)); }
void main() {
#if defined(PER_VERTEX)
    vec3 L = g_rad;
#elif defined(COEF_VARYINGS)
    vec3 d = view_dir(g_pos, normalize(g_rad));
    float y[NCOEF];
    sh_basis(d, y);
    vec3 L = vec3(0.0);
    for (int i = 0; i < NCOEF; ++i) L += fs_c.c[i] * y[i];  // interpolated coefficients at this view direction
#else
    vec3 d = view_dir(g_pos, normalize(g_rad));
    vec3 L = radiance(g_ids, g_bary, d);  // interpolated coefficients, evaluated at this fragment's view direction
#endif
    if (linear_out) { f_col = vec4(L, 1.0); return; }
    vec3 c = srgb(clamp(L * scale, 0.0, 1.0));
    if (wireframe) {  // edges from the barycentrics: about one pixel wide, antialiased
        float e = min(min(g_bary.x, g_bary.y), g_bary.z);
        c = mix(c, wire_color, 0.8 * (1.0 - smoothstep(0.0, 1.0, e / max(fwidth(e), 1e-8))));
    }
    f_col = vec4(c, 1.0);
}
"""

_MARKER_VERTEX = """
#version 330
uniform mat4 mvp;
uniform float point_size;
in vec3 in_pos;
in vec3 in_col;
out vec3 v_col;
void main() { gl_Position = mvp * vec4(in_pos, 1.0); gl_PointSize = point_size; v_col = in_col; }
"""
_MARKER_FRAGMENT = """
#version 330
in vec3 v_col;
out vec4 f_col;
void main() {  // a disc in the light's colour with a dark rim
    float r = length(gl_PointCoord - vec2(0.5)) * 2.0;
    if (r > 1.0) discard;
    f_col = vec4(r > 0.7 ? vec3(0.05) : v_col, 1.0);
}
"""


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
        f = max(float(depth.max()) * 1.01, 1e-6) if far is None else far
        near = max(float(depth.min()) * 0.99, f * 1e-3) if near is None else near
        far = max(f, near * 1.0001)
    return view, perspective(camera.fov, camera.width / camera.height, near, far)


def auto_white(radiance) -> float:
    """The default white point: 99th percentile of the positive entries of ``radiance`` (1 when there are none)."""
    r = np.asarray(radiance, np.float64)
    pos = r[r > 0]
    return float(np.percentile(pos, 99)) if pos.size else 1.0


def _srgb(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0), 1 / 2.4) - 0.055)


def create_context(backend: str = "egl"):
    """A headless moderngl context (EGL: Mesa llvmpipe without a GPU); LodprtError saying what is missing."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a dependency
        raise LodprtError(f"moderngl is not installed ({exc})") from exc
    try:
        return moderngl.create_standalone_context(require=330, backend=backend)
    except Exception as exc:
        raise LodprtError(f"cannot create an offscreen OpenGL 3.3 context ({backend.upper()}): {exc}") from exc


class Renderer:
    """Draws ``lodprt.runtime.Frame`` objects with moderngl, offscreen or into a window's framebuffer.

    ``ctx`` None creates a headless EGL context (released by ``release()``); a viewer passes its window's context
    and draws with ``draw(frame, target=ctx.screen)``. Radiance is reconstructed in the shader from the frame's SH
    coefficients (any order up to 8; fetched from a float texture by vertex index): per fragment from the
    barycentric interpolation of the three vertices' coefficients evaluated at the fragment's own view direction
    (default), or per vertex (``per_vertex=True``: T-7 at each vertex, colours interpolated, which is exactly
    ``Frame.radiance`` when the camera is the frame's). Tone mapping is the module's (see above).
    """

    def __init__(self, ctx=None, *, backend: str = "egl"):
        self.ctx = ctx if ctx is not None else create_context(backend)
        self._owns = ctx is None
        self._programs: dict = {}
        self._fbos: dict = {}
        self._uploaded = None  # (id(frame), buffers) of the last frame sent to the GPU
        self._marker = self.ctx.program(vertex_shader=_MARKER_VERTEX, fragment_shader=_MARKER_FRAGMENT)

    # -- resources ------------------------------------------------------------------------------------------
    def _program(self, ncoef: int, per_vertex: bool):
        key = (ncoef, per_vertex)
        if key not in self._programs:
            order = int(round(np.sqrt(ncoef)))
            if order * order != ncoef or not 1 <= order <= _MAX_ORDER:
                raise LodprtError(f"frame coefficients: {ncoef} per channel; the renderer needs a square number "
                                  f"of at most {_MAX_ORDER * _MAX_ORDER} (SH order 1..{_MAX_ORDER})")
            common = _FRAME_COMMON.format(ncoef=ncoef, sh=_sh_glsl(order))
            defines = f"#version 330\n#define NCOEF {ncoef}\n"
            info = self.ctx.info
            limit = min(int(info.get(k, 64)) for k in ("GL_MAX_GEOMETRY_OUTPUT_COMPONENTS",
                                                       "GL_MAX_FRAGMENT_INPUT_COMPONENTS"))
            if per_vertex:
                defines += "#define PER_VERTEX\n"
            elif 4 * (ncoef + 4) <= min(limit, 4 * int(info.get("GL_MAX_VARYING_VECTORS", 15))):
                defines += "#define COEF_VARYINGS\n"  # coefficients fit the varyings (order <= 5 on llvmpipe)
            common = common.replace("#version 330\n", defines, 1)
            self._programs[key] = self.ctx.program(vertex_shader=common + _FRAME_VERTEX,
                                                   geometry_shader=defines + _FRAME_GEOMETRY,
                                                   fragment_shader=common + _FRAME_FRAGMENT)
        return self._programs[key]

    def _upload(self, frame):
        if self._uploaded is not None and self._uploaded[0] is frame:
            return self._uploaded[1]
        self._free_upload()
        pos = np.ascontiguousarray(frame.positions, np.float32)
        tri = np.ascontiguousarray(frame.triangles, np.int32)
        coef = np.asarray(frame.coefficients, np.float32)
        a = len(pos)
        if pos.ndim != 2 or pos.shape[1] != 3:
            raise LodprtError(f"frame positions: expected (A, 3), got {pos.shape}")
        if tri.ndim != 2 or tri.shape[1] != 3 or (tri.size and (tri.min() < 0 or tri.max() >= a)):
            raise LodprtError(f"frame triangles: expected (M, 3) indices into {a} positions, got shape {tri.shape}")
        if coef.ndim != 3 or coef.shape[0] != a or coef.shape[1] not in (1, 3):
            raise LodprtError(f"frame coefficients: expected ({a}, 3, ncoef) (or 1 channel), got {coef.shape}")
        nrm = np.ascontiguousarray(frame.normals, np.float32) if frame.normals is not None else np.zeros_like(pos)
        ncoef = coef.shape[2]
        texels = np.broadcast_to(coef, (a, 3, ncoef)).transpose(0, 2, 1).reshape(-1, 3)
        width = min(4096, int(self.ctx.info["GL_MAX_TEXTURE_SIZE"]))
        height = max(1, -(-len(texels) // width))
        if height > int(self.ctx.info["GL_MAX_TEXTURE_SIZE"]):
            raise LodprtError(f"frame: {a} vertices x {ncoef} coefficients do not fit one {width}-wide texture")
        data = np.zeros((height * width, 3), np.float32)
        data[: len(texels)] = texels
        tex = self.ctx.texture((width, height), 3, data.tobytes(), dtype="f4")
        vbo = self.ctx.buffer(np.hstack([pos, nrm]).tobytes() if a else b"\0" * 24)
        ibo = self.ctx.buffer(tri.tobytes() if tri.size else b"\0" * 12)
        up = {"tex": tex, "width": width, "vbo": vbo, "ibo": ibo, "ncoef": ncoef, "count": tri.size, "vaos": {}}
        self._uploaded = (frame, up)
        return up

    def _free_upload(self):
        if self._uploaded is not None:
            up = self._uploaded[1]
            for vao in up["vaos"].values():
                vao.release()
            for k in ("tex", "vbo", "ibo"):
                up[k].release()
            self._uploaded = None

    def _offscreen(self, size: tuple[int, int], linear: bool):
        key = (size, linear)
        if key not in self._fbos:
            for old in [k for k in self._fbos if k[1] == linear]:  # one cached target per kind
                self._release_fbo(self._fbos.pop(old))
            size = check_size(size, self.ctx)
            colour = self.ctx.renderbuffer(size, 4, dtype="f4" if linear else "f1")
            try:
                self._fbos[key] = self.ctx.framebuffer([colour], self.ctx.depth_renderbuffer(size))
            except Exception as exc:  # moderngl.Error: out of memory for a size within the limits
                colour.release()
                raise LodprtError(f"size {size[0]} x {size[1]}: cannot make an offscreen framebuffer ({exc})") from exc
        return self._fbos[key]

    @staticmethod
    def _release_fbo(fbo) -> None:
        attachments = (*fbo.color_attachments, fbo.depth_attachment)
        fbo.release()
        for att in attachments:
            att.release()

    # -- drawing --------------------------------------------------------------------------------------------
    def draw(self, frame, *, target=None, camera=None, per_vertex: bool = False, linear: bool = False,
             exposure: float = 0.0, white: float | None = None, wireframe: bool = False,
             wire_color=(0.0, 0.8, 1.0), light_markers: bool = True, background=(0.0, 0.0, 0.0)) -> dict:
        """Draw ``frame`` seen by ``camera`` (default ``frame.camera``) into ``target`` (a moderngl framebuffer;
        default an offscreen one of the camera's size, RGBA8, or RGBA32F with ``linear``).

        ``linear``: raw radiance, background 0, no wireframe or markers. Otherwise tone-mapped sRGB with
        ``exposure`` (stops) and ``white`` (None: ``auto_white(frame.radiance)``), ``wireframe`` edges of the
        frame's triangles, light markers at ``frame.lights``. Returns {"white", "triangles", "gl_error"}.
        """
        import moderngl

        cam = camera if camera is not None else frame.camera
        size = (int(cam.width), int(cam.height))
        if target is None:
            target = self._offscreen(size, linear)
        up = self._upload(frame)
        pos = np.asarray(frame.positions, np.float64)
        lights = np.asarray(frame.lights, np.float64).reshape(-1, 3) if frame.lights is not None else np.zeros((0, 3))
        view, proj = camera_matrices(cam, np.vstack([pos, lights]) if light_markers and not linear else pos)
        mvp = (proj @ view).T.astype(np.float32).tobytes()  # column-major
        if white is None:
            white = auto_white(frame.radiance)
        if not (np.isfinite(white) and white > 0 and np.isfinite(exposure)):
            raise LodprtError(f"tone mapping: white {white!r} must be > 0 and exposure {exposure!r} finite")
        target.use()
        target.viewport = (0, 0) + size
        ctx = self.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        bg = (0.0, 0.0, 0.0) if linear else tuple(float(c) for c in background)
        target.clear(*bg, 1.0, depth=1.0)
        if up["count"]:
            prog = self._program(up["ncoef"], per_vertex)
            vao = up["vaos"].get(per_vertex)
            if vao is None:
                layout = (up["vbo"], "3f 3f", "in_pos", "in_nrm") if "in_nrm" in prog else (up["vbo"], "3f 12x", "in_pos")
                vao = up["vaos"][per_vertex] = ctx.vertex_array(prog, [layout], index_buffer=up["ibo"],
                                                                index_element_size=4)  # order 1 ignores normals
            prog["mvp"].write(mvp)
            uniforms = {"eye": tuple(float(x) for x in cam.eye), "tex_width": up["width"], "linear_out": bool(linear),
                        "scale": float(2.0**exposure / white), "wireframe": bool(wireframe),
                        "wire_color": tuple(float(c) for c in wire_color), "coef": 0}
            for name, value in uniforms.items():
                if name in prog:  # the GLSL compiler drops unused ones (order 1 has no view dependence)
                    prog[name].value = value
            up["tex"].use(0)
            vao.render(moderngl.TRIANGLES, vertices=up["count"])
        if light_markers and not linear and len(lights):
            col = np.asarray(frame.light_colors, np.float64).reshape(-1, 3) if frame.light_colors is not None \
                else np.ones_like(lights)
            col = col / np.maximum(col.max(1, keepdims=True), 1e-12)
            col = np.where(col.max(1, keepdims=True) > 0, 0.35 + 0.65 * col, 1.0)  # visible even for dim lights
            buf = ctx.buffer(np.hstack([lights, col]).astype(np.float32).tobytes())
            vao = ctx.vertex_array(self._marker, [(buf, "3f 3f", "in_pos", "in_col")])
            self._marker["mvp"].write(mvp)
            self._marker["point_size"].value = float(max(7, min(size) // 40))
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.PROGRAM_POINT_SIZE)
            vao.render(moderngl.POINTS)
            ctx.enable(moderngl.DEPTH_TEST)
            vao.release()
            buf.release()
        return {"white": float(white), "triangles": int(up["count"] // 3), "gl_error": ctx.error}

    def image(self, frame, *, linear: bool = False, **kw) -> np.ndarray:
        """Draw offscreen and read back: (H, W, 3) uint8 sRGB, or float32 linear radiance with ``linear``;
        row 0 is the top of the image. Keywords as ``draw``."""
        cam = kw.get("camera") or frame.camera
        size = (int(cam.width), int(cam.height))
        info = self.draw(frame, linear=linear, **kw)
        if info["gl_error"] != "GL_NO_ERROR":
            raise LodprtError(f"OpenGL error while drawing: {info['gl_error']}")
        fbo = self._offscreen(size, linear)
        if linear:
            img = np.frombuffer(fbo.read(components=3, dtype="f4"), np.float32).reshape(size[1], size[0], 3)
        else:
            img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)
        return img[::-1].copy()  # OpenGL's first row is the bottom

    def release(self) -> None:
        """Free the GPU resources (and the context when this renderer created it)."""
        self._free_upload()
        for fbo in self._fbos.values():
            self._release_fbo(fbo)
        self._fbos = {}
        for prog in self._programs.values():
            prog.release()
        self._programs = {}
        if self._owns:
            self.ctx.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


# ---------------------------------------------------------------------------------------------------------------
# Full-resolution frames straight from a store ("LOD off"): every referenced vertex, no view cut.


def full_frame(store, camera, *, lights=None, colors=None, sample: int | None = None):
    """A ``lodprt.runtime.Frame`` with every referenced vertex of ``store`` and its completed coefficients.

    Either ``sample`` (one light exactly at light sample K, that sample's coefficients) or ``lights`` (L, 3)
    positions, each interpolated from its nearest samples (``lodprt.runtime.light_coefficients``: the run time's
    T-12 weights, clamped into the sampled region). ``colors`` (L, 3) RGB
    intensities (default the store's); the frame's coefficients carry them (linear radiance).
    """
    from lodprt.runtime.session import Frame, light_coefficients
    from lodprt.store.bake_store import radiance_toward

    faces = store.faces
    ids = np.unique(faces.ravel()).astype(np.int32)
    remap = np.full(store.num_vertices, -1, np.int64)
    remap[ids] = np.arange(len(ids))
    if sample is not None:
        store.check_sample(sample)
        lights = store.light_positions[sample][None, :].astype(np.float64)
        colors = np.broadcast_to(store.intensity if colors is None else np.asarray(colors, np.float64),
                                 lights.shape).astype(np.float64)
        coeffs = store.coefficients(sample)[ids] * colors[0][None, :, None]
    else:
        lights = np.asarray(lights, np.float64).reshape(-1, 3)
        if not len(lights) or not np.isfinite(lights).all():
            raise LodprtError(f"lights: expected (L, 3) finite positions, L >= 1, got {lights.tolist()}")
        lights, colors, coeffs = light_coefficients(store, lights, colors=colors)
        coeffs = coeffs[ids]
    pos = store.positions[ids].astype(np.float32)
    nrm = store.normals[ids].astype(np.float32)
    rad = radiance_toward(pos, nrm, coeffs, camera.eye, np.ones(3))
    return Frame(vertex_ids=ids, positions=pos, normals=nrm, triangles=remap[faces].astype(np.int32),
                 coefficients=coeffs.astype(np.float32), radiance=rad, lights=lights.copy(),
                 light_colors=colors.copy(), camera=camera,
                 stats={"triangles": len(faces), "active_nodes": len(ids), "lod": False})


class StoreFrames:
    """The ``Runtime`` interface (set_lights, set_camera, set_lod, set_error_bound, update) over ``full_frame``,
    for stores baked without a hierarchy: always full resolution (no view cut)."""

    lod = False

    def __init__(self, store):
        self.store = store
        self.white = None
        self.camera = None
        self._lights = store.light_positions[store.num_samples // 2][None, :]
        self._colors = None

    def set_lights(self, positions, colors=None) -> None:
        self._lights, self._colors = np.asarray(positions, np.float64).reshape(-1, 3), colors

    def set_camera(self, camera) -> None:
        self.camera = camera

    def set_lod(self, enabled: bool) -> None:
        if enabled:
            log.warning("%s has no hierarchy: LOD is not available, showing full resolution", self.store.path)

    def set_error_bound(self, error_bound: float, alpha: float | None = None) -> None:
        pass

    def update(self):
        t0 = time.perf_counter()
        frame = full_frame(self.store, self.camera, lights=self._lights, colors=self._colors)
        if self.white is None:
            self.white = auto_white(frame.radiance)
        frame.stats["ms_total"] = 1e3 * (time.perf_counter() - t0)
        return frame


def frame_source(store, *, error_bound: float | None = None, alpha: float = 0.6, lod: bool = True,
                 criterion: str = "screen"):
    """What the display draws from: the run time (``store.runtime``: moving lights, view-dependent cut; ``lod``
    False starts with the full mesh) when the store has a hierarchy, else ``StoreFrames`` (full resolution)."""
    if store.has_hierarchy:
        from lodprt.runtime.session import Runtime

        return Runtime(store, error_bound=error_bound, alpha=alpha, lod=lod, criterion=criterion)
    if lod:
        log.warning("%s: no hierarchy (or no run time): drawing full resolution", store.path)
    return StoreFrames(store)


def check_output(path, suffixes: tuple[str, ...], *, overwrite: bool) -> Path:
    """The output path, refused (LodprtError naming it) for a wrong suffix, a missing folder, or an existing file
    without ``overwrite``."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise LodprtError(f"{path}: the output must end in {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise LodprtError(f"{path}: the folder {path.parent} does not exist")
    if path.exists() and not overwrite:
        raise LodprtError(f"{path}: already exists; pass --overwrite to replace it")
    return path


def scene_centre(store) -> tuple[float, float, float]:
    """Centre of the bounding box of the vertices the faces use (the default look-at point)."""
    p = store.positions[np.unique(store.faces.ravel())]
    return tuple(float(x) for x in 0.5 * (p.min(0) + p.max(0)))


def save_image(path, image: np.ndarray) -> None:
    """(H, W, 3) uint8 -> PNG, or float32 linear -> .npy."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        np.save(path, np.asarray(image, np.float32))
    else:
        from PIL import Image

        Image.fromarray(np.asarray(image, np.uint8)).save(path)


def default_eye(store) -> tuple[float, float, float]:
    """A three-quarter view from the front (+z) and above that frames the scene at a 40-degree field of view."""
    p = store.positions[np.unique(store.faces.ravel())]
    c = 0.5 * (p.min(0) + p.max(0))
    r = 0.5 * float(np.linalg.norm(p.max(0) - p.min(0))) or 1.0
    return tuple(float(x) for x in c + r * np.array([0.5, 0.9, 1.9]))


def render_to_file(store, out, *, lights, camera, colors=None, error_bound: float | None = None, alpha: float = 0.6,
                   criterion: str = "screen",
                   lod: bool = True, overwrite: bool = False, **draw) -> dict:
    """``lodprt render``: one frame of ``store`` (view cut unless ``lod`` is False) to ``out`` (.png tone-mapped,
    .npy linear (H, W, 3) float32). ``draw`` keywords go to ``Renderer.draw``. Returns the frame's stats."""
    out = check_output(out, (".png", ".npy"), overwrite=overwrite)
    source = frame_source(store, error_bound=error_bound, alpha=alpha, lod=lod, criterion=criterion)
    source.set_lights(lights, colors)
    source.set_camera(camera)
    frame = source.update()
    linear = out.suffix.lower() == ".npy"
    if draw.get("white") is None and not linear:
        draw["white"] = source.white or auto_white(frame.radiance)
    with Renderer() as renderer:
        t0 = time.perf_counter()
        image = renderer.image(frame, linear=linear, **draw)
        ms = 1e3 * (time.perf_counter() - t0)
    save_image(out, image)
    return dict(frame.stats, ms_draw=ms, lod=bool(getattr(source, "lod", False)))


def orbit(camera, angle: float):
    """``camera`` turned by ``angle`` radians about the vertical (``up``) axis through its target."""
    import dataclasses

    return dataclasses.replace(camera, eye=tuple(_rotate_about(camera.eye, camera.target, camera.up, angle)))


def _rotate_about(point, centre, axis, angle: float) -> np.ndarray:
    """Rodrigues rotation of ``point`` about the line through ``centre`` along ``axis``."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    v = np.asarray(point, np.float64) - np.asarray(centre, np.float64)
    c, s = np.cos(angle), np.sin(angle)
    return np.asarray(centre, np.float64) + v * c + np.cross(k, v) * s + k * np.dot(k, v) * (1 - c)


def turntable(store, out, *, lights, camera, colors=None, frames: int = 36, light_turns: float = 1.0,
              fps: float = 12.0, error_bound: float | None = None, alpha: float = 0.6, lod: bool = True,
              criterion: str = "screen",
              overwrite: bool = False, **draw) -> Path:
    """``lodprt turntable``: ``frames`` views of one camera orbit about the target's vertical axis, the lights
    turning ``light_turns`` times the other way about the same axis (clamped to the sampled light region by the
    run time). ``out`` a folder (created; frame_0000.png, ...) or a .gif (imageio). One run time for the whole
    orbit, so the view cut moves incrementally from frame to frame and the white point stays fixed."""
    out = Path(out)
    if frames < 1:
        raise LodprtError(f"--frames {frames}: must be >= 1")
    gif = out.suffix.lower() == ".gif"
    if gif:
        check_output(out, (".gif",), overwrite=overwrite)
        import imageio.v3 as iio
    elif out.suffix:
        raise LodprtError(f"{out}: give a folder (PNG sequence) or a .gif path")
    elif out.exists() and (not out.is_dir() or (any(out.iterdir()) and not overwrite)):
        raise LodprtError(f"{out}: already exists and is not an empty folder; pass --overwrite to write into it")
    elif not out.parent.is_dir():
        raise LodprtError(f"{out}: the folder {out.parent} does not exist")
    lights = np.asarray(lights, np.float64).reshape(-1, 3)
    source = frame_source(store, error_bound=error_bound, alpha=alpha, lod=lod, criterion=criterion)
    images = []
    with Renderer() as renderer:
        for k in range(frames):
            a = 2 * np.pi * k / frames
            source.set_lights([_rotate_about(p, camera.target, camera.up, -light_turns * a) for p in lights], colors)
            source.set_camera(orbit(camera, a))
            frame = source.update()
            kw = dict(draw)
            if kw.get("white") is None:
                kw["white"] = source.white or auto_white(frame.radiance)
            img = renderer.image(frame, **kw)
            if gif:
                images.append(img)
            else:
                out.mkdir(exist_ok=True)
                save_image(out / f"frame_{k:04d}.png", img)
    if gif:
        iio.imwrite(out, np.stack(images), duration=1000.0 / fps, loop=0)
    return out
