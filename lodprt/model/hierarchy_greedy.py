"""Vertex hierarchy built in sequence (SPEC 3; thesis 3.2; tag H-G): ``build_greedy``.

The same kind of hierarchy as ``lodprt.model.hierarchy_build`` (legal half-edge collapses ``v -> u`` in creation
order, the same costs, legality rules, cones, radii, error vectors and recorded neighbours), made by one Warp
thread per unit of the mesh instead of rounds of parallel passes: a collapse is made on the mesh as it stands and
only the survivor's ring is evaluated again, so the build evaluates about 3 moves per collapse where the rounds
evaluate every live vertex every round (docs/HIERARCHY.md, "The sequential build"). The default build:
``build_hierarchy`` (``method="sequential"``), ``bake`` and ``lodprt bake`` call it.

Units are whole connected components (each holding its groups: split further by ``component``); a component with
more than ``TILE`` used vertices is first built in tiles of about that many, each down to 1/``REDUCE`` of its
faces, its tiles' borders waiting for a second phase over the whole component on its live part renumbered densely
(docs/HIERARCHY.md: built down to the base in the tiles, the borders would come after every coarse level, and the
run time's cut would keep them at full resolution). Tiles and components' second phases are one pool of jobs on up
to ``workers`` threads (``lodprt.launches.run_jobs``; a CPU launch releases the GIL): a component's second phase
starts as soon as its own tiles are done, beside other components' tiles, and a free thread takes the job of the
longest estimated time. Jobs share no face or vertex they change and each writes its own node range (the second
phases their own node arrays, merged after the tiles' nodes in component order), so the hierarchy is the same, bit
for bit, on any number of threads and in any order.
"""

from __future__ import annotations

import concurrent.futures
import functools
import os
import threading
import time

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.launches import Job, run_jobs, warp_view
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


def _inputs(positions, faces, normals, component, target_base, caller):
    """float64 positions, int32 faces without repeated corners, unit float64 normals and the ``component`` labels
    (or None); ``checked_inputs`` refuses bad input, naming ``caller``."""
    pos, f, nrm, comp = checked_inputs(caller, positions, faces, normals, component, target_base)
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


def _compacted(kh, kp, m, t, group, fidx):
    """A second phase's mesh and state on the live faces ``fidx`` (one connected component's), their vertices
    renumbered densely in id order (after the tiles, the survivors lie scattered over the arrays; dense, they share
    cache lines): (Mesh, State, the original id of each vertex, the node standing at each). Carried: positions,
    flags, groups, quadrics, each vertex's cone and radius; the nodes are the phase's own (vertex i stands for node
    i, ``_merged`` maps them); the corner lists are made anew by ``prepare``'s own loop (``corner_lists``); the
    per-round state starts afresh, as at every phase."""
    wp = warp()
    faces = m.faces.numpy()[fidx]
    keep = np.unique(faces.ravel())
    faces = np.searchsorted(keep, faces).astype(np.int32)
    V = len(keep)
    c = kh.Mesh()
    c.pos, c.faces = warp_view(np.ascontiguousarray(m.pos.numpy()[keep]), wp.float64), warp_view(faces, wp.int32)
    c.alive = warp_view(np.ones(len(faces), np.uint8), wp.uint8)
    c.head = warp_view(np.full(V, -1, np.int32), wp.int32)
    c.nxt = warp_view(np.full(faces.size, -1, np.int32), wp.int32)
    wp.launch(kp.corner_lists, dim=1, inputs=[c], device="cpu")  # as ``prepare`` makes them
    for name in ("boundary", "frozen", "movable"):
        setattr(c, name, warp_view(getattr(m, name).numpy()[keep], wp.uint8))
    c.group, c.quadric = warp_view(group[keep], wp.int32), warp_view(m.quadric.numpy()[keep], wp.float64)
    d = _state(kh, V, t.axis.numpy()[keep])
    d.half, d.radius = warp_view(t.half.numpy()[keep], wp.float64), warp_view(t.radius.numpy()[keep], wp.float64)
    return c, d, keep, t.node_of.numpy()[keep]


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


