"""Hierarchy build in sequence (SPEC 3; thesis 3.2, figures 5, 6, 7 and 10; tag H-G), float64 Warp kernels: one
thread builds one unit of the mesh in one launch.

The host (``lodprt.model.hierarchy_greedy``) prepares the mesh (``lodprt.kernels.hierarchy_prepare``), splits it
into units (components, or tiles whose borders wait for a later phase), launches ``greedy_build`` once per unit from
several threads, each with its own scratch and queue (units share no vertex or face they change, nor a node id),
and compacts the node ids.

* ``greedy_build``: rounds of half-edge collapses made one at a time on the mesh as it stands (rule H-G,
  docs/HIERARCHY.md). A queue of proposals keyed by (round, cost class, position: blocks of ``bsize`` vertex ids
  visited in a fixed permuted order) hands out the cheapest proposal of the round; a collapse keeps the survivor's
  closed ring from collapsing and ``v``'s ring from taking a collapse until the next round (rule H-R's conflicts:
  at most one collapse per vertex and round, so the depth is at most the rounds), a waiting proposal holds
  costlier ones around it back, and the survivor's new ring is marked for a fresh evaluation (the
  QEM cost of ``u``'s position under ``Q_v + Q_u`` plus ``edge_weight |uv|^4``, the legality of figure 6 and the
  link condition, read on the current mesh).

Loops are bounded by the arrays: a ring holds at most ``CAP`` vertices (a vertex with more takes no part), classes
are clamped into the queue's rows, node and neighbour writes stay in the unit's ranges (sized for every collapse).
"""

import warp as wp

from lodprt.kernels.hierarchy import closest_on_triangle, moved_face_ok, quadric_at, survivor_valence_ok, vec_at

wp.set_module_options({"enable_backward": False, "optimization_level": 3})

#: the cost of an edge that is no candidate move
NONE = wp.constant(wp.float64(1.0e300))
#: most neighbours a one-ring may hold (the survivor's valence is capped far below: MAX_VALENCE)
CAP = wp.constant(128)
#: cost classes per round in the queue: floor(log2 cost) + CLASS_OFFSET, clamped into 1..CLASSES-1 (0: unevaluated)
CLASSES = wp.constant(128)
CLASS_OFFSET = wp.constant(100)


@wp.struct
class Mesh:
    pos: wp.array2d(dtype=wp.float64)  # (V, 3) positions
    faces: wp.array2d(dtype=wp.int32)  # (F, 3) faces; a collapse rewrites v's corners to u
    alive: wp.array(dtype=wp.uint8)  # (F,) 0 once the face vanished
    head: wp.array(dtype=wp.int32)  # (V,) first corner of each vertex (-1: none)
    nxt: wp.array(dtype=wp.int32)  # (3F,) next corner of the same vertex (-1: none)
    boundary: wp.array(dtype=wp.uint8)  # (V,) 1 on the boundary
    frozen: wp.array(dtype=wp.uint8)  # (V,) 1 where the vertex is never a target
    movable: wp.array(dtype=wp.uint8)  # (V,) 1 where the vertex may collapse
    group: wp.array(dtype=wp.int32)  # (V,) mesh group; moves stay within one
    group_faces: wp.array(dtype=wp.int32)  # (G,) live faces of each group
    face_group: wp.array(dtype=wp.int32)  # (F,) the counter a face counts in (this phase's unit of the face)
    count_group: wp.array(dtype=wp.int32)  # (V,) the counter whose faces stop the vertex's collapses
    quadric: wp.array2d(dtype=wp.float64)  # (V, 10) QEM quadrics (summed at every collapse)


@wp.struct
class Scratch:
    seen: wp.array(dtype=wp.int32)  # (V,) stamp of the last gather that met the vertex (first ring)
    slot: wp.array(dtype=wp.int32)  # (V,) its place in that ring
    seen2: wp.array(dtype=wp.int32)  # (V,) the same for the second ring
    slot2: wp.array(dtype=wp.int32)
    ring: wp.array(dtype=wp.int32)  # (2 CAP + 2,) two rings: [0, CAP) and [CAP, 2 CAP)
    rcnt: wp.array(dtype=wp.int32)  # (2 CAP + 2,) faces on each ring edge
    cost: wp.array(dtype=wp.float64)  # (CAP + 2,) candidate costs of one evaluation
    stamp: wp.array(dtype=wp.int32)  # (1,) the last stamp used: seen/slot outlive a launch


