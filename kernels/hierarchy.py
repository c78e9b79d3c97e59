"""Hierarchy build, one round of collapses (SPEC 3; thesis 3.2, figures 5, 6 and 10; tag H-R), float64 Warp kernels.

The host (``lodprt.model.hierarchy_rounds``) owns the round: it builds the face corners around each vertex and the
one-rings (``fill_corners``, ``gather_rings``), launches these kernels, and records the nodes. A one-ring lives in a
padded CSR: vertex ``v``'s sorted distinct neighbours are ``dst[start[v]:end[v]]`` with ``start = 2 x`` its corner
start (two ring entries per corner, deduplicated in place), the faces on each edge in ``count`` beside them.

* ``best_moves``: each movable vertex's cheapest legal move ``v -> u`` (QEM cost of ``u``'s position under
  ``Q_v + Q_u`` plus ``edge_weight |uv|^4``; legal: boundary and component rules, link condition, the survivor's
  valence, no fold-over (figure 6), no sliver).
* ``greedy_select``: the round's pairwise non-conflicting collapses, taken in rank order (one thread).
* ``collapse_errors``: the error vector of each collapse (figure 10).

The per-vertex and per-collapse kernels take ``first``, the index of their thread 0: the host splits one pass into
slices launched from several threads at once (each thread writes only its own vertices' or collapses' outputs).
Every loop is sized from the arrays' shapes or the CSR starts and ends read from them.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

#: the cost of an edge that is no candidate move (above every finite QEM cost the rounds meet)
NONE = wp.constant(wp.float64(1.0e300))


@wp.func
def vec_at(p: wp.array2d(dtype=wp.float64), i: int):
    return wp.vec3d(p[i, 0], p[i, 1], p[i, 2])


@wp.func
def quadric_at(q: wp.array2d(dtype=wp.float64), i: int, x: wp.vec3d):
    """``x^T Q_i x`` with ``x = (p, 1)``; the 10 upper-triangle entries in the order of ``QUADRIC_ENTRIES``."""
    a = x[0]
    b = x[1]
    c = x[2]
    two = wp.float64(2.0)
    s = q[i, 0] * a * a + two * q[i, 1] * a * b + two * q[i, 2] * a * c + two * q[i, 3] * a
    s = s + q[i, 4] * b * b + two * q[i, 5] * b * c + two * q[i, 6] * b
    return s + q[i, 7] * c * c + two * q[i, 8] * c + q[i, 9]


@wp.func
def is_neighbour(start: wp.array(dtype=wp.int64), end: wp.array(dtype=wp.int64), dst: wp.array(dtype=wp.int32),
                 a: int, w: int):
    """Whether ``w`` is among ``a``'s sorted neighbours (binary search)."""
    lo = int(start[a])
    hi = int(end[a])
    while lo < hi:
        mid = (lo + hi) // 2
        if dst[mid] < w:
            lo = mid + 1
        else:
            hi = mid
    if lo < int(end[a]):
        return dst[lo] == w
    return False


@wp.func
def survivor_valence_ok(after: int, u_on_boundary: wp.uint8, max_valence: int):
    """The survivor's valence after a collapse: at most ``max_valence``, at least 3 (2 on the boundary)."""
    least = 3
    if u_on_boundary != wp.uint8(0):
        least = 2
    return after <= max_valence and after >= least


@wp.func
def moved_face_ok(pv: wp.vec3d, pu: wp.vec3d, pb: wp.vec3d, pc: wp.vec3d, fold_cos: wp.float64,
                  sliver: wp.float64):
    """Whether the face (v, b, c) moved to (u, b, c) neither turns over (figure 6: the cosine of its normal's turn
    above ``fold_cos``) nor becomes a sliver (twice its area above ``sliver`` x its longest edge squared)."""
    old = wp.cross(pb - pv, pc - pv)
    e1 = pb - pu
    e2 = pc - pu
    new = wp.cross(e1, e2)
    n2 = wp.dot(new, new)
    fold = wp.dot(old, new) <= fold_cos * wp.sqrt(n2 * wp.dot(old, old))
    lmax = wp.max(wp.max(wp.dot(e1, e1), wp.dot(e2, e2)), wp.dot(pc - pb, pc - pb))
    return not (fold or n2 <= (sliver * lmax) * (sliver * lmax))


