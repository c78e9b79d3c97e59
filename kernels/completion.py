"""Coefficient completion (SPEC 5, T-15; host: ``lodprt.model.completion``), CPU kernels.

``ring_weights``: the completion weights of plan rows ``first + tid``, as ``lodprt.model.completion.ring_weights``
(the float64 numpy reference, whose docstring states the rules) computes them: the ring sorted by angle about the
vertex normal (a stable insertion sort of the row's CSR ids, angles recomputed from positions), the T-15 cotangent
weights on the plane of the fan's area-weighted normal, else the boundary rule on an open ring, else mean value,
else Shepard; float64 maths, weights normalised to sum 1 and stored as float32.

``complete_in_order``: ``CompletionPlan.complete``'s rows, wave after wave, in one thread (one launch: a completion
between a GI bake's gathering passes does not wait for the interpreter lock once per wave). Unless a row's collapsed
vertex already has values (``have``), it gets the T-15 blend of its CSR ring,

    T-15  c(p) = sum_j w_j c(q_j) / sum_j w_j,

the sums over the ring neighbours that are not dark (all of them when every neighbour is dark). A ring holds
vertices of earlier waves only, so every value a row reads is final when it is read. The value type (float32 or
float64) is the output's; the float32 weights are widened to it, and the sums run in it, in ring order. Every loop
runs from the CSR starts and ends and from the output's shape; the host checks that rows, ring ids and vertices lie
inside the arrays they index.
"""

from typing import Any

import warp as wp

wp.set_module_options({"enable_backward": False})

RULE_T15 = wp.constant(0)
RULE_MEAN_VALUE = wp.constant(1)
RULE_SHEPARD = wp.constant(2)
RULE_BOUNDARY = wp.constant(3)
#: an angular gap in a sorted ring at least this close to 180 degrees makes it an open boundary ring
GAP_SLACK = wp.constant(wp.float64(1.0e-6))
PI = wp.constant(wp.float64(3.141592653589793))
TWO_PI = wp.constant(wp.float64(6.283185307179586))


@wp.func
def vec3d_of(x: Any):
    return wp.vec3d(wp.float64(x[0]), wp.float64(x[1]), wp.float64(x[2]))


@wp.func
def ring_angle(d: wp.vec3d, t1: wp.vec3d, t2: wp.vec3d):
    return wp.atan2(wp.dot(d, t2), wp.dot(d, t1))


@wp.func
def offset_at(positions: wp.array(dtype=Any), ids: wp.array(dtype=wp.int32), lo: int, n: int, j: int,
              p: wp.vec3d):
    """d = q - p of sorted entry ``j`` of the ring (cyclic)."""
    return vec3d_of(positions[ids[lo + ((j + n) % n)]]) - p


@wp.func
def project(x: wp.vec3d, nf: wp.vec3d):
    return x - wp.dot(x, nf) * nf


@wp.func
def cot(a: wp.vec3d, b: wp.vec3d):
    """cot of the angle between a and b: inf or NaN where they are parallel (then the rule is not used)."""
    return wp.dot(a, b) / wp.length(wp.cross(a, b))


@wp.func
def tan_half(a: wp.vec3d, b: wp.vec3d, nf: wp.vec3d):
    """tan of half the signed angle at p between a and b (negative where the ring folds back)."""
    r = wp.sqrt(wp.dot(a, a) * wp.dot(b, b))
    return (wp.dot(wp.cross(a, b), nf) / r) / (wp.float64(1.0) + wp.dot(a, b) / r)


