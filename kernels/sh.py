"""Real SH basis as float32 Warp functions, same convention as ``lodprt.model.sh`` (T-5).

Index i = l(l+1) + m, order n = n*n coefficients, no Condon-Shortley phase: y_0 = 1/sqrt(4 pi),
(y_1^{-1}, y_1^0, y_1^1) = sqrt(3/(4 pi)) (y, z, x).

Same steps as the float64 reference (see the comment above ``lodprt.model.sh.basis``): y_l^{+-m} = sqrt(2) Q_l^m(z)
{Re, Im} (x + i y)^m with (x + i y)^m from the Cartesian recurrence, and the fully normalised Q_l^m (no sin^m
factor, no factorial) from Q_m^m = Q_{m-1}^{m-1} sqrt((2m+1)/(2m)) and the normalised three-term recurrence in
Reinsch's difference form, evaluated at |z| with 1 - |z| = (x^2 + y^2)/(1 + |z|) and parity (-1)^(l-m) for z < 0.
That form keeps float32 within ~5e-6 absolute of the float64 reference up to order 32 (the plain a_lm, b_lm form
reaches 1e-5 already at order 14, from the rounding of z near the poles).  Nothing is precomputed on the host:
the recurrence coefficients are formed inline with wp.sqrt.
"""

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

#: Highest order (bands) the float32 kernels offer.  Measured worst error against the float64 reference over
#: ~220k directions (poles and equator included): 1.0e-6 at order 8, 1.5e-6 at 12, 4.5e-6 at 32, 7.4e-6 at 48;
#: 32 keeps a 2x margin on the 1e-5 test and is far beyond what a bake stores per vertex.
MAX_KERNEL_ORDER = 32


@wp.func
def unit_direction(d: wp.vec3):
    """``d`` normalised, scaling by the largest component first so tiny vectors do not underflow to a zero length;
    a zero vector reads as +z."""
    big = wp.max(wp.max(wp.abs(d[0]), wp.abs(d[1])), wp.abs(d[2]))
    u = wp.vec3(0.0, 0.0, 1.0)
    if big > 0.0:
        u = wp.normalize(d / big)
    return u


@wp.func
def bands_of(ncoef: int):
    """The SH order (bands) whose basis has ``ncoef`` values: sqrt(ncoef) (1 for a diffuse-only store's y_0).
    Kernels size their SH loops from the coefficient array they read, never from a setting passed beside it."""
    return int(wp.sqrt(float(ncoef)) + 0.5)


@wp.func
def sh_basis(
    d: wp.vec3,  # In: direction, any length (normalised here; a zero vector reads as +z)
    order: int,  # In: bands; order^2 values are written
    out: wp.array2d(dtype=wp.float32),  # Out: out[row, i] = y_i(d) for i < order^2
    row: int,  # In: row of out to fill
):
    u = unit_direction(d)
    x = u[0]
    y = u[1]
    z = u[2]
    t = wp.abs(z)
    one_minus_t = (x * x + y * y) / (1.0 + t)  # 1 - |z| without cancellation near the poles
    flip = float(1.0)
    if z < 0.0:
        flip = -1.0  # parity: Q_l^m(-t) = (-1)^(l-m) Q_l^m(t)

    re = float(1.0)  # Re (x + i y)^m = sin^m(theta) cos(m phi)
    im = float(0.0)  # Im (x + i y)^m = sin^m(theta) sin(m phi)
    qmm = float(0.28209479177387814)  # Q_0^0 = 1/sqrt(4 pi)
    for m in range(order):
        fm = float(m)
        if m > 0:
            re_next = re * x - im * y
            im = re * y + im * x
            re = re_next
            qmm = qmm * wp.sqrt((2.0 * fm + 1.0) / (2.0 * fm))
        q = qmm  # Q_l^m(|z|)
        e = qmm  # e_l = Q_l^m - g_l Q_{l-1}^m, e_m = Q_m^m
        sign = float(1.0)
        for l in range(m, order):
            if l > m:
                fl = float(l)
                g = wp.sqrt((2.0 * fl + 1.0) * (fl - fm) / ((2.0 * fl - 1.0) * (fl + fm)))
                e = g / (fl - fm) * ((fl + fm - 1.0) * e - (2.0 * fl - 1.0) * one_minus_t * q)
                q = g * q + e
                sign = sign * flip
            base = l * (l + 1)
            if m == 0:
                out[row, base] = sign * q
            else:
                s = 1.4142135623730951 * sign * q
                out[row, base + m] = s * re
                out[row, base - m] = s * im


