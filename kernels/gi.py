"""Diffuse interreflection under one point light (docs/THEORY.md, G-1..G-6): per-vertex gathering of the previous
bounce's outgoing diffuse radiance with BVH rays.

Each gathering vertex casts the rays of a cosine-weighted spherical Fibonacci set ``dirs`` (unit vectors about +z in
a local frame, built on the host by :func:`lodprt.precompute.gi.cosine_fibonacci`), turned about its normal by a
per-vertex random angle (``wp.rand_init(seed, vertex)``) and taken to the normal's frame. With cosine-weighted rays
the estimate of the hemisphere integral is a plain mean (G-2):

    E_b(p) = (1/pi) integral L_{b-1}(h(p, w)) (n.w) dw  ~  (1/R) sum_r L_{b-1}(h_r)

where ``L_{b-1}(h_r)`` is the previous bounce's outgoing diffuse radiance at the ray's hit, interpolated from the
hit triangle's vertices by barycentrics; misses and hits on the back of a surface bring 0. The host multiplies
``E_b`` by the receiver's ``kd`` (Lambert BRDF kd / pi, G-1). Specular of indirect light (G-4): every ray's
incident radiance reflects into a Phong lobe about the mirror direction of the ray, projected on SH in closed form
(P-6): ``(ks / R) s sum_r L_{b-1}(h_r) / (n.w_r) sqrt(4 pi/(2l+1)) z_l y_lm(R_r)``, where ``s = 2 / mean_r(1/(n.w_r))``
normalises the 1/cos weights of the set (their integral is 2): exact for uniform incident radiance.
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis
from lodprt.kernels.shading import incident
from lodprt.kernels.visibility import LIT

wp.set_module_options({"enable_backward": False})

TWO_PI = 6.283185307179586


@wp.func
def normal_frame(n: wp.vec3):
    """Two unit tangents completing ``n`` to a right-handed orthonormal frame (Duff et al. 2017, branch-free)."""
    s = float(1.0)
    if n[2] < 0.0:
        s = -1.0
    a = -1.0 / (s + n[2])
    b = n[0] * n[1] * a
    t = wp.vec3(1.0 + s * n[0] * n[0] * a, s * b, -s * n[0])
    u = wp.vec3(b, s + n[1] * n[1] * a, -n[1])
    return t, u


@wp.func
def gather_direction(local: wp.vec3, angle: float, t: wp.vec3, u: wp.vec3, n: wp.vec3):
    """``local`` (about +z) turned by ``angle`` about z, then expressed in the frame (t, u, n)."""
    c = wp.cos(angle)
    s = wp.sin(angle)
    x = c * local[0] - s * local[1]
    y = s * local[0] + c * local[1]
    return x * t + y * u + local[2] * n


@wp.func
def vertex_angle(seed: int, v: int):
    state = wp.rand_init(seed, v)
    return wp.randf(state) * TWO_PI


@wp.kernel
def direct_diffuse(
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    material_id: wp.array(dtype=wp.int32),  # In: (V,) material of each vertex
    ids: wp.array(dtype=wp.int32),  # In: (K,) vertices to light
    visible: wp.array(dtype=wp.uint8),  # In: (K,) visibility state (kernels.visibility)
    kd: wp.array2d(dtype=wp.float32),  # In: (M, C) diffuse albedo
    light: wp.vec3,  # In: light position
    falloff: int,  # In: 1 inverse-square, 0 none
    radius: float,  # In: light radius
    radiance: wp.array2d(dtype=wp.float32),  # Out: (V, C) rows ids[k]: V E kd max(N.L, 0) (G-1, bounce 0)
):
    k = wp.tid()
    v = ids[k]
    channels = radiance.shape[1]
    lit = visible[k] == wp.uint8(LIT)
    n = normals[v]
    l, e = incident(points[v], n, light, falloff, radius)
    cos_i = wp.max(wp.dot(n, l), 0.0)
    m = material_id[v]
    for c in range(channels):
        val = float(0.0)
        if lit:
            val = e * cos_i * kd[m, c]
        radiance[v, c] = val


@wp.kernel
def gather_bounce(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) the BVH's triangles
    material_id: wp.array(dtype=wp.int32),  # In: (V,) material of each vertex
    ids: wp.array(dtype=wp.int32),  # In: (G,) gathering vertices
    ks: wp.array(dtype=wp.float32),  # In: (M,) specular coefficient
    zonal: wp.array2d(dtype=wp.float32),  # In: (M, order) sqrt(4 pi/(2l+1)) z_l of max(cos,0)^n per material
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) cosine-weighted unit directions about +z
    previous: wp.array2d(dtype=wp.float32),  # In: (V, C) previous bounce's outgoing diffuse radiance
    seed: int,  # In: seed of the per-vertex rotations
    offset: float,  # In: ray origin offset along the normal
    max_dist: float,  # In: ray length
    spec_scale: float,  # In: 2 / mean_r(1 / cos_r) of ``dirs`` (G-4: exact for uniform incident light)
    basis: wp.array2d(dtype=wp.float32),  # Scratch: (G, order^2)
    gathered: wp.array2d(dtype=wp.float32),  # Out: (G, C) E_b = mean of L_{b-1} at the hits (G-2)
    specular: wp.array3d(dtype=wp.float32),  # InOut: (G, C, ncoef) += specular of the incident light (G-4)
):
    k = wp.tid()
    v = ids[k]
    p = points[v]
    n = normals[v]
    t, u = normal_frame(n)
    angle = vertex_angle(seed, v)
    o = p + offset * n
    channels = gathered.shape[1]
    count = dirs.shape[0]
    for c in range(channels):
        gathered[k, c] = 0.0
    m = material_id[v]
    spec = ks[m]
    ncoef = specular.shape[2]
    nb = wp.min(wp.min(bands_of(ncoef), bands_of(basis.shape[1])), zonal.shape[1])
    if spec == 0.0 or ncoef < 2:
        nb = 0
    inv = 1.0 / float(count)
    for r in range(count):
        d = gather_direction(dirs[r], angle, t, u, n)
        hit = wp.mesh_query_ray(mesh, o, d, max_dist)
        if not hit.result:
            continue
        if wp.dot(hit.normal, d) >= 0.0:
            continue  # the back of a surface: no diffuse light leaves it toward p
        f = hit.face
        a = faces[f, 0]
        b = faces[f, 1]
        e = faces[f, 2]
        bu = hit.u  # barycentric weights of the triangle's vertices: u, v, 1 - u - v (wp.mesh_eval_position)
        bv = hit.v
        bw = 1.0 - bu - bv
        cos_r = wp.max(wp.dot(n, d), 1.0e-6)
        if nb > 0:
            sh_basis(2.0 * wp.dot(n, d) * n - d, nb, basis, k)
        for c in range(channels):
            li = bu * previous[a, c] + bv * previous[b, c] + bw * previous[e, c]
            gathered[k, c] = gathered[k, c] + inv * li
            if nb > 0:
                w = spec * spec_scale * inv * li / cos_r
                for lband in range(nb):
                    g = w * zonal[m, lband]
                    for i in range(lband * lband, (lband + 1) * (lband + 1)):
                        specular[k, c, i] = specular[k, c, i] + g * basis[k, i]


@wp.kernel
def hit_distance(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    ids: wp.array(dtype=wp.int32),  # In: (K,) vertices
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) cosine-weighted unit directions about +z
    seed: int,  # In: seed of the per-vertex rotations
    offset: float,  # In: ray origin offset along the normal
    max_dist: float,  # In: ray length (misses count as infinitely far)
    inverse: wp.array(dtype=wp.float32),  # Out: (K,) mean of 1 / hit distance (G-5: 1 / harmonic mean distance)
):
    k = wp.tid()
    v = ids[k]
    n = normals[v]
    t, u = normal_frame(n)
    angle = vertex_angle(seed, v)
    o = points[v] + offset * n
    acc = float(0.0)
    for r in range(dirs.shape[0]):
        d = gather_direction(dirs[r], angle, t, u, n)
        hit = wp.mesh_query_ray(mesh, o, d, max_dist)
        if hit.result:
            acc = acc + 1.0 / wp.max(hit.t, offset)
    inverse[k] = acc / float(dirs.shape[0])
