"""Light-dependent cut: the bottom-up ``qreduce`` pass of thesis figure 8, one launch per hierarchy height.

A node's two children are collapsed into it when both are entirely dark for the light (every leaf below back-facing
or in shadow; a child is also dark when its normal cone faces away, T-11: L . n_v < cos(pi/2 + theta)), or when both
are entirely lit and the incident angles of all the leaves below them lie within ``epsilon`` of each other. Heights
are processed from the leaves up, so one sweep reaches the fixed point ("repeat until nothing collapses").
"""

import warp as wp

from lodprt.kernels.visibility import LIT

wp.set_module_options({"enable_backward": False})


@wp.kernel
def leaf_light_state(
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    normals: wp.array(dtype=wp.vec3),  # In: (V,) unit vertex normals
    visible: wp.array(dtype=wp.uint8),  # In: (V,) visibility state per vertex (kernels.visibility states)
    light: wp.vec3,  # In: light position
    active: wp.array(dtype=wp.uint8),  # Out: (N,) 1 for the leaves, 0 above
    dark: wp.array(dtype=wp.uint8),  # Out: (N,) every leaf below back-facing or shadowed
    lit: wp.array(dtype=wp.uint8),  # Out: (N,) every leaf below lit
    amin: wp.array(dtype=wp.float32),  # Out: (N,) least incident angle below (radians)
    amax: wp.array(dtype=wp.float32),  # Out: (N,) largest incident angle below
):
    v = wp.tid()
    active[v] = wp.uint8(1)
    if visible[v] == wp.uint8(LIT):
        to_light = light - points[v]
        d = wp.length(to_light)
        c = float(1.0)
        if d > 0.0:
            c = wp.clamp(wp.dot(normals[v], to_light / d), -1.0, 1.0)
        a = wp.acos(c)  # incident angle
        lit[v] = wp.uint8(1)
        dark[v] = wp.uint8(0)
        amin[v] = a
        amax[v] = a
    else:
        lit[v] = wp.uint8(0)
        dark[v] = wp.uint8(1)
        amin[v] = 0.0
        amax[v] = 0.0


@wp.func
def faces_away(p: wp.vec3, axis: wp.vec3, half_angle: float, light: wp.vec3):
    # T-11: the whole normal cone is back-facing when L . n_v < cos(pi/2 + theta) = -sin(theta)
    to_light = light - p
    d = wp.length(to_light)
    if d == 0.0:
        return False
    return wp.dot(to_light / d, axis) < -wp.sin(half_angle)


@wp.kernel
def qreduce_level(
    nodes: wp.array(dtype=wp.int32),  # In: (K,) internal nodes of one height
    children: wp.array2d(dtype=wp.int32),  # In: (N, 2) children
    vertex: wp.array(dtype=wp.int32),  # In: (N,) original vertex of each node
    points: wp.array(dtype=wp.vec3),  # In: (V,) vertex positions
    cone_axis: wp.array(dtype=wp.vec3),  # In: (N,) normal cone axes
    cone_half: wp.array(dtype=wp.float32),  # In: (N,) cone half-angles
    light: wp.vec3,  # In: light position
    epsilon: float,  # In: incident-angle threshold (radians)
    active: wp.array(dtype=wp.uint8),  # InOut: (N,) the cut
    dark: wp.array(dtype=wp.uint8),  # InOut: (N,)
    lit: wp.array(dtype=wp.uint8),  # InOut: (N,)
    amin: wp.array(dtype=wp.float32),  # InOut: (N,)
    amax: wp.array(dtype=wp.float32),  # InOut: (N,)
):
    k = wp.tid()
    p = nodes[k]
    c0 = children[p, 0]
    c1 = children[p, 1]
    if active[c0] == wp.uint8(0) or active[c1] == wp.uint8(0):
        return
    d0 = dark[c0] == wp.uint8(1) or faces_away(points[vertex[c0]], cone_axis[c0], cone_half[c0], light)
    d1 = dark[c1] == wp.uint8(1) or faces_away(points[vertex[c1]], cone_axis[c1], cone_half[c1], light)
    lo = wp.min(amin[c0], amin[c1])
    hi = wp.max(amax[c0], amax[c1])
    both_lit = lit[c0] == wp.uint8(1) and lit[c1] == wp.uint8(1)
    if (d0 and d1) or (both_lit and hi - lo < epsilon):
        active[p] = wp.uint8(1)
        active[c0] = wp.uint8(0)
        active[c1] = wp.uint8(0)
        if d0 and d1:
            dark[p] = wp.uint8(1)
            lit[p] = wp.uint8(0)
        else:
            dark[p] = wp.uint8(0)
            lit[p] = wp.uint8(1)
        amin[p] = lo
        amax[p] = hi
