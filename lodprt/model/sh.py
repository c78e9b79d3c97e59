"""Real spherical harmonics, float64 numpy reference (T-5..T-8, P-4, P-6): basis, quadrature projection and
reconstruction, clamped cosine-power lobes, zonal convolution, band windows, rotation. Summary in docs/THEORY.md.

Convention, written down once for all of lodprt
-----------------------------------------------
Index i = l(l+1) + m (0-based); "order n" = number of bands = n*n coefficients, l = 0..n-1.
Directions are unit (x, y, z) vectors (normalised here); theta is measured from +z, phi = atan2(y, x).

    y_l^m = sqrt(2) K_l^m cos(m phi) P_l^m(cos theta)      m > 0                                        (T-5)
          = sqrt(2) K_l^m sin(-m phi) P_l^-m(cos theta)    m < 0
          = K_l^0 P_l^0(cos theta)                          m = 0
    K_l^m = sqrt((2l+1)/(4 pi) (l-|m|)!/(l+|m|)!)

No Condon-Shortley phase: y_0 = 1/sqrt(4 pi), (y_1^{-1}, y_1^0, y_1^1) = sqrt(3/(4 pi)) (y, z, x).
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import is_whole

_SQRT2 = np.sqrt(2.0)
_Y00 = 1.0 / np.sqrt(4.0 * np.pi)


def num_coefficients(order: int) -> int:
    """order^2: the number of coefficients of an order-``order`` (that many bands) expansion."""
    return _check_order(order) ** 2


def sh_index(l: int, m: int) -> int:
    """Single index i = l(l+1) + m of band l, degree m (0 <= |m| <= l)."""
    if not (is_whole(l, 0) and is_whole(m, -l, l)):
        raise ValueError(f"sh_index: need integers with |m| <= l, got l={l!r}, m={m!r}")
    return int(l) * (int(l) + 1) + int(m)


def _check_order(order, name="order") -> int:
    if not is_whole(order, 1):
        raise ValueError(f"{name} must be an integer >= 1, got {order!r}")
    return int(order)


def _order_of(n_coeffs: int, who: str) -> int:
    order = int(round(np.sqrt(n_coeffs)))
    if n_coeffs < 1 or order * order != n_coeffs:
        raise ValueError(f"{who}: the last axis must hold order**2 coefficients (1, 4, 9, ...), got {n_coeffs}")
    return order


def unit_vectors(directions) -> np.ndarray:
    """(..., 3) float64 unit vectors; a zero vector reads as +z. ValueError on a wrong shape or non-finite entries."""
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim < 1 or d.shape[-1] != 3:
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    if not np.isfinite(d).all():
        raise ValueError("directions must be finite (found NaN or inf)")
    # scale by the largest component first so that tiny vectors do not underflow to a zero norm
    big = np.max(np.abs(d), axis=-1, keepdims=True)
    d = d / np.where(big > 0, big, 1.0)
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    return np.where(big > 0, d / np.where(n > 0, n, 1.0), np.array([0.0, 0.0, 1.0]))


# How the basis is evaluated (no factorial is ever formed, nothing divides by sin(theta)):
# y_l^{+-m} = sqrt(2) Q_l^m(z) * {Re, Im} (x + i y)^m, because sin^m(theta) cos(m phi) = Re (x + i y)^m and
# sin^m(theta) sin(m phi) = Im (x + i y)^m; (x + i y)^m comes from the Cartesian recurrence
# (x + i y)^m = (x + i y)^{m-1} (x + i y).  Q_l^m = K_l^m P_l^m / sin^m(theta) is the fully normalised associated
# Legendre function without its sin^m factor (Holmes-Featherstone normalisation):
#
#     Q_0^0 = 1/sqrt(4 pi),   Q_m^m = Q_{m-1}^{m-1} sqrt((2m+1)/(2m)),   Q_{m+1}^m = sqrt(2m+3) z Q_m^m,
#     Q_l^m = a_lm (z Q_{l-1}^m - b_lm Q_{l-2}^m),  a_lm = sqrt((4l^2-1)/(l^2-m^2)),
#                                                   b_lm = sqrt(((l-1)^2-m^2)/(4(l-1)^2-1)).
#
# Near the poles that three-term recurrence (whose characteristic roots merge at z = +-1) amplifies the rounding of z
# by ~l^2: about 1e-5 absolute at l = 15 in float32.  It is therefore run in Reinsch's difference form, which is
# algebraically identical: with g_l = K_l^m / K_{l-1}^m = sqrt((2l+1)(l-m) / ((2l-1)(l+m))) and
# e_l = Q_l^m - g_l Q_{l-1}^m,
#
#     e_m = Q_m^m,
#     e_l = g_l / (l-m) * ((l+m-1) e_{l-1} - (2l-1) (1 - t) Q_{l-1}^m),     Q_l^m = g_l Q_{l-1}^m + e_l,
#
# evaluated at t = |z| with 1 - t = (x^2 + y^2) / (1 + t) (no cancellation at the poles), and
# Q_l^m(z) = (-1)^(l-m) Q_l^m(|z|) for z < 0.  (Substituting e_l into the a_lm, b_lm recurrence gives the same
# Q_l^m; the m = l + 1 step reproduces Q_{m+1}^m = sqrt(2m+3) z Q_m^m.)  The float32 Warp version
# (``lodprt.kernels.sh``) runs the very same steps; the basis agrees with scipy to 1e-12 up to l = 100 in float64.
def basis(directions, order: int) -> np.ndarray:
    """Real SH basis y_i(d), i < order^2 (T-5): directions (..., 3) -> (..., order^2) float64.

    Directions are normalised here (a zero vector reads as +z); ValueError on a wrong shape, non-finite entries
    or order < 1.  Accurate to ~1e-13 absolute up to l = 100 (tested against scipy), stable at the poles.
    """
    order = _check_order(order)
    d = unit_vectors(directions)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    t = np.abs(z)
    one_minus_t = (x * x + y * y) / (1.0 + t)  # 1 - |z| without cancellation near the poles
    flip = np.where(z < 0, -1.0, 1.0)  # parity: Q_l^m(-t) = (-1)^(l-m) Q_l^m(t)
    out = np.empty(d.shape[:-1] + (order * order,), dtype=np.float64)
    re, im = np.ones_like(x), np.zeros_like(x)  # (x + i y)^m
    qmm = np.full_like(x, _Y00)  # Q_m^m
    for m in range(order):
        if m > 0:
            re, im = re * x - im * y, re * y + im * x
            qmm = qmm * np.sqrt((2.0 * m + 1.0) / (2.0 * m))
        q, e, sign = qmm, qmm, np.ones_like(x)
        for l in range(m, order):
            if l > m:  # Reinsch difference form of the normalised recurrence (comment above)
                g = np.sqrt((2.0 * l + 1.0) * (l - m) / ((2.0 * l - 1.0) * (l + m)))
                e = g / (l - m) * ((l + m - 1.0) * e - (2.0 * l - 1.0) * one_minus_t * q)
                q = g * q + e
                sign = sign * flip
            qs = sign * q
            if m == 0:
                out[..., l * (l + 1)] = qs
            else:
                out[..., l * (l + 1) + m] = _SQRT2 * qs * re
                out[..., l * (l + 1) - m] = _SQRT2 * qs * im
    return out


def quadrature(n_theta: int, n_phi: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre in cos(theta) x uniform phi: (dirs (Q, 3), weights (Q,)), Q = n_theta * n_phi.

    Integrates exactly every polynomial of degree <= 2 n_theta - 1 in z times a trigonometric polynomial of
    degree < n_phi in phi (so every y_l^m with l <= 2 n_theta - 1, |m| < n_phi); the weights sum to 4 pi.
    ``n_phi`` defaults to 2 n_theta.  Rows are theta-major (n_theta blocks of n_phi directions).
    """
    n_theta = _check_order(n_theta, "n_theta")
    n_phi = 2 * n_theta if n_phi is None else _check_order(n_phi, "n_phi")
    t, wt = np.polynomial.legendre.leggauss(n_theta)
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    tt, pp = np.meshgrid(t, phi, indexing="ij")
    s = np.sqrt(np.clip(1.0 - tt * tt, 0.0, None))
    dirs = np.stack([s * np.cos(pp), s * np.sin(pp), tt], axis=-1).reshape(-1, 3)
    weights = np.repeat(wt, n_phi) * (2.0 * np.pi / n_phi)
    return dirs, weights


