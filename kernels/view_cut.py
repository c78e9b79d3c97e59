"""Per-frame moves of the view cut (thesis 3.2, 3.4.2; seed 003 table 5.1) as sequential kernels: collapses and
forced splits of a list of nodes under the El-Sana & Varshney dependency rules, each checked against the cut as
it is at that moment, so the cut stays legal after every single move.

They run on one thread (``dim=1``): the moves of one frame depend on each other (a split may need its coarser
neighbours split first), and done in order in compiled code they cost a few nanoseconds per original edge they
scan instead of a numpy round trip per dependency level. The host side is ``lodprt.runtime.view_cut.Cut``
(``coarsen_list``, ``force_refine_list``); ``Cut.can_refine`` / ``Cut.blockers_of_coarsen`` are the reference the
tests compare with.

State (shared with the host): ``active`` (N,) uint8, 1 for the nodes of the cut; ``anc`` (V,) int32 the active
ancestor-or-self of every original vertex. Hierarchy (read only): ``children`` (N, 2), ``parent`` (N,),
``creation`` (N,) int32, ``leaf_order`` (V,) int32, ``leaf_range`` (N, 2) int64 (the hierarchy's own, not
copied); original edges in CSR with rows in depth-first leaf order (``edge_ptr`` (V+1,) int64 indexed by leaf
rank, ``edge_nbr`` (E,) int32 original vertex ids), so the edges leaving the leaves of node k are
``edge_nbr[edge_ptr[leaf_range[k, 0]]:edge_ptr[leaf_range[k, 1]]]``.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

#: a root's missing parent counts as created after every node (the collapse rule)
LATEST = wp.constant(2147483647)


@wp.func
def set_leaves(
    node: int,
    leaf_order: wp.array(dtype=wp.int32),
    leaf_range: wp.array2d(dtype=wp.int64),
    anc: wp.array(dtype=wp.int32),
):
    """Every original vertex under ``node`` gets ``node`` as its active ancestor."""
    for i in range(int(leaf_range[node, 0]), int(leaf_range[node, 1])):
        anc[leaf_order[i]] = node


@wp.func
def refine_blocker(
    node: int,
    creation: wp.array(dtype=wp.int32),
    leaf_range: wp.array2d(dtype=wp.int64),
    edge_ptr: wp.array(dtype=wp.int64),
    edge_nbr: wp.array(dtype=wp.int32),
    anc: wp.array(dtype=wp.int32),
):
    """Split rule (thesis 3.2): an active neighbour of active ``node`` created after it, or -1 when there is none
    (the split is allowed)."""
    for e in range(int(edge_ptr[int(leaf_range[node, 0])]), int(edge_ptr[int(leaf_range[node, 1])])):
        a = anc[edge_nbr[e]]
        if a != node and creation[a] > creation[node]:
            return a
    return -1


@wp.func
def split(
    node: int,
    children: wp.array2d(dtype=wp.int32),
    leaf_order: wp.array(dtype=wp.int32),
    leaf_range: wp.array2d(dtype=wp.int64),
    active: wp.array(dtype=wp.uint8),
    anc: wp.array(dtype=wp.int32),
):
    c0 = children[node, 0]
    c1 = children[node, 1]
    active[node] = wp.uint8(0)
    active[c0] = wp.uint8(1)
    active[c1] = wp.uint8(1)
    set_leaves(c0, leaf_order, leaf_range, anc)
    set_leaves(c1, leaf_order, leaf_range, anc)


@wp.kernel
def coarsen_list(
    nodes: wp.array(dtype=wp.int32),  # In: (K,) nodes whose two children should collapse into them, in order
    children: wp.array2d(dtype=wp.int32),
    parent: wp.array(dtype=wp.int32),
    creation: wp.array(dtype=wp.int32),
    leaf_order: wp.array(dtype=wp.int32),
    leaf_range: wp.array2d(dtype=wp.int64),
    edge_ptr: wp.array(dtype=wp.int64),
    edge_nbr: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.uint8),  # In/out: the cut
    anc: wp.array(dtype=wp.int32),  # In/out: active ancestor of every original vertex
    done: wp.array(dtype=wp.uint8),  # Out: (K,) 1 where the collapse was made
    blocker: wp.array(dtype=wp.int32),  # Out: (K,) an active neighbour forbidding it, -1 where none
):
    """Collapse rule (thesis 3.2): both children of P active, and every active neighbour n of theirs has
    creation[parent[n]] > creation[P] (a root's missing parent counts as later). One thread, nodes in order."""
    for i in range(nodes.shape[0]):
        p = nodes[i]
        done[i] = wp.uint8(0)
        blocker[i] = -1
        c0 = children[p, 0]
        if c0 < 0:
            continue
        c1 = children[p, 1]
        if active[c0] == wp.uint8(0) or active[c1] == wp.uint8(0):
            continue
        b = int(-1)
        for e in range(int(edge_ptr[int(leaf_range[p, 0])]), int(edge_ptr[int(leaf_range[p, 1])])):
            a = anc[edge_nbr[e]]
            if a != c0 and a != c1:
                later = LATEST
                if parent[a] >= 0:
                    later = creation[parent[a]]
                if later <= creation[p]:
                    b = a
                    break
        if b >= 0:
            blocker[i] = b
            continue
        active[c0] = wp.uint8(0)
        active[c1] = wp.uint8(0)
        active[p] = wp.uint8(1)
        set_leaves(p, leaf_order, leaf_range, anc)
        done[i] = wp.uint8(1)


@wp.kernel
def force_refine_list(
    nodes: wp.array(dtype=wp.int32),  # In: (K,) active nodes to split, most wanted first
    max_splits: int,  # In: stop taking new nodes once this many splits are made (< 0: no limit)
    children: wp.array2d(dtype=wp.int32),
    creation: wp.array(dtype=wp.int32),
    leaf_order: wp.array(dtype=wp.int32),
    leaf_range: wp.array2d(dtype=wp.int64),
    edge_ptr: wp.array(dtype=wp.int64),
    edge_nbr: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.uint8),  # In/out: the cut
    anc: wp.array(dtype=wp.int32),  # In/out: active ancestor of every original vertex
    stack: wp.array(dtype=wp.int32),  # Scratch: (>= 1,) pending splits; a chain longer than this stops early
    result: wp.array(dtype=wp.int32),  # Out: (3,) splits made, nodes of the list taken, 1 if the stack overflowed
):
    """Forced refinement (seed 003, table 5.1): for each node of the list still active and internal, split it;
    an active neighbour created after it (coarser) is split first, recursively. Every pushed blocker was created
    after the node below it on the stack, so the stack is a chain of strictly growing creation numbers and the
    loop ends. One thread, nodes in order; each node's chain is finished before the budget is looked at."""
    splits = int(0)
    taken = int(0)
    cap = stack.shape[0]
    overflow = int(0)
    for i in range(nodes.shape[0]):
        if max_splits >= 0 and splits >= max_splits:
            break
        if overflow != 0:
            break
        taken = i + 1
        n = nodes[i]
        if active[n] == wp.uint8(0) or children[n, 0] < 0:
            continue
        stack[0] = n
        top = int(1)
        while top > 0:
            k = stack[top - 1]
            if active[k] == wp.uint8(0):
                top -= 1
                continue
            b = refine_blocker(k, creation, leaf_range, edge_ptr, edge_nbr, anc)
            if b >= 0:
                if top >= cap:
                    overflow = 1
                    break
                stack[top] = b
                top += 1
                continue
            split(k, children, leaf_order, leaf_range, active, anc)
            splits += 1
            top -= 1
    result[0] = splits
    result[1] = taken
    result[2] = overflow


