"""De-ringing of truncated SH lighting by per-band windows (W-1..W-3; docs/ENVIRONMENT.md, "De-ringing").

A sharp light (a small bright disc, a sun) projected on a few bands rings: the reconstructed irradiance
``E(n) = sum_lm A_l L_lm y_lm(n)`` dips below zero opposite the light. A window multiplies band ``l`` by ``w_l``

    W-1  hann     w_l = (1 + cos(pi l / W)) / 2        for l < W, 0 beyond
         lanczos  w_l = sinc(l / W) = sin(pi l / W) / (pi l / W)   (w_0 = 1), for l < W, 0 beyond (Lanczos sigma)
         none     w_l = 1

with ``W`` the window's width in bands (``W = order`` is the classic choice, that of :func:`lodprt.model.sh.window`).
A per-band factor is a zonal convolution (P-6), so it commutes with rotation (P-4): the window chosen for an
environment holds for every rotation of it.

    W-2  auto: if E >= 0 everywhere already, no window; else for hann and lanczos the widest W in [1, 4 order + 1]
         with min_n E_W(n) >= 0 (narrowed from the widest in half-band steps, then bisected, as Filament's cmgen
         narrows its window), and of the two the one closest to the unwindowed irradiance (W-3). W = 1 keeps
         band 0 only, non-negative whenever L_00 >= 0.

    W-3  the error it costs, by Parseval: rel-RMSE over the sphere of E_W against E,
         sqrt(sum_lm ((1 - w_l) A_l L_lm)^2 / sum_lm (A_l L_lm)^2), all channels together.

``A_l`` is the clamped cosine's convolution factor ``sqrt(4 pi/(2l+1)) z_l`` (``A_0..2 = pi, 2pi/3, pi/4``; I-6 for
``l <= 2``, :func:`lodprt.model.sh.cosine_power_zonal` beyond). "Everywhere" is a dense spherical Fibonacci set
(cmgen tests a set as well) whose lowest points are then polished by a shrinking local search on the sphere, so a
dip narrower than the set's spacing is still found.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model import sh

#: the windows W-1 defines
KINDS = ("hann", "lanczos", "none")
#: what ``--window`` accepts
CHOICES = ("auto", "hann", "lanczos", "none")
#: points of the spherical Fibonacci test set of W-2
TEST_POINTS = 16384
#: bisection steps of W-2 after the half-band scan (the width is then known to 0.5 / 2^steps bands)
BISECTION_STEPS = 16


def band_factors(kind: str, order: int, width: float | None = None) -> np.ndarray:
    """W-1: the per-band multipliers w_l, l < order, of window ``kind`` of width ``width`` bands (default ``order``):
    (order,) float64. LodprtError on an unknown kind or a width that is not > 0."""
    order = int(order)
    if order < 1:
        raise LodprtError(f"window: order must be >= 1, got {order}")
    if kind not in KINDS:
        raise LodprtError(f"window {kind!r}: choose one of {', '.join(KINDS)}")
    w = float(order if width is None else width)
    if not np.isfinite(w) or w <= 0:
        raise LodprtError(f"window width {width!r}: must be a finite number of bands > 0")
    l = np.arange(order, dtype=np.float64)
    if kind == "none":
        return np.ones(order)
    inside = l < w
    if kind == "hann":
        f = 0.5 * (1.0 + np.cos(np.pi * l / w))
    else:
        f = np.sinc(l / w)
    return np.where(inside, f, 0.0)


def apply_window(coeffs, factors) -> np.ndarray:
    """Multiply band l of coefficients (..., n^2) by factors[l] (W-1): (..., n^2) float64."""
    c = np.asarray(coeffs, np.float64)
    f = np.asarray(factors, np.float64)
    if c.ndim < 1 or c.shape[-1] != len(f) ** 2:
        raise LodprtError(f"window: coefficients {c.shape} do not hold {len(f)}^2 per channel")
    return c * np.repeat(f, 2 * np.arange(len(f)) + 1)


def irradiance_factors(order: int) -> np.ndarray:
    """A_l per coefficient (order^2,): the clamped cosine's P-6 factors (pi, 2pi/3, pi/4, 0, -pi/24, ...)."""
    return sh.zonal_scale(sh.cosine_power_zonal(1.0, order))