@wp.func
def legal_move(
    v: int, u: int, e: int,
    pos: wp.array2d(dtype=wp.float64), faces: wp.array2d(dtype=wp.int32), boundary: wp.array(dtype=wp.uint8),
    start: wp.array(dtype=wp.int64), end: wp.array(dtype=wp.int64), dst: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32), fstart: wp.array(dtype=wp.int64), corner: wp.array(dtype=wp.int32),
    fold_cos: wp.float64, sliver: wp.float64, max_valence: int,
):
    """Link condition (the common neighbours of u and v are the third corners of the faces on uv), valence of the
    survivor, and no fold-over or sliver on the faces that move (docs/HIERARCHY.md)."""
    common = int(0)
    for k in range(int(start[v]), int(end[v])):
        w = dst[k]
        if w != u and is_neighbour(start, end, dst, u, w):
            common += 1
    after = int(end[u] - start[u]) + int(end[v] - start[v]) - common - 2
    ok = common == count[e] and survivor_valence_ok(after, boundary[u], max_valence)
    pv = vec_at(pos, v)
    pu = vec_at(pos, u)
    k = int(fstart[v])
    while ok and k < int(fstart[v + 1]):
        c = corner[k]
        f = c // 3
        j = c % 3
        b = faces[f, (j + 1) % 3]
        cc = faces[f, (j + 2) % 3]
        k += 1
        if b == u or cc == u:
            continue  # the faces on uv vanish
        ok = moved_face_ok(pv, pu, vec_at(pos, b), vec_at(pos, cc), fold_cos, sliver)
    return ok


@wp.kernel
def best_moves(
    first: int,  # In: the vertex of thread 0 (a slice of the pass)
    pos: wp.array2d(dtype=wp.float64),  # In: (n, 3) live positions
    quadric: wp.array2d(dtype=wp.float64),  # In: (n, 10) QEM quadrics
    faces: wp.array2d(dtype=wp.int32),  # In: (M, 3) live faces
    due: wp.array(dtype=wp.uint8),  # In: (n,) 1 where the vertex may collapse now
    frozen: wp.array(dtype=wp.uint8),  # In: (n,) 1 where the vertex is never a target
    boundary: wp.array(dtype=wp.uint8),  # In: (n,) 1 on the boundary
    group: wp.array(dtype=wp.int32),  # In: (n,) mesh group (read when split is 1)
    level: wp.array(dtype=wp.int32),  # In: (n,) seeded removal level (read when phase >= 0)
    phase: int,  # In: seeded phase (targets survive it), -1 for none
    split: int,  # In: 1 when groups may touch (moves stay within a group)
    start: wp.array(dtype=wp.int64),  # In: (n + 1,) start of each vertex's sorted neighbours (padded CSR)
    end: wp.array(dtype=wp.int64),  # In: (n,) end of each vertex's sorted neighbours
    dst: wp.array(dtype=wp.int32),  # In: (6M,) neighbours
    count: wp.array(dtype=wp.int32),  # In: (6M,) faces on each edge
    fstart: wp.array(dtype=wp.int64),  # In: (n + 1,) CSR start of each vertex's face corners
    corner: wp.array(dtype=wp.int32),  # In: (3M,) flat corner indices into faces
    edge_weight: wp.float64,  # In: weight of |uv|^4 in the cost
    fold_cos: wp.float64,  # In: a moved face keeps its normal within this cosine
    sliver: wp.float64,  # In: twice the area below sliver x longest edge^2 is a sliver
    max_valence: int,  # In: largest valence of a survivor
    edge_cost: wp.array(dtype=wp.float64),  # Temp: (6M,) cost of each edge's move (NONE: not a candidate)
    best: wp.array(dtype=wp.int64),  # Out: (n,) edge index of the cheapest legal move, -1 when none
    best_cost: wp.array(dtype=wp.float64),  # Out: (n,) its cost (undefined where best is -1)
):
    v = first + wp.tid()
    best[v] = wp.int64(-1)
    best_cost[v] = wp.float64(0.0)
    if due[v] == wp.uint8(0):
        return
    pv = vec_at(pos, v)
    need = 2 - int(boundary[v])  # boundary vertices move along boundary edges only (one face)
    lo = int(start[v])
    hi = int(end[v])
    left = int(0)
    for e in range(lo, hi):
        u = dst[e]
        edge_cost[e] = NONE
        if frozen[u] != wp.uint8(0) or count[e] != need:
            continue
        if phase >= 0 and level[u] <= phase:
            continue
        if split != 0 and group[u] != group[v]:
            continue
        pu = vec_at(pos, u)
        d = pu - pv
        d2 = wp.dot(d, d)
        edge_cost[e] = quadric_at(quadric, v, pu) + quadric_at(quadric, u, pu) + edge_weight * d2 * d2
        left += 1
    # the cheapest candidate first (the first in neighbour order among equal costs); legality only as needed
    while left > 0:
        at = int(-1)
        low = NONE
        for e in range(lo, hi):
            if edge_cost[e] < low:
                low = edge_cost[e]
                at = e
        if at < 0:
            return  # costs of NONE or more (not finite) are no moves
        if legal_move(v, dst[at], at, pos, faces, boundary, start, end, dst, count, fstart, corner, fold_cos, sliver,
                      max_valence):
            best[v] = wp.int64(at)
            best_cost[v] = low
            return
        edge_cost[at] = NONE
        left -= 1


