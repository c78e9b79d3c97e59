"""The 9-coefficient irradiance (I-7, the seed's 7-register vertex program) in GLSL 330, run through moderngl (EGL
offscreen): :func:`irradiance_gl` evaluates it per normal (tests), :func:`render_irradiance` draws a diffuse mesh lit
by it. The maths is :mod:`lodprt.model.irradiance`."""

from __future__ import annotations

import numpy as np

from lodprt.model.irradiance import shader_constants, unit_normals

#: GLSL 330 function ``vec3 irradiance(vec3 n)`` over the seed's 7 registers (uniforms of the same names)
GLSL_IRRADIANCE = """
uniform vec4 cAr; uniform vec4 cAg; uniform vec4 cAb;
uniform vec4 cBr; uniform vec4 cBg; uniform vec4 cBb;
uniform vec4 cC;
vec3 irradiance(vec3 n) {
    vec4 a = vec4(n, 1.0);
    vec3 e1 = vec3(dot(cAr, a), dot(cAg, a), dot(cAb, a));          // constant and linear terms
    vec4 b = n.xyzz * n.yzzx;                                         // (xy, yz, z^2, zx)
    vec3 e2 = vec3(dot(cBr, b), dot(cBg, b), dot(cBb, b));          // four quadratic terms
    vec3 e3 = cC.rgb * (n.x * n.x - n.y * n.y);                       // the last one
    return e1 + e2 + e3;
}
"""

_POINTS_VS = (
    "#version 330\n"
    + GLSL_IRRADIANCE
    + """
uniform ivec2 grid;
in vec3 in_normal;
out vec3 v_e;
void main() {
    int k = gl_VertexID;
    vec2 px = vec2(k % grid.x, k / grid.x) + 0.5;
    gl_Position = vec4(2.0 * px / vec2(grid) - 1.0, 0.0, 1.0);
    gl_PointSize = 1.0;
    v_e = irradiance(normalize(in_normal));
}
"""
)
_POINTS_FS = """
#version 330
in vec3 v_e;
out vec4 f_col;
void main() { f_col = vec4(v_e, 1.0); }
"""


def _set_registers(prog, coeffs) -> None:
    for name, value in shader_constants(coeffs).items():
        if name in prog:
            prog[name].value = tuple(float(x) for x in value)


def irradiance_gl(normals, coeffs) -> np.ndarray:
    """E(n) evaluated by :data:`GLSL_IRRADIANCE` on the GPU (moderngl, EGL): normals (N, 3) -> (N, 3) float32.

    Each normal is drawn as one point into its own pixel of a float32 framebuffer and read back.
    """
    n = unit_normals(normals).reshape(-1, 3).astype(np.float32)
    if len(n) == 0:
        return np.zeros((0, 3), np.float32)
    from lodprt.display.render import create_context

    width = min(len(n), 1024)
    height = -(-len(n) // width)
    ctx = create_context()
    try:
        prog = ctx.program(vertex_shader=_POINTS_VS, fragment_shader=_POINTS_FS)
        _set_registers(prog, coeffs)
        prog["grid"].value = (width, height)
        vbo = ctx.buffer(n.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f", "in_normal")])
        tex = ctx.texture((width, height), 4, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[tex])
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao.render(mode=ctx.POINTS, vertices=len(n))
        img = np.frombuffer(tex.read(), np.float32).reshape(height, width, 4)
        return img.reshape(-1, 4)[: len(n), :3].copy()
    finally:
        ctx.release()


_SHADE_VS = (
    "#version 330\n"
    + GLSL_IRRADIANCE
    + """
uniform mat4 mvp;
uniform float exposure;
in vec3 in_pos;
in vec3 in_normal;
in vec3 in_albedo;
out vec3 v_col;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_col = exposure * in_albedo * irradiance(normalize(in_normal)) / 3.14159265358979;  // kd E / pi
}
"""
)
_SHADE_FS = """
#version 330
in vec3 v_col;
out vec4 f_col;
void main() {
    vec3 x = clamp(v_col, 0.0, 1.0);                                   // display white = 1 / exposure
    vec3 s = mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, x));
    f_col = vec4(s, 1.0);
}
"""


def render_irradiance(positions, triangles, normals, coeffs, *, albedo=(0.8, 0.8, 0.8), eye, target,
                      up=(0.0, 1.0, 0.0), fov=40.0, size=(800, 600), exposure=1.0,
                      background=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Render a diffuse mesh lit by the 9-coefficient irradiance, evaluated per vertex in the GLSL shader.

    positions, normals (V, 3); triangles (M, 3); albedo (3,) or (V, 3); radiance ``kd E / pi`` is scaled by
    ``exposure``, clipped to [0, 1] and sRGB-encoded in the fragment shader. Returns (H, W, 3) uint8, first row
    on top; camera as in :func:`lodprt.display.render.render`.
    """
    from lodprt.display.render import check_size, create_context, draw_mesh, fit_mvp

    size = check_size(size)
    pos = np.asarray(positions, np.float32)
    nrm = np.asarray(normals, np.float32)
    alb = np.broadcast_to(np.asarray(albedo, np.float32), pos.shape).astype(np.float32)
    mvp = fit_mvp(pos, eye=eye, target=target, up=up, fov=fov, size=size)
    ctx = create_context()
    try:
        prog = ctx.program(vertex_shader=_SHADE_VS, fragment_shader=_SHADE_FS)
        _set_registers(prog, coeffs)
        prog["exposure"].value = float(exposure)
        return draw_mesh(prog, np.hstack([pos, nrm, alb]), ("3f 3f 3f", "in_pos", "in_normal", "in_albedo"),
                         triangles, mvp, size, background)
    finally:
        ctx.release()
