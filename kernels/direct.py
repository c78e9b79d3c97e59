"""Run-time direct light of point lights anywhere (docs/THEORY.md, "Lights between samples", M-1..M-4): the actual
light's unshadowed Phong radiance in closed form (T-6, P-6) times its visibility, added to the interpolated residual
of the light samples (``kernels.runtime.relight`` over the residual store, M-2).

    M-1   L(p, s; x) = D(p, s; x) V(p; x) + sum_j w_j R_j(p, s)
    M-3   V(p; x) = one any-hit shadow ray toward x (RAYS, "direct"); or (AGREE_OR_RAY, "direct-agree") the
                    samples' state where every sample j with w_j > 0 agrees (all LIT or all SHADOWED), else a ray
    M-4   V(p; x) = sum_j w_j [V_j = LIT] / sum_j w_j over the samples that face the light (mode 1, no rays)
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis_fast
from lodprt.kernels.shading import incident
from lodprt.kernels.visibility import LIT, SHADOWED, light_state

wp.set_module_options({"enable_backward": False})

#: visibility modes of ``direct_light``
AGREE_OR_RAY = wp.constant(0)
BLEND = wp.constant(1)
RAYS = wp.constant(2)


@wp.func
def light_visibility(
    mesh: wp.uint64,
    p: wp.vec3,
    n: wp.vec3,
    light: wp.vec3,
    offset: float,
    v: int,  # In: the vertex (row of sample_vis)
    li: int,  # In: the light (row of light_slots)
    light_slots: wp.array2d(dtype=wp.int32),
    light_weights: wp.array2d(dtype=wp.float32),
    sample_vis: wp.array2d(dtype=wp.uint8),
    mode: int,
):
    """(visibility in [0, 1], rays cast) of vertex v for light li (M-3, M-4); the vertex faces the light. RAYS
    reads no sample visibility (``sample_vis`` may be a placeholder)."""
    if mode == int(RAYS):
        if light_state(mesh, p, n, light, offset) == int(LIT):
            return 1.0, 1
        return 0.0, 1
    lit = float(0.0)
    shadowed = float(0.0)
    total = float(0.0)
    for j in range(light_slots.shape[1]):
        s = light_slots[li, j]
        w = light_weights[li, j]
        if s >= 0 and w > 0.0:
            total += w
            st = int(sample_vis[v, s])
            if st == int(LIT):
                lit += w
            elif st == int(SHADOWED):
                shadowed += w
    if mode == int(BLEND):
        if lit + shadowed > 0.0:
            return lit / (lit + shadowed), 0
        return 1.0, 0
    if mode == int(AGREE_OR_RAY) and total > 0.0:
        if lit == total:
            return 1.0, 0
        if shadowed == total:
            return 0.0, 0
    if light_state(mesh, p, n, light, offset) == int(LIT):
        return 1.0, 1
    return 0.0, 1


@wp.kernel
def direct_light(
    offset: int,  # In: first row of this launch (a launch may cover a slice of the rows)
    vid: wp.array(dtype=wp.int32),  # In: (A,) vertices to light
    positions: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    material_id: wp.array(dtype=wp.int32),  # In: (V,) material of each vertex
    kd: wp.array2d(dtype=wp.float32),  # In: (M, 3) diffuse albedo per material, RGB
    ks: wp.array(dtype=wp.float32),  # In: (M,) specular coefficient
    zonal: wp.array2d(dtype=wp.float32),  # In: (M, order) sqrt(4 pi/(2l+1)) z_l of max(cos,0)^n per material
    falloff: int,  # In: 1 inverse-square, 0 none
    radius: float,  # In: light radius (near-field clamp of the falloff)
    mesh: wp.uint64,  # In: BVH of the scene
    ray_offset: float,  # In: shadow-ray offset in scene units (the bake's)
    lights: wp.array(dtype=wp.vec3),  # In: (L,) light positions
    colors: wp.array(dtype=wp.vec3),  # In: (L,) RGB intensities
    light_slots: wp.array2d(dtype=wp.int32),  # In: (L, K) sample-cache slot of each light's samples (-1: none)
    light_weights: wp.array2d(dtype=wp.float32),  # In: (L, K) their interpolation weights (T-12)
    sample_vis: wp.array2d(dtype=wp.uint8),  # In: (V, S) visibility state of every vertex for every slot
    mode: int,  # In: AGREE_OR_RAY, BLEND or RAYS
    eye: wp.vec3,  # In: camera position (radiance toward it)
    with_radiance: int,  # In: 1 adds to radiance, 0 leaves it alone (it may be a (1, 3) placeholder)
    eye_ready: int,  # In: 1 when eye_basis already holds the basis toward the eye (kernels.runtime.relight's)
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (A, >= ncoef) SH basis toward the reflection vector
    eye_basis: wp.array2d(dtype=wp.float32),  # Scratch or In: (A, >= ncoef) SH basis toward the eye
    out_coeffs: wp.array3d(dtype=wp.float32),  # In/Out: (A, 3, ncoef) the residual's coefficients; D V added
    radiance: wp.array2d(dtype=wp.float32),  # In/Out: (A, 3) radiance toward the eye; D V toward it added
    rays: wp.array(dtype=wp.int32),  # Out: (A,) shadow rays cast for the row (all lights)
    lit: wp.array(dtype=wp.int32),  # Out: (A,) bit li set when light li (< 31) reaches the vertex (V > 1/2, M-6)
):
    k = wp.tid() + offset
    v = vid[k]
    p = positions[v]
    n = normals[v]
    m = material_id[v]
    # the SH width comes from the arrays: 1 (y_0 of a diffuse-only store) or order^2
    ncoef = wp.min(wp.min(out_coeffs.shape[2], basis.shape[1]), eye_basis.shape[1])
    nb = wp.min(bands_of(ncoef), zonal.shape[1])
    if with_radiance == 1 and eye_ready == 0:
        dv = eye - p
        if wp.length(dv) <= 0.0:
            dv = n
        sh_basis_fast(dv, bands_of(ncoef), eye_basis, k)
    cast = int(0)
    mask = int(0)
    for li in range(lights.shape[0]):
        x = lights[li]
        to_light = x - p
        if wp.length(to_light) > ray_offset and wp.dot(n, to_light) <= 0.0:
            continue  # BACK_FACING: D = 0 (the bake's phong_sh gives 0 to any state but LIT)
        vis, r_cast = light_visibility(mesh, p, n, x, ray_offset, v, li, light_slots, light_weights, sample_vis,
                                       mode)
        cast += r_cast
        if vis > 0.5 and li < 31:
            mask = mask | (1 << li)
        if vis <= 0.0:
            continue
        l, e = incident(p, n, x, falloff, radius)
        cos_i = wp.max(wp.dot(n, l), 0.0)
        col = colors[li] * vis
        # M-1 with T-6: the diffuse term lands in y_0 (sqrt(4 pi) kd (N.L) E)
        d0 = e * cos_i * 3.5449077018110318
        for c in range(3):
            val = col[c] * kd[m, c] * d0
            out_coeffs[k, c, 0] += val
            if with_radiance == 1:
                radiance[k, c] += val * eye_basis[k, 0]
        spec = e * ks[m]
        if spec == 0.0 or ncoef == 1:
            continue
        # P-6: the zonal lobe about R = 2 (N.L) N - L rotated to R
        refl = 2.0 * wp.dot(n, l) * n - l
        sh_basis_fast(refl, nb, basis, k)
        for lband in range(nb):
            g = spec * zonal[m, lband]
            for i in range(lband * lband, (lband + 1) * (lband + 1)):
                val = g * basis[k, i]
                for c in range(3):
                    out_coeffs[k, c, i] += col[c] * val
                    if with_radiance == 1:
                        radiance[k, c] += col[c] * val * eye_basis[k, i]
    rays[k] = cast
    lit[k] = mask