@wp.func
def ring_min(x: wp.array(dtype=wp.float64), a: int, start: wp.array(dtype=wp.int64), end: wp.array(dtype=wp.int64),
             dst: wp.array(dtype=wp.int32)):
    m = x[a]
    for k in range(int(start[a]), int(end[a])):
        m = wp.min(m, x[dst[k]])
    return m


@wp.func
def mark_ring(x: wp.array(dtype=wp.uint8), a: int, start: wp.array(dtype=wp.int64), end: wp.array(dtype=wp.int64),
              dst: wp.array(dtype=wp.int32)):
    x[a] = wp.uint8(1)
    for k in range(int(start[a]), int(end[a])):
        x[dst[k]] = wp.uint8(1)


@wp.kernel
def greedy_select(
    order: wp.array(dtype=wp.int32),  # In: (P,) the vertices with a legal move, in rank order
    target: wp.array(dtype=wp.int32),  # In: (n,) each vertex's target u
    rank_class: wp.array(dtype=wp.float64),  # In: (n,) each proposal's cost class
    start: wp.array(dtype=wp.int64),  # In: (n + 1,) start of each vertex's neighbours (padded CSR)
    end: wp.array(dtype=wp.int64),  # In: (n,) end of each vertex's neighbours
    dst: wp.array(dtype=wp.int32),  # In: (6M,) neighbours
    ring_v: wp.array(dtype=wp.uint8),  # Temp: (n,) zeros: closed one-rings of the v made
    ring_vu: wp.array(dtype=wp.uint8),  # Temp: (n,) zeros: ... and of their u
    wait_v: wp.array(dtype=wp.float64),  # Temp: (n,) +inf: class of each vertex's waiting proposal
    wait_u: wp.array(dtype=wp.float64),  # Temp: (n,) +inf: cheapest class of the waiting proposals into it
    made: wp.array(dtype=wp.uint8),  # Out: (P,) 1 where the proposal order[i] is made this round
):
    # one thread: proposals in rank order; the greedy independent set in that order is the one the Luby-style
    # selection of local rank minima reaches (docs/HIERARCHY.md, rule H-R: selection)
    for i in range(order.shape[0]):
        v = int(order[i])
        u = int(target[v])
        c = rank_class[v]
        # a proposal conflicting with a made collapse, or with a waiting one of a cheaper class, waits
        stop = ring_vu[v] != wp.uint8(0) or ring_v[u] != wp.uint8(0)
        if not stop:  # a cheaper waiting class in either ring, in turn (the first one found decides)
            stop = ring_min(wait_v, v, start, end, dst) < c
        if not stop:
            stop = ring_min(wait_v, u, start, end, dst) < c
        if not stop:
            stop = ring_min(wait_u, v, start, end, dst) < c
        if stop:
            wait_v[v] = c
            wait_u[u] = wp.min(wait_u[u], c)
        else:
            made[i] = wp.uint8(1)
            mark_ring(ring_v, v, start, end, dst)
            mark_ring(ring_vu, v, start, end, dst)
            mark_ring(ring_vu, u, start, end, dst)


@wp.func
def closest_on_triangle(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d):
    """Closest point to p on the triangle abc (Ericson, Real-Time Collision Detection 5.1.5); a zero-area
    triangle gives the closest of its edges' closest points."""
    zero = wp.float64(0.0)
    ab = b - a
    ac = c - a
    d1 = wp.dot(ab, p - a)
    d2 = wp.dot(ac, p - a)
    d3 = wp.dot(ab, p - b)
    d4 = wp.dot(ac, p - b)
    d5 = wp.dot(ab, p - c)
    d6 = wp.dot(ac, p - c)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    if denom == zero:
        best = a
        bd = wp.float64(1.0e300)
        for s in range(3):
            x = a
            y = b
            if s == 1:
                x = b
                y = c
            if s == 2:
                x = c
                y = a
            d = y - x
            dd = wp.dot(d, d)
            t = zero
            if dd > zero:
                t = wp.clamp(wp.dot(p - x, d) / dd, zero, wp.float64(1.0))
            q = x + d * t
            dq = wp.dot(p - q, p - q)
            if dq < bd:
                bd = dq
                best = q
        return best
    if d1 <= zero and d2 <= zero:
        return a
    if d3 >= zero and d4 <= d3:
        return b
    if d6 >= zero and d5 <= d6:
        return c
    if vc <= zero and d1 >= zero and d3 <= zero:
        return a + ab * (d1 / (d1 - d3))
    if vb <= zero and d2 >= zero and d6 <= zero:
        return a + ac * (d2 / (d2 - d6))
    if va <= zero and (d4 - d3) >= zero and (d5 - d6) >= zero:
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))
    return a + ab * (vb / denom) + ac * (vc / denom)


