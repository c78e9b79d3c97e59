"""Irradiance environment maps with 9 SH coefficients (Ramamoorthi & Hanrahan 2001; seed 002, I-4..I-7).

With ``L_lm`` the order-3 (l <= 2) SH coefficients of the environment's radiance (lodprt's convention,
``lodprt.model.sh``: y_1 = sqrt(3/4pi) (y, z, x), no Condon-Shortley phase), the irradiance at unit normal ``n`` is

    E(n) = sum_{l<=2} A_l L_lm y_lm(n),      A_0 = pi, A_1 = 2 pi/3, A_2 = pi/4                      (I-6)

(the A_l are the clamped-cosine kernel's convolution factors sqrt(4pi/(2l+1)) h_l, P-6). The outgoing radiance of a
Lambertian surface of albedo ``kd`` is ``kd E(n) / pi``. The same E is a quadratic form (R-H, eq. 12):

    E(n) = n^T M n,  n = (x, y, z, 1),
    M = [[ c1 L22,  c1 L2-2, c1 L21, c2 L11],
         [ c1 L2-2, -c1 L22, c1 L2-1, c2 L1-1],
         [ c1 L21,  c1 L2-1, c3 L20, c2 L10],
         [ c2 L11,  c2 L1-1, c2 L10, c4 L00 - c5 L20]]

with the table-1 constants c1 = 0.429043, c2 = 0.511664, c3 = 0.743125, c4 = 0.886227, c5 = 0.247708, derived
here in float64 from A_l and the SH normalisations (within one unit of the printed sixth digit: the exact c2, c3
round to 0.511663, 0.743124; the tests check it). The seed's GPU variant
(I-7, its table 1) packs the same polynomial for three channels into 7 vec4 constant registers
``cAr cAg cAb cBr cBg cBb cC``:

    E_c(n) = cA_c . (x, y, z, 1) + cB_c . (xy, yz, z^2, zx) + cC_c (x^2 - y^2)

with cA = (k1 L11, k1 L1-1, k1 L10, k0 L00 - k3 L20), cB = (k2 L2-2, k2 L2-1, 3 k3 L20, k2 L21), cC = k4 L22 and
k0 = A0 n0, k1 = A1 n1, k2 = A2 n2, k3 = A2 n3, k4 = A2 n4 (n0..n4 the y_lm normalisations 1/(2 sqrt pi),
sqrt3/(2 sqrt pi), sqrt15/(2 sqrt pi), sqrt5/(4 sqrt pi), sqrt15/(4 sqrt pi)). (The seed's eq. 7 prints
``c_0 R_1^0``; its table, and the algebra, have ``R_0^0``.) :data:`GLSL_IRRADIANCE` evaluates exactly this in a
shader; :func:`irradiance_gl` runs it through moderngl (EGL offscreen) for tests and pictures.
"""

from __future__ import annotations

import numpy as np

from lodprt.model import sh
from lodprt.errors import LodprtError

#: A_l of I-6, l = 0, 1, 2
A_HAT = (np.pi, 2.0 * np.pi / 3.0, np.pi / 4.0)

# SH normalisations of band 0..2 (lodprt convention): y00 = N0, y1m = N1 (y, z, x), y2-2 = N2 xy, y2-1 = N2 yz,
# y20 = N3 (3 z^2 - 1), y21 = N2 xz, y22 = N4 (x^2 - y^2)
_N0 = 0.5 / np.sqrt(np.pi)
_N1 = np.sqrt(3.0) / (2.0 * np.sqrt(np.pi))
_N2 = np.sqrt(15.0) / (2.0 * np.sqrt(np.pi))
_N3 = np.sqrt(5.0) / (4.0 * np.sqrt(np.pi))
_N4 = np.sqrt(15.0) / (4.0 * np.sqrt(np.pi))

#: Ramamoorthi-Hanrahan table-1 constants (off-diagonal entries of M appear twice in n^T M n, hence the halves)
RH_CONSTANTS = {
    "c1": A_HAT[2] * _N4,  # 0.429043: x^2 - y^2 and, halved twice over, xy, yz, xz
    "c2": A_HAT[1] * _N1 / 2.0,  # 0.511664
    "c3": A_HAT[2] * _N3 * 3.0,  # 0.743125
    "c4": A_HAT[0] * _N0,  # 0.886227
    "c5": A_HAT[2] * _N3,  # 0.247708
}
#: the digits printed in Ramamoorthi-Hanrahan table 1
RH_TABLE1 = {"c1": 0.429043, "c2": 0.511664, "c3": 0.743125, "c4": 0.886227, "c5": 0.247708}

