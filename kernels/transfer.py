"""Distant-light transfer per vertex (patent sections 2-3, P-10..P-12), float32 Warp kernels on any device.

Every ray-cast kernel integrates over the same well-distributed set of R unit directions ``dirs`` (a spherical
Fibonacci set built on the host), each of weight ``4 pi / R``; with ``rotate = 1`` each vertex turns the set by its
own random rotation (Shoemake's uniform quaternion from ``wp.rand_init(seed, vertex)``), which trades the set's
structured error for noise that does not correlate between neighbouring vertices. Rays leave ``p + offset n``
(offset in scene units, as in ``lodprt.kernels.visibility``). Outputs are accumulated into arrays the host zeroed.
The SH basis is ``lodprt.kernels.sh.sh_basis`` (lodprt's convention, float32), written into a per-thread row of a
scratch array.
"""

import warp as wp

from lodprt.kernels.sh import sh_basis

wp.set_module_options({"enable_backward": False})

FOUR_PI = 12.566370614359172

#: glossy occlusion modes
GLOSSY_NONE = 0  # the full sphere: the transfer matrix tends to the identity
GLOSSY_HEMISPHERE = 1  # the upper hemisphere about the normal, nothing blocks
GLOSSY_SHADOWED = 2  # the upper hemisphere, rays blocked by the scene (P-11)


@wp.func
def vertex_rotation(seed: int, v: int, rotate: int):
    # uniform random rotation (Shoemake 1992) per vertex, identity when rotate == 0
    if rotate == 0:
        return wp.quat_identity()
    state = wp.rand_init(seed, v)
    u1 = wp.randf(state)
    u2 = wp.randf(state) * 6.283185307179586
    u3 = wp.randf(state) * 6.283185307179586
    a = wp.sqrt(1.0 - u1)
    b = wp.sqrt(u1)
    return wp.quat(a * wp.sin(u2), a * wp.cos(u2), b * wp.sin(u3), b * wp.cos(u3))


@wp.kernel
def unshadowed_closed_form(
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    order: int,  # In: SH bands
    zonal_scale: wp.array(dtype=wp.float32),  # In: (order^2,) sqrt(4 pi/(2l+1)) z_l of max(cos, 0) per coefficient
    out: wp.array2d(dtype=wp.float32),  # Out: (V, order^2) integral of max(n.s, 0) y_i(s) ds
):
    v = wp.tid()
    sh_basis(normals[v], order, out, v)
    for i in range(order * order):
        out[v, i] = out[v, i] * zonal_scale[i]


@wp.kernel
def diffuse_direct(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per vertex
    seed: int,  # In: seed of the per-vertex rotations
    order: int,  # In: SH bands
    offset: float,  # In: ray origin offset along the normal
    shadowed: int,  # In: 1 to cast shadow rays (M_p = H_N V_p, P-10), 0 for H_N alone
    max_dist: float,  # In: ray length
    first: int,  # In: vertex of thread 0 (launches of vertex ranges)
    scratch: wp.array2d(dtype=wp.float32),  # Temp: (V, order^2) basis row per thread
    out: wp.array2d(dtype=wp.float32),  # Out: (V, order^2) += sum_r w max(n.s_r, 0) V(s_r) y_i(s_r)
):
    v = first + wp.tid()
    p = points[v]
    n = normals[v]
    q = vertex_rotation(seed, v, rotate)
    o = p + offset * n
    w = FOUR_PI / float(dirs.shape[0])
    for r in range(dirs.shape[0]):
        d = wp.quat_rotate(q, dirs[r])
        c = wp.dot(n, d)
        if c <= 0.0:
            continue
        if shadowed != 0:
            if wp.mesh_query_ray_anyhit(mesh, o, d, max_dist):
                continue
        sh_basis(d, order, scratch, v)
        for i in range(order * order):
            out[v, i] = out[v, i] + w * c * scratch[v, i]


