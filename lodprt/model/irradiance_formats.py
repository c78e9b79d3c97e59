"""The 9 x 3 irradiance SH coefficients in the conventions engines read (IF-1..IF-3, docs/EXPORT.md).

From lodprt's order-3 lighting coefficients L_lm (real orthonormal SH, no Condon-Shortley phase, index l(l+1)+m,
lodprt's frame: right-handed, +y up) and the Ramamoorthi-Hanrahan irradiance E_lm = A_l L_lm (I-6,
:mod:`lodprt.model.irradiance`):

* IF-1 ``gltf`` (``irradianceCoefficients`` of the KHR_lights_environment draft and of EXT_lights_image_based, as
  Babylon.js reads them): c_i = s_i E_i, nine RGB triples; the basis carries the Condon-Shortley phase
  (s_i = -1 for odd m), the cosine lobe is folded in, the Lambert 1/pi is not; glTF's frame is lodprt's.
* IF-2 ``unity`` (``SphericalHarmonicsL2``, ``sh[channel, coefficient]``): u_i = m_i k_i E_i / pi, the basis
  constants k_i and the Lambert 1/pi folded in, so that Unity's ShadeSH9 polynomial gives E/pi; m_i mirrors x
  (Unity is left-handed: a glTF/lodprt direction (x, y, z) is (-x, y, z) there, as glTF importers map it).
* IF-3 ``filament`` (cmgen's ``sh.txt``, ``IndirectLight::Builder::irradiance``): f_i = k_i E_i / pi, nine RGB
  triples "pre-scaled" for Filament's shader polynomial, which clamps at 0; world frame = lodprt's.

Each consumer evaluates ``sum_i coefficient_i * constant_i * P_i(n)`` with P = (1, y, z, x, xy, yz, 3z^2 - 1, xz,
x^2 - y^2); tests/test_export.py does so the way each consumer does and compares with the R-H formula.
"""

from __future__ import annotations

import math

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model.irradiance import irradiance_coefficients

FORMATS = ("gltf", "unity", "filament")
#: the 9 coefficients in order, l = 0..2, m = -l..l
NAMES = ("L00", "L1-1", "L10", "L11", "L2-2", "L2-1", "L20", "L21", "L22")
#: P_i: the polynomial part of real SH i (of the unit direction (x, y, z)); every convention below shares it
POLYNOMIALS = ("1", "y", "z", "x", "x*y", "y*z", "3*z*z - 1", "x*z", "x*x - y*y")
_SQRT_PI = math.sqrt(math.pi)
#: k_i: lodprt's y_i = k_i P_i (``lodprt.model.sh.basis``, no Condon-Shortley phase; tested against it)
BASIS_CONSTANTS = np.array([1 / (2 * _SQRT_PI)] + [math.sqrt(3) / (2 * _SQRT_PI)] * 3
                           + [math.sqrt(15) / (2 * _SQRT_PI)] * 2 + [math.sqrt(5) / (4 * _SQRT_PI),
                                                                    math.sqrt(15) / (2 * _SQRT_PI),
                                                                    math.sqrt(15) / (4 * _SQRT_PI)])
#: (-1)^m: the Condon-Shortley phase of coefficient i (IF-1)
CONDON_SHORTLEY = np.array([1, -1, 1, -1, 1, -1, 1, -1, 1], np.float64)
#: sign of coefficient i under x -> -x (odd in x: x, xy, xz) (IF-2)
MIRROR_X = np.array([1, 1, 1, -1, -1, 1, 1, -1, 1], np.float64)
#: Unity's 7 vec4 shader constants, in the order ShadeSH9 reads them
UNITY_REGISTERS = ("unity_SHAr", "unity_SHAg", "unity_SHAb", "unity_SHBr", "unity_SHBg", "unity_SHBb", "unity_SHC")


def _irradiance_rgb(coeffs) -> np.ndarray:
    """E_lm = A_l L_lm (I-6) of RGB lighting coefficients: (3, >= 9) -> (3, 9) float64."""
    e = irradiance_coefficients(coeffs)
    if len(e) != 3:
        raise LodprtError(f"irradiance formats: need RGB lighting coefficients (3, 9), got {len(e)} channel(s)")
    return e


def gltf_coefficients(coeffs) -> np.ndarray:
    """IF-1: ``irradianceCoefficients``, (9, 3): c_i = (-1)^m A_l L_lm, i.e. the irradiance's SH coefficients over
    the real basis with the Condon-Shortley phase (Babylon.js's ``SphericalHarmonics``); no 1/pi."""
    return (_irradiance_rgb(coeffs) * CONDON_SHORTLEY).T.copy()


