"""Real spherical harmonics: float64 numpy reference (SPEC 1; T-5..T-8, P-4, P-6).

Convention, written down once for all of lodprt:
    index i = l(l+1) + m (0-based); "order n" = number of bands = n*n coefficients, l = 0..n-1.
    Directions are unit (x, y, z); theta is measured from +z, phi = atan2(y, x).

        y_l^m = sqrt(2) K_l^m cos(m phi) P_l^m(cos theta)     m > 0
              = sqrt(2) K_l^m sin(-m phi) P_l^-m(cos theta)   m < 0
              = K_l^0 P_l^0(cos theta)                         m = 0
        K_l^m = sqrt((2l+1)/(4 pi) (l-|m|)!/(l+|m|)!)

    No Condon-Shortley phase: y_1^{-1}, y_1^0, y_1^1 = sqrt(3/(4 pi)) (y, z, x); y_0 = 1/sqrt(4 pi).

No factorial is formed: K_l^m P_l^m(cos theta) = Q_l^m(z) sin^m(theta) with Q from the fully normalised
recurrences (Holmes-Featherstone form without the sin^m factor), and sin^m(theta) cos(m phi) = Re (x + i y)^m,
sin^m(theta) sin(m phi) = Im (x + i y)^m in Cartesian form, so nothing divides by sin(theta) at the poles:

    Q_0^0 = 1/sqrt(4 pi),  Q_m^m = Q_{m-1}^{m-1} sqrt((2m+1)/(2m)),  Q_{m+1}^m = sqrt(2m+3) z Q_m^m,
    Q_l^m = a_lm (z Q_{l-1}^m - b_lm Q_{l-2}^m),  a_lm = sqrt((4l^2-1)/(l^2-m^2)),
    b_lm = sqrt(((l-1)^2-m^2)/(4(l-1)^2-1)).
"""

from __future__ import annotations

import numpy as np

_SQRT2 = np.sqrt(2.0)


def num_coefficients(order: int) -> int:
    """order^2: coefficients of an order-``order`` (that many bands) expansion."""
    return order * order


def sh_index(l: int, m: int) -> int:
    """Single index i = l(l+1) + m of band l, degree m (|m| <= l)."""
    if not 0 <= abs(m) <= l:
        raise ValueError(f"sh_index: need |m| <= l, got l={l}, m={m}")
    return l * (l + 1) + m


def _check_order(order, name="order") -> int:
    if isinstance(order, bool) or int(order) != order or order < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {order!r}")
    return int(order)


def _unit(directions) -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim < 1 or d.shape[-1] != 3:
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    # a zero vector reads as +z rather than NaN
    return np.where(n > 0, d / np.where(n > 0, n, 1.0), np.array([0.0, 0.0, 1.0]))


def basis(directions, order: int) -> np.ndarray:
    """Real SH basis y_i(d) for i < order^2 (T-5): directions (..., 3) -> (..., order^2) float64.

    Directions are normalised here. Accurate to high order (tested against scipy up to l = 100).
    """
    order = _check_order(order)
    d = _unit(directions)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    out = np.empty(d.shape[:-1] + (order * order,), dtype=np.float64)
    re, im = np.ones_like(x), np.zeros_like(x)  # (x + i y)^m
    qmm = np.full_like(x, 1.0 / np.sqrt(4.0 * np.pi))
    for m in range(order):
        if m > 0:
            re, im = re * x - im * y, re * y + im * x
            qmm = qmm * np.sqrt((2.0 * m + 1.0) / (2.0 * m))
        q_prev2, q_prev = None, qmm
        for l in range(m, order):
            if l == m:
                q = qmm
            elif l == m + 1:
                q = np.sqrt(2.0 * m + 3.0) * z * qmm
            else:
                a = np.sqrt((4.0 * l * l - 1.0) / (l * l - m * m))
                b = np.sqrt(((l - 1.0) ** 2 - m * m) / (4.0 * (l - 1.0) ** 2 - 1.0))
                q = a * (z * q_prev - b * q_prev2)
            if l > m:
                q_prev2, q_prev = q_prev, q
            if m == 0:
                out[..., l * (l + 1)] = q
            else:
                out[..., l * (l + 1) + m] = _SQRT2 * q * re
                out[..., l * (l + 1) - m] = _SQRT2 * q * im
    return out