def quadrature_for_order(order: int) -> tuple[np.ndarray, np.ndarray]:
    """quadrature(order, 2 order): exact for the product of two order-``order`` expansions (bands <= 2 order - 2).

    With it the Gram matrix of ``basis(dirs, order)`` is the identity, so projection (T-6) of a band-limited
    function is exact and the product integral of two expansions is the dot product of their coefficients (T-8).
    """
    order = _check_order(order)
    return quadrature(order, 2 * order)


def project(values, dirs, weights, order: int) -> np.ndarray:
    """T-6 by quadrature, f_i = sum_q w_q f(s_q) y_i(s_q).

    values (Q,) or (Q, ...) samples of f (trailing dims are independent functions, e.g. colour channels),
    dirs (Q, 3), weights (Q,) -> coefficients (..., order^2) float64 (the Q axis becomes the last axis).
    """
    values = np.asarray(values, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if dirs.ndim != 2 or dirs.shape[1] != 3:
        raise ValueError(f"project: dirs must have shape (Q, 3), got {dirs.shape}")
    if weights.shape != (len(dirs),) or values.ndim < 1 or values.shape[0] != len(dirs):
        raise ValueError(
            f"project: values {values.shape} (Q, ...), dirs {dirs.shape} (Q, 3) and weights {weights.shape} (Q,) "
            "disagree on Q"
        )
    y = basis(dirs, order)  # (Q, n^2)
    wv = values * weights.reshape((-1,) + (1,) * (values.ndim - 1))
    return np.tensordot(wv, y, axes=([0], [0]))


def evaluate(coeffs, dirs) -> np.ndarray:
    """T-7 reconstruction f(s) = sum_i c_i y_i(s).

    coeffs (..., n^2) and dirs (..., 3): the leading dims (everything but the last axis) broadcast with numpy's
    rules, the result has the broadcast leading shape.  E.g. coeffs (n^2,) with dirs (Q, 3) -> (Q,);
    coeffs (K, n^2) with dirs (K, 3) -> (K,) (one direction per function); coeffs (K, 1, n^2) with dirs (Q, 3)
    -> (K, Q).
    """
    coeffs = np.asarray(coeffs, dtype=np.float64)
    if coeffs.ndim < 1:
        raise ValueError("evaluate: coeffs must have shape (..., order**2)")
    order = _order_of(coeffs.shape[-1], "evaluate")
    return np.einsum("...i,...i->...", coeffs, basis(dirs, order))


def cosine_power_zonal(shininess: float, order: int) -> np.ndarray:
    """Zonal coefficients z_l (coefficient of y_l^0) of max(cos theta, 0)^n about +z, l < order: (order,) float64.

    z_l = integral max(t, 0)^n y_l^0 ds = 2 pi K_l^0 I_l,  I_l = integral_0^1 t^n P_l(t) dt, from

        I_0 = 1/(n+1),  I_1 = 1/(n+2),  I_l = I_{l-2} (n - l + 2)/(n + l + 1).

    (Gradshteyn-Ryzhik 7.126.2 gives I_l = sqrt(pi) 2^(-n-1) Gamma(n+1) / (Gamma(1 + n/2 - l/2)
    Gamma(3/2 + n/2 + l/2)); the ratio I_l / I_{l-2} of two such Gamma products is the factor above.)  Only ratios
    of size <= 1 are multiplied, so any real n >= 0 (up to 1e4 and beyond) is finite; for integer n the factor
    vanishes at l = n + 2, giving exact zeros for l = n+2, n+4, ...
    """
    order = _check_order(order)
    n = float(shininess)
    if not np.isfinite(n) or n < 0:
        raise ValueError(f"shininess must be finite and >= 0, got {shininess!r}")
    integ = np.empty(order)
    integ[0] = 1.0 / (n + 1.0)
    if order > 1:
        integ[1] = 1.0 / (n + 2.0)
    for l in range(2, order):
        integ[l] = integ[l - 2] * (n - l + 2.0) / (n + l + 1.0)
    bands = np.arange(order)
    return 2.0 * np.pi * np.sqrt((2 * bands + 1) / (4.0 * np.pi)) * integ


def _band_of_index(order: int) -> np.ndarray:
    """Band l of each of the order^2 coefficients."""
    return np.repeat(np.arange(order), 2 * np.arange(order) + 1)


def zonal_scale(h: np.ndarray) -> np.ndarray:
    """sqrt(4 pi/(2l+1)) h_l spread over the (2l+1) coefficients of each band (P-6): (order,) -> (order^2,).

    Multiplying SH coefficients by it convolves them with the zonal kernel of coefficients ``h`` (:func:`convolve_zonal`).
    """
    order = len(h)
    bands = np.arange(order)
    return (np.sqrt(4.0 * np.pi / (2 * bands + 1)) * h)[_band_of_index(order)]


def cosine_power_lobe(axis, shininess: float, order: int) -> np.ndarray:
    """Closed-form projection (T-6) of max(axis . s, 0)^n: axis (..., 3) -> (..., order^2) float64.

    The zonal lobe about +z rotated to ``axis`` (P-4 for a zonal function, i.e. P-6 with a delta at the axis):
    f_lm = sqrt(4 pi/(2l+1)) z_l y_lm(axis), z_l = cosine_power_zonal(n, order).  ``axis`` is normalised.
    """
    return basis(axis, order) * zonal_scale(cosine_power_zonal(shininess, order))


def lobe_energy_captured(shininess: float, order: int) -> float:
    """Fraction in (0, 1] of integral max(cos theta, 0)^(2n) ds = 2 pi/(2n+1) kept by an order-``order`` expansion.

    = sum_l z_l^2 / (2 pi/(2n+1)) (Parseval; rotation does not change it), clipped to 1 against rounding.
    """
    z = cosine_power_zonal(shininess, order)
    exact = 2.0 * np.pi / (2.0 * float(shininess) + 1.0)
    return float(min(np.sum(z * z) / exact, 1.0))


def convolve_zonal(coeffs, kernel_zonal) -> np.ndarray:
    """P-6: (h * f)_lm = sqrt(4 pi/(2l+1)) h_l f_lm.

    coeffs (..., n^2) of f; kernel_zonal (n,) holding h_l = coefficient of y_l^0 of the zonal (about +z) kernel h.
    Returns (..., n^2): the coefficients of (h * f)(s) = integral h(s . u) f(u) du.  E.g. h = max(cos, 0)
    (cosine_power_zonal(1, n)) turns radiance into irradiance.
    """
    coeffs = np.asarray(coeffs, dtype=np.float64)
    h = np.asarray(kernel_zonal, dtype=np.float64)
    if h.ndim != 1 or len(h) < 1:
        raise ValueError(f"convolve_zonal: kernel_zonal must have shape (order,), got {h.shape}")
    if coeffs.ndim < 1 or coeffs.shape[-1] != len(h) ** 2:
        raise ValueError(f"convolve_zonal: coeffs {coeffs.shape} do not hold {len(h)}**2 coefficients for a kernel of {len(h)} bands")
    return coeffs * zonal_scale(h)


def window(order: int, kind: str = "hann") -> np.ndarray:
    """Per-band multipliers w_l, l < order, against ringing of truncated sharp lobes: (order,) float64.

    Multiply band l of a coefficient vector (or a zonal kernel) by w_l; nothing in lodprt applies a window
    unless asked.
        hann:    w_l = (1 + cos(pi l / order)) / 2
        lanczos: w_l = sinc(l / order) = sin(pi l / order) / (pi l / order),  w_0 = 1
        none:    w_l = 1
    """
    order = _check_order(order)
    l = np.arange(order, dtype=np.float64)
    if kind == "hann":
        return 0.5 * (1.0 + np.cos(np.pi * l / order))
    if kind == "lanczos":
        return np.sinc(l / order)
    if kind == "none":
        return np.ones(order)
    raise ValueError(f"window kind must be 'hann', 'lanczos' or 'none', got {kind!r}")


# -- rotation (P-4): Ivanic & Ruedenberg, J. Phys. Chem. 100, 6342 (1996) + erratum 102, 9099 (1998) ------------
#
# Band-l matrix from band l-1 and the band-1 matrix r (indices -l..l):
#     M^l_mn = u_mn U_mn + v_mn V_mn + w_mn W_mn,  d = (l+n)(l-n) for |n| < l, (2l)(2l-1) for |n| = l,
#     u = sqrt((l+m)(l-m)/d),  v = 1/2 sqrt((1+delta_m0)(l+|m|-1)(l+|m|)/d) (1 - 2 delta_m0),
#     w = -1/2 sqrt((l-|m|-1)(l-|m|)/d) (1 - delta_m0),
#     P(i, a, b) = r_i1 M^{l-1}_{a,l-1} - r_i,-1 M^{l-1}_{a,-l+1}   (b = l)
#                = r_i1 M^{l-1}_{a,-l+1} + r_i,-1 M^{l-1}_{a,l-1}   (b = -l)
#                = r_i0 M^{l-1}_{a,b}                               (otherwise)
#     U = P(0, m, n)
#     V = P(1, 1, n) + P(-1, -1, n)                                                       (m = 0)
#       = P(1, m-1, n) sqrt(1 + delta_m1) - P(-1, -m+1, n) (1 - delta_m1)                 (m > 0)
#       = P(1, m+1, n) (1 - delta_m,-1) + P(-1, -m-1, n) sqrt(1 + delta_m,-1)             (m < 0)
#     W = P(1, m+1, n) + P(-1, -m-1, n)  (m > 0);   P(1, m-1, n) - P(-1, -m+1, n)  (m < 0)
# (the erratum's corrected V for m < 0 and the sqrt(1 + delta) factors are used).  Everything is float64.


def _band1(R: np.ndarray) -> np.ndarray:
    """Band-1 matrix: y_1 is sqrt(3/4pi) (y, z, x), and a.s rotated by R is a.(R^T s) = (R a).s."""
    perm = [1, 2, 0]
    return R[np.ix_(perm, perm)]


def _check_rotation(R) -> np.ndarray:
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f"R must be a 3x3 rotation matrix, got shape {R.shape}")
    if not np.isfinite(R).all():
        raise ValueError("R must be finite")
    # 1e-5 admits rotations stored in float32; the nearest exact rotation (polar factor) is then used
    if not np.allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-5) or np.linalg.det(R) < 0:
        raise ValueError("R must be a proper rotation (orthonormal to 1e-5, det +1)")
    u, _, vt = np.linalg.svd(R)
    return u @ vt