def unity_coefficients(coeffs) -> np.ndarray:
    """IF-2: ``SphericalHarmonicsL2`` as ``sh[channel, coefficient]``, (3, 9): u_i = m_i k_i A_l L_lm / pi (basis
    constants and Lambert 1/pi folded in, x mirrored into Unity's left-handed frame)."""
    return _irradiance_rgb(coeffs) * (BASIS_CONSTANTS * MIRROR_X / math.pi)


def unity_shader_registers(sh) -> dict[str, list[float]]:
    """IF-2: the 7 vec4 constants Unity packs from ``SphericalHarmonicsL2`` ``sh`` (3, 9) for ShadeSH9:
    SHA = (u3, u1, u2, u0 - u6), SHB = (u4, u5, 3 u6, u7) per channel, SHC = (r8, g8, b8, 1)."""
    sh = np.asarray(sh, np.float64)
    out = {}
    for c, ch in zip("rgb", sh):
        out[f"unity_SHA{c}"] = [ch[3], ch[1], ch[2], ch[0] - ch[6]]
    for c, ch in zip("rgb", sh):
        out[f"unity_SHB{c}"] = [ch[4], ch[5], 3.0 * ch[6], ch[7]]
    out["unity_SHC"] = [sh[0, 8], sh[1, 8], sh[2, 8], 1.0]
    return {k: [float(x) for x in out[k]] for k in UNITY_REGISTERS}


def filament_coefficients(coeffs) -> np.ndarray:
    """IF-3: Filament's pre-scaled irradiance SH, (9, 3): f_i = k_i A_l L_lm / pi."""
    return (_irradiance_rgb(coeffs) * (BASIS_CONSTANTS / math.pi)).T.copy()


def filament_sh_txt(f) -> str:
    """IF-3 as cmgen writes ``sh.txt``: one ``(r, g, b); // Llm, irradiance, pre-scaled base`` line per
    coefficient."""
    return "".join(f"({r:15.12f}, {g:15.12f}, {b:15.12f}); // {n}, irradiance, pre-scaled base\n"
                   for n, (r, g, b) in zip(NAMES, np.asarray(f, np.float64)))


CONVENTIONS = {
    "gltf": "irradianceCoefficients[i] = RGB E_lm = A_l L_lm (cosine lobe folded in, no Lambert 1/pi), "
            "i = l(l+1)+m, real SH with the Condon-Shortley phase (Babylon.js SphericalHarmonics: E(n) = sum_i c_i "
            "K_i P_i(n), K = (0.282095, -0.488603, 0.488603, -0.488603, 1.092548, -1.092548, 0.315392, -1.092548, "
            "0.546274)); glTF frame (right-handed, +y up) = lodprt's; outgoing radiance of albedo rho is rho E / pi",
    "unity": "SphericalHarmonicsL2 sh[channel, i] = k_i E_lm / pi (basis constants and Lambert 1/pi folded in), "
             "Unity's left-handed frame: lodprt (x, y, z) = Unity (-x, y, z); ShadeSH9(n) = E(n)/pi = sh[3] x + "
             "sh[1] y + sh[2] z + sh[0] - sh[6] + sh[4] xy + sh[5] yz + 3 sh[6] z^2 + sh[7] xz + sh[8] (x^2 - y^2)",
    "filament": "pre-scaled irradiance SH f_i = k_i E_lm / pi (basis constants and Lambert 1/pi folded in), as "
                "cmgen's sh.txt and IndirectLight::Builder::irradiance(3, sh) take them; Filament's shader: "
                "E(n)/pi = max(0, f0 + f1 y + f2 z + f3 x + f4 xy + f5 yz + f6 (3z^2 - 1) + f7 xz + f8 (x^2 - y^2)); "
                "world frame (right-handed, +y up) = lodprt's",
}


def export_document(fmt: str, coeffs, *, source: str | None = None) -> dict:
    """The JSON document ``lodprt irradiance --format fmt`` prints for RGB lighting coefficients (3, 9)."""
    meta = {"generator": "lodprt", "source": source, "convention": CONVENTIONS.get(fmt)}
    if fmt == "gltf":
        light = {"name": source or "lodprt", "intensity": 1.0,
                 "irradianceCoefficients": gltf_coefficients(coeffs).tolist(), "extras": {"lodprt": meta}}
        return {"KHR_lights_environment": {"lights": [light]}}
    if fmt == "unity":
        u = unity_coefficients(coeffs)
        return {"SphericalHarmonicsL2": u.tolist(), "shader_constants": unity_shader_registers(u), "lodprt": meta}
    if fmt == "filament":
        f = filament_coefficients(coeffs)
        return {"bands": 3, "irradiance": f.tolist(), "sh_txt": filament_sh_txt(f), "lodprt": meta}
    raise LodprtError(f"--format {fmt!r}: choose one of {', '.join(FORMATS)}")