@wp.struct
class Queue:
    bits: wp.array2d(dtype=wp.uint64)  # (2 CLASSES, W) one bit per position, rows: round parity x class
    count: wp.array(dtype=wp.int32)  # (2 CLASSES,) bits set in each row
    cursor: wp.array(dtype=wp.int32)  # (2 CLASSES,) no bit of the row lies before this word
    row: wp.array(dtype=wp.int32)  # (V,) the row of the vertex's live entry (-1: none)
    ver: wp.array(dtype=wp.int32)  # (V,) the version the live entry carries
    bperm: wp.array(dtype=wp.int32)  # (B,) block -> its place in the visiting order
    binv: wp.array(dtype=wp.int32)  # (B,) place -> block
    bsize: int
    ctr: wp.array(dtype=wp.int64)  # (16,) counters, below


# ctr: 1 collapses made, 2 neighbour entries written, 5 overflow (0, 3, 4, 6 unused),
# 7 scan row, 8 round, 9 + p lowest row of parity p, 11 + p entries of parity p, 13 end of the neighbour range


@wp.struct
class State:
    version: wp.array(dtype=wp.int32)  # (V,) bumped at every evaluation and mark
    pending: wp.array(dtype=wp.uint8)  # (V,) 1 while the vertex's proposal waits for an evaluation
    lastcost: wp.array(dtype=wp.float64)  # (V,) cost of its last proposal
    target: wp.array(dtype=wp.int32)  # (V,) its last proposal's u (legal when it was evaluated)
    evalt: wp.array(dtype=wp.int32)  # (V,) collapses made when it was evaluated
    modt: wp.array(dtype=wp.int32)  # (V,) collapses made when its ring last changed
    used: wp.array(dtype=wp.int32)  # (V,) the last round a collapse made it unable to collapse (-1: none) ...
    used_u: wp.array(dtype=wp.int32)  # (V,) ... or to take a collapse (rule H-G, below)
    wait_v: wp.array(dtype=wp.int32)  # (V,) class of its proposal that waits for the next round (-1: none) ...
    wait_vr: wp.array(dtype=wp.int32)  # (V,) ... in this round
    wait_u: wp.array(dtype=wp.int32)  # (V,) cheapest class of the waiting proposals into it ...
    wait_ur: wp.array(dtype=wp.int32)  # (V,) ... in this round
    dead: wp.array(dtype=wp.uint8)  # (V,) 1 once collapsed
    node_of: wp.array(dtype=wp.int32)  # (V,) the node standing at the vertex now
    axis: wp.array(dtype=wp.vec3d)  # (V,) that node's cone axis
    half: wp.array(dtype=wp.float64)  # (V,) its cone half-angle
    radius: wp.array(dtype=wp.float64)  # (V,) its bounding radius


@wp.struct
class Nodes:
    parent: wp.array(dtype=wp.int32)  # (N,)
    children: wp.array2d(dtype=wp.int32)  # (N, 2) (node(u), node(v))
    vertex: wp.array(dtype=wp.int32)  # (N,) u
    axis: wp.array(dtype=wp.vec3d)  # (N,) normal cone (figure 7)
    half: wp.array(dtype=wp.float64)
    radius: wp.array(dtype=wp.float64)
    error: wp.array(dtype=wp.vec3d)  # (N,) p_v - p', p' closest on the faces around u after (figure 10)
    nb_count: wp.array(dtype=wp.int32)  # (N,) v's neighbours before the collapse
    nbs: wp.array(dtype=wp.int32)  # (E,) those neighbours, sorted, node after node


@wp.func
def gather(m: Mesh, v: int, st: int, seen: wp.array(dtype=wp.int32), slot: wp.array(dtype=wp.int32),
           ring: wp.array(dtype=wp.int32), rcnt: wp.array(dtype=wp.int32), base: int):
    """v's distinct neighbours into ring[base:] and the faces on each edge into rcnt[base:] (stamp ``st``); drops
    the dead corners from v's list; returns the count, CAP + 1 when the ring does not fit."""
    n = int(0)
    prev = int(-1)
    c = m.head[v]
    while c >= 0:
        f = c // 3
        nc = m.nxt[c]
        if m.alive[f] == wp.uint8(0):
            if prev < 0:
                m.head[v] = nc
            else:
                m.nxt[prev] = nc
        else:
            j = c % 3
            for s in range(1, 3):
                w = m.faces[f, (j + s) % 3]
                if seen[w] != st:
                    seen[w] = st
                    slot[w] = n
                    if n < CAP:
                        ring[base + n] = w
                        rcnt[base + n] = 1
                    n += 1
                elif slot[w] < CAP:
                    rcnt[base + slot[w]] += 1
            prev = c
        c = nc
    return wp.min(n, CAP + 1)


