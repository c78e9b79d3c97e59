"""Per-node bounds of one light sample (SPEC S-2 and E-1; host: ``lodprt.runtime.node_bounds``), float32 CPU kernels.

Both kernels bound the radiance of a difference of SH coefficient rows toward any view direction, per channel,
with ``radiance_bound``'s sum over bands ``sum_l sqrt((2l + 1) / 4 pi) |r_l|`` (S-2: Cauchy-Schwarz per band and
the addition theorem):

* ``residual_bounds``: per collapse row m, of the T-15 residual ``C(v) - sum_j w_j C(q_j)`` over its CSR ring;
* ``leaf_step_bounds``: per row of an adjacency CSR (a leaf v), the largest over its original neighbours q of
  ``C(v) - C(q)``.

Each takes ``first``, the index of its thread 0: the host slices one pass over several threads (a CPU launch
releases the GIL); each thread writes only its own row. The coefficient count per channel is read from the arrays
(``c.shape[1] // out.shape[1]``), every loop from CSR starts and ends read from them.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def band_weight(l: int):
    return wp.sqrt(float(2 * l + 1) / (4.0 * wp.pi))


@wp.func
def add_band(x: float, j: int, n: int, band: float, total: float):
    """Coefficient ``x`` (index j of n, band l = floor(sqrt(j))) into its band's sum of squares; at the band's
    last coefficient ((l + 1)^2 = j + 1, or j + 1 = n) the band's weighted norm into ``total``: (band, total)."""
    l = int(wp.floor(wp.sqrt(float(j))))
    b = band + x * x
    t = total
    if (l + 1) * (l + 1) == j + 1 or j + 1 == n:  # S-2 one band's norm, weighted
        t = total + band_weight(l) * wp.sqrt(b)
        b = 0.0
    return b, t


@wp.kernel
def residual_bounds(
    first: int,  # In: the row of thread 0 (a slice of the pass)
    vertex: wp.array(dtype=wp.int32),  # In: (M,) the vertex each collapse removed
    ring_ptr: wp.array(dtype=wp.int64),  # In: (M + 1,) CSR start of each row's ring
    ring_ids: wp.array(dtype=wp.int32),  # In: ring vertex ids
    ring_w: wp.array(dtype=wp.float32),  # In: their T-15 weights
    c: wp.array2d(dtype=wp.float32),  # In: (V, C * n) completed coefficients
    inv_white: wp.float32,  # In: 1 / white
    out: wp.array2d(dtype=wp.float32),  # Out: (M, C) S-2 bound of the T-15 residual, in units of white
):
    m = first + wp.tid()
    v = int(vertex[m])
    lo = int(ring_ptr[m])
    hi = int(ring_ptr[m + 1])
    C = out.shape[1]
    n = c.shape[1] // C
    for ch in range(C):
        band, total = float(0.0), float(0.0)
        for j in range(n):
            k = ch * n + j
            s = float(0.0)
            for e in range(lo, hi):  # T-15 sum_j w_j C(q_j)
                s += ring_w[e] * c[int(ring_ids[e]), k]
            band, total = add_band((c[v, k] - s) * inv_white, j, n, band, total)
        out[m, ch] = total


@wp.kernel
def leaf_step_bounds(
    first: int,  # In: the row of thread 0 (a slice of the pass)
    row_vertex: wp.array(dtype=wp.int32),  # In: (R,) the vertex of each adjacency row
    ptr: wp.array(dtype=wp.int64),  # In: (R + 1,) CSR start of each row's neighbours
    nbr: wp.array(dtype=wp.int32),  # In: (E,) the original neighbours of the rows' vertices
    c: wp.array2d(dtype=wp.float32),  # In: (V, C * n) completed coefficients
    inv_white: wp.float32,  # In: 1 / white
    out: wp.array2d(dtype=wp.float32),  # Out: (N, C) written at each row's vertex (0 where it has no neighbour)
):
    r = first + wp.tid()
    v = int(row_vertex[r])
    C = out.shape[1]
    n = c.shape[1] // C
    for ch in range(C):
        best = float(0.0)
        for e in range(int(ptr[r]), int(ptr[r + 1])):
            q = int(nbr[e])
            band, total = float(0.0), float(0.0)
            for j in range(n):  # S-2 (b) one edge's step
                band, total = add_band(c[v, j + ch * n] * inv_white - c[q, j + ch * n] * inv_white, j, n, band, total)
            best = wp.max(best, total)
        out[v, ch] = best
