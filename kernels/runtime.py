"""Per-frame run-time kernels (SPEC 5; thesis 3.4): view-cut errors of candidate nodes (T-13, T-14) and
relighting of the active vertices from interpolated light samples (T-12, T-7).

The float64 numpy versions in ``lodprt.runtime`` (``Runtime.node_errors_reference``, ``Runtime.coefficients``)
compute the same quantities and are the tests' reference.
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis_fast

wp.set_module_options({"enable_backward": False})


@wp.func
def display(x: float):
    """clip(x, 0, 1): the screen intensity of a radiance in units of the white point (thesis 3.4.2.2)."""
    return wp.clamp(x, 0.0, 1.0)


@wp.kernel
def view_errors(
    offset: int,  # In: first row of this launch (a launch may cover a slice of the rows)
    nodes: wp.array(dtype=wp.int32),  # In: (K,) internal nodes to evaluate
    first_internal: int,  # In: V, the id of the first internal node (row 0 of the boxes)
    node_pos: wp.array(dtype=wp.vec3),  # In: (N,) position of each node's vertex
    node_collapsed: wp.array(dtype=wp.vec3),  # In: (N,) position p of the vertex each node's collapse removed
    error_vector: wp.array(dtype=wp.vec3),  # In: (N,) p - p' (figure 10)
    axis: wp.array(dtype=wp.vec3),  # In: (N,) normal-cone axis
    half_angle: wp.array(dtype=wp.float32),  # In: (N,) normal-cone half-angle, radians
    radius: wp.array(dtype=wp.float32),  # In: (N,) bounding-sphere radius at node_pos
    planes: wp.array(dtype=wp.vec4),  # In: (6,) inward frustum planes, unit normals
    vp: wp.mat44,  # In: projection @ view (row-major, column vectors)
    eye: wp.vec3,  # In: camera position
    half_w: float,  # In: half the screen width in pixels
    half_h: float,  # In: half the screen height in pixels
    diag: float,  # In: screen diagonal in pixels
    used: wp.array(dtype=wp.int32),  # In: (U,) light samples with a non-zero weight
    weights: wp.array2d(dtype=wp.float32),  # In: (S, 3) RGB weight of every light sample (T-12, intensities)
    box_centre: wp.array4d(dtype=wp.float16),  # In: (N - V, S, C, ncoef) coefficient box centre / white per node
    box_half: wp.array4d(dtype=wp.float16),  # In: (N - V, S, C, ncoef) coefficient box half-width / white
    alpha: float,  # In: weight of e_geo (T-14)
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (K, >= ncoef); ncoef = 1 (diffuse-only store) or order^2
    culled: wp.array(dtype=wp.uint8),  # Out: (K,) 1 when back-facing (T-13) or outside the frustum
    err: wp.array(dtype=wp.float32),  # Out: (K,) alpha e_geo + (1 - alpha) e_lumi (T-14)
    e_geo: wp.array(dtype=wp.float32),  # Out: (K,)
    e_lumi: wp.array(dtype=wp.float32),  # Out: (K,)
):
    k = wp.tid() + offset
    node = nodes[k]
    p = node_pos[node]
    r = radius[node]
    out = int(0)
    for i in range(6):
        pl = planes[i]
        if pl[0] * p[0] + pl[1] * p[1] + pl[2] * p[2] + pl[3] < -r:
            out = 1
    # T-13: the whole cone faces away from every direction to the eye (widened by the sphere's angle)
    v = eye - p
    d = wp.length(v)
    vh = wp.vec3(0.0, 0.0, 1.0)
    if d > 0.0:
        vh = v / d
    if d > r:
        ang = wp.acos(wp.clamp(wp.dot(vh, axis[node]), -1.0, 1.0))
        spread = wp.asin(wp.clamp(r / d, 0.0, 1.0))
        if ang > 1.5707963267948966 + half_angle[node] + spread:
            out = 1
    culled[k] = wp.uint8(out)
    if out == 1:  # culled nodes are coarsened whatever their error: none is computed
        e_geo[k] = 0.0
        e_lumi[k] = 0.0
        err[k] = 0.0
        return
    # e_geo: both ends of the error vector on screen, their distance over the diagonal
    a = node_collapsed[node]
    b = a - error_vector[node]
    ca = vp * wp.vec4(a[0], a[1], a[2], 1.0)
    cb = vp * wp.vec4(b[0], b[1], b[2], 1.0)
    g = float(1.0)
    if ca[3] > 1.0e-12 and cb[3] > 1.0e-12:
        dx = (ca[0] / ca[3] - cb[0] / cb[3]) * half_w
        dy = (ca[1] / ca[3] - cb[1] / cb[3]) * half_h
        g = wp.min(wp.sqrt(dx * dx + dy * dy) / diag, 1.0)
    # e_lumi: the display spread of the interval that holds the leaves' radiance toward the eye
    # the SH width comes from the boxes themselves: 1 (y_0 of a diffuse-only store) or order^2
    ncoef = wp.min(box_centre.shape[3], basis.shape[1])
    sh_basis_fast(vh, bands_of(ncoef), basis, k)
    row = node - first_internal
    channels = box_centre.shape[2]
    hr = float(0.0)
    hg = float(0.0)
    hb = float(0.0)
    lr = float(0.0)
    lg = float(0.0)
    lb = float(0.0)
    for u in range(used.shape[0]):
        j = used[u]
        for c in range(channels):
            mid = float(0.0)
            rad = float(0.0)
            for i in range(ncoef):
                y = basis[k, i]
                mid += wp.float32(box_centre[row, j, c, i]) * y
                rad += wp.float32(box_half[row, j, c, i]) * wp.abs(y)
            if channels == 1 or c == 0:
                hr += (mid + rad) * weights[j, 0]
                lr += (mid - rad) * weights[j, 0]
            if channels == 1 or c == 1:
                hg += (mid + rad) * weights[j, 1]
                lg += (mid - rad) * weights[j, 1]
            if channels == 1 or c == 2:
                hb += (mid + rad) * weights[j, 2]
                lb += (mid - rad) * weights[j, 2]
    lum = wp.max(wp.max(display(hr) - display(lr), display(hg) - display(lg)), display(hb) - display(lb))
    lum = wp.clamp(lum, 0.0, 1.0)
    e_geo[k] = g
    e_lumi[k] = lum
    err[k] = alpha * g + (1.0 - alpha) * lum


@wp.kernel
def relight(
    offset: int,  # In: first row of this launch (a launch may cover a slice of the rows)
    vid: wp.array(dtype=wp.int32),  # In: (A,) active vertices
    positions: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) vertex normals (view direction for an eye on the vertex)
    eye: wp.vec3,  # In: camera position
    used: wp.array(dtype=wp.int32),  # In: (U,) light samples with a non-zero weight
    weights: wp.array2d(dtype=wp.float32),  # In: (S, 3) RGB weight of every light sample
    coeffs: wp.array4d(dtype=wp.float32),  # In: (V, S, C, ncoef) completed coefficients of every sample
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (A, >= ncoef); ncoef = 1 (diffuse-only store) or order^2
    out_coeffs: wp.array3d(dtype=wp.float32),  # Out: (A, 3, ncoef) interpolated RGB coefficients
    radiance: wp.array2d(dtype=wp.float32),  # Out: (A, 3) radiance toward the eye (T-7)
):
    k = wp.tid() + offset
    v = vid[k]
    dv = eye - positions[v]
    if wp.length(dv) <= 0.0:
        dv = normals[v]
    # the SH width comes from the arrays: 1 (y_0 of a diffuse-only store) or order^2
    ncoef = wp.min(wp.min(coeffs.shape[3], out_coeffs.shape[2]), basis.shape[1])
    sh_basis_fast(dv, bands_of(ncoef), basis, k)
    channels = coeffs.shape[2]
    for c in range(3):
        for i in range(ncoef):
            out_coeffs[k, c, i] = 0.0
    for u in range(used.shape[0]):
        j = used[u]
        w0 = weights[j, 0]
        w1 = weights[j, 1]
        w2 = weights[j, 2]
        if channels == 1:  # grey: one coefficient read feeds R, G and B
            for i in range(ncoef):
                x = coeffs[v, j, 0, i]
                out_coeffs[k, 0, i] += w0 * x
                out_coeffs[k, 1, i] += w1 * x
                out_coeffs[k, 2, i] += w2 * x
        else:
            for i in range(ncoef):
                out_coeffs[k, 0, i] += w0 * coeffs[v, j, 0, i]
                out_coeffs[k, 1, i] += w1 * coeffs[v, j, 1, i]
                out_coeffs[k, 2, i] += w2 * coeffs[v, j, 2, i]
    for c in range(3):
        rad = float(0.0)
        for i in range(ncoef):
            rad += out_coeffs[k, c, i] * basis[k, i]
        radiance[k, c] = rad
