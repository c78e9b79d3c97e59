"""Real SH basis in float32 Warp functions (SPEC 1), same convention as ``lodprt.sh`` (index l(l+1)+m, no
Condon-Shortley phase, y_1 = sqrt(3/4pi) (y, z, x)).

Same recurrences as the float64 reference: Q_l^m(z) fully normalised without the sin^m factor, times
Re/Im (x + i y)^m, so nothing divides by sin(theta) and no factorial is formed. Accurate to about 1e-6 absolute
up to MAX_KERNEL_ORDER (tested against the float64 reference at 1e-5).
"""

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

#: highest order (bands) the float32 kernels offer
MAX_KERNEL_ORDER = 12


@wp.func
def sh_basis(
    d: wp.vec3,  # In: direction (normalised here; zero reads as +z)
    order: int,  # In: bands, order^2 values written
    out: wp.array2d(dtype=wp.float32),  # Out: out[row, i] = y_i(d)
    row: int,  # In: row of out to fill
):
    n = wp.length(d)
    u = wp.vec3(0.0, 0.0, 1.0)
    if n > 0.0:
        u = d / n
    x = u[0]
    y = u[1]
    z = u[2]
    re = float(1.0)
    im = float(0.0)
    qmm = float(0.28209479177387814)  # 1/sqrt(4 pi)
    for m in range(order):
        if m > 0:
            re_new = re * x - im * y
            im = re * y + im * x
            re = re_new
            fm = float(m)
            qmm = qmm * wp.sqrt((2.0 * fm + 1.0) / (2.0 * fm))
        q_prev2 = float(0.0)
        q_prev = qmm
        for l in range(m, order):
            q = qmm
            fl = float(l)
            fm = float(m)
            if l == m + 1:
                q = wp.sqrt(2.0 * fm + 3.0) * z * qmm
            elif l > m + 1:
                a = wp.sqrt((4.0 * fl * fl - 1.0) / (fl * fl - fm * fm))
                b = wp.sqrt(((fl - 1.0) * (fl - 1.0) - fm * fm) / (4.0 * (fl - 1.0) * (fl - 1.0) - 1.0))
                q = a * (z * q_prev - b * q_prev2)
            if l > m:
                q_prev2 = q_prev
                q_prev = q
            base = l * (l + 1)
            if m == 0:
                out[row, base] = q
            else:
                out[row, base + m] = 1.4142135623730951 * q * re
                out[row, base - m] = 1.4142135623730951 * q * im


@wp.kernel
def sh_basis_kernel(
    dirs: wp.array(dtype=wp.vec3),  # In: (N,) directions
    order: int,  # In: bands
    out: wp.array2d(dtype=wp.float32),  # Out: (N, order^2) basis values
):
    k = wp.tid()
    sh_basis(dirs[k], order, out, k)


def eval_basis(dirs: np.ndarray, order: int, device) -> np.ndarray:
    """SH basis of ``dirs`` (N, 3) on a Warp device: (N, order^2) float32."""
    if not 1 <= order <= MAX_KERNEL_ORDER:
        raise ValueError(f"order {order}: the float32 kernels offer orders 1..{MAX_KERNEL_ORDER}")
    dirs = np.asarray(dirs, dtype=np.float32).reshape(-1, 3)
    out = wp.zeros((len(dirs), order * order), dtype=wp.float32, device=device)
    wp.launch(sh_basis_kernel, dim=len(dirs), inputs=[wp.array(dirs, dtype=wp.vec3, device=device), order], outputs=[out], device=device)
    return out.numpy()