#: the seed's k0..k4 (called c0..c4 there): A_l times the y_lm normalisations
SEED_CONSTANTS = {
    "k0": A_HAT[0] * _N0,
    "k1": A_HAT[1] * _N1,
    "k2": A_HAT[2] * _N2,
    "k3": A_HAT[2] * _N3,
    "k4": A_HAT[2] * _N4,
}

#: names of the seed's 7 vec4 constant registers, in table order
REGISTERS = ("cAr", "cAg", "cAb", "cBr", "cBg", "cBb", "cC")


def _check9(coeffs) -> np.ndarray:
    c = np.asarray(coeffs, np.float64)
    if c.ndim == 1:
        c = c[None]
    if c.ndim != 2 or c.shape[1] < 9:
        raise LodprtError(f"irradiance: lighting coefficients must have shape (channels, >= 9), got {np.shape(coeffs)}")
    if not np.isfinite(c).all():
        raise LodprtError("irradiance: lighting coefficients must be finite")
    return c[:, :9]


def lighting_coefficients(env) -> np.ndarray:
    """The 9 RGB radiance coefficients L_lm of an :class:`lodprt.environment.Environment`: (3, 9) float64."""
    return env.project(3)


def irradiance_coefficients(coeffs) -> np.ndarray:
    """E_lm = A_l L_lm (I-6): (C, 9) -> (C, 9) float64, the SH coefficients of the irradiance."""
    c = _check9(coeffs)
    a = np.array([A_HAT[0]] + [A_HAT[1]] * 3 + [A_HAT[2]] * 5)
    return c * a


def quadratic_matrices(coeffs) -> np.ndarray:
    """Per channel the 4x4 symmetric matrix M of E(n) = n^T M n, n = (x, y, z, 1) (R-H eq. 12): (C, 4, 4)."""
    L = _check9(coeffs)
    c1, c2, c3, c4, c5 = (RH_CONSTANTS[k] for k in ("c1", "c2", "c3", "c4", "c5"))
    l00, l1m1, l10, l11, l2m2, l2m1, l20, l21, l22 = L.T
    m = np.empty((len(L), 4, 4))
    m[:, 0] = np.stack([c1 * l22, c1 * l2m2, c1 * l21, c2 * l11], -1)
    m[:, 1] = np.stack([c1 * l2m2, -c1 * l22, c1 * l2m1, c2 * l1m1], -1)
    m[:, 2] = np.stack([c1 * l21, c1 * l2m1, c3 * l20, c2 * l10], -1)
    m[:, 3] = np.stack([c2 * l11, c2 * l1m1, c2 * l10, c4 * l00 - c5 * l20], -1)
    return m


def shader_constants(coeffs) -> dict[str, np.ndarray]:
    """The seed's 7 vec4 registers (its table 1) for RGB coefficients (3, 9): name -> (4,) float64.

    ``cC`` holds (k4 R22, k4 G22, k4 B22, 0): its w is undefined in the seed and written as 0.
    """
    L = _check9(coeffs)
    if len(L) != 3:
        raise LodprtError(f"shader_constants: need RGB coefficients (3, 9), got {len(L)} channel(s)")
    k0, k1, k2, k3, k4 = (SEED_CONSTANTS[k] for k in ("k0", "k1", "k2", "k3", "k4"))
    out = {}
    for ch, name in zip(L, "rgb"):
        out[f"cA{name}"] = np.array([k1 * ch[3], k1 * ch[1], k1 * ch[2], k0 * ch[0] - k3 * ch[6]])
        out[f"cB{name}"] = np.array([k2 * ch[4], k2 * ch[5], 3.0 * k3 * ch[6], k2 * ch[7]])
    out["cC"] = np.array([k4 * L[0, 8], k4 * L[1, 8], k4 * L[2, 8], 0.0])
    return {k: out[k] for k in REGISTERS}