def rotation_matrices(R, order: int) -> list[np.ndarray]:
    """P-4: per-band rotation matrices [D_0, ..., D_{order-1}], D_l of shape (2l+1, 2l+1), row/column m + l.

    R (3, 3) a proper rotation.  The band-l coefficients c_l of f map to D_l c_l, the coefficients of the rotated
    function g(s) = f(R^T s).  Built by the Ivanic-Ruedenberg recurrence (comment above) from the band-1 matrix;
    every D_l is orthogonal.
    """
    order = _check_order(order)
    R = _check_rotation(R)
    mats = [np.ones((1, 1))]
    if order == 1:
        return mats
    r1 = _band1(R)
    mats.append(r1)

    def r(i, j):  # band-1 element, i, j in -1..1
        return r1[i + 1, j + 1]

    for l in range(2, order):
        prev = mats[l - 1]

        def m_prev(a, b):
            return prev[a + l - 1, b + l - 1]

        def p(i, a, b):
            if b == l:
                return r(i, 1) * m_prev(a, l - 1) - r(i, -1) * m_prev(a, -l + 1)
            if b == -l:
                return r(i, 1) * m_prev(a, -l + 1) + r(i, -1) * m_prev(a, l - 1)
            return r(i, 0) * m_prev(a, b)

        cur = np.zeros((2 * l + 1, 2 * l + 1))
        for m in range(-l, l + 1):
            d0 = 1.0 if m == 0 else 0.0
            am = abs(m)
            for n in range(-l, l + 1):
                denom = (l + n) * (l - n) if abs(n) < l else (2 * l) * (2 * l - 1)
                u = np.sqrt((l + m) * (l - m) / denom)
                v = 0.5 * np.sqrt((1 + d0) * (l + am - 1) * (l + am) / denom) * (1 - 2 * d0)
                w = -0.5 * np.sqrt(max(l - am - 1, 0) * (l - am) / denom) * (1 - d0)
                val = 0.0
                if u != 0:
                    val += u * p(0, m, n)
                if v != 0:
                    if m == 0:
                        vv = p(1, 1, n) + p(-1, -1, n)
                    elif m > 0:
                        d1 = 1.0 if m == 1 else 0.0
                        vv = p(1, m - 1, n) * np.sqrt(1 + d1) - p(-1, -m + 1, n) * (1 - d1)
                    else:
                        d1 = 1.0 if m == -1 else 0.0
                        vv = p(1, m + 1, n) * (1 - d1) + p(-1, -m - 1, n) * np.sqrt(1 + d1)
                    val += v * vv
                if w != 0:
                    if m > 0:
                        ww = p(1, m + 1, n) + p(-1, -m - 1, n)
                    else:
                        ww = p(1, m - 1, n) - p(-1, -m + 1, n)
                    val += w * ww
                cur[m + l, n + l] = val
        mats.append(cur)
    return mats


def rotate(coeffs, R) -> np.ndarray:
    """P-4: rotate an expansion by R (3, 3): coeffs (..., order^2) -> (..., order^2) float64, band by band.

    The result c' satisfies evaluate(c', s) == evaluate(coeffs, R^T s) for every s, i.e. it is the function
    rotated by R (a lobe about axis a moves to R a).  Leading dims are a batch; the last axis must hold exactly
    order^2 entries for some order >= 1.
    """
    coeffs = np.asarray(coeffs, dtype=np.float64)
    if coeffs.ndim < 1:
        raise ValueError("rotate: coeffs must have shape (..., order**2)")
    order = _order_of(coeffs.shape[-1], "rotate")
    out = np.empty_like(coeffs)
    for l, d in enumerate(rotation_matrices(R, order)):
        sl = slice(l * l, (l + 1) * (l + 1))
        out[..., sl] = coeffs[..., sl] @ d.T
    return out