@wp.kernel
def diffuse_bounce(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) the BVH's triangles
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per vertex
    seed: int,  # In: seed of the per-vertex rotations
    offset: float,  # In: ray origin offset along the normal
    max_dist: float,  # In: ray length
    first: int,  # In: vertex of thread 0 (launches of vertex ranges)
    previous: wp.array2d(dtype=wp.float32),  # In: (V, K) the previous pass' transfer (albedo included)
    out: wp.array2d(dtype=wp.float32),  # Out: (V, K) += sum_r w max(n.s_r, 0) T_prev(hit_r), front-face hits only
):
    v = first + wp.tid()
    p = points[v]
    n = normals[v]
    q = vertex_rotation(seed, v, rotate)
    o = p + offset * n
    w = FOUR_PI / float(dirs.shape[0])
    k_count = previous.shape[1]
    for r in range(dirs.shape[0]):
        d = wp.quat_rotate(q, dirs[r])
        c = wp.dot(n, d)
        if c <= 0.0:
            continue
        hit = wp.mesh_query_ray(mesh, o, d, max_dist)
        if not hit.result:
            continue
        if wp.dot(hit.normal, d) >= 0.0:
            continue  # the back of a surface: no diffuse light leaves it toward p
        f = hit.face
        a = faces[f, 0]
        b = faces[f, 1]
        e = faces[f, 2]
        bu = hit.u  # barycentric weights of the hit triangle's vertices: u, v, 1 - u - v (wp.mesh_eval_position)
        bv = hit.v
        bw = 1.0 - bu - bv
        for k in range(k_count):
            t = bu * previous[a, k] + bv * previous[b, k] + bw * previous[e, k]
            out[v, k] = out[v, k] + w * c * t


@wp.kernel
def glossy_transfer(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    ids: wp.array(dtype=wp.int32),  # In: (G,) vertices that get a matrix
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per vertex
    seed: int,  # In: seed of the per-vertex rotations
    order_out: int,  # In: bands of the transferred radiance (rows)
    order_in: int,  # In: bands of the source lighting (columns)
    offset: float,  # In: ray origin offset along the normal
    mode: int,  # In: GLOSSY_NONE, GLOSSY_HEMISPHERE or GLOSSY_SHADOWED
    max_dist: float,  # In: ray length
    first: int,  # In: row of thread 0 (launches of row ranges)
    scratch: wp.array2d(dtype=wp.float32),  # Temp: (G, max(order_out, order_in)^2) basis row per thread
    out: wp.array3d(dtype=wp.float32),  # Out: (G, order_out^2, order_in^2) += sum_r w V(s_r) y_i(s_r) y_j(s_r)
):
    k = first + wp.tid()
    v = ids[k]
    p = points[v]
    n = normals[v]
    q = vertex_rotation(seed, v, rotate)
    o = p + offset * n
    w = FOUR_PI / float(dirs.shape[0])
    big = wp.max(order_out, order_in)
    for r in range(dirs.shape[0]):
        d = wp.quat_rotate(q, dirs[r])
        if mode != GLOSSY_NONE:
            if wp.dot(n, d) <= 0.0:
                continue
            if mode == GLOSSY_SHADOWED:
                if wp.mesh_query_ray_anyhit(mesh, o, d, max_dist):
                    continue
        sh_basis(d, big, scratch, k)
        for i in range(order_out * order_out):
            yi = w * scratch[k, i]
            for j in range(order_in * order_in):
                out[k, i, j] = out[k, i, j] + yi * scratch[k, j]


@wp.kernel
def closest_hits(
    mesh: wp.uint64,  # In: BVH
    origins: wp.array(dtype=wp.vec3),  # In: (N,) ray origins
    directions: wp.array(dtype=wp.vec3),  # In: (N,) unit ray directions
    max_dist: float,  # In: ray length
    face: wp.array(dtype=wp.int32),  # Out: (N,) hit triangle, -1 for a miss
    bary: wp.array(dtype=wp.vec3),  # Out: (N,) barycentric weights of the triangle's 3 vertices as diffuse_bounce uses them
):
    i = wp.tid()
    hit = wp.mesh_query_ray(mesh, origins[i], directions[i], max_dist)
    if hit.result:
        face[i] = hit.face
        bary[i] = wp.vec3(hit.u, hit.v, 1.0 - hit.u - hit.v)
    else:
        face[i] = -1


# -- mirror (caustic) paths: specular chains followed in the interreflection passes (C-1, C-2) ------------------


@wp.func
def mirror_step(
    normals: wp.array(dtype=wp.vec3),
    faces: wp.array2d(dtype=wp.int32),
    f: int,
    u: float,
    v: float,
    face_normal: wp.vec3,
    d: wp.vec3,
):
    # C-1: d reflected about the hit's interpolated (smooth) normal m, d - 2 (d.m) m; zero when d meets the back
    # of the triangle or the reflection would leave through it (a grazing hit on a coarse mesh): absorbed there
    m = wp.normalize(u * normals[faces[f, 0]] + v * normals[faces[f, 1]] + (1.0 - u - v) * normals[faces[f, 2]])
    r = d - 2.0 * wp.dot(d, m) * m
    if wp.dot(r, face_normal) <= 0.0 or wp.dot(d, face_normal) >= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    return r