def _normals(normals) -> np.ndarray:
    n = np.asarray(normals, np.float64)
    if n.ndim < 1 or n.shape[-1] != 3:
        raise LodprtError(f"irradiance: normals must have shape (..., 3), got {n.shape}")
    return sh._unit(n)


def irradiance(normals, coeffs, *, method: str = "matrix") -> np.ndarray:
    """Irradiance E(n) from 9 lighting coefficients: normals (..., 3), coeffs (C, 9) -> (..., C) float64.

    method: ``matrix`` (n^T M n), ``sh`` (sum A_l L_lm y_lm(n)) or ``registers`` (the seed's 7 vec4 constants);
    all three are the same polynomial (tested).
    """
    n = _normals(normals)
    L = _check9(coeffs)
    if method == "sh":
        return sh.basis(n, 3) @ irradiance_coefficients(L).T
    if method == "matrix":
        h = np.concatenate([n, np.ones(n.shape[:-1] + (1,))], axis=-1)
        return np.einsum("...i,cij,...j->...c", h, quadratic_matrices(L), h)
    if method == "registers":
        r = shader_constants(L)
        x, y, z = n[..., 0], n[..., 1], n[..., 2]
        a = np.stack([x, y, z, np.ones_like(x)], -1)
        b = np.stack([x * y, y * z, z * z, z * x], -1)
        out = [a @ r[f"cA{c}"] + b @ r[f"cB{c}"] + r["cC"][i] * (x * x - y * y) for i, c in enumerate("rgb")]
        return np.stack(out, -1)
    raise LodprtError(f"irradiance: method must be 'matrix', 'sh' or 'registers', got {method!r}")


def brute_force_irradiance(env, normals, *, chunk: int = 256) -> np.ndarray:
    """E(n) = sum_t L_t max(n . d_t, 0) Omega_t over every texel of ``env``: normals (N, 3) -> (N, 3) float64."""
    n = _normals(normals).reshape(-1, 3)
    d = env.directions()
    lw = env.radiance() * env.solid_angles()[:, None]
    out = np.empty((len(n), 3))
    for s in range(0, len(n), chunk):
        out[s : s + chunk] = np.clip(n[s : s + chunk] @ d.T, 0, None) @ lw
    return out


def irradiance_range(coeffs, *, samples: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """Per channel (min, max) of E(n) over ``samples`` spherical-Fibonacci normals.

    A negative minimum is ringing of the truncated expansion: a single directional light gives -3.7% of the
    maximum (the 3-band clamped cosine dips below zero at cos = -8/15). It is reported, never clamped; windowing
    the bands (``lodprt.sh.window``) does not help at 3 bands (Hann -6.7%, Lanczos -4.3% of the maximum).
    """
    k = np.arange(samples) + 0.5
    z = 1 - 2 * k / samples
    phi = np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z * z)
    e = irradiance(np.stack([r * np.cos(phi), r * np.sin(phi), z], 1), coeffs)
    return e.min(0), e.max(0)


def describe(coeffs) -> dict:
    """Everything ``lodprt irradiance`` prints: coefficients, A_l, constants, matrices, registers, the range of E
    over the sphere (JSON-ready)."""
    L = _check9(coeffs)
    names = [f"L{l}{m}" for l in range(3) for m in range(-l, l + 1)]
    lo, hi = irradiance_range(L)
    return {
        "irradiance_min": lo.tolist(),
        "irradiance_max": hi.tolist(),
        "convention": "real orthonormal SH, index l*(l+1)+m, no Condon-Shortley phase, y_1 = sqrt(3/4pi) (y, z, x); "
        "E(n) = n^T M n with n = (x, y, z, 1); outgoing radiance of albedo kd is kd E / pi; linear RGB",
        "coefficient_names": names,
        "coefficients": {c: L[i].tolist() for i, c in enumerate("rgb"[: len(L)])},
        "A": list(A_HAT),
        "constants": dict(RH_CONSTANTS),
        "matrices": {c: m.tolist() for c, m in zip("rgb", quadratic_matrices(L))},
        "registers": {k: v.tolist() for k, v in shader_constants(L).items()} if len(L) == 3 else None,
    }


# -- GLSL -------------------------------------------------------------------------------------------------------

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
    n = _normals(normals).reshape(-1, 3).astype(np.float32)
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
    on top; camera as in :func:`lodprt.render.render`.
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