@wp.func
def push(q: Queue, cost: wp.float64, v: int, ver: int, next_round: int):
    """Make (cost, v, ver) v's live entry, in this round or the next (an older entry of v turns stale)."""
    c = int(0)
    if cost > wp.float64(0.0):
        c = wp.clamp(int(wp.floor(wp.log2(cost))) + CLASS_OFFSET, 1, CLASSES - 1)
    p = int((q.ctr[8] + wp.int64(next_round)) % wp.int64(2))
    r = c + p * CLASSES
    ps = q.bperm[v / q.bsize] * q.bsize + v % q.bsize
    wi = ps / 64
    bit = wp.uint64(1) << wp.uint64(ps % 64)
    if (q.bits[r, wi] & bit) == wp.uint64(0):
        q.bits[r, wi] = q.bits[r, wi] | bit
        q.count[r] = q.count[r] + 1
        q.ctr[11 + p] = q.ctr[11 + p] + wp.int64(1)
    if wi < q.cursor[r]:
        q.cursor[r] = wi
    if wp.int64(r) < q.ctr[9 + p]:
        q.ctr[9 + p] = wp.int64(r)
    if next_round == 0 and wp.int64(r) < q.ctr[7]:
        q.ctr[7] = wp.int64(r)
    q.row[v] = r
    q.ver[v] = ver


@wp.func
def pop(q: Queue):
    """The first entry (lowest class, then position) of the round, cleared: (row, v); the next round once this one
    is empty; (-1, -1) when both are."""
    for attempt in range(2):
        p = int(q.ctr[8] % wp.int64(2))
        if q.ctr[11 + p] > wp.int64(0):
            r = wp.max(int(q.ctr[7]), int(q.ctr[9 + p]))
            while r < (p + 1) * CLASSES:
                if q.count[r] == 0:
                    r += 1
                    continue
                wi = q.cursor[r]
                while q.bits[r, wi] == wp.uint64(0):
                    wi += 1
                q.cursor[r] = wi
                w = q.bits[r, wi]
                low = w & (~w + wp.uint64(1))
                b = int(wp.log2(wp.float64(low)) + wp.float64(0.5))
                q.bits[r, wi] = w & ~low
                q.count[r] = q.count[r] - 1
                q.ctr[11 + p] = q.ctr[11 + p] - wp.int64(1)
                q.ctr[7] = wp.int64(r)
                ps = wi * 64 + b
                return r, q.binv[ps / q.bsize] * q.bsize + ps % q.bsize
        q.ctr[8] = q.ctr[8] + wp.int64(1)  # the round is over
        nxt = int(q.ctr[8] % wp.int64(2))
        q.ctr[9 + p] = wp.int64((p + 1) * CLASSES)
        q.ctr[7] = q.ctr[9 + nxt]
        if q.ctr[11 + nxt] == wp.int64(0):
            return -1, -1
    return -1, -1


@wp.func
def legal(m: Mesh, s: Scratch, v: int, u: int, nv: int, cnt_uv: int, st: int, fold_cos: wp.float64,
          sliver: wp.float64, max_valence: int):
    """Whether v -> u is legal on the mesh as it stands (v's ring in s.ring[:nv]): the link condition, u's valence,
    no moved face turned over (figure 6) or made a sliver."""
    nu = gather(m, u, st, s.seen2, s.slot2, s.ring, s.rcnt, CAP)
    if nu > CAP:
        return False
    common = int(0)
    for i in range(nv):
        w = s.ring[i]
        if w != u and s.seen2[w] == st:
            common += 1
    if common != cnt_uv or not survivor_valence_ok(nu + nv - common - 2, m.boundary[u], max_valence):
        return False
    pv = vec_at(m.pos, v)
    pu = vec_at(m.pos, u)
    c = m.head[v]
    while c >= 0:
        f = c // 3
        j = c % 3
        c = m.nxt[c]
        if m.alive[f] == wp.uint8(0):
            continue
        b = m.faces[f, (j + 1) % 3]
        cc = m.faces[f, (j + 2) % 3]
        if b == u or cc == u:
            continue  # the faces on uv vanish
        if not moved_face_ok(pv, pu, vec_at(m.pos, b), vec_at(m.pos, cc), fold_cos, sliver):
            return False
    return True


