"""Vertex hierarchy built in sequence (SPEC 3; thesis 3.2; tag H-G): ``build_greedy``.

The same kind of hierarchy as ``lodprt.model.hierarchy_build`` (legal half-edge collapses ``v -> u`` in creation
order, the same costs, legality rules, cones, radii, error vectors and recorded neighbours), made by one Warp
thread per unit of the mesh instead of rounds of parallel passes: a collapse is made on the mesh as it stands and
only the survivor's ring is evaluated again, so the build evaluates about 3 moves per collapse where the rounds
evaluate every live vertex every round (docs/HIERARCHY.md, "The sequential build"). The default build:
``build_hierarchy`` (``method="sequential"``), ``bake`` and ``lodprt bake`` call it.

Units are whole connected components (each holding its groups: split further by ``component``); a component with
more than ``TILE`` used vertices is first built in tiles of about that many, each down to 1/``REDUCE`` of its
faces, its tiles' borders waiting for a second phase over whole components on the live mesh renumbered densely
(docs/HIERARCHY.md: built down to the base in the tiles, the borders would come after every coarse level, and the
run time's cut would keep them at full resolution). The units of a phase run on up to ``workers`` threads, the
largest first, each thread taking the next unit when done (a CPU launch releases the GIL); they share no face or
vertex they change and each writes its own node range, so the hierarchy is the same, bit for bit, on any number of
threads.
"""

from __future__ import annotations

import concurrent.futures
import os
import threading
import time

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.launches import warp_view
from lodprt.model.hierarchy import Hierarchy, broken_link, distinct_corners
from lodprt.model.hierarchy_inputs import BOUNDARY_WEIGHT, CONE_SLACK, checked_inputs
from lodprt.model.hierarchy_levels import mesh_groups
from lodprt.model.hierarchy_rounds import EDGE_WEIGHT, FOLD_COS, MAX_VALENCE, SLIVER

#: vertex ids are visited in blocks of this many, the blocks in a fixed permuted order (each block's memory is read
#: together; no sweep crosses the mesh in id order, which would chain the El-Sana & Varshney dependencies)
BLOCK = 1024
#: a prime far from any block count (the stride of the blocks' permutation)
STRIDE = 40503
#: a connected component with more used vertices than this is first built in tiles of about this many, on
#: several threads, their borders waiting for a second phase over the whole component
TILE = 20_000
#: the first phase stops each tile at 1/REDUCE of its faces, so that its borders collapse among the coarse levels
REDUCE = 8


def _inputs(positions, faces, normals, component, target_base):
    """float64 positions, int32 faces without repeated corners, unit float64 normals and the ``component`` labels
    (or None); ``checked_inputs`` refuses bad input."""
    pos, f, nrm, comp = checked_inputs("build_greedy", positions, faces, normals, component, target_base)
    return pos, np.ascontiguousarray(f[distinct_corners(f)]), nrm, comp


def _groups(V, faces, comp):
    """int32 groups (moves stay within one) and connected components (the units) of the V vertices."""
    pieces = mesh_groups(V, faces).astype(np.int32)
    return (pieces if comp is None else mesh_groups(V, faces, comp).astype(np.int32)), pieces


def _mesh(kh, pos, faces, keep_boundary):
    """The kernels' Mesh before ``prepare`` (``_prepared``) makes its corner lists, quadrics and flags."""
    wp = warp()
    V, F = len(pos), len(faces)
    m = kh.Mesh()
    m.pos, m.faces = warp_view(pos, wp.float64), warp_view(faces.copy(), wp.int32)
    m.alive = warp_view(np.ones(F, np.uint8), wp.uint8)
    m.head, m.nxt = warp_view(np.full(V, -1, np.int32), wp.int32), warp_view(np.full(3 * F, -1, np.int32), wp.int32)
    movable = np.zeros(V, np.uint8)
    movable[faces.ravel()] = 2 if keep_boundary else 1
    m.movable = warp_view(movable, wp.uint8)
    m.boundary, m.frozen = warp_view(np.zeros(V, np.uint8), wp.uint8), warp_view(np.zeros(V, np.uint8), wp.uint8)
    m.quadric = warp_view(np.zeros((V, 10)), wp.float64)
    return m


