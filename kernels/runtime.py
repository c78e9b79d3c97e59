"""Per-frame run-time kernels (SPEC 5; thesis 3.4): view-cut errors of candidate nodes (T-13; T-14 or S-1/S-2)
and relighting of the active vertices from interpolated light samples (T-12, T-7).

The float64 numpy versions (``lodprt.runtime.errors_reference.node_errors_reference``, ``Runtime.coefficients``)
compute the same quantities and are the tests' reference.
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis_fast

wp.set_module_options({"enable_backward": False})


@wp.func
def display(x: float):
    """clip(x, 0, 1): the screen intensity of a radiance in units of the white point (thesis 3.4.2.2)."""
    return wp.clamp(x, 0.0, 1.0)


@wp.func
def detail_bound(
    row: int,  # In: the node's row in detail
    used: wp.array(dtype=wp.int32),
    weights: wp.array2d(dtype=wp.float32),
    detail: wp.array3d(dtype=wp.float16),
    sharp: int,  # In: 0 sum_j |W_jc| D_jc (T-12 blends the samples); 1 max_j D_jc sum_j |W_jc| (M-5)
    bracket: wp.array(dtype=wp.int32),  # In: (S,) 1 for the slots whose detail the M-5 max takes (sharp = 1 only)
):
    """S-2: max over RGB of sum_j |W_jc| D_jc (units of white, at most 1); D_jc bounds the radiance the subtree's
    completion could miss toward any view direction (``lodprt.runtime.node_bounds.detail_bounds``). M-5 (the
    direct path's hard shadows between samples): max_j D_jc sum_j |W_jc| over the samples around the light
    (``bracket``), each sample's detail at full weight."""
    channels = detail.shape[2]
    dr = float(0.0)
    dg = float(0.0)
    db = float(0.0)
    mr = float(0.0)
    mg = float(0.0)
    mb = float(0.0)
    for u in range(used.shape[0]):
        j = used[u]
        for c in range(channels):
            det = wp.float32(detail[row, j, c])
            near = float(0.0)
            if sharp == 1:
                if bracket[j] == 1:
                    near = det
            if channels == 1 or c == 0:
                dr += det * wp.abs(weights[j, 0])
                mr = wp.max(mr, near)
            if channels == 1 or c == 1:
                dg += det * wp.abs(weights[j, 1])
                mg = wp.max(mg, near)
            if channels == 1 or c == 2:
                db += det * wp.abs(weights[j, 2])
                mb = wp.max(mb, near)
    if sharp == 1:
        tr = float(0.0)
        tg = float(0.0)
        tb = float(0.0)
        for u in range(used.shape[0]):
            j = used[u]
            tr += wp.abs(weights[j, 0])
            tg += wp.abs(weights[j, 1])
            tb += wp.abs(weights[j, 2])
        dr = mr * tr
        dg = mg * tg
        db = mb * tb
    return wp.min(wp.max(wp.max(dr, dg), db), 1.0)


@wp.func
def spread_bound(
    k: int,  # In: row of basis
    row: int,  # In: the node's row in the boxes
    used: wp.array(dtype=wp.int32),
    weights: wp.array2d(dtype=wp.float32),
    box_centre: wp.array4d(dtype=wp.float16),
    box_half: wp.array4d(dtype=wp.float16),
    basis: wp.array2d(dtype=wp.float32),
    ncoef: int,
):
    """T-14 e_lumi: the display spread of the interval that holds the leaves' radiance toward the eye."""
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
    return wp.clamp(lum, 0.0, 1.0)


@wp.kernel
def view_errors(
    offset: int,  # In: first row of this launch (a launch may cover a slice of the rows)
    nodes: wp.array(dtype=wp.int32),  # In: (K,) internal nodes to evaluate
    first_internal: int,  # In: V, the id of the first internal node (row 0 of the boxes)
    positions: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    vertex: wp.array(dtype=wp.int32),  # In: (N,) each node's vertex
    children: wp.array2d(dtype=wp.int32),  # In: (N, 2) each node's children (-1 for a leaf)
    error_vector: wp.array(dtype=wp.vec3),  # In: (N,) p - p' (figure 10)
    axis: wp.array(dtype=wp.vec3),  # In: (N,) normal-cone axis
    half_angle: wp.array(dtype=wp.float32),  # In: (N,) normal-cone half-angle, radians
    radius: wp.array(dtype=wp.float32),  # In: (N,) bounding-sphere radius at the node's vertex
    planes: wp.array(dtype=wp.vec4),  # In: (6,) inward frustum planes, unit normals
    vp: wp.mat44,  # In: projection @ view (row-major, column vectors)
    eye: wp.vec3,  # In: camera position
    half_w: float,  # In: half the screen width in pixels
    half_h: float,  # In: half the screen height in pixels
    diag: float,  # In: screen diagonal in pixels
    focal_px: float,  # In: focal length in pixels, (height / 2) / tan(fov / 2)
    used: wp.array(dtype=wp.int32),  # In: (U,) sample slots with a non-zero weight
    weights: wp.array2d(dtype=wp.float32),  # In: (S, 3) RGB weight of every sample slot (T-12, intensities)
    box_centre: wp.array4d(dtype=wp.float16),  # In: (N - V, S, C, ncoef) coefficient box centre / white per node
    #                                                  and sample slot
    box_half: wp.array4d(dtype=wp.float16),  # In: (N - V, S, C, ncoef) coefficient box half-width / white
    detail: wp.array3d(dtype=wp.float16),  # In: (N - V, S, C) S-2 bound of the completion residual / white
    criterion: int,  # In: the criterion's MODE (lodprt.runtime.criteria): 0 "screen" (S-1), 1 "thesis" (T-14)
    sharp: int,  # In: 1 for the direct interpolations (M-5: each sample's S-2 detail at full weight), 0 for T-12
    bracket: wp.array(dtype=wp.int32),  # In: (S,) M-5: 1 for the slots around the light (sharp = 1 only)
    exact: int,  # In: 1 computes every term; 0 stops once the refine/coarsen decision is known; 2 every S-1 term
    bound: float,  # In: the error bound (the decision's threshold)
    hysteresis: float,  # In: >= 1; a candidate is collapsed only at or below bound / hysteresis
    geo_rate: float,  # In: S-1 units of white per pixel of geometric error
    area_ref: float,  # In: S-1 pixels a node may cover before its shading term grows with sqrt(area / area_ref)
    alpha: float,  # In: weight of e_geo (T-14)
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (K, >= ncoef); ncoef = 1 (diffuse-only store) or order^2
    culled: wp.array(dtype=wp.uint8),  # Out: (K,) 1 when back-facing (T-13) or outside the frustum
    err: wp.array(dtype=wp.float32),  # Out: (K,) the criterion's error (S-1 or T-14); with exact = 0 an upper
    #                                        bound where that already decides against refining
    e_geo: wp.array(dtype=wp.float32),  # Out: (K,)
    e_lumi: wp.array(dtype=wp.float32),  # Out: (K,)
    footprint: wp.array(dtype=wp.float32),  # Out: (K,) radius of the node's bounding sphere on screen, pixels
    e_detail: wp.array(dtype=wp.float32),  # Out: (K,) radiance toward the eye the subtree's completion could miss
):
    k = wp.tid() + offset
    node = nodes[k]
    p = positions[vertex[node]]
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
        footprint[k] = 0.0
        e_detail[k] = 0.0
        return
    # screen footprint: the bounding sphere's projected radius r f / depth (unbounded when the eye is inside it)
    cp = vp * wp.vec4(p[0], p[1], p[2], 1.0)
    fp = float(1.0e9)
    if cp[3] > r:
        fp = wp.min(r * focal_px / cp[3], 1.0e9)
    # e_geo: both ends of the error vector on screen, their distance over the diagonal
    a = p  # the position p of the vertex the node's collapse removed (its second child's vertex)
    if children[node, 1] >= 0:
        a = positions[vertex[children[node, 1]]]
    b = a - error_vector[node]
    ca = vp * wp.vec4(a[0], a[1], a[2], 1.0)
    cb = vp * wp.vec4(b[0], b[1], b[2], 1.0)
    g = float(1.0)
    if ca[3] > 1.0e-12 and cb[3] > 1.0e-12:
        dx = (ca[0] / ca[3] - cb[0] / cb[3]) * half_w
        dy = (ca[1] / ca[3] - cb[1] / cb[3]) * half_h
        g = wp.min(wp.sqrt(dx * dx + dy * dy) / diag, 1.0)
    # the SH width comes from the boxes themselves: 1 (y_0 of a diffuse-only store) or order^2
    ncoef = wp.min(box_centre.shape[3], basis.shape[1])
    row = node - first_internal
    # S-1 (criterion 0): geometry in pixels at the exchange rate geo_rate, luminance weighted by pixel coverage
    geo_term = g * diag * geo_rate
    area = 3.141592653589793 * fp * fp
    cover = float(1.0)  # S-1: a node in view decides at least one pixel, however small its footprint
    if area > area_ref:  # S-1: a large node's squared error summed over its pixels, at most bound^2 area_ref
        cover = wp.sqrt(area / area_ref)
    e_geo[k] = g
    footprint[k] = fp
    e_lumi[k] = -1.0  # -1: not computed (the decision did not need it; exact = 1 computes every term)
    e_detail[k] = -1.0
    if criterion == 0 and exact == 0 and (geo_term > bound or cover * hysteresis <= bound):
        # decided without the luminance: refine on geometry, or at most bound / hysteresis (either decision)
        err[k] = wp.max(geo_term, cover)
        if geo_term <= bound:
            err[k] = wp.min(err[k], bound)
        return
    if criterion == 0:
        det = detail_bound(row, used, weights, detail, sharp, bracket)
        e_detail[k] = det
        err[k] = wp.max(geo_term, det * cover)  # S-1 with S-2
        if exact != 1:  # 0: decided; 2: S-1 and S-2 in full, without T-14's spread (the frame estimate, E-1)
            return
    sh_basis_fast(vh, bands_of(ncoef), basis, k)  # T-14's spread reads the basis toward the eye
    lum = spread_bound(k, row, used, weights, box_centre, box_half, basis, ncoef)
    e_lumi[k] = lum
    if criterion == 1:
        err[k] = alpha * g + (1.0 - alpha) * lum  # T-14


@wp.kernel
def relight(
    offset: int,  # In: first row of this launch (a launch may cover a slice of the rows)
    vid: wp.array(dtype=wp.int32),  # In: (A,) active vertices
    positions: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) vertex normals (view direction for an eye on the vertex)
    eye: wp.vec3,  # In: camera position
    used: wp.array(dtype=wp.int32),  # In: (U,) sample slots with a non-zero weight
    weights: wp.array2d(dtype=wp.float32),  # In: (S, 3) RGB weight of every sample slot
    coeffs: wp.array4d(dtype=wp.float32),  # In: (V, S, C, ncoef) completed coefficients of every sample slot
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
    r0 = float(0.0)
    r1 = float(0.0)
    r2 = float(0.0)
    # coefficient-major: each output written once, the vertex's samples read from its contiguous block
    for i in range(ncoef):
        s0 = float(0.0)
        s1 = float(0.0)
        s2 = float(0.0)
        for u in range(used.shape[0]):
            j = used[u]
            if channels == 1:  # grey: one coefficient read feeds R, G and B
                x = coeffs[v, j, 0, i]
                s0 += weights[j, 0] * x
                s1 += weights[j, 1] * x
                s2 += weights[j, 2] * x
            else:
                s0 += weights[j, 0] * coeffs[v, j, 0, i]
                s1 += weights[j, 1] * coeffs[v, j, 1, i]
                s2 += weights[j, 2] * coeffs[v, j, 2, i]
        out_coeffs[k, 0, i] = s0
        out_coeffs[k, 1, i] = s1
        out_coeffs[k, 2, i] = s2
        y = basis[k, i]
        r0 += s0 * y
        r1 += s1 * y
        r2 += s2 * y
    radiance[k, 0] = r0  # T-7
    radiance[k, 1] = r1
    radiance[k, 2] = r2


@wp.kernel
def first_hits(
    offset: int,  # In: first cell of this launch (a launch may cover a slice of the cells)
    mesh: wp.uint64,  # In: BVH of the whole scene
    eye: wp.vec3,  # In: camera position
    corner: wp.vec3,  # In: direction (unnormalised) from the eye through the corner of grid cell (0, 0)
    du: wp.vec3,  # In: direction step from one grid column to the next
    dv: wp.vec3,  # In: direction step from one grid row to the next
    columns: int,  # In: grid columns (rows = face.shape[0] / columns)
    face: wp.array(dtype=wp.int32),  # Out: (rows * columns,) the first face the ray through each cell's centre
    #                                       meets, -1 where it meets none
    bary: wp.array(dtype=wp.vec3),  # Out: (rows * columns,) the hit's barycentric weights of the face's three
    #                                      corners, in index order (0 where the ray meets none)
):
    """E-1, E-2 (docs/RUNTIME.md): one primary ray from the eye through the centre of each cell of a screen grid,
    the first face it meets and where on it."""
    k = wp.tid() + offset
    i = k % columns
    j = k / columns
    d = corner + (float(i) + 0.5) * du + (float(j) + 0.5) * dv
    face[k] = -1
    bary[k] = wp.vec3(0.0, 0.0, 0.0)
    q = wp.mesh_query_ray(mesh, eye, wp.normalize(d), 1.0e30)
    if q.result:
        face[k] = q.face
        bary[k] = wp.vec3(q.u, q.v, 1.0 - q.u - q.v)  # Warp's hit point: u p0 + v p1 + (1 - u - v) p2


@wp.kernel
def hit_radiance(
    offset: int,  # In: first ray of this launch (a launch may cover a slice of the rays)
    corners: wp.array2d(dtype=wp.int32),  # In: (R, 3) rows (of the arrays below) of the corners of the face each
    #                                              ray met, in the face's index order; -1 in column 0: none
    bary: wp.array(dtype=wp.vec3),  # In: (R,) the hit's barycentric weights of those corners (first_hits)
    positions: wp.array(dtype=wp.vec3),  # In: (A,) corner positions
    normals: wp.array(dtype=wp.vec3),  # In: (A,) corner normals (view direction for an eye on the point)
    coeffs: wp.array3d(dtype=wp.float32),  # In: (A, 3, ncoef) corner RGB coefficients; ncoef = 1 or order^2
    eye: wp.vec3,  # In: camera position
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (R, >= ncoef)
    radiance: wp.array2d(dtype=wp.float32),  # Out: (R, 3) radiance toward the eye at the hit, 0 for no hit
):
    """E-1 (docs/RUNTIME.md): what the renderer draws at a ray's hit, as a fragment there: the corners' positions,
    normals and coefficients interpolated with the hit's barycentric weights, then T-7 toward the eye."""
    k = wp.tid() + offset
    radiance[k, 0] = 0.0
    radiance[k, 1] = 0.0
    radiance[k, 2] = 0.0
    a = corners[k, 0]
    if a < 0:
        return
    b = corners[k, 1]
    c = corners[k, 2]
    w = bary[k]
    p = w[0] * positions[a] + w[1] * positions[b] + w[2] * positions[c]
    dv = eye - p
    if wp.length(dv) <= 0.0:
        dv = w[0] * normals[a] + w[1] * normals[b] + w[2] * normals[c]
    ncoef = wp.min(coeffs.shape[2], basis.shape[1])
    sh_basis_fast(dv, bands_of(ncoef), basis, k)
    for ch in range(3):
        r = float(0.0)
        for i in range(ncoef):  # T-7 of the interpolated coefficients
            r += (w[0] * coeffs[a, ch, i] + w[1] * coeffs[b, ch, i] + w[2] * coeffs[c, ch, i]) * basis[k, i]
        radiance[k, ch] = r
