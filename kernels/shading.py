"""Phong outgoing radiance per vertex under one point light, projected onto SH over the view direction (SPEC 4).

    L_o(x, s) = V(x) E(d) [ kd (L.N) + ks max(R.s, 0)^n ],   E(d) = 1 / max(d, radius)^2  or 1 (no falloff)

projected as L_i = integral L_o(x, s) y_i(s) ds (T-6, Kristensen et al. 2005). The diffuse term is constant in s,
so it lands in y_0 alone (sqrt(4 pi) kd (L.N)); the specular lobe is circularly symmetric about the reflection
vector R, so its coefficients are the zonal ones rotated to R (P-6 form): ks sqrt(4 pi / (2l+1)) z_l y_lm(R).
``phong_sh`` uses that closed form; ``phong_sh_quadrature`` integrates the same radiance numerically and is kept as
the independent check (and as the path for radiance with no closed form).

Coefficients are for a light of unit intensity; the light's RGB intensity is applied when reading.
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis
from lodprt.kernels.visibility import LIT

wp.set_module_options({"enable_backward": False})


@wp.func
def incident(p: wp.vec3, n: wp.vec3, light: wp.vec3, falloff: int, radius: float):
    """Unit direction to the light and the irradiance factor E(d); a light exactly on the vertex shines along n."""
    to_light = light - p
    d = wp.length(to_light)
    l = n
    if d > 0.0:
        l = to_light / d
    e = float(1.0)
    if falloff == 1:
        r = wp.max(d, radius)
        e = 1.0 / (r * r)
    return l, e


@wp.kernel
def phong_sh(
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    material_id: wp.array(dtype=wp.int32),  # In: (V,) material of each vertex
    ids: wp.array(dtype=wp.int32),  # In: (K,) vertices to bake
    visible: wp.array(dtype=wp.uint8),  # In: (K,) visibility state (kernels.visibility)
    kd: wp.array2d(dtype=wp.float32),  # In: (M, C) diffuse albedo per material and channel
    ks: wp.array(dtype=wp.float32),  # In: (M,) specular coefficient
    zonal: wp.array2d(dtype=wp.float32),  # In: (M, order) sqrt(4 pi/(2l+1)) z_l of max(cos,0)^n per material
    light: wp.vec3,  # In: light position
    falloff: int,  # In: 1 inverse-square, 0 none
    radius: float,  # In: light radius (near-field clamp of the falloff)
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (K, order^2)
    coeffs: wp.array3d(dtype=wp.float32),  # Out: (K, C, ncoef)
):
    k = wp.tid()
    v = ids[k]
    channels = coeffs.shape[1]
    ncoef = coeffs.shape[2]
    for c in range(channels):
        for i in range(ncoef):
            coeffs[k, c, i] = 0.0
    if visible[k] != wp.uint8(LIT):
        return
    n = normals[v]
    l, e = incident(points[v], n, light, falloff, radius)
    cos_i = wp.max(wp.dot(n, l), 0.0)
    m = material_id[v]
    # diffuse: constant over view directions -> y_0 only (T-6 of a constant c is sqrt(4 pi) c)
    for c in range(channels):
        coeffs[k, c, 0] = e * cos_i * kd[m, c] * 3.5449077018110318
    spec = e * ks[m]
    if spec == 0.0:  # diffuse-only scenes store y_0 alone (ks = 0 everywhere)
        return
    # specular: zonal lobe about R = 2 (N.L) N - L rotated to R (P-6)
    r = 2.0 * wp.dot(n, l) * n - l
    # bands from the arrays (never past the output, the scratch or the zonal table)
    nb = wp.min(wp.min(bands_of(ncoef), bands_of(basis.shape[1])), zonal.shape[1])
    sh_basis(r, nb, basis, k)
    for lband in range(nb):
        g = spec * zonal[m, lband]
        for i in range(lband * lband, (lband + 1) * (lband + 1)):
            val = g * basis[k, i]
            for c in range(channels):
                coeffs[k, c, i] += val


@wp.kernel
def phong_sh_quadrature(
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    material_id: wp.array(dtype=wp.int32),  # In: (V,) material of each vertex
    ids: wp.array(dtype=wp.int32),  # In: (K,) vertices to bake
    visible: wp.array(dtype=wp.uint8),  # In: (K,) visibility state (kernels.visibility)
    kd: wp.array2d(dtype=wp.float32),  # In: (M, C) diffuse albedo
    ks: wp.array(dtype=wp.float32),  # In: (M,) specular coefficient
    shininess: wp.array(dtype=wp.float32),  # In: (M,) Phong exponent n
    light: wp.vec3,  # In: light position
    falloff: int,  # In: 1 inverse-square, 0 none
    radius: float,  # In: light radius
    dirs: wp.array(dtype=wp.vec3),  # In: (Q,) quadrature directions
    weights: wp.array(dtype=wp.float32),  # In: (Q,) quadrature weights (solid angle)
    ybasis: wp.array2d(dtype=wp.float32),  # In: (Q, ncoef) SH basis at the quadrature directions
    coeffs: wp.array3d(dtype=wp.float32),  # Out: (K, C, ncoef)
):
    k = wp.tid()
    v = ids[k]
    channels = coeffs.shape[1]
    ncoef = coeffs.shape[2]
    for c in range(channels):
        for i in range(ncoef):
            coeffs[k, c, i] = 0.0
    if visible[k] != wp.uint8(LIT):
        return
    n = normals[v]
    l, e = incident(points[v], n, light, falloff, radius)
    cos_i = wp.max(wp.dot(n, l), 0.0)
    m = material_id[v]
    r = 2.0 * wp.dot(n, l) * n - l
    for q in range(dirs.shape[0]):
        lobe = wp.max(wp.dot(r, dirs[q]), 0.0)
        s = e * ks[m] * wp.pow(lobe, shininess[m]) * weights[q]
        for c in range(channels):
            f = e * cos_i * kd[m, c] * weights[q] + s  # T-6 by quadrature
            for i in range(ncoef):
                coeffs[k, c, i] += f * ybasis[q, i]
