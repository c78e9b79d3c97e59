"""Irradiance environment maps with 9 SH coefficients (Ramamoorthi & Hanrahan 2001; seed 002, I-4..I-7).

E(n) = sum_{l<=2} A_l L_lm y_lm(n) (I-6) from the order-3 lighting coefficients, evaluated three ways: the SH sum,
the quadratic form n^T M n (R-H eq. 12, table-1 constants c1..c5 derived in float64) and the seed's 7 vec4 shader
registers (I-7, its table 1); plus a brute-force integral and the range of E over the sphere. A Lambertian surface
of albedo kd leaves kd E / pi. Formulas and constants: docs/ENVIRONMENT.md, "Irradiance environment maps". The
GLSL version of the register polynomial is :mod:`lodprt.display.irradiance_render`.
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


def unit_normals(normals) -> np.ndarray:
    """(..., 3) float64 unit normals (a zero vector reads as +z); LodprtError on a wrong shape."""
    n = np.asarray(normals, np.float64)
    if n.ndim < 1 or n.shape[-1] != 3:
        raise LodprtError(f"irradiance: normals must have shape (..., 3), got {n.shape}")
    return sh.unit_vectors(n)


def irradiance(normals, coeffs, *, method: str = "matrix") -> np.ndarray:
    """Irradiance E(n) from 9 lighting coefficients: normals (..., 3), coeffs (C, 9) -> (..., C) float64.

    method: ``matrix`` (n^T M n), ``sh`` (sum A_l L_lm y_lm(n)) or ``registers`` (the seed's 7 vec4 constants);
    all three are the same polynomial (tested).
    """
    n = unit_normals(normals)
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
    n = unit_normals(normals).reshape(-1, 3)
    d = env.directions()
    lw = env.radiance() * env.solid_angles()[:, None]
    out = np.empty((len(n), 3))
    for s in range(0, len(n), chunk):
        out[s : s + chunk] = np.clip(n[s : s + chunk] @ d.T, 0, None) @ lw
    return out


def irradiance_range(coeffs, *, samples: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """Per channel (min, max) of E(n) over ``samples`` spherical-Fibonacci normals.

    A negative minimum is ringing of the truncated expansion: a single directional light gives -3.7% of the
    maximum (the 3-band clamped cosine dips below zero at cos = -8/15). It is reported, never clamped; the
    classic windows of width 3 bands make it worse (Hann -6.7%, Lanczos -4.3%), a narrower one removes it
    (``lodprt.model.windowing.choose_window``, ``lodprt irradiance --window auto``).
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