@functools.lru_cache(maxsize=4)
def _test_set(order: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    y = sh.basis(dirs, order)
    dirs.setflags(write=False)
    y.setflags(write=False)
    return dirs, y


def _polish(e_coeffs: np.ndarray, start: np.ndarray, spacing: float, steps: int = 8) -> float:
    """Local minimum of the SH function e_coeffs (n^2,) near the unit directions ``start`` (K, 3): a 7 x 7 grid on
    the tangent plane, re-centred on its lowest point and shrunk 3x per step (from ``spacing`` radians)."""
    order = int(round(np.sqrt(len(e_coeffs))))
    best = start.copy()
    t = np.linspace(-1.0, 1.0, 7)
    gu, gv = np.meshgrid(t, t, indexing="ij")
    gu, gv = gu.ravel(), gv.ravel()
    r = spacing
    vals = sh.basis(best, order) @ e_coeffs
    for _ in range(steps):
        helper = np.where(np.abs(best[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(best, helper)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(best, t1)
        cand = best[:, None] + r * (gu[None, :, None] * t1[:, None] + gv[None, :, None] * t2[:, None])
        cand /= np.linalg.norm(cand, axis=2, keepdims=True)
        v = sh.basis(cand, order) @ e_coeffs  # (K, 49)
        j = v.argmin(1)
        rows = np.arange(len(best))
        better = v[rows, j] < vals
        best[better] = cand[rows, j][better]
        vals = np.minimum(vals, v[rows, j])
        r /= 3.0
    return float(vals.min())


def irradiance_minimum(coeffs, *, points: int = TEST_POINTS, polish: int = 6) -> np.ndarray:
    """Per channel the minimum over the sphere of the irradiance of lighting ``coeffs`` (C, n^2) (W-2's test):
    the lowest of ``points`` spherical-Fibonacci normals, its ``polish`` lowest then refined locally. (C,) float64."""
    c = np.atleast_2d(np.asarray(coeffs, np.float64))
    order = int(round(np.sqrt(c.shape[-1])))
    e = c * irradiance_factors(order)
    dirs, y = _test_set(order, int(points))
    vals = y @ e.T  # (P, C)
    spacing = float(np.sqrt(4.0 * np.pi / len(dirs)))
    out = np.empty(len(c))
    for ch in range(len(c)):
        low = np.argsort(vals[:, ch])[: max(1, polish)]
        out[ch] = min(float(vals[low, ch].min()), _polish(e[ch], dirs[low], spacing)) if polish else vals[:, ch].min()
    return out


def window_error(coeffs, factors) -> float:
    """W-3: rel-RMSE over the sphere of the windowed irradiance against the unwindowed one (Parseval)."""
    c = np.atleast_2d(np.asarray(coeffs, np.float64))
    order = len(factors)
    e = c * irradiance_factors(order)
    diff = e - apply_window(e, factors)
    norm = float(np.sqrt((e * e).sum()))
    return float(np.sqrt((diff * diff).sum())) / norm if norm > 0 else 0.0


@dataclasses.dataclass
class WindowChoice:
    """A window and what it does to one lighting: kind, width (bands; None for none), factors w_l, the irradiance
    minimum per channel before and after, its maximum, the W-3 error, and whether ``auto`` chose it."""

    kind: str
    width: float | None
    factors: np.ndarray
    minimum_before: np.ndarray
    minimum_after: np.ndarray
    maximum: np.ndarray
    rel_rmse: float
    requested: str

    def to_json(self) -> dict:
        return {
            "requested": self.requested,
            "kind": self.kind,
            "width_bands": self.width,
            "factors": [float(x) for x in self.factors],
            "irradiance_min_unwindowed": self.minimum_before.tolist(),
            "irradiance_min": self.minimum_after.tolist(),
            "irradiance_max_unwindowed": self.maximum.tolist(),
            "rel_rmse_vs_unwindowed": self.rel_rmse,
        }

    def describe(self) -> str:
        if self.kind == "none":
            return "no window" + (" (irradiance already >= 0)" if self.requested == "auto" else "")
        return (f"{self.kind} window of width {self.width:.4g} bands (w_l = "
                + ", ".join(f"{x:.3f}" for x in self.factors) + f"; irradiance rel-RMSE {100 * self.rel_rmse:.2f}% "
                "vs unwindowed)")


def _nonnegative(c: np.ndarray, points: int) -> bool:
    """E >= 0 on the test set (a fast matrix product) and then at the polished minima (W-2)."""
    order = int(round(np.sqrt(c.shape[-1])))
    if ((_test_set(order, points)[1] @ (c * irradiance_factors(order)).T) < 0).any():
        return False
    return bool((irradiance_minimum(c, points=points) >= 0).all())


def _widest_nonnegative(c: np.ndarray, kind: str, order: int, points: int) -> float | None:
    """W-2: the widest width in [1, 4 order + 1] whose windowed irradiance is >= 0 (None if none is): narrowed in
    steps of half a band from the widest, then bisected between the first width that passes and the one above."""
    def ok(width):
        return _nonnegative(apply_window(c, band_factors(kind, order, width)), points)

    above = None
    for width in np.arange(4.0 * order + 1.0, 1.0 - 1e-9, -0.5):
        if ok(width):
            break
        above = width
    else:
        return None
    if above is None:
        return float(width)
    lo, hi = float(width), float(above)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def choose_window(coeffs, window: str = "auto", *, width: float | None = None, points: int = TEST_POINTS) -> WindowChoice:
    """The window for lighting ``coeffs`` (C, n^2): ``auto`` (W-2), or ``hann`` / ``lanczos`` of ``width`` bands
    (default the order), or ``none``. LodprtError on an unknown name, a width with auto/none, or when no window
    can make the irradiance non-negative (a negative L_00: not the projection of a radiance >= 0)."""
    if window not in CHOICES:
        raise LodprtError(f"--window {window!r}: choose one of {', '.join(CHOICES)}")
    if width is not None and window not in ("hann", "lanczos"):
        raise LodprtError(f"--window-width applies to the hann and lanczos windows, not to {window!r}")
    c = np.atleast_2d(np.asarray(coeffs, np.float64))
    if not np.isfinite(c).all():
        raise LodprtError("window: lighting coefficients must be finite")
    order = int(round(np.sqrt(c.shape[-1])))
    if order * order != c.shape[-1]:
        raise LodprtError(f"window: lighting coefficients {c.shape} do not hold order^2 per channel")
    before = irradiance_minimum(c, points=points)
    e_max = (_test_set(order, points)[1] @ (c * irradiance_factors(order)).T).max(0)

    def made(kind, w):
        f = band_factors(kind, order, w)
        return WindowChoice(kind, None if kind == "none" else float(w), f, before,
                            irradiance_minimum(apply_window(c, f), points=points), e_max, window_error(c, f), window)

    if window != "auto":
        return made(window, order if width is None else width)
    if (before >= 0).all():
        return made("none", None)
    found = [(kind, w) for kind in ("hann", "lanczos") if (w := _widest_nonnegative(c, kind, order, points)) is not None]
    if not found:
        raise LodprtError("window auto: no window makes this irradiance non-negative (L_00 < 0 in some channel: "
                          "these coefficients are not the projection of a non-negative radiance)")
    return min((made(k, w) for k, w in found), key=lambda ch: ch.rel_rmse)
