"""Before and after the sequential hierarchy build (``lodprt.kernels.hierarchy_greedy``, tag H-G), one Warp thread
each: ``components`` (the mesh's groups: connected components, split by a label, by union-find), ``corner_lists``
(each vertex's corners, for a second phase's compacted mesh), ``prepare`` (corner lists, Garland-Heckbert quadrics,
boundary and non-manifold flags, boundary planes: what ``lodprt.model.hierarchy_build`` computes for the rounds
build) and ``leaf_layout`` (the hierarchy's depth-first leaf order for a tree whose children precede their parents).
Loops are bounded by the arrays' shapes.
"""

import warp as wp

from lodprt.kernels.hierarchy import vec_at
from lodprt.kernels.hierarchy_greedy import CAP, Mesh, Scratch, gather

wp.set_module_options({"enable_backward": False, "optimization_level": 3})


@wp.func
def find(root: wp.array(dtype=wp.int32), x: int):
    """The root of x's set, halving the path on the way (every link points to a smaller id: the root is the set's
    smallest member)."""
    while root[x] != x:
        root[x] = root[root[x]]
        x = root[x]
    return x


@wp.kernel
def components(
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) vertex ids, each in [0, V)
    label: wp.array(dtype=wp.int32),  # In: (V,) edges join only vertices of the same label (unread when split 0)
    split: int,  # In: 1 reads label, 0 joins every edge
    root: wp.array(dtype=wp.int32),  # Temp: (V,)
    group: wp.array(dtype=wp.int32),  # Out: (V,) group of each vertex, numbered in the order of their smallest id
):
    V = root.shape[0]
    for v in range(V):
        root[v] = v
    for f in range(faces.shape[0]):
        for j in range(3):
            a = faces[f, j]
            b = faces[f, (j + 1) % 3]
            if split != 0 and label[a] != label[b]:
                continue
            ra = find(root, a)
            rb = find(root, b)
            if ra < rb:  # the larger root joins the smaller, which stays its set's smallest member
                root[rb] = ra
            elif rb < ra:
                root[ra] = rb
    n = int(0)
    for v in range(wp.min(V, group.shape[0])):
        r = find(root, v)
        if r == v:  # v is its group's smallest member, met before the others
            group[v] = n
            n += 1
        else:
            group[v] = group[r]


@wp.func
def add_plane(quadric: wp.array2d(dtype=wp.float64), x: int, n: wp.vec3d, d: wp.float64, w: wp.float64):
    """Q_x += w (n, d)(n, d)^T, the 10 entries in the order of ``QUADRIC_ENTRIES``."""
    p = wp.vec4d(n[0], n[1], n[2], d)
    k = int(0)
    for r in range(4):
        for c in range(r, 4):
            quadric[x, k] += w * p[r] * p[c]
            k += 1


@wp.func
def face_normal(m: Mesh, f: int):
    """Unit normal of face f (zero for a degenerate face) and twice its area."""
    p0 = vec_at(m.pos, m.faces[f, 0])
    cr = wp.cross(vec_at(m.pos, m.faces[f, 1]) - p0, vec_at(m.pos, m.faces[f, 2]) - p0)
    dbl = wp.length(cr)
    if dbl > wp.float64(0.0):
        return cr / dbl, dbl
    return wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0)), dbl


@wp.func
def boundary_planes(m: Mesh, s: Scratch, a: int, nr: int, boundary_weight: wp.float64):
    """For each boundary edge a b (b > a) of a's ring: the plane through it perpendicular to its face, weighted
    ``boundary_weight |ab|^2``, added to Q_a and Q_b."""
    for i in range(nr):
        b = s.ring[i]
        if s.rcnt[i] != 1 or b < a:
            continue
        fn = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
        c = m.head[a]
        while c >= 0:
            f = c // 3
            c = m.nxt[c]
            if m.faces[f, 0] == b or m.faces[f, 1] == b or m.faces[f, 2] == b:
                fn, dbl = face_normal(m, f)
                break
        pa = vec_at(m.pos, a)
        dd = vec_at(m.pos, b) - pa
        mm = wp.cross(dd, fn)
        lm = wp.length(mm)
        if lm > wp.float64(0.0):
            mm = mm / lm
        w = boundary_weight * wp.dot(dd, dd)
        add_plane(m.quadric, a, mm, -wp.dot(mm, pa), w)
        add_plane(m.quadric, b, mm, -wp.dot(mm, pa), w)