def _prepared(kh, kp, m, background):
    """Launch ``prepare`` on ``m`` (on a thread of its own with ``background``, while the caller goes on with the
    groups and tiles, which do not read what it writes); returns the call that waits for it."""
    wp = warp()

    def run():
        wp.launch(kp.prepare, dim=1, inputs=[m, _scratch(kh, m.pos.shape[0]), BOUNDARY_WEIGHT], device="cpu")

    if not background:
        run()
        return lambda: None
    pool = concurrent.futures.ThreadPoolExecutor(1)
    job = pool.submit(run)
    pool.shutdown(wait=False)
    return job.result  # re-raises the launch's error in the caller


def _set_groups(m, faces, group):
    """The Mesh's groups: of each vertex, of each face (its first corner's) and each group's face count."""
    wp = warp()
    G = int(group.max()) + 1 if len(group) else 1
    m.group = warp_view(group, wp.int32)
    m.face_group, m.count_group = warp_view(group[faces[:, 0]], wp.int32), warp_view(group, wp.int32)
    m.group_faces = warp_view(np.bincount(group[faces[:, 0]], minlength=G).astype(np.int32), wp.int32)


def _compacted(kh, m, t, group):
    """The second phase's mesh and state on the live part of the mesh, its vertices renumbered densely in id order
    (after the tiles, the survivors lie scattered over the arrays; dense, they share cache lines): (Mesh, State,
    the original id of each vertex). Carried: positions, flags, groups, quadrics, the node standing at each vertex
    with its cone and radius; the corner lists are made anew over the live faces (each vertex's in corner order, as
    ``prepare`` makes them); the per-round state starts afresh, as at every phase."""
    wp = warp()
    faces = m.faces.numpy()[m.alive.numpy().astype(bool)]
    keep = np.flatnonzero(np.bincount(faces.ravel(), minlength=len(group)))
    new = np.full(len(group), -1, np.int32)
    new[keep] = np.arange(len(keep), dtype=np.int32)
    faces = new[faces]
    V, corners = len(keep), faces.ravel()
    order = np.argsort(corners, kind="stable").astype(np.int32)
    same = corners[order[1:]] == corners[order[:-1]]
    nxt = np.full(len(corners), -1, np.int32)
    nxt[order[:-1][same]] = order[1:][same]
    first = order[np.concatenate([[True], ~same])]
    head = np.full(V, -1, np.int32)
    head[corners[first]] = first
    c = kh.Mesh()
    c.pos, c.faces = warp_view(np.ascontiguousarray(m.pos.numpy()[keep]), wp.float64), warp_view(faces, wp.int32)
    c.alive = warp_view(np.ones(len(faces), np.uint8), wp.uint8)
    c.head, c.nxt = warp_view(head, wp.int32), warp_view(nxt, wp.int32)
    for name in ("boundary", "frozen", "movable"):
        setattr(c, name, warp_view(getattr(m, name).numpy()[keep], wp.uint8))
    c.group, c.quadric = warp_view(group[keep], wp.int32), warp_view(m.quadric.numpy()[keep], wp.float64)
    d = _state(kh, V, t.axis.numpy()[keep])
    d.node_of = warp_view(t.node_of.numpy()[keep], wp.int32)
    d.half, d.radius = warp_view(t.half.numpy()[keep], wp.float64), warp_view(t.radius.numpy()[keep], wp.float64)
    return c, d, keep


def _scratch(kh, V):
    wp = warp()
    s = kh.Scratch()
    s.seen, s.slot = warp_view(np.full(V, -1, np.int32), wp.int32), warp_view(np.zeros(V, np.int32), wp.int32)
    s.seen2, s.slot2 = warp_view(np.full(V, -1, np.int32), wp.int32), warp_view(np.zeros(V, np.int32), wp.int32)
    s.ring, s.rcnt = warp_view(np.zeros(2 * kh.CAP + 2, np.int32), wp.int32), warp_view(
        np.zeros(2 * kh.CAP + 2, np.int32), wp.int32)
    s.cost = warp_view(np.zeros(kh.CAP + 2), wp.float64)
    s.stamp = warp_view(np.zeros(1, np.int32), wp.int32)
    return s