@wp.func
def merge_cone(a1: wp.vec3d, t1: wp.float64, a2: wp.vec3d, t2: wp.float64):
    """The smallest cone holding cones (a1, t1) and (a2, t2) (``lodprt.model.hierarchy_attributes.merge_cones``)."""
    pi = wp.float64(3.141592653589793)
    c = wp.dot(a1, a2)
    g = wp.atan2(wp.length(wp.cross(a1, a2)), c)
    if g + t2 <= t1:
        return a1, t1
    if g + t1 <= t2:
        return a2, t2
    t = wp.float64(0.5) * (g + t1 + t2)
    if t >= pi:
        return a1, pi
    perp = a2 - c * a1
    pn = wp.length(perp)
    if pn < wp.float64(1e-12):  # (anti)parallel axes: any direction perpendicular to a1
        e = wp.vec3d(wp.float64(1.0), wp.float64(0.0), wp.float64(0.0))
        if wp.abs(a1[0]) >= wp.float64(0.9):
            e = wp.vec3d(wp.float64(0.0), wp.float64(1.0), wp.float64(0.0))
        perp = wp.cross(a1, e)
        pn = wp.length(perp)
    perp = perp / pn
    ang = t - t1
    return wp.normalize(wp.cos(ang) * a1 + wp.sin(ang) * perp), t


@wp.func
def evaluate(m: Mesh, s: Scratch, q: Queue, t: State, part: wp.array(dtype=wp.int32), me: int, v: int, nv: int,
             st: int, edge_weight: wp.float64, fold_cos: wp.float64, sliver: wp.float64, max_valence: int):
    """v's cheapest legal move (its ring in s.ring[:nv]) becomes its entry in this round; none: no entry (a later
    collapse around v marks it again). Returns the stamp last used."""
    t.pending[v] = wp.uint8(0)
    t.evalt[v] = int(q.ctr[1])
    t.version[v] = t.version[v] + 1
    pv = vec_at(m.pos, v)
    need = 2 - int(m.boundary[v])  # a boundary vertex moves along a boundary edge (one face) only
    left = int(0)
    for i in range(nv):
        u = s.ring[i]
        s.cost[i] = NONE
        if m.frozen[u] != wp.uint8(0) or s.rcnt[i] != need or m.group[u] != m.group[v] or part[u] != me:
            continue
        pu = vec_at(m.pos, u)
        d = pu - pv
        d2 = wp.dot(d, d)
        s.cost[i] = quadric_at(m.quadric, v, pu) + quadric_at(m.quadric, u, pu) + edge_weight * d2 * d2
        left += 1
    while left > 0:  # the cheapest candidate first; legality only as needed
        at = int(-1)
        low = NONE
        for i in range(nv):
            if s.cost[i] < low:
                low = s.cost[i]
                at = i
        if at < 0:
            return st
        st += 1
        if legal(m, s, v, s.ring[at], nv, s.rcnt[at], st, fold_cos, sliver, max_valence):
            t.target[v] = s.ring[at]
            t.lastcost[v] = low
            push(q, low, v, t.version[v], 0)
            return st
        s.cost[at] = NONE
        left -= 1
    return st