@wp.func
def link_corners(m: Mesh):
    """Each vertex's corner list (head, nxt; both -1 on entry), its corners in increasing order."""
    for c in range(wp.min(3 * m.faces.shape[0], m.nxt.shape[0]) - 1, -1, -1):
        v = m.faces[c // 3, c % 3]
        m.nxt[c] = m.head[v]
        m.head[v] = c


@wp.kernel
def corner_lists(m: Mesh):  # In: faces; Out: head, nxt (both -1 on entry)
    link_corners(m)


@wp.kernel
def prepare(
    m: Mesh,  # In: pos, faces, alive (all 1), movable (1 where the vertex may move: used, and not on the rim when
    #            the rim is kept); Out: head, nxt, quadric, boundary, frozen, movable (frozen ones cleared)
    s: Scratch,  # Temp
    boundary_weight: wp.float64,  # In: weight of the boundary planes relative to the face quadrics
):
    V = m.pos.shape[0]
    F = m.faces.shape[0]
    link_corners(m)
    for f in range(F):  # Garland-Heckbert: area x plane plane^T at each corner
        n, dbl = face_normal(m, f)
        if dbl <= wp.float64(0.0):
            continue
        d = -wp.dot(n, vec_at(m.pos, m.faces[f, 0]))
        for j in range(3):
            add_plane(m.quadric, m.faces[f, j], n, d, wp.float64(0.5) * dbl)
    for a in range(V):
        if m.head[a] < 0:
            continue
        nr = gather(m, a, a, s.seen, s.slot, s.ring, s.rcnt, 0)
        if nr > CAP:
            m.frozen[a] = wp.uint8(1)
            continue
        rim = int(0)
        for i in range(nr):
            if s.rcnt[i] == 1:
                rim += 1
            if s.rcnt[i] > 2:
                m.frozen[a] = wp.uint8(1)  # a non-manifold edge (its other end marks itself too)
        if rim > 0:
            m.boundary[a] = wp.uint8(1)
        if rim != 0 and rim != 2:
            m.frozen[a] = wp.uint8(1)  # a non-manifold boundary vertex (bow tie)
        boundary_planes(m, s, a, nr, boundary_weight)
    for a in range(V):
        if m.frozen[a] != wp.uint8(0) or (m.boundary[a] != wp.uint8(0) and m.movable[a] == wp.uint8(2)):
            m.movable[a] = wp.uint8(0)
        elif m.movable[a] != wp.uint8(0):
            m.movable[a] = wp.uint8(1)


@wp.kernel
def leaf_layout(
    parent: wp.array(dtype=wp.int32),  # In: (N,) -1 for roots; every child's id below its parent's (creation order)
    children: wp.array2d(dtype=wp.int32),  # In: (N, 2) -1 for leaves
    rng: wp.array2d(dtype=wp.int64),  # Out: (N, 2) each node's [lo, hi) into order
    order: wp.array(dtype=wp.int32),  # Out: (V,) leaves in depth-first order, child 0 first, roots in id order
):
    """One thread: ``lodprt.model.hierarchy.leaf_layout`` for a hierarchy in creation order (leaf counts in id
    order, the roots' starts in id order, the children's starts in reverse id order)."""
    N = parent.shape[0]
    for k in range(N):
        if children[k, 0] < 0:
            rng[k, 1] = wp.int64(1)
        else:
            rng[k, 1] = rng[children[k, 0], 1] + rng[children[k, 1], 1]
    at = wp.int64(0)
    for k in range(N):
        if parent[k] < 0:
            rng[k, 0] = at
            at += rng[k, 1]
    for i in range(N):
        k = N - 1 - i
        a = children[k, 0]
        if a >= 0:
            rng[a, 0] = rng[k, 0]
            rng[children[k, 1], 0] = rng[k, 0] + rng[a, 1]
        elif rng[k, 0] < wp.int64(order.shape[0]):
            order[int(rng[k, 0])] = k
    for k in range(N):
        rng[k, 1] = rng[k, 0] + rng[k, 1]