def _queue(kh, V):
    wp = warp()
    q = kh.Queue()
    nblocks = max(1, -(-V // BLOCK))
    stride = STRIDE
    while np.gcd(stride, nblocks) != 1:
        stride += 2
    perm = (np.arange(nblocks, dtype=np.int64) * stride % nblocks).astype(np.int32)
    inv = np.empty(nblocks, np.int32)
    inv[perm] = np.arange(nblocks, dtype=np.int32)
    rows = 2 * kh.CLASSES
    q.bits = warp_view(np.zeros((rows, nblocks * BLOCK // 64 + 1), np.uint64), wp.uint64)
    q.count, q.cursor = warp_view(np.zeros(rows, np.int32), wp.int32), warp_view(np.zeros(rows, np.int32), wp.int32)
    q.row, q.ver = warp_view(np.full(V, -1, np.int32), wp.int32), warp_view(np.zeros(V, np.int32), wp.int32)
    q.bperm, q.binv, q.bsize = warp_view(perm, wp.int32), warp_view(inv, wp.int32), BLOCK
    return q  # empty again after every unit (each launch runs until no entry is left): a thread reuses it


def _counters(kh, nb_base, nb_count):
    """A unit's queue counters: both round parities empty, its neighbours recorded in ``nb_count`` entries from
    ``nb_base``."""
    ctr = np.zeros(16, np.int64)
    ctr[9], ctr[10], ctr[2], ctr[13] = kh.CLASSES, 2 * kh.CLASSES, nb_base, nb_base + nb_count
    return ctr


def _state(kh, V, normals):
    wp = warp()
    t = kh.State()
    for name in ("version", "target", "evalt", "modt"):
        setattr(t, name, warp_view(np.zeros(V, np.int32), wp.int32))
    t.pending, t.dead = (warp_view(np.zeros(V, np.uint8), wp.uint8) for _ in range(2))
    t.lastcost, t.half, t.radius = (warp_view(np.zeros(V), wp.float64) for _ in range(3))
    for name in ("used", "used_u", "wait_v", "wait_vr", "wait_u", "wait_ur"):
        setattr(t, name, warp_view(np.full(V, -1, np.int32), wp.int32))
    t.node_of = warp_view(np.arange(V, dtype=np.int32), wp.int32)
    t.axis = warp_view(normals.copy(), wp.vec3d)
    return t


def _nodes(kh, V, normals, most):
    """The node arrays sized for ``most`` collapses (numpy, and the kernels' Nodes viewing them; the recorded
    neighbours are each phase's own)."""
    wp = warp()
    N = V + most
    arr = {"parent": np.full(N, -1, np.int32), "children": np.full((N, 2), -1, np.int32),
           "vertex": np.arange(N, dtype=np.int32), "axis": np.zeros((N, 3)), "half": np.zeros(N),
           "radius": np.zeros(N), "error": np.zeros((N, 3)), "nb_count": np.zeros(N, np.int32)}
    arr["axis"][:V] = normals
    nd = kh.Nodes()
    types = {"axis": wp.vec3d, "error": wp.vec3d, "half": wp.float64, "radius": wp.float64}
    for name, a in arr.items():
        setattr(nd, name, warp_view(a, types.get(name, wp.int32)))
    return nd, arr


def _sizes(vunit, funit, movable):
    """Per unit: the collapses it may make and the neighbour entries it may record (each corner of its faces two,
    plus MAX_VALENCE per collapse: a vertex's valence when it collapses is at most the larger)."""
    U = int(max(vunit.max(initial=-1), funit.max(initial=-1))) + 1
    moves = np.bincount(vunit[movable], minlength=U)
    return moves, moves * MAX_VALENCE + np.bincount(funit, minlength=U) * 6


def _tiles(pos, faces, pieces, used):
    """The first phase's units when a connected component has more than ``TILE`` vertices that faces use (``used``;
    known before ``prepare`` has found which may move), else None: (F,)
    unit of each face (a cell of a grid over its component's two longest extents, by the face's first corner; a
    smaller component's faces keep its id, a unit that holds no vertex) and (V,) unit of each vertex, -1 where it
    waits for the second phase (on the tiles' borders: faces in two units; in a smaller component; where no face
    is)."""
    size = np.bincount(pieces[used], minlength=int(pieces.max(initial=0)) + 1)
    big = np.flatnonzero(size > TILE)
    if not len(big):
        return None
    funit = pieces[faces[:, 0]]
    nxt = len(size)
    for g in big:
        sel = np.flatnonzero(funit == g)
        c = pos[faces[sel, 0]]  # a face's first corner places it
        lo = np.array([c[:, d].min() for d in range(3)])  # column by column: numpy's min(0) strides slowly
        ext = np.array([c[:, d].max() for d in range(3)]) - lo
        ax = np.argsort(-ext)[:2]
        k = -(-int(size[g]) // TILE)
        a = int(np.ceil(np.sqrt(k)))
        b = -(-k // a)
        i = np.clip(((c[:, ax[0]] - lo[ax[0]]) / max(ext[ax[0]], 1e-300) * a).astype(np.int64), 0, a - 1)
        j = np.clip(((c[:, ax[1]] - lo[ax[1]]) / max(ext[ax[1]], 1e-300) * b).astype(np.int64), 0, b - 1)
        funit[sel] = nxt + i * b + j
        nxt += a * b
    vunit = np.full(len(pos), -1, np.int32)
    for k in range(3):  # one of the vertex's units ...
        vunit[faces[:, k]] = funit
    for k in range(3):  # ... -1 where its faces lie in two
        vunit[faces[funit != vunit[faces[:, k]], k]] = -1
    vunit[vunit < len(size)] = -1  # a smaller component waits for the second phase
    return funit, vunit


def _phase(kh, m, t, nd_arr, units, counters, at, target_base, workers, report, pieces, reduce=0):
    """One phase: a launch per unit of ``units`` ((V,) unit of each vertex, -1: it stays; (F,) unit of each face),
    on up to ``workers`` threads that each take the unit of the longest estimated time left when done (``_run``;
    ``pieces``: (V,) the connected component of each vertex, a unit's kind); each unit stops at
    ``target_base`` faces of ``counters`` ((V,) the counter of each vertex, (F,) of each face), or with ``reduce`` at
    1/``reduce`` of the faces its counter holds when that is more (a tile: its counter is its own). Units share no face
    or vertex they change, and each has its own node and neighbour range, so the result does not depend on the
    threads. ``report(collapses)`` is called with the collapses of the units done so far, in the calling thread. The
    nodes are compacted from node ``at``; returns the next free node, the recorded neighbours and the most rounds of
    a unit."""
    vunit, funit = units
    wp = warp()
    nd, arr = nd_arr
    V = len(vunit)
    alive = m.alive.numpy().astype(bool)
    movable = m.movable.numpy().astype(bool) & (vunit >= 0) & (t.dead.numpy() == 0)  # what may yet collapse
    moves, entries = _sizes(vunit, funit, movable)
    todo = [int(u) for u in np.argsort(-moves, kind="stable") if moves[u]]
    node_base = at + np.concatenate([[0], np.cumsum(moves)[:-1]]).astype(np.int64)
    nb_base = np.concatenate([[0], np.cumsum(entries)[:-1]]).astype(np.int64)
    nd.nbs = warp_view(np.zeros(int(entries.sum()), np.int32), wp.int32)
    vcount, fcount = counters
    m.count_group, m.face_group = warp_view(np.maximum(vcount, 0), wp.int32), warp_view(fcount, wp.int32)
    m.group_faces = warp_view(np.bincount(fcount[alive], minlength=int(fcount.max(initial=0)) + 1).astype(np.int32),
                              wp.int32)
    unit_wp = warp_view(vunit, wp.int32)
    key = vunit.astype(np.int16) if len(moves) < 2**15 else vunit  # 16 bits: numpy's stable sort is a radix sort
    members = np.argsort(key, kind="stable").astype(np.int32)  # each unit's vertices, ids ascending
    starts = np.searchsorted(vunit[members], np.arange(len(moves) + 1))
    members_wp = warp_view(members, wp.int32)
    stop = np.full(len(moves), int(target_base), np.int64)
    if reduce:
        held = m.group_faces.numpy()
        stop[:len(held)] = np.maximum(stop[:len(held)], held[:len(stop)] // reduce)
    for a in (t.used, t.used_u, t.wait_v, t.wait_vr, t.wait_u, t.wait_ur):  # rounds count from 0 again
        a.numpy().fill(-1)
    ctrs = {u: _counters(kh, nb_base[u], entries[u]) for u in todo}

    def launch(s, q, u):
        q.ctr = warp_view(ctrs[u], wp.int64)
        wp.launch(kh.greedy_build, dim=1, device="cpu",
                  inputs=[m, s, q, t, nd, unit_wp, u, members_wp, int(starts[u]), int(starts[u + 1] - starts[u]),
                          int(node_base[u]), int(stop[u]), EDGE_WEIGHT, FOLD_COS, SLIVER, MAX_VALENCE])
        done.append(u)

    done = []
    kind = {u: int(pieces[members[starts[u]]]) for u in todo}
    _run(lambda: (_scratch(kh, V), _queue(kh, V)), launch, todo, workers,
         lambda: report(sum(int(ctrs[u][1]) for u in list(done))), size=moves, kind=kind)
    if any(c[5] for c in ctrs.values()):
        raise LodprtError("build_greedy: neighbour space exhausted (an internal sizing error)")
    nbs = nd.nbs.numpy()
    order = sorted(todo)
    recorded = [nbs[nb_base[u]:int(ctrs[u][2])] for u in order]
    at = _compact(arr, t.node_of.numpy(), at, node_base[order], [int(ctrs[u][1]) for u in order])
    return at, recorded, max((int(c[8]) for c in ctrs.values()), default=0)


def _compact(arr, node_of, at, node_base, made):
    """Move each unit's nodes (from ``node_base``, ``made`` of them, in increasing order) down to follow the earlier
    units' (creation = node id) and fix the references to them (parents, children, the node at each vertex). The
    rows the move leaves behind get their parent and children cleared: a later phase's node written there takes
    its parent only when it collapses, so a root of that phase would otherwise keep a stale one."""
    new_id = np.arange(len(arr["parent"]), dtype=np.int32)
    end = at
    for src, n in zip(node_base, made):
        new_id[src:src + n] = np.arange(at, at + n, dtype=np.int32)
        for a in arr.values():
            if src != at:
                a[at:at + n] = a[src:src + n]
        at += n
        end = max(end, int(src) + n)
    for a in (arr["parent"], arr["children"], node_of):
        live = a >= 0
        a[live] = new_id[a[live]]
    arr["parent"][at:end] = -1
    arr["children"][at:end] = -1
    return at


def build_greedy(positions: np.ndarray, faces: np.ndarray, normals: np.ndarray, *, component=None,
                 target_base: int = 64, keep_boundary: bool = False, workers: int | None = None,
                 progress=None) -> Hierarchy:
    """The vertex hierarchy of a triangle mesh built in sequence (module docstring): the arguments and the result
    of ``lodprt.model.hierarchy_build.build_hierarchy``, which calls it for ``method="sequential"`` (its default).
    ``progress(collapses, total)`` is called as units finish (one launch per unit: a scene of one small component
    reports once). A vertex with more than ``CAP`` (128) neighbours takes part in no collapse. Raises LodprtError
    naming the bad input."""
    from lodprt.devices import load_kernels
    from lodprt.kernels import hierarchy_greedy as kh
    from lodprt.kernels import hierarchy_prepare as kp

    t0 = time.perf_counter()
    pos, work, nrm, comp = _inputs(positions, faces, normals, component, target_base)
    V = len(pos)
    workers = _workers(workers)
    load_kernels("cpu", kh, kp)
    m = _mesh(kh, pos, work, keep_boundary)
    prepared = _prepared(kh, kp, m, workers > 1)  # on its own thread while the groups and tiles are found
    group, pieces = _groups(V, work, comp)
    used = np.zeros(V, bool)
    used[work.ravel()] = True
    tiles = _tiles(pos, work, pieces, used)
    prepared()
    _set_groups(m, work, group)
    t = _state(kh, V, nrm)
    movable = m.movable.numpy().astype(bool)
    nd_arr = _nodes(kh, V, nrm, int(movable.sum()))
    at, recorded, rounds = V, [], 0
    total = int(movable.sum())

    def phase(m, t, units, counters, pieces, reduce=0):
        nonlocal at, rounds
        before = at - V

        def report(made):
            if progress is not None:
                progress(before + made, total)

        at, rec, r = _phase(kh, m, t, nd_arr, units, counters, at, target_base, workers, report, pieces, reduce)
        recorded.extend(rec)
        rounds += r

    if tiles is None:  # whole components, each group to target_base
        phase(m, t, (pieces, pieces[work[:, 0]]), (group, group[work[:, 0]]), pieces)
    else:  # each tile to 1/REDUCE of its faces (its own counter), its borders waiting; then the rest, dense
        phase(m, t, (tiles[1], tiles[0]), (tiles[1], tiles[0]), pieces, REDUCE)
        c, d, keep = _compacted(kh, m, t, group)
        m = t = None  # the full-size mesh and state are done with (memory)
        first, done = at, len(recorded)
        cf = c.faces.numpy()
        phase(c, d, (pieces[keep], pieces[keep][cf[:, 0]]), (group[keep], group[keep][cf[:, 0]]), pieces[keep])
        nd_arr[1]["vertex"][first:at] = keep[nd_arr[1]["vertex"][first:at]]  # the original vertex ids
        recorded[done:] = [keep[r] for r in recorded[done:]]
    h = _hierarchy(kp, nd_arr[1], at, V, np.concatenate(recorded), rounds)
    h.build_seconds = time.perf_counter() - t0
    return h


def _workers(workers):
    """The threads a phase may use: ``workers``, or by default every core this process may use."""
    if workers is None:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return int(workers)


def _run(make, launch, todo, workers, after, size=None, kind=None):
    """``launch(*make(), unit)`` for every unit of ``todo`` on up to ``workers`` threads (a CPU launch releases the
    GIL), each with its own ``make()`` (scratch, queue); ``after()`` in the calling thread after each of its units and
    at the end. A free thread takes the first unit of ``todo`` left, or with ``size`` and ``kind`` (unit -> its
    collapses, and the component it lies in) the one of the longest estimated time: its size times the seconds per
    collapse its kind's finished units took (a kind with none finished yet: the slowest rate known), so that a costly
    kind's last tiles do not start last and keep one thread busy alone at the end. Each unit's result does not depend
    on the order."""
    left = list(todo)
    lock = threading.Lock()
    failed = []
    rate = {}  # kind -> [seconds, collapses] of its finished units

    def take():
        if size is None or len(left) < 2:
            return left.pop(0)
        slowest = max((sec / max(n, 1) for sec, n in rate.values()), default=1.0)
        est = [size[u] * (rate[kind[u]][0] / max(rate[kind[u]][1], 1) if kind[u] in rate else slowest) for u in left]
        return left.pop(int(np.argmax(est)))  # ties: the first, the largest

    def work(caller=False):
        own = make()
        while True:
            with lock:
                if not left or failed:
                    return
                u = take()
            try:
                t = time.perf_counter()
                launch(*own, u)
                if size is not None:
                    with lock:
                        r = rate.setdefault(kind[u], [0.0, 0])
                        r[0], r[1] = r[0] + time.perf_counter() - t, r[1] + int(size[u])
            except BaseException as e:  # noqa: BLE001 (re-raised in the calling thread)
                failed.append(e)
                return
            if caller:
                after()

    threads = [threading.Thread(target=work) for _ in range(max(1, min(int(workers), len(left))) - 1)]
    for th in threads:
        th.start()
    work(caller=True)
    for th in threads:
        th.join()
    if failed:
        raise failed[0]
    after()


def _hierarchy(kp, arr, N, V, nbs, rounds) -> Hierarchy:
    """The ``Hierarchy`` of the first N nodes (the leaf layout by ``leaf_layout``: children precede parents)."""
    offsets = np.zeros(N + 1, np.int64)
    np.cumsum(arr["nb_count"][:N], out=offsets[1:])
    parent, children = arr["parent"][:N], arr["children"][:N]
    broken = broken_link(parent, children, np.arange(N))
    if broken is not None:
        raise LodprtError(f"build_greedy: {broken} (an internal error)")
    half = np.minimum(arr["half"][:N] + CONE_SLACK, np.pi).astype(np.float32)
    half[:V] = 0
    leaf_order, leaf_range = np.zeros(V, np.int32), np.zeros((N, 2), np.int64)
    wp = warp()
    wp.launch(kp.leaf_layout, dim=1, inputs=[warp_view(parent, wp.int32), warp_view(children, wp.int32),
                                             warp_view(leaf_range, wp.int64), warp_view(leaf_order, wp.int32)],
              device="cpu")
    return Hierarchy(num_vertices=V, parent=parent, children=children, vertex=arr["vertex"][:N],
                     creation=np.arange(N, dtype=np.int32), cone_axis=arr["axis"][:N].astype(np.float32),
                     cone_half_angle=half, radius=(arr["radius"][:N] * (1 + 1e-6)).astype(np.float32),
                     error_vector=arr["error"][:N].astype(np.float32), neighbour_offsets=offsets,
                     neighbours=nbs.astype(np.int32, copy=False), leaf_order=leaf_order, leaf_range=leaf_range,
                     levels=rounds, method="sequential")