@wp.kernel
def collapse_errors(
    first: int,  # In: the collapse of thread 0 (a slice of the pass)
    pos: wp.array2d(dtype=wp.float64),  # In: (n, 3) live positions
    faces: wp.array2d(dtype=wp.int32),  # In: (M, 3) the faces before the round's collapses
    fstart: wp.array(dtype=wp.int64),  # In: (n + 1,) CSR start of each vertex's face corners
    corner: wp.array(dtype=wp.int32),  # In: (3M,) flat corner indices into faces
    cv: wp.array(dtype=wp.int32),  # In: (C,) collapsed vertices v
    cu: wp.array(dtype=wp.int32),  # In: (C,) their survivors u
    error: wp.array2d(dtype=wp.float64),  # Out: (C, 3) p_v - p', p' closest on the faces around u after (fig. 10)
):
    i = first + wp.tid()
    v = int(cv[i])
    u = int(cu[i])
    p = vec_at(pos, v)
    bd = wp.float64(1.0e300)
    out = wp.vec3d(0.0, 0.0, 0.0)
    # the faces around u after the collapse: u's own without v, and v's without u moved onto u (the round's other
    # collapses touch neither: rule H-R)
    for side in range(2):
        a = u
        skip = v
        if side == 1:
            a = v
            skip = u
        for k in range(int(fstart[a]), int(fstart[a + 1])):
            f = corner[k] // 3
            x = faces[f, 0]
            y = faces[f, 1]
            z = faces[f, 2]
            if x == skip or y == skip or z == skip:
                continue
            if x == v:
                x = u
            if y == v:
                y = u
            if z == v:
                z = u
            q = closest_on_triangle(p, vec_at(pos, x), vec_at(pos, y), vec_at(pos, z))
            dq = wp.dot(p - q, p - q)
            if dq < bd:
                bd = dq
                out = p - q
    error[i, 0] = out[0]
    error[i, 1] = out[1]
    error[i, 2] = out[2]


@wp.kernel
def fill_corners(
    flat: wp.array(dtype=wp.int32),  # In: (3M,) the faces' corners, flat
    fstart: wp.array(dtype=wp.int64),  # In: (n + 1,) CSR start of each vertex's corners (cumulated counts)
    fill: wp.array(dtype=wp.int32),  # Temp: (n,) zeros: corners placed per vertex
    corner: wp.array(dtype=wp.int32),  # Out: (3M,) flat corner indices grouped by vertex
):
    c = wp.tid()
    v = flat[c]
    corner[fstart[v] + wp.int64(wp.atomic_add(fill, v, 1))] = c  # ascending within a vertex on the CPU


@wp.func
def sort_segment(a: wp.array(dtype=wp.int32), lo: int, m: int):
    """Sort ``a[lo:lo + m]`` ascending in place (insertion sort; Shell sort, halving gaps, past 32 entries)."""
    gap = int(1)
    if m > 32:
        gap = m // 2
    while gap > 0:
        for i in range(lo + gap, lo + m):
            x = a[i]
            j = i
            while j >= lo + gap and a[j - gap] > x:
                a[j] = a[j - gap]
                j -= gap
            a[j] = x
        gap = gap // 2