@wp.kernel
def mirror_direct(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) the BVH's triangles
    reflectance: wp.array(dtype=wp.float32),  # In: (F,) mirror reflectance per face, 0 for non-mirrors
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per vertex
    seed: int,  # In: seed of the per-vertex rotations
    order: int,  # In: SH bands
    offset: float,  # In: ray origin offset along the normal
    max_dist: float,  # In: ray length
    max_mirror: int,  # In: most mirror reflections per path (longer chains are dropped)
    first: int,  # In: vertex of thread 0 (launches of vertex ranges)
    scratch: wp.array2d(dtype=wp.float32),  # Temp: (V, order^2) basis row per thread
    out: wp.array2d(dtype=wp.float32),  # Out: (V, order^2) += C-1: sum_r w max(n.s_r, 0) rho(chain) y_i(s_out)
):
    v = first + wp.tid()
    n = normals[v]
    q = vertex_rotation(seed, v, rotate)
    p0 = points[v] + offset * n
    w = FOUR_PI / float(dirs.shape[0])
    for r in range(dirs.shape[0]):
        d0 = wp.quat_rotate(q, dirs[r])
        c = wp.dot(n, d0)
        if c <= 0.0:
            continue
        o = p0
        d = d0
        rho = float(1.0)
        for k in range(max_mirror + 1):
            hit = wp.mesh_query_ray(mesh, o, d, max_dist)
            if not hit.result:  # escaped: the environment seen along the (reflected) direction
                sh_basis(d, order, scratch, v)
                for i in range(order * order):
                    out[v, i] = out[v, i] + w * c * rho * scratch[v, i]
                break
            refl = reflectance[hit.face]
            if refl <= 0.0 or k == max_mirror:
                break  # a diffuse occluder, or one reflection too many
            dn = mirror_step(normals, faces, hit.face, hit.u, hit.v, hit.normal, d)
            if wp.length_sq(dn) == 0.0:
                break
            rho = rho * refl
            o = o + hit.t * d + offset * wp.normalize(hit.normal)
            d = dn


@wp.kernel
def mirror_bounce(
    mesh: wp.uint64,  # In: BVH of the scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) the BVH's triangles
    reflectance: wp.array(dtype=wp.float32),  # In: (F,) mirror reflectance per face, 0 for non-mirrors
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per vertex
    seed: int,  # In: seed of the per-vertex rotations
    offset: float,  # In: ray origin offset along the normal
    max_dist: float,  # In: ray length
    max_mirror: int,  # In: most mirror reflections per path (longer chains are dropped)
    first: int,  # In: vertex of thread 0 (launches of vertex ranges)
    previous: wp.array2d(dtype=wp.float32),  # In: (V, K) the previous pass' transfer (albedo included)
    out: wp.array2d(dtype=wp.float32),  # Out: (V, K) += C-2: sum_r w max(n.s_r, 0) sum_hits rho T_prev(hit)
):
    v = first + wp.tid()
    n = normals[v]
    q = vertex_rotation(seed, v, rotate)
    p0 = points[v] + offset * n
    w = FOUR_PI / float(dirs.shape[0])
    k_count = previous.shape[1]
    for r in range(dirs.shape[0]):
        d0 = wp.quat_rotate(q, dirs[r])
        c = wp.dot(n, d0)
        if c <= 0.0:
            continue
        o = p0
        d = d0
        rho = float(1.0)
        for k in range(max_mirror + 1):
            hit = wp.mesh_query_ray(mesh, o, d, max_dist)
            if not hit.result:
                break  # escaped: no bounce light (the environment came in pass 0)
            if wp.dot(hit.normal, d) >= 0.0:
                break  # the back of a surface
            f = hit.face
            bw = 1.0 - hit.u - hit.v
            for j in range(k_count):  # the hit surface's own diffuse light (a mirror's kd part too)
                t = hit.u * previous[faces[f, 0], j] + hit.v * previous[faces[f, 1], j] + bw * previous[faces[f, 2], j]
                out[v, j] = out[v, j] + w * c * rho * t
            refl = reflectance[f]
            if refl <= 0.0 or k == max_mirror:
                break
            dn = mirror_step(normals, faces, hit.face, hit.u, hit.v, hit.normal, d)
            if wp.length_sq(dn) == 0.0:
                break
            rho = rho * refl
            o = o + hit.t * d + offset * wp.normalize(hit.normal)
            d = dn