class _Units:
    """One phase's units on the mesh ``m`` and state ``t``: ``units`` ((V,) unit of each vertex, -1: it stays; (F,)
    unit of each face), launched one at a time (``launch``, on any thread); each stops at ``target_base`` faces of
    ``counters`` ((V,) the counter of each vertex, (F,) of each face), or with ``reduce`` at 1/``reduce`` of the
    faces its counter holds when that is more (a tile: its counter is its own). Units share no face or vertex they
    change, and each has its own node range from node ``at`` and neighbour range, so the result depends neither on
    the threads nor on the order. ``kind``: the connected component of each unit (``pieces``: of each vertex)."""

    def __init__(self, kh, m, t, nd, units, counters, at, target_base, pieces, reduce=0):
        vunit, funit = units
        wp = warp()
        self.kh, self.m, self.t, self.nd, self.at = kh, m, t, nd, at
        alive = m.alive.numpy().astype(bool)
        movable = m.movable.numpy().astype(bool) & (vunit >= 0) & (t.dead.numpy() == 0)  # what may yet collapse
        self.moves, entries = _sizes(vunit, funit, movable)
        self.todo = [int(u) for u in np.argsort(-self.moves, kind="stable") if self.moves[u]]
        self.node_base = at + np.concatenate([[0], np.cumsum(self.moves)[:-1]]).astype(np.int64)
        self.nb_base = np.concatenate([[0], np.cumsum(entries)[:-1]]).astype(np.int64)
        nd.nbs = warp_view(np.zeros(int(entries.sum()), np.int32), wp.int32)
        vcount, fcount = counters
        m.count_group, m.face_group = warp_view(np.maximum(vcount, 0), wp.int32), warp_view(fcount, wp.int32)
        m.group_faces = warp_view(np.bincount(fcount[alive], minlength=int(fcount.max(initial=0)) + 1)
                                  .astype(np.int32), wp.int32)
        self.unit_wp = warp_view(vunit, wp.int32)
        key = vunit.astype(np.int16) if len(self.moves) < 2**15 else vunit  # 16 bits: a radix sort
        members = np.argsort(key, kind="stable").astype(np.int32)  # each unit's vertices, ids ascending
        self.starts = np.searchsorted(vunit[members], np.arange(len(self.moves) + 1))
        self.members_wp = warp_view(members, wp.int32)
        self.stop = np.full(len(self.moves), int(target_base), np.int64)
        if reduce:
            held = m.group_faces.numpy()
            self.stop[:len(held)] = np.maximum(self.stop[:len(held)], held[:len(self.stop)] // reduce)
        for a in (t.used, t.used_u, t.wait_v, t.wait_vr, t.wait_u, t.wait_ur):  # rounds count from 0 again
            a.numpy().fill(-1)
        self.ctrs = {u: _counters(kh, self.nb_base[u], entries[u]) for u in self.todo}
        self.kind = {u: int(pieces[members[self.starts[u]]]) for u in self.todo}
        self.unstarted, self.lock = len(self.todo), threading.Lock()
        self.collapses = 0  # made by the units done so far (a running total: ``made`` is asked after every job)

    def launch(self, s, q, u):
        """Build unit ``u`` with a thread's scratch ``s`` and queue ``q`` (made for this mesh's vertex count)."""
        wp, kh = warp(), self.kh
        q.ctr = warp_view(self.ctrs[u], wp.int64)
        wp.launch(kh.greedy_build, dim=1, device="cpu",
                  inputs=[self.m, s, q, self.t, self.nd, self.unit_wp, u, self.members_wp, int(self.starts[u]),
                          int(self.starts[u + 1] - self.starts[u]), int(self.node_base[u]), int(self.stop[u]),
                          EDGE_WEIGHT, FOLD_COS, SLIVER, MAX_VALENCE])
        with self.lock:
            self.collapses += int(self.ctrs[u][1])

    def release(self) -> None:
        """Let the mesh, state and unit arrays go (every unit is done; ``finish`` needs none of them)."""
        self.m = self.t = self.unit_wp = self.members_wp = None

    def made(self) -> int:
        """Collapses made by the units done so far."""
        return self.collapses

    def jobs(self, follow=None, after=None) -> list:
        """A ``Job`` per unit, each making the thread's scratch and queue for this mesh once (``follow``: kind -> the
        work that waits for the units of that kind; ``after()``: called when a unit is done)."""
        V = self.m.pos.shape[0]

        def run(cache, u):
            with self.lock:
                self.unstarted -= 1
            if cache.get("mesh") is not self.m:
                cache["mesh"], cache["sq"] = self.m, (_scratch(self.kh, V), _queue(self.kh, V))
            self.launch(*cache["sq"], u)
            if not self.unstarted:  # no unit of this mesh left to start: the thread's scratch and queue go (memory)
                cache.clear()
            if after is not None:
                after()

        return [Job(functools.partial(run, u=u), size=float(self.moves[u]), kind=self.kind[u],
                    follow=float((follow or {}).get(self.kind[u], 0.0))) for u in self.todo]

    def finish(self, arr, refs=()):
        """After every unit: the recorded neighbours (in unit order) and the most rounds of a unit; the nodes
        compacted from node ``at`` (``_compact``, ``refs``: more arrays of node ids to follow them); returns (next
        free node, recorded, rounds)."""
        if any(c[5] for c in self.ctrs.values()):
            raise LodprtError("build_greedy: neighbour space exhausted (an internal sizing error)")
        nbs, order = self.nd.nbs.numpy(), sorted(self.todo)
        recorded = [nbs[self.nb_base[u]:int(self.ctrs[u][2])] for u in order]
        at = _compact(arr, refs, self.at, self.node_base[order], [int(self.ctrs[u][1]) for u in order])
        self.release()
        return at, recorded, max((int(c[8]) for c in self.ctrs.values()), default=0)


def _compact(arr, refs, at, node_base, made):
    """Move each unit's nodes (from ``node_base``, ``made`` of them, in increasing order) down to follow the earlier
    units' (creation = node id) and fix the references to them (parents, children and the arrays of ``refs``)."""
    new_id = np.arange(len(arr["parent"]), dtype=np.int32)
    for src, n in zip(node_base, made):
        new_id[src:src + n] = np.arange(at, at + n, dtype=np.int32)
        for a in arr.values():
            if src != at:
                a[at:at + n] = a[src:src + n]
        at += n
    for a in (arr["parent"], arr["children"], *refs):
        live = a >= 0
        a[live] = new_id[a[live]]
    return at


def _rest(kh, compacted, group, target_base):
    """The second phase of one connected component once its tiles are done, on its live part renumbered densely
    (``compacted``: ``_compacted``'s), with nodes of its own (vertex i standing for node i), down to ``target_base``
    faces per group. Returns what ``_merged`` needs."""
    c, d, keep, standing = compacted
    V, cf = len(keep), c.faces.numpy()
    nd, arr = _nodes(kh, V, np.zeros((V, 3)), int((c.movable.numpy() != 0).sum()))
    zero = np.zeros(V, np.int32)
    u = _Units(kh, c, d, nd, (zero, np.zeros(len(cf), np.int32)), (group[keep], group[keep][cf[:, 0]]), V,
               target_base, zero)
    s, q = _scratch(kh, V), _queue(kh, V)
    for k in u.todo:  # one unit, or none when nothing is left to move
        u.launch(s, q, k)
    end, recorded, rounds = u.finish(arr)
    return {"keep": keep, "standing": standing, "arr": arr, "made": end - V,
            "recorded": keep[np.concatenate(recorded)] if recorded else np.zeros(0, np.int32), "rounds": rounds}


def _merged(arr, at, r):
    """Append a component's second-phase nodes (``_rest``'s ``r``) at node ``at``: its node i < V is the node
    standing at its vertex i (``r["standing"]``, compacted ids), node V + k becomes ``at + k``; returns the next
    free node."""
    V, n, local = len(r["keep"]), r["made"], r["arr"]
    ids = np.concatenate([r["standing"], np.arange(at, at + n, dtype=np.int32)]).astype(np.int32)
    own = slice(V, V + n)
    parent = local["parent"][own]
    arr["parent"][at:at + n] = np.where(parent >= 0, ids[np.maximum(parent, 0)], -1)
    arr["children"][at:at + n] = ids[local["children"][own]]
    arr["vertex"][at:at + n] = r["keep"][local["vertex"][own]]
    for name in ("axis", "half", "radius", "error", "nb_count"):
        arr[name][at:at + n] = local[name][own]
    below = local["parent"][:V]
    arr["parent"][r["standing"][below >= 0]] = ids[below[below >= 0]]
    return at + n


def _two_phases(kh, kp, hold, nd_arr, tiles, group, pieces, at, target_base, workers, report):
    """Every tile down to 1/REDUCE of its faces (on the full-size mesh and state ``hold`` = [m, t]), then each
    connected component's rest (``_rest``), as one pool of jobs (``run_jobs``): a component's second phase starts as
    soon as its own tiles are done, beside other components' tiles (a component with no tile at once), and the
    tiles of the component with the most work behind them start first. Its nodes follow every tile's, components in
    id order, whatever the order the jobs ran in. Returns (next free node, recorded neighbours, rounds)."""
    m, t = hold
    nd, arr = nd_arr
    tile = _Units(kh, m, t, nd, (tiles[1], tiles[0]), (tiles[1], tiles[0]), at, target_base, pieces, REDUCE)
    C = int(pieces.max(initial=-1)) + 1
    fcomp = pieces[m.faces.numpy()[:, 0]]
    forder = np.argsort(fcomp.astype(np.int16) if C < 2**15 else fcomp, kind="stable").astype(np.int32)
    fstart = np.searchsorted(fcomp[forder], np.arange(C + 1))
    movable = m.movable.numpy() != 0
    comps = np.flatnonzero(np.bincount(pieces[movable], minlength=C))
    rest = np.bincount(pieces[movable & (tiles[1] < 0)], minlength=C).astype(float)  # no tile moves these
    del fcomp, movable, m, t
    for u in tile.todo:
        rest[tile.kind[u]] += tile.moves[u] / REDUCE
    lock, needed, rest_made = threading.Lock(), [len(tile.todo) + len(comps)], [0]

    def done_with_full_size():  # once every tile is done and every component compacted, the full size goes
        with lock:
            needed[0] -= 1
            if not needed[0]:
                hold.clear()
                tile.release()

    def second(cache, a):
        if not tile.unstarted:
            cache.clear()
        fidx = forder[fstart[a]:fstart[a + 1]]
        compacted = _compacted(kh, kp, hold[0], hold[1], group, fidx[hold[0].alive.numpy()[fidx] != 0])
        done_with_full_size()
        results[a] = _rest(kh, compacted, group, target_base)
        with lock:
            rest_made[0] += results[a]["made"]

    jobs, results = tile.jobs({int(a): rest[a] for a in comps}, after=done_with_full_size), {}
    at_job = {}
    for a in comps:
        at_job[int(a)] = len(jobs)
        jobs.append(Job(functools.partial(second, a=int(a)), size=float(rest[a]), kind=int(a)))
    for k, u in enumerate(tile.todo):
        jobs[k].then.append(at_job[tile.kind[u]])
        jobs[at_job[tile.kind[u]]].waits += 1
    run_jobs(jobs, workers, lambda: report(tile.made() + rest_made[0]))
    at, recorded, rounds = tile.finish(arr, [r["standing"] for r in results.values()])
    for a in sorted(results):
        at = _merged(arr, at, results[a])
        recorded.append(results[a]["recorded"])
    return at, recorded, rounds + max((r["rounds"] for r in results.values()), default=0)


def build_greedy(positions: np.ndarray, faces: np.ndarray, normals: np.ndarray, *, component=None,
                 target_base: int = 64, keep_boundary: bool = False, workers: int | None = None,
                 progress=None, caller: str = "build_greedy") -> Hierarchy:
    """The vertex hierarchy of a triangle mesh built in sequence (module docstring): the arguments and the result
    of ``lodprt.model.hierarchy_build.build_hierarchy``, which calls it for ``method="sequential"`` (its default).
    ``progress(collapses, total)`` is called as units finish (one launch per unit: a scene of one small component
    reports once). A vertex with more than ``CAP`` (128) neighbours takes part in no collapse. Raises LodprtError
    naming the bad input, after ``caller`` (the function the user called)."""
    from lodprt.devices import load_kernels
    from lodprt.kernels import hierarchy_greedy as kh
    from lodprt.kernels import hierarchy_prepare as kp

    t0 = time.perf_counter()
    pos, work, nrm, comp = _inputs(positions, faces, normals, component, target_base, caller)
    V = len(pos)
    workers = _workers(workers)
    load_kernels("cpu", kh, kp)
    m = _mesh(kh, pos, work, keep_boundary)
    used = m.movable.numpy() != 0  # before ``prepare`` writes it
    prepared = _prepared(kh, kp, m, workers > 1)  # on its own thread while the groups and tiles are found
    group, pieces = _groups(V, work, comp)
    tiles = _tiles(pos, work, pieces, used)
    prepared()
    m.group = warp_view(group, warp().int32)  # the per-phase counters are ``_Units``' to set
    t = _state(kh, V, nrm)
    total = int((m.movable.numpy() != 0).sum())
    nd_arr = _nodes(kh, V, nrm, total)

    def report(made):
        if progress is not None:
            progress(made, total)

    if tiles is None:  # whole components, each group to target_base
        units = _Units(kh, m, t, nd_arr[0], (pieces, pieces[work[:, 0]]), (group, group[work[:, 0]]), V,
                       target_base, pieces)
        run_jobs(units.jobs(), workers, lambda: report(units.made()))
        at, recorded, rounds = units.finish(nd_arr[1])
    else:  # each tile to 1/REDUCE of its faces (its own counter), its borders waiting; then each component's rest
        hold = [m, t]
        m = t = None
        at, recorded, rounds = _two_phases(kh, kp, hold, nd_arr, tiles, group, pieces, V, target_base, workers, report)
    h = _hierarchy(kp, nd_arr[1], at, V, np.concatenate(recorded), rounds)
    h.build_seconds = time.perf_counter() - t0
    return h


def _workers(workers):
    """The threads a phase may use: ``workers``, or by default every core this process may use."""
    if workers is None:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return int(workers)


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