@wp.func
def sh_basis_fast(
    d: wp.vec3,  # In: direction, any length (normalised here; a zero vector reads as +z)
    order: int,  # In: bands; order^2 values are written
    out: wp.array2d(dtype=wp.float32),  # Out: out[row, i] = y_i(d) for i < order^2
    row: int,  # In: row of out to fill
):
    """``sh_basis`` with the bands l <= 3 written as their closed-form polynomials in (x, y, z) (same convention:
    no Condon-Shortley phase, y_1 = sqrt(3/4pi) (y, z, x)); orders above 4 take the recurrence. About ten times
    cheaper per direction for the run time's per-frame kernels, which evaluate one basis per node or vertex."""
    if order > 4:
        sh_basis(d, order, out, row)
        return
    u = unit_direction(d)
    x = u[0]
    y = u[1]
    z = u[2]
    out[row, 0] = 0.28209479177387814
    if order > 1:
        out[row, 1] = 0.4886025119029199 * y
        out[row, 2] = 0.4886025119029199 * z
        out[row, 3] = 0.4886025119029199 * x
    if order > 2:
        out[row, 4] = 1.0925484305920792 * x * y
        out[row, 5] = 1.0925484305920792 * y * z
        out[row, 6] = 0.31539156525252005 * (3.0 * z * z - 1.0)
        out[row, 7] = 1.0925484305920792 * x * z
        out[row, 8] = 0.5462742152960396 * (x * x - y * y)
    if order > 3:
        out[row, 9] = 0.5900435899266435 * y * (3.0 * x * x - y * y)
        out[row, 10] = 2.890611442640554 * x * y * z
        out[row, 11] = 0.4570457994644658 * y * (5.0 * z * z - 1.0)
        out[row, 12] = 0.3731763325901154 * z * (5.0 * z * z - 3.0)
        out[row, 13] = 0.4570457994644658 * x * (5.0 * z * z - 1.0)
        out[row, 14] = 1.445305721320277 * z * (x * x - y * y)
        out[row, 15] = 0.5900435899266435 * x * (x * x - 3.0 * y * y)


@wp.kernel
def sh_basis_kernel(
    dirs: wp.array(dtype=wp.vec3),  # In: (N,) directions, any length
    order: int,  # In: bands, 1..MAX_KERNEL_ORDER
    fast: int,  # In: 1 through sh_basis_fast (closed forms up to order 4), 0 through the recurrence
    out: wp.array2d(dtype=wp.float32),  # Out: (N, order^2) basis values y_i(dirs[k])
):
    k = wp.tid()
    if fast != 0:
        sh_basis_fast(dirs[k], order, out, k)
    else:
        sh_basis(dirs[k], order, out, k)


def eval_basis(dirs: np.ndarray, order: int, device, *, fast: bool = False) -> np.ndarray:
    """SH basis of ``dirs`` (N, 3) (or one direction (3,)) evaluated by the float32 kernel on ``device``.

    Returns (N, order^2) float32 numpy.  ValueError unless 1 <= order <= MAX_KERNEL_ORDER and dirs is (N, 3).
    ``fast``: through ``sh_basis_fast`` (closed forms up to order 4).
    """
    if isinstance(order, bool) or int(order) != order or not 1 <= order <= MAX_KERNEL_ORDER:
        raise ValueError(f"order {order!r}: the float32 SH kernels offer orders 1..{MAX_KERNEL_ORDER}")
    order = int(order)
    d = np.asarray(dirs, dtype=np.float32)
    if d.shape == (3,):
        d = d[None]
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"eval_basis: dirs must have shape (N, 3), got {d.shape}")
    out = wp.zeros((len(d), order * order), dtype=wp.float32, device=device)
    if len(d):
        wdirs = wp.array(np.ascontiguousarray(d), dtype=wp.vec3, device=device)
        wp.launch(sh_basis_kernel, dim=len(d), inputs=[wdirs, order, int(bool(fast))], outputs=[out], device=device)
    return out.numpy()