@wp.func
def record(m: Mesh, s: Scratch, q: Queue, t: State, nd: Nodes, v: int, u: int, nv: int, node_base: int):
    """The node of v -> u: children, v's sorted neighbours (s.ring[:nv]), cone, radius (figure 7)."""
    k = node_base + int(q.ctr[1])
    q.ctr[1] = q.ctr[1] + wp.int64(1)
    a = t.node_of[u]
    b = t.node_of[v]
    nd.parent[a] = k
    nd.parent[b] = k
    nd.parent[k] = -1  # a root until it collapses
    nd.children[k, 0] = a
    nd.children[k, 1] = b
    nd.vertex[k] = u
    t.node_of[u] = k
    off = int(q.ctr[2])
    if off + nv > wp.min(int(q.ctr[13]), nd.nbs.shape[0]):
        q.ctr[5] = wp.int64(1)  # out of this unit's neighbour range: the host raises
        return k
    for i in range(nv):  # insertion sort into place
        w = s.ring[i]
        z = off + i
        while z > off and nd.nbs[z - 1] > w:
            nd.nbs[z] = nd.nbs[z - 1]
            z -= 1
        nd.nbs[z] = w
    nd.nb_count[k] = nv
    q.ctr[2] = wp.int64(off + nv)
    ax, hf = merge_cone(t.axis[u], t.half[u], t.axis[v], t.half[v])
    t.axis[u] = ax
    t.half[u] = hf
    nd.axis[k] = ax
    nd.half[k] = hf
    r = wp.max(t.radius[u], t.radius[v] + wp.length(vec_at(m.pos, v) - vec_at(m.pos, u)))
    t.radius[u] = r
    nd.radius[k] = r
    return k


@wp.func
def collapse(m: Mesh, s: Scratch, q: Queue, t: State, nd: Nodes, part: wp.array(dtype=wp.int32), me: int, v: int,
             u: int, nv: int, st: int, node_base: int, rnd: int):
    """Make v -> u: its node, the faces (those on uv vanish, the others move to u), Q_u += Q_v, the error vector
    (figure 10), and the survivor's new ring marked for evaluation. Returns the stamp last used."""
    k = record(m, s, q, t, nd, v, u, nv, node_base)
    for i in range(nv):  # v's ring takes no other collapse this round (rule H-R's u' in N[v])
        if part[s.ring[i]] == me:  # a tile's border vertex belongs to a later phase (and another thread reads it)
            t.used_u[s.ring[i]] = rnd
    c = m.head[v]
    while c >= 0:
        f = c // 3
        j = c % 3
        nc = m.nxt[c]
        if m.alive[f] != wp.uint8(0):
            if m.faces[f, 0] == u or m.faces[f, 1] == u or m.faces[f, 2] == u:
                m.alive[f] = wp.uint8(0)
                m.group_faces[m.face_group[f]] = m.group_faces[m.face_group[f]] - 1
            else:
                m.faces[f, j] = u
                m.nxt[c] = m.head[u]
                m.head[u] = c
        c = nc
    m.head[v] = -1
    t.dead[v] = wp.uint8(1)
    for e in range(10):
        m.quadric[u, e] = m.quadric[u, e] + m.quadric[v, e]
    p = vec_at(m.pos, v)
    bd = wp.float64(1.0e300)
    out = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    c = m.head[u]
    while c >= 0:
        f = c // 3
        c = m.nxt[c]
        if m.alive[f] == wp.uint8(0):
            continue
        x = closest_on_triangle(p, vec_at(m.pos, m.faces[f, 0]), vec_at(m.pos, m.faces[f, 1]),
                                vec_at(m.pos, m.faces[f, 2]))
        dq = wp.dot(p - x, p - x)
        if dq < bd:
            bd = dq
            out = p - x
    nd.error[k] = out
    st += 1
    nu = gather(m, u, st, s.seen, s.slot, s.ring, s.rcnt, 0)
    n = wp.min(nu, CAP)
    for i in range(n + 1):
        w = u
        if i < n:
            w = s.ring[i]
        if part[w] != me:
            continue  # a tile's border vertex: read only until the phase that owns it
        t.modt[w] = int(q.ctr[1])
        t.used[w] = rnd  # no vertex of the survivor's closed ring collapses this round (H-R's v' in N[v] or N[u])
        if m.movable[w] != wp.uint8(0) and t.dead[w] == wp.uint8(0) and t.pending[w] == wp.uint8(0):
            t.pending[w] = wp.uint8(1)
            t.version[w] = t.version[w] + 1
            push(q, t.lastcost[w], w, t.version[w], 0)
    return st


@wp.func
def wait(q: Queue, t: State, v: int, u: int, c: int, ver: int, rnd: int):
    """v's proposal (class c, into u; u -1 when unknown) waits for the next round, and holds costlier moves around
    it back in this one (the rounds build's hold rule, docs/HIERARCHY.md)."""
    t.wait_v[v] = c
    t.wait_vr[v] = rnd
    if u >= 0:
        if t.wait_ur[u] != rnd or c < t.wait_u[u]:
            t.wait_u[u] = c
            t.wait_ur[u] = rnd
    push(q, t.lastcost[v], v, ver, 1)