@wp.func
def candidate_weight(positions: wp.array(dtype=Any), ids: wp.array(dtype=wp.int32), lo: int, n: int, j: int,
                     p: wp.vec3d, nf: wp.vec3d, rule: int, tiny: wp.float64):
    """Unnormalised weight of sorted entry j under ``rule`` (T-15, mean value or Shepard)."""
    d = project(offset_at(positions, ids, lo, n, j, p), nf)
    dist2 = wp.dot(d, d)
    if rule == RULE_T15:  # T-15 at q_j: angles between p - q_j and the edges to q_j-1 and q_j+1
        dp = project(offset_at(positions, ids, lo, n, j - 1, p), nf)
        dn = project(offset_at(positions, ids, lo, n, j + 1, p), nf)
        return (cot(-d, dp - d) + cot(-d, dn - d)) / dist2
    if rule == RULE_MEAN_VALUE:  # Floater: (tan(alpha_j-1 / 2) + tan(alpha_j / 2)) / |p - q_j|
        dp = project(offset_at(positions, ids, lo, n, j - 1, p), nf)
        dn = project(offset_at(positions, ids, lo, n, j + 1, p), nf)
        return (tan_half(dp, d, nf) + tan_half(d, dn, nf)) / wp.sqrt(dist2)
    return wp.float64(1.0) / wp.max(dist2, tiny)  # Shepard


@wp.kernel
def complete_in_order(
    rows: wp.array(dtype=wp.int32),  # In: plan rows, wave after wave (``CompletionPlan.by_wave``)
    vertex: wp.array(dtype=wp.int32),  # In: (M,) the vertex each collapse removed
    ring_ptr: wp.array(dtype=wp.int64),  # In: (M + 1,) CSR start of each row's ring
    ring_ids: wp.array(dtype=wp.int32),  # In: ring vertex ids
    ring_w: wp.array(dtype=wp.float32),  # In: their T-15 weights
    dark: wp.array(dtype=wp.uint8),  # In: (V,) 1 where a vertex lies under a dark cut node
    have: wp.array(dtype=wp.uint8),  # In: (V,) 1 where a vertex already has its values (kept or dark)
    out: wp.array2d(dtype=Any),  # In/Out: (V, K) values; the rows of the plan rows' vertices written
):
    for i in range(rows.shape[0]):  # one thread, in wave order: a ring holds vertices of earlier waves only
        m = int(rows[i])
        v = int(vertex[m])
        if have[v] == wp.uint8(0):
            lo = int(ring_ptr[m])
            hi = int(ring_ptr[m + 1])
            zero = out.dtype(0.0)
            lit = zero
            every = zero
            for j in range(lo, hi):
                w = out.dtype(ring_w[j])
                every += w
                if dark[ring_ids[j]] == wp.uint8(0):
                    lit += w
            use_lit = lit > zero
            total = every
            if use_lit:
                total = lit
            K = out.shape[1]
            for k in range(K):
                out[v, k] = zero
            for j in range(lo, hi):
                q = int(ring_ids[j])
                if not use_lit or dark[q] == wp.uint8(0):
                    w = out.dtype(ring_w[j]) / total  # T-15, weights renormalised over the ring
                    for k in range(K):
                        out[v, k] = out[v, k] + w * out[q, k]


wp.overload(complete_in_order, {"out": wp.array2d(dtype=wp.float32)})
wp.overload(complete_in_order, {"out": wp.array2d(dtype=wp.float64)})