def quadrature(n_theta: int, n_phi: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre in cos(theta) x uniform phi: (dirs (Q, 3), weights (Q,)) with Q = n_theta * n_phi.

    Integrates exactly every polynomial of degree <= 2 n_theta - 1 in z times trigonometric terms of degree
    < n_phi in phi; the weights sum to 4 pi. ``n_phi`` defaults to 2 n_theta.
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
    """A quadrature that integrates products of two order-``order`` expansions exactly."""
    order = _check_order(order)
    return quadrature(order, 2 * order)


def project(values, dirs, weights, order: int) -> np.ndarray:
    """T-6 by quadrature: values (Q,) or (Q, ...) of f at ``dirs`` (Q, 3) -> coefficients (..., order^2)."""
    values = np.asarray(values, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if values.shape[0] != len(dirs) or len(weights) != len(dirs):
        raise ValueError(f"project: values {values.shape}, dirs {dirs.shape} and weights {weights.shape} disagree on Q")
    y = basis(dirs, order)  # (Q, n)
    wv = values * weights.reshape((-1,) + (1,) * (values.ndim - 1))
    return np.tensordot(wv, y, axes=([0], [0]))


def evaluate(coeffs, dirs) -> np.ndarray:
    """T-7 reconstruction sum_i c_i y_i(d): coeffs (..., n^2), dirs (..., 3) broadcast on the leading dims."""
    coeffs = np.asarray(coeffs, dtype=np.float64)
    order = int(round(np.sqrt(coeffs.shape[-1])))
    if order * order != coeffs.shape[-1]:
        raise ValueError(f"evaluate: the last axis must hold a square number of coefficients, got {coeffs.shape[-1]}")
    return np.sum(coeffs * basis(dirs, order), axis=-1)


def cosine_power_zonal(shininess: float, order: int) -> np.ndarray:
    """Zonal coefficients z_l (coefficient of y_l^0) of max(cos theta, 0)^n about +z, l < order, float64.

    z_l = 2 pi K_l^0 I_l with I_l = integral_0^1 t^n P_l(t) dt from the ratio recurrence
    I_0 = 1/(n+1), I_1 = 1/(n+2), I_l = I_{l-2} (n - l + 2)/(n + l + 1)  (from Gradshteyn 7.126 by a Gamma ratio),
    stable for any real n >= 0 (no Gamma or factorial is formed); exact zeros for integer n of the right parity.
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
    return np.repeat(np.arange(order), 2 * np.arange(order) + 1)


def cosine_power_lobe(axis, shininess: float, order: int) -> np.ndarray:
    """Closed-form projection of max(axis . s, 0)^n: f_lm = sqrt(4 pi/(2l+1)) z_l y_lm(axis) (zonal rotated, P-6).

    axis (..., 3) -> (..., order^2).
    """
    z = cosine_power_zonal(shininess, order)
    bands = np.arange(order)
    scale = (np.sqrt(4.0 * np.pi / (2 * bands + 1)) * z)[_band_of_index(order)]
    return basis(axis, order) * scale


def lobe_energy_captured(shininess: float, order: int) -> float:
    """Fraction of integral max(cos,0)^(2n) ds = 2 pi/(2n+1) that an order-``order`` expansion keeps (in (0, 1])."""
    z = cosine_power_zonal(shininess, order)
    exact = 2.0 * np.pi / (2.0 * float(shininess) + 1.0)
    return float(min(np.sum(z * z) / exact, 1.0))


def convolve_zonal(coeffs, kernel_zonal) -> np.ndarray:
    """P-6: (h * f)_lm = sqrt(4 pi/(2l+1)) h_l f_lm; coeffs (..., n^2), kernel_zonal (n,) = h's y_l^0 coefficients."""
    coeffs = np.asarray(coeffs, dtype=np.float64)
    h = np.asarray(kernel_zonal, dtype=np.float64)
    order = len(h)
    if coeffs.shape[-1] != order * order:
        raise ValueError(f"convolve_zonal: {coeffs.shape[-1]} coefficients do not match a kernel of {order} bands")
    bands = np.arange(order)
    return coeffs * (np.sqrt(4.0 * np.pi / (2 * bands + 1)) * h)[_band_of_index(order)]


def window(order: int, kind: str = "hann") -> np.ndarray:
    """Per-band multipliers against ringing of truncated sharp lobes (an option, never applied silently).

    hann: w_l = (1 + cos(pi l / order)) / 2;  lanczos: w_l = sinc(l / order);  none: 1.
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


# -- rotation (P-4): Ivanic & Ruedenberg 1996 (+ 1998 erratum), real SH, per band -------------------------------


def _band1(R: np.ndarray) -> np.ndarray:
    # y_1^{-1,0,1} are proportional to (y, z, x): a linear function a.s rotated to a.(R^T s) = (R a).s
    perm = [1, 2, 0]
    return R[np.ix_(perm, perm)]


def rotation_matrices(R, order: int) -> list[np.ndarray]:
    """Per-band matrices D_l ((2l+1) x (2l+1), index m + l) of the rotation R (3x3, proper), l < order.

    Coefficients c of f map to D c, the coefficients of g(s) = f(R^T s) (the function rotated by R).
    """
    order = _check_order(order)
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f"rotation_matrices: R must be 3x3, got {R.shape}")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ValueError("rotation_matrices: R must be a proper rotation (orthonormal, det +1)")
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
            for n in range(-l, l + 1):
                d0 = 1.0 if m == 0 else 0.0
                denom = (l + n) * (l - n) if abs(n) < l else (2 * l) * (2 * l - 1)
                u = np.sqrt((l + m) * (l - m) / denom)
                v = 0.5 * np.sqrt((1 + d0) * (l + abs(m) - 1) * (l + abs(m)) / denom) * (1 - 2 * d0)
                w = -0.5 * np.sqrt(max(l - abs(m) - 1, 0) * (l - abs(m)) / denom) * (1 - d0)
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
    """P-4: coefficients (..., n^2) of g(s) = f(R^T s), f given by ``coeffs``; any order, band by band."""
    coeffs = np.asarray(coeffs, dtype=np.float64)
    order = int(round(np.sqrt(coeffs.shape[-1])))
    if order * order != coeffs.shape[-1]:
        raise ValueError(f"rotate: the last axis must hold a square number of coefficients, got {coeffs.shape[-1]}")
    out = np.empty_like(coeffs)
    for l, d in enumerate(rotation_matrices(R, order)):
        sl = slice(l * l, (l + 1) * (l + 1))
        out[..., sl] = coeffs[..., sl] @ d.T
    return out
