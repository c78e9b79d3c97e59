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

import functools
import logging
import threading

import numpy as np

from lodprt.errors import LodprtError
from lodprt.runtime.camera import camera_matrices, look_at, perspective
from lodprt.runtime.frames import auto_white, tone_scale

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


def _srgb(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0), 1 / 2.4) - 0.055)


def create_context(backend: str = "egl"):
    """A headless moderngl context (EGL: Mesa llvmpipe without a GPU); LodprtError saying what is missing."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a dependency
        raise LodprtError(f"moderngl is not installed ({exc})") from exc
    try:
        ctx = moderngl.create_standalone_context(require=330, backend=backend)
    except Exception as exc:
        raise LodprtError(f"cannot create an offscreen OpenGL 3.3 context ({backend.upper()}): {exc}") from exc
    _CURRENT.ctx = ctx  # a new context is current
    return ctx


#: per thread, the moderngl context lodprt last made current (``create_context`` makes its new one current,
#: ``_make_current`` a renderer's before its GL calls)
_CURRENT = threading.local()


def _make_current(ctx) -> None:
    """Make ``ctx`` the thread's current OpenGL context unless lodprt made it so last. Making or releasing another
    (a second Renderer) leaves that one current, and this renderer's GL calls would go there (GL_INVALID_OPERATION
    on names it does not know). Entered without a matching exit: on EGL, moderngl's exit restores a saved context,
    and a nested enter and exit left the context drawing garbage (seen with moderngl 5.13)."""
    if getattr(_CURRENT, "ctx", None) is not ctx:
        ctx.__enter__()
        _CURRENT.ctx = ctx


def _in_context(method):
    """``method`` run with the renderer's context current (``_make_current``)."""
    @functools.wraps(method)
    def run(self, *args, **kw):
        _make_current(self.ctx)
        return method(self, *args, **kw)

    return run


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
        _make_current(self.ctx)
        self._owns = ctx is None
        self._programs: dict = {}
        self._fbos: dict = {}
        self._uploaded = None  # (id(frame), buffers) of the last frame sent to the GPU
        self._stand_in = None  # (frame, eye, stand-in) of ``_drawable``'s last order-above-the-shaders frame
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

    def _drawable(self, frame, cam, per_vertex: bool):
        """``frame``, or, for SH orders above the shaders' (_MAX_ORDER) drawn per vertex, a stand-in whose one
        coefficient per channel is the vertex's radiance toward ``cam``'s eye evaluated here (T-7 in numpy, any
        order) over y_0, which the shader's y_0 term gives back: the same picture. Per fragment such orders are a
        clear error naming ``--per-vertex``."""
        import dataclasses

        coef = np.asarray(frame.coefficients)
        if coef.ndim != 3 or coef.shape[2] <= _MAX_ORDER * _MAX_ORDER:
            return frame
        if not per_vertex:
            raise LodprtError(f"frame coefficients: {coef.shape[2]} per channel; per-fragment shading evaluates "
                              f"SH orders 1..{_MAX_ORDER}: draw it per vertex (--per-vertex, per_vertex=True)")
        eye = tuple(float(x) for x in cam.eye)
        held = self._stand_in
        if held is not None and held[0] is frame and held[1] == eye:
            return held[2]
        from lodprt.store.bake_store import radiance_toward

        pos = np.asarray(frame.positions)
        nrm = np.zeros_like(pos) if frame.normals is None else frame.normals
        rad = radiance_toward(pos, nrm, coef, eye, np.ones(3))  # (A, 3)
        y0 = 0.28209479177387814  # the constant SH basis function, 1 / (2 sqrt(pi))
        stand_in = dataclasses.replace(frame, coefficients=(rad / y0)[:, :, None].astype(np.float32))
        self._stand_in = (frame, eye, stand_in)
        return stand_in

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
            size = check_size(size, self.ctx)
            colour = self.ctx.renderbuffer(size, 4, dtype="f4" if linear else "f1")
            try:
                fbo = self.ctx.framebuffer([colour], self.ctx.depth_renderbuffer(size))
            except Exception as exc:  # moderngl.Error: out of memory for a size within the limits
                colour.release()
                raise LodprtError(f"size {size[0]} x {size[1]}: cannot make an offscreen framebuffer ({exc})") from exc
            # one cached target per kind; the new one is bound before the old is released: moderngl binds again
            # the framebuffer it last bound after making one, and a released name is GL_INVALID_OPERATION there
            fbo.use()
            for old in [k for k in self._fbos if k[1] == linear]:
                self._release_fbo(self._fbos.pop(old))
            self._fbos[key] = fbo
        return self._fbos[key]

    @staticmethod
    def _release_fbo(fbo) -> None:
        attachments = (*fbo.color_attachments, fbo.depth_attachment)
        fbo.release()
        for att in attachments:
            att.release()

    # -- drawing --------------------------------------------------------------------------------------------
    @_in_context
    def draw(self, frame, *, target=None, camera=None, per_vertex: bool = False, linear: bool = False,
             exposure: float = 0.0, white: float | None = None, wireframe: bool = False,
             wire_color=(0.0, 0.8, 1.0), light_markers: bool = True, background=(0.0, 0.0, 0.0)) -> dict:
        """Draw ``frame`` seen by ``camera`` (default ``frame.camera``) into ``target`` (a moderngl framebuffer;
        default an offscreen one of the camera's size, RGBA8, or RGBA32F with ``linear``).

        ``linear``: raw radiance, background 0, no wireframe or markers. Otherwise tone-mapped sRGB with
        ``exposure`` (stops) and ``white`` (None: ``frame.white``, the white of the Runtime that made the frame,
        one for all its frames; else ``auto_white(frame.radiance)``), ``wireframe`` edges of the
        frame's triangles, light markers at ``frame.lights``. Returns {"white", "triangles", "gl_error"}.
        """
        import moderngl

        cam = camera if camera is not None else frame.camera
        size = (int(cam.width), int(cam.height))
        if target is None:
            target = self._offscreen(size, linear)
        up = self._upload(self._drawable(frame, cam, per_vertex))
        pos = np.asarray(frame.positions, np.float64)
        lights = np.asarray(frame.lights, np.float64).reshape(-1, 3) if frame.lights is not None else np.zeros((0, 3))
        view, proj = camera_matrices(cam, np.vstack([pos, lights]) if light_markers and not linear else pos)
        mvp = (proj @ view).T.astype(np.float32).tobytes()  # column-major
        if white is None:
            white = getattr(frame, "white", None) or auto_white(frame.radiance)
        scale = tone_scale(white, exposure)
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
                        "scale": scale, "wireframe": bool(wireframe),
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

    @_in_context
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
        _make_current(self.ctx)  # freed in this renderer's context, whichever was current
        self._free_upload()
        for fbo in self._fbos.values():
            self._release_fbo(fbo)
        self._fbos = {}
        for prog in self._programs.values():
            prog.release()
        self._programs = {}
        if self._owns:
            self.ctx.release()
            _CURRENT.ctx = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


# ---------------------------------------------------------------------------------------------------------------
# Full-resolution frames straight from a store ("LOD off"): every referenced vertex, no view cut.


