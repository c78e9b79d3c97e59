"""Neighbourhood transfer (patent 5; N-1, N-2 of docs/VOLUMES.md), float32 Warp kernels on any device.

At a point p near an object O (the BVH ``mesh``), the transferred radiance ``L'_p(s)`` is the distant lighting
where O lets it through and the light O reflects where it blocks it. The kernel integrates, over R directions of
weight ``4 pi / R`` (a spherical Fibonacci set, turned per point when asked), the two parts that differ from the
identity:

    blocked_ij     = sum_r w (1 - V(p, s_r)) y_i(s_r) y_j(s_r)                  (the light O takes away)
    reflected_cij  = sum_r w front(p, s_r) y_i(s_r) T_cj(hit_r)                (the light O's surface sends to p)

with ``T`` O's own per-vertex diffuse transfer (albedo/pi included) interpolated at the hit with the triangle's
barycentric weights, and ``front`` 1 where the ray meets the front of a face (the back of a surface sends no
diffuse light). The host forms ``M = I - blocked + reflected`` (N-2), so a point no ray from which meets O gets the
identity exactly. Loops over coefficients are sized from the output arrays.
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis
from lodprt.kernels.transfer import vertex_rotation

wp.set_module_options({"enable_backward": False})

FOUR_PI = 12.566370614359172


@wp.kernel
def neighbourhood_transfer(
    mesh: wp.uint64,  # In: BVH of the object O
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) the BVH's triangles
    points: wp.array(dtype=wp.vec3),  # In: (P,) grid points
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per point
    seed: int,  # In: seed of the per-point rotations
    max_dist: float,  # In: ray length
    reflected_transfer: wp.array3d(dtype=wp.float32),  # In: (V, 3, ni^2) O's exit transfer, or (0, 3, ni^2): none
    first: int,  # In: point of thread 0 (launches of point ranges)
    scratch: wp.array2d(dtype=wp.float32),  # Temp: (P, big^2) basis row per point, big^2 >= no^2 and ni^2
    blocked: wp.array3d(dtype=wp.float32),  # Out: (P, no^2, ni^2) += w y_i y_j where O blocks s_r
    reflected: wp.array4d(dtype=wp.float32),  # Out: (P, 3, no^2, ni^2) += w y_i T_cj(hit) at front-face hits
):
    k = first + wp.tid()
    p = points[k]
    q = vertex_rotation(seed, k, rotate)
    w = FOUR_PI / float(dirs.shape[0])
    big = bands_of(scratch.shape[1])
    no2 = blocked.shape[1]
    ni2 = blocked.shape[2]
    has_reflection = reflected_transfer.shape[0] > 0
    for r in range(dirs.shape[0]):
        d = wp.quat_rotate(q, dirs[r])
        hit = wp.mesh_query_ray(mesh, p, d, max_dist)
        if not hit.result:
            continue
        sh_basis(d, big, scratch, k)
        for i in range(no2):
            yi = w * scratch[k, i]
            for j in range(ni2):
                blocked[k, i, j] = blocked[k, i, j] + yi * scratch[k, j]
        if has_reflection and wp.dot(hit.normal, d) < 0.0:
            f = hit.face
            a = faces[f, 0]
            b = faces[f, 1]
            e = faces[f, 2]
            bu = hit.u  # barycentric weights of the hit triangle's vertices: u, v, 1 - u - v
            bv = hit.v
            bw = 1.0 - bu - bv
            for c in range(3):
                for j in range(ni2):
                    t = bu * reflected_transfer[a, c, j] + bv * reflected_transfer[b, c, j] + bw * reflected_transfer[e, c, j]
                    for i in range(no2):
                        reflected[k, c, i, j] = reflected[k, c, i, j] + w * scratch[k, i] * t