@wp.kernel
def ring_weights(
    first: int,  # In: the plan row of thread 0 (a slice of the rows)
    vertex: wp.array(dtype=wp.int32),  # In: (M,) the vertex each collapse removed
    ring_ptr: wp.array(dtype=wp.int64),  # In: (M + 1,) CSR start of each row's ring
    positions: wp.array(dtype=Any),  # In: (V,) vertex positions, vec3 or vec3d (read as float64)
    normals: wp.array(dtype=Any),  # In: (V,) vertex normals (to sort the rings), of the positions' type
    ring_ids: wp.array(dtype=wp.int32),  # In/Out: ring vertex ids in CSR order; sorted by angle on return
    ring_w: wp.array(dtype=wp.float32),  # Out: their weights, summing to 1 over each ring
    rule: wp.array(dtype=wp.int8),  # Out: (M,) the rule each row's weights follow
):
    m = first + wp.tid()
    lo = int(ring_ptr[m])
    n = int(ring_ptr[m + 1]) - lo
    p = vec3d_of(positions[vertex[m]])
    nrm = vec3d_of(normals[vertex[m]])
    helper = wp.vec3d(wp.float64(0.0), wp.float64(1.0), wp.float64(0.0))
    if wp.abs(nrm[0]) < wp.float64(0.9):
        helper = wp.vec3d(wp.float64(1.0), wp.float64(0.0), wp.float64(0.0))
    t1 = wp.normalize(wp.cross(nrm, helper))
    t2 = wp.cross(nrm, t1)
    for i in range(1, n):  # stable insertion sort of the ring by angle about the normal
        key = ring_ids[lo + i]
        ka = ring_angle(vec3d_of(positions[key]) - p, t1, t2)
        j = i - 1
        while j >= 0:
            if ring_angle(vec3d_of(positions[ring_ids[lo + j]]) - p, t1, t2) <= ka:
                break
            ring_ids[lo + j + 1] = ring_ids[lo + j]
            j -= 1
        ring_ids[lo + j + 1] = key
    # the largest angular gap (first of equals) and the area-weighted normal of the fan (p, q_j, q_j+1)
    gap_at = int(0)
    gap = wp.float64(-1.0)
    fan = wp.vec3d()
    for j in range(n):
        d = offset_at(positions, ring_ids, lo, n, j, p)
        dn = offset_at(positions, ring_ids, lo, n, j + 1, p)
        g = ring_angle(dn, t1, t2) - ring_angle(d, t1, t2)
        g = g - TWO_PI * wp.floor(g / TWO_PI)
        if g > gap:
            gap = g
            gap_at = j
        fan = fan + wp.cross(d, dn)
    open_ring = n >= 2 and gap >= PI - GAP_SLACK
    fl = wp.length(fan)
    nf = nrm
    if fl > wp.float64(0.0):
        nf = fan / fl
    scale2 = wp.float64(0.0)
    for j in range(n):
        d = project(offset_at(positions, ring_ids, lo, n, j, p), nf)
        scale2 = wp.max(scale2, wp.dot(d, d))
    tiny = wp.float64(1.0e-24) * wp.max(scale2, wp.float64(1.0e-300))
    chosen = int(RULE_SHEPARD)
    if n >= 3:  # T-15 where every weight is finite and positive, else (not open) mean value likewise
        for r in range(2):
            cand = int(RULE_T15)
            if r == 1:
                cand = RULE_MEAN_VALUE
            if chosen == RULE_SHEPARD and (cand == RULE_T15 or not open_ring):
                good = int(1)
                for j in range(n):
                    w = candidate_weight(positions, ring_ids, lo, n, j, p, nf, cand, tiny)
                    if not (wp.isfinite(w) and w > wp.float64(0.0)):
                        good = 0
                if good == 1:
                    chosen = cand
    if chosen == RULE_SHEPARD and open_ring:
        chosen = RULE_BOUNDARY
    rule[m] = wp.int8(chosen)  # an empty ring: Shepard, with no weight to write
    if chosen == RULE_BOUNDARY:  # p on the segment between the neighbours either side of the gap
        b = (gap_at + 1) % n
        da = offset_at(positions, ring_ids, lo, n, gap_at, p)
        seg = offset_at(positions, ring_ids, lo, n, b, p) - da
        l2 = wp.dot(seg, seg)
        t = wp.float64(0.5)
        if l2 > wp.float64(0.0):
            t = wp.clamp(-wp.dot(da, seg) / l2, wp.float64(0.0), wp.float64(1.0))
        for j in range(n):
            ring_w[lo + j] = wp.float32(0.0)
        ring_w[lo + gap_at] = wp.float32(wp.float64(1.0) - t)
        ring_w[lo + b] = wp.float32(t)
        return
    total = wp.float64(0.0)
    for j in range(n):
        total += candidate_weight(positions, ring_ids, lo, n, j, p, nf, chosen, tiny)
    for j in range(n):
        ring_w[lo + j] = wp.float32(candidate_weight(positions, ring_ids, lo, n, j, p, nf, chosen, tiny) / total)


for _vec in (wp.vec3, wp.vec3d):
    wp.overload(ring_weights, {"positions": wp.array(dtype=_vec), "normals": wp.array(dtype=_vec)})