@wp.kernel
def gather_rings(
    first: int,  # In: the vertex of thread 0 (a slice of the pass)
    faces: wp.array2d(dtype=wp.int32),  # In: (M, 3) faces
    fstart: wp.array(dtype=wp.int64),  # In: (n + 1,) CSR start of each vertex's corners
    corner: wp.array(dtype=wp.int32),  # In: (3M,) flat corner indices grouped by vertex
    dst: wp.array(dtype=wp.int32),  # Out: (6M,) each vertex's distinct neighbours, ascending, from 2 x fstart[v]
    count: wp.array(dtype=wp.int32),  # Out: (6M,) the faces on each of those edges (Temp before)
    end: wp.array(dtype=wp.int64),  # Out: (n,) end of each vertex's neighbours in dst
):
    v = first + wp.tid()
    k0 = int(fstart[v])
    k = int(fstart[v + 1]) - k0
    lo = 2 * k0
    for i in range(k):  # the next and the previous corner of each face around v, in two halves
        c = corner[k0 + i]
        f = c // 3
        j = c % 3
        dst[lo + i] = faces[f, (j + 1) % 3]
        dst[lo + k + i] = faces[f, (j + 2) % 3]
    sort_segment(dst, lo, k)
    sort_segment(dst, lo + k, k)
    a = lo  # merge the halves into count (a scratch here), then fold the repeats into counts
    b = lo + k
    for i in range(lo, lo + 2 * k):
        if b >= lo + 2 * k or (a < lo + k and dst[a] <= dst[b]):
            count[i] = dst[a]
            a += 1
        else:
            count[i] = dst[b]
            b += 1
    o = lo - 1  # count[o] is written once count[o] was read (o < i)
    run = int(0)
    for i in range(lo, lo + 2 * k):
        x = count[i]
        if i == lo or x != dst[o]:
            if o >= lo:
                count[o] = run
            o += 1
            dst[o] = x
            run = 0
        run += 1
    if k > 0:
        count[o] = run
    end[v] = wp.int64(o + 1)


@wp.kernel
def merge_quadrics(
    first: int,  # In: the collapse of thread 0 (a slice of the pass)
    cv: wp.array(dtype=wp.int32),  # In: (C,) collapsed vertices v (distinct from every u)
    cu: wp.array(dtype=wp.int32),  # In: (C,) their survivors u (distinct)
    quadric: wp.array2d(dtype=wp.float64),  # In/Out: (n, 10) QEM quadrics: Q_u += Q_v (Garland-Heckbert)
):
    i = first + wp.tid()
    v = int(cv[i])
    u = int(cu[i])
    for k in range(quadric.shape[1]):
        quadric[u, k] = quadric[u, k] + quadric[v, k]


#: the 10 upper-triangle entries of a symmetric 4 x 4 quadric (``QUADRIC_ENTRIES``)
vec10d = wp.types.vector(length=10, dtype=wp.float64)


@wp.func
def face_quadric(plane: wp.array2d(dtype=wp.float64), weight: wp.array(dtype=wp.float64), f: int):
    """``weight x plane plane^T`` of face ``f``, entry (r, c) as ``(weight p_r) p_c`` (numpy's order of the products)."""
    a = weight[f] * plane[f, 0]
    b = weight[f] * plane[f, 1]
    c = weight[f] * plane[f, 2]
    d = weight[f] * plane[f, 3]
    return vec10d(a * plane[f, 0], a * plane[f, 1], a * plane[f, 2], a * plane[f, 3], b * plane[f, 1],
                  b * plane[f, 2], b * plane[f, 3], c * plane[f, 2], c * plane[f, 3], d * plane[f, 3])


@wp.kernel
def plane_sums(
    first: int,  # In: the vertex of thread 0 (a slice of the pass)
    fstart: wp.array(dtype=wp.int64),  # In: (n + 1,) CSR start of each vertex's corners
    corner: wp.array(dtype=wp.int32),  # In: (3M,) flat corner indices grouped by vertex, ascending
    plane: wp.array2d(dtype=wp.float64),  # In: (M, 4) each face's plane p = (n, -n.x)
    weight: wp.array(dtype=wp.float64),  # In: (M,) each face's weight (its area)
    quadric: wp.array2d(dtype=wp.float64),  # Out: (n, 10) the sums over the faces at each vertex (QUADRIC_ENTRIES)
):
    # Garland-Heckbert: Q_v = sum of the face quadrics at v, added corner slot by corner slot (the faces that have v
    # as corner 0, in face order, then corner 1, then 2): the float sums numpy's per-slot bincounts give (on the CPU,
    # where no multiply-add is fused)
    v = first + wp.tid()
    s0 = vec10d()
    s1 = vec10d()
    s2 = vec10d()
    for k in range(int(fstart[v]), int(fstart[v + 1])):
        c = int(corner[k])
        j = c % 3
        if j == 0:
            s0 = s0 + face_quadric(plane, weight, c // 3)
        elif j == 1:
            s1 = s1 + face_quadric(plane, weight, c // 3)
        else:
            s2 = s2 + face_quadric(plane, weight, c // 3)
    total = ((vec10d() + s0) + s1) + s2
    for k in range(10):
        quadric[v, k] = total[k]