@wp.func
def held(s: Scratch, t: State, v: int, u: int, nv: int, c: int, rnd: int):
    """Whether a waiting proposal of a cheaper class than c lies at v, u or in v's ring (s.ring[:nv])."""
    for i in range(nv + 2):
        w = v
        if i == nv:
            w = u
        elif i < nv:
            w = s.ring[i]
        if t.wait_vr[w] == rnd and t.wait_v[w] < c:
            return True
        if t.wait_ur[w] == rnd and t.wait_u[w] < c:
            return True
    return False


@wp.kernel
def greedy_build(
    m: Mesh,  # In/Out: the mesh, collapsed in place
    s: Scratch,  # Temp: this thread's rings
    q: Queue,  # Temp: this thread's queue (empty again at the end); q.ctr this unit's counters
    t: State,  # Temp: per-vertex state (units share no vertex they change)
    nd: Nodes,  # Out: nodes node_base.. of this unit, its neighbours from q.ctr[2]
    part: wp.array(dtype=wp.int32),  # In: (V,) the unit of each vertex (-1: it waits for a later phase)
    me: int,  # In: this launch's unit
    members: wp.array(dtype=wp.int32),  # In: the vertices of every unit, unit after unit, ids ascending in each
    first: int,  # In: where this unit's vertices start in members ...
    count: int,  # In: ... and how many they are
    node_base: int,  # In: id of this unit's first node
    target_base: int,  # In: a group stops once it has at most this many faces
    edge_weight: wp.float64,  # In: weight of |uv|^4 in the cost
    fold_cos: wp.float64,  # In: a moved face keeps its normal within this cosine
    sliver: wp.float64,  # In: twice the area below sliver x longest edge^2 is a sliver
    max_valence: int,  # In: largest valence of a survivor
):
    V = m.pos.shape[0]
    start = wp.clamp(first, 0, members.shape[0])
    for i in range(start, wp.min(start + count, members.shape[0])):  # every movable vertex starts unevaluated
        v = members[i]  # (class 0), in the queue's order
        if v >= 0 and v < V:
            if m.movable[v] != wp.uint8(0) and part[v] == me and t.dead[v] == wp.uint8(0):
                t.pending[v] = wp.uint8(1)
                push(q, wp.float64(-1.0), v, t.version[v], 0)
    st = wp.max(V, s.stamp[0])  # above every stamp ``prepare`` (vertex ids) or an earlier launch left in s.seen
    while True:
        r, v = pop(q)
        if r < 0:
            break
        if q.row[v] != r:
            continue  # a stale bit: v was queued again since
        q.row[v] = -1
        ver = q.ver[v]
        rnd = int(q.ctr[8])
        if t.dead[v] != wp.uint8(0) or ver != t.version[v] or m.group_faces[m.count_group[v]] <= target_base:
            continue
        u = t.target[v]
        c = r % CLASSES
        if t.pending[v] != wp.uint8(0):
            u = -1
        if t.used[v] == rnd or (u >= 0 and t.used_u[u] == rnd):
            wait(q, t, v, u, c, ver, rnd)  # blocked by this round's collapses (rule H-G): the next round
            continue
        st += 1
        nv = gather(m, v, st, s.seen, s.slot, s.ring, s.rcnt, 0)
        if nv > CAP:
            continue
        if u >= 0 and held(s, t, v, u, nv, c, rnd):
            wait(q, t, v, u, c, ver, rnd)
            continue
        if t.pending[v] == wp.uint8(0):
            # its cost holds (a change to Q_u or v's ring would have marked v); the link around u may have moved
            i = s.slot[u]
            st += 1
            if s.seen[u] == st - 1 and t.dead[u] == wp.uint8(0):
                same = t.modt[u] <= t.evalt[v] and t.modt[v] <= t.evalt[v]  # legal at evalt, nothing moved since
                if same or legal(m, s, v, u, nv, s.rcnt[i], st, fold_cos, sliver, max_valence):
                    st = collapse(m, s, q, t, nd, part, me, v, u, nv, st, node_base, rnd)
                    continue
        st = evaluate(m, s, q, t, part, me, v, nv, st, edge_weight, fold_cos, sliver, max_valence)
    s.stamp[0] = st + 1
