"""Shadow-ray visibility from vertices to a point light through Warp's BVH (SPEC 4, "in shadow" of qreduce).

A ray leaves each vertex from ``p + offset * n`` (``offset`` scales with the scene, so 1e-4 and 1e4 unit scenes
behave alike) toward the light and stops ``offset`` short of it; any hit means shadow. Vertices facing away from the
light cast no ray at all: their state is decided by the normal alone.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

#: Visibility state of a vertex for one light, written by :func:`shadow_rays` as uint8. Defined here once: the
#: other kernel modules and the host (``lodprt.precompute``, the tests) import these numbers from this module.
SHADOWED = wp.constant(0)
LIT = wp.constant(1)
BACK_FACING = wp.constant(2)  # facing away from the light: no ray cast
SKIPPED = wp.constant(3)


@wp.func
def ray_origin(p: wp.vec3, n: wp.vec3, offset: float):
    # lift the origin off the surface along the normal so the ray does not hit the triangles around the vertex
    return p + offset * n


@wp.func
def light_state(
    mesh: wp.uint64,  # In: BVH of the whole scene
    p: wp.vec3,  # In: vertex position
    n: wp.vec3,  # In: unit vertex normal
    light: wp.vec3,  # In: light position
    offset: float,  # In: ray offset in scene units
):
    """SHADOWED, LIT or BACK_FACING of one vertex for one point light (one any-hit ray when it faces the light)."""
    to_light = light - p
    if wp.length(to_light) <= offset:
        # the light sits on the vertex: nothing can lie between them
        return int(LIT)
    if wp.dot(n, to_light) <= 0.0:
        return int(BACK_FACING)  # no ray: the surface itself hides the light
    o = ray_origin(p, n, offset)
    d = light - o
    dist = wp.length(d)
    if dist <= 2.0 * offset:
        return int(LIT)
    if wp.mesh_query_ray_anyhit(mesh, o, d / dist, dist - offset):
        return int(SHADOWED)
    return int(LIT)


@wp.kernel
def shadow_rays(
    mesh: wp.uint64,  # In: BVH of the whole scene
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    ids: wp.array(dtype=wp.int32),  # In: (K,) vertices to test
    light: wp.vec3,  # In: light position
    offset: float,  # In: ray offset in scene units
    visible: wp.array(dtype=wp.uint8),  # Out: (K,) SHADOWED, LIT or BACK_FACING
):
    k = wp.tid()
    v = ids[k]
    visible[k] = wp.uint8(light_state(mesh, points[v], normals[v], light, offset))