@wp.kernel
def retriangulate(
    moved: wp.array(dtype=wp.int32),  # In: (K,) original vertices whose active ancestor changed since the last call
    vf_ptr: wp.array(dtype=wp.int32),  # In: (V + 1,) CSR rows of the faces around each original vertex
    vf: wp.array(dtype=wp.int32),  # In: faces around each vertex (face ids)
    faces: wp.array2d(dtype=wp.int32),  # In: (F, 3) original faces
    vertex: wp.array(dtype=wp.int32),  # In: (N,) original vertex of each node
    anc: wp.array(dtype=wp.int32),  # In: (V,) the cut's active ancestor of every original vertex
    fmap: wp.array2d(dtype=wp.int32),  # In/out: (F, 3) each face through the active ancestors (T-3.2)
    slot: wp.array(dtype=wp.int32),  # In/out: (F,) position of the face in ``live``, -1 when degenerate
    live: wp.array(dtype=wp.int32),  # In/out: (F,) the non-degenerate faces, densely, first ``count[0]``
    count: wp.array(dtype=wp.int32),  # In/out: (1,) number of live faces
    stamp: wp.array(dtype=wp.int32),  # In/out: (F,) the last call that mapped the face
    call: int,  # In: this call's number (a face is mapped once per call)
):
    """T-3.2 incremental triangulation (one thread): the faces around the ``moved`` vertices are mapped again
    through the active ancestors; a face that became degenerate leaves the dense list (the last one takes its
    place), one that stopped being degenerate is appended. The list is the cut's mesh in a deterministic order.
    A face around two or three moved vertices is mapped at its first (``stamp``): a second visit would map it
    to the same vertices and find its place in the list already right."""
    n = count[0]
    for k in range(moved.shape[0]):
        v = moved[k]
        for t in range(vf_ptr[v], vf_ptr[v + 1]):
            f = vf[t]
            if stamp[f] == call:
                continue
            stamp[f] = call
            x = vertex[anc[faces[f, 0]]]
            y = vertex[anc[faces[f, 1]]]
            z = vertex[anc[faces[f, 2]]]
            fmap[f, 0] = x
            fmap[f, 1] = y
            fmap[f, 2] = z
            s = slot[f]
            if x != y and y != z and x != z:
                if s < 0:
                    live[n] = f
                    slot[f] = n
                    n += 1
            elif s >= 0:
                n -= 1
                last = live[n]
                live[s] = last
                slot[last] = s
                slot[f] = -1
    count[0] = n


@wp.kernel
def gather_live(
    live: wp.array(dtype=wp.int32),  # In: (>= M,) live face ids (``retriangulate``)
    fmap: wp.array2d(dtype=wp.int32),  # In: (F, 3) mapped faces
    out: wp.array2d(dtype=wp.int32),  # Out: (M, 3) the live faces' rows, in list order
):
    k = wp.tid()
    f = live[k]
    out[k, 0] = fmap[f, 0]
    out[k, 1] = fmap[f, 1]
    out[k, 2] = fmap[f, 2]
