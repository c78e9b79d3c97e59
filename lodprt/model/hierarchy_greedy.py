"""Vertex hierarchy built in sequence (SPEC 3; thesis 3.2; tag H-G): ``build_greedy``.

The same kind of hierarchy as ``lodprt.model.hierarchy_build`` (legal half-edge collapses ``v -> u`` in creation
order, the same costs, legality rules, cones, radii, error vectors and recorded neighbours), made by one Warp
thread per part of the mesh instead of rounds of parallel passes: a collapse is made on the mesh as it stands and
only the survivor's ring is evaluated again, so the build evaluates about 3 moves per collapse where the rounds
evaluate every live vertex every round (docs/HIERARCHY.md, "The sequential build"). Opt-in for now:
``bake(scene, path, tree=build_greedy(...))``.

Parts are whole connected components (each holding its groups: split further by ``component``), at most ``PARTS``
of them, balanced by their movable vertices; the parts run at once on up to ``workers`` threads (a CPU launch releases the GIL) and share no
vertex, face or node, so the hierarchy is the same, bit for bit, on any number of threads.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.launches import warp_view
from lodprt.model.hierarchy import Hierarchy, leaf_layout
from lodprt.model.hierarchy_build import BOUNDARY_WEIGHT, CONE_SLACK
from lodprt.model.hierarchy_levels import mesh_groups
from lodprt.model.hierarchy_rounds import EDGE_WEIGHT, FOLD_COS, MAX_VALENCE, SLIVER

#: the groups are dealt into this many parts (fixed, so that the node order does not depend on the threads)
PARTS = 2
#: vertex ids are visited in blocks of this many, the blocks in a fixed permuted order (each block's memory is read
#: together; no sweep crosses the mesh in id order, which would chain the El-Sana & Varshney dependencies)
BLOCK = 1024
#: a prime far from any block count (the stride of the blocks' permutation)
STRIDE = 40503


def _inputs(positions, faces, normals, component, target_base):
    """float64 positions, int32 faces without repeated corners, unit float64 normals, int32 groups (moves stay
    within one) and connected components (parts are made of them)."""
    pos = np.ascontiguousarray(positions, np.float64)
    nrm = np.asarray(normals, np.float64)
    f = np.asarray(faces)
    for name, a, shape in (("positions", pos, 3), ("normals", nrm, 3), ("faces", f, 3)):
        if a.ndim != 2 or a.shape[1] != shape:
            raise LodprtError(f"build_greedy: {name} must be an (N, 3) array, got {a.shape}")
    V = len(pos)
    if nrm.shape != pos.shape or not np.issubdtype(f.dtype, np.integer):
        raise LodprtError(f"build_greedy: normals {nrm.shape} must match positions {pos.shape}, and faces be "
                          f"integers (got {f.dtype})")
    if len(f) and (f.min() < 0 or f.max() >= V):
        raise LodprtError(f"build_greedy: faces index vertices {f.min()}..{f.max()} outside 0..{V - 1}")
    if not (np.isfinite(pos).all() and np.isfinite(nrm).all()):
        raise LodprtError("build_greedy: non-finite positions or normals")
    if 2 * V >= 2**31 - 1 or int(target_base) < 1:
        raise LodprtError(f"build_greedy: {V} vertices (at most 2^30) and target_base {target_base} (at least 1)")
    if component is not None and (np.shape(component) != (V,) or not np.issubdtype(np.asarray(component).dtype,
                                                                                   np.integer)):
        raise LodprtError(f"build_greedy: component must be a (V,) = ({V},) integer array")
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(length > 0, nrm / np.where(length > 0, length, 1), [0.0, 1.0, 0.0])
    f = f.astype(np.int32)
    f = np.ascontiguousarray(f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])])
    pieces = mesh_groups(V, f).astype(np.int32)
    group = pieces if component is None else mesh_groups(V, f, np.asarray(component)).astype(np.int32)
    return pos, f, nrm, group, pieces


def _mesh(kh, pos, faces, group, keep_boundary):
    """The kernels' Mesh, its corner lists, quadrics and flags made by ``prepare``."""
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
    m.group = warp_view(group, wp.int32)
    G = int(group.max()) + 1 if V else 1
    m.face_group = warp_view(group[faces[:, 0]], wp.int32)
    m.group_faces = warp_view(np.bincount(group[faces[:, 0]], minlength=G).astype(np.int32), wp.int32)
    m.quadric = warp_view(np.zeros((V, 10)), wp.float64)
    s = _scratch(kh, V)
    wp.launch(kh.prepare, dim=1, inputs=[m, s, BOUNDARY_WEIGHT], device="cpu")
    return m, s


def _scratch(kh, V):
    wp = warp()
    s = kh.Scratch()
    s.seen, s.slot = warp_view(np.full(V, -1, np.int32), wp.int32), warp_view(np.zeros(V, np.int32), wp.int32)
    s.seen2, s.slot2 = warp_view(np.full(V, -1, np.int32), wp.int32), warp_view(np.zeros(V, np.int32), wp.int32)
    s.ring, s.rcnt = warp_view(np.zeros(2 * kh.CAP + 2, np.int32), wp.int32), warp_view(
        np.zeros(2 * kh.CAP + 2, np.int32), wp.int32)
    s.cost = warp_view(np.zeros(kh.CAP + 2), wp.float64)
    return s


def _queue(kh, V, nb_base):
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
    ctr = np.zeros(16, np.int64)
    ctr[9], ctr[10], ctr[2] = kh.CLASSES, 2 * kh.CLASSES, nb_base  # both parities empty; neighbours from nb_base
    q.ctr = warp_view(ctr, wp.int64)
    return q


def _state(kh, V, normals):
    wp = warp()
    t = kh.State()
    for name in ("version", "target", "evalt", "modt"):
        setattr(t, name, warp_view(np.zeros(V, np.int32), wp.int32))
    t.pending, t.dead, t.checked = (warp_view(np.zeros(V, np.uint8), wp.uint8) for _ in range(3))
    t.lastcost, t.half, t.radius = (warp_view(np.zeros(V), wp.float64) for _ in range(3))
    for name in ("used", "wait_v", "wait_vr", "wait_u", "wait_ur"):
        setattr(t, name, warp_view(np.full(V, -1, np.int32), wp.int32))
    t.node_of = warp_view(np.arange(V, dtype=np.int32), wp.int32)
    t.axis = warp_view(normals.copy(), wp.vec3d)
    return t


def _nodes(kh, V, normals, most, neighbours):
    """The node arrays sized for ``most`` collapses and ``neighbours`` recorded neighbours (numpy, Warp views)."""
    wp = warp()
    N = V + most
    arr = {"parent": np.full(N, -1, np.int32), "children": np.full((N, 2), -1, np.int32),
           "vertex": np.arange(N, dtype=np.int32), "axis": np.zeros((N, 3)), "half": np.zeros(N),
           "radius": np.zeros(N), "error": np.zeros((N, 3)), "nb_count": np.zeros(N, np.int32),
           "nbs": np.zeros(neighbours, np.int32)}
    arr["axis"][:V] = normals
    nd = kh.Nodes()
    types = {"axis": wp.vec3d, "error": wp.vec3d, "half": wp.float64, "radius": wp.float64}
    for name, a in arr.items():
        setattr(nd, name, warp_view(a, types.get(name, wp.int32)))
    return nd, arr


def _parts(pieces, movable, faces):
    """(V,) part of each vertex (whole connected components, the largest first onto the lightest part: parts share
    no face), the movable vertices and the neighbour entries each part may record at most (its valences capped at
    MAX_VALENCE at collapse time)."""
    G = int(pieces.max()) + 1 if len(pieces) else 1
    size = np.bincount(pieces[movable], minlength=G)
    owner = np.zeros(G, np.int32)
    load = np.zeros(PARTS, np.int64)
    for g in np.argsort(-size, kind="stable"):
        owner[g] = int(np.argmin(load))
        load[owner[g]] += size[g]
    part = owner[pieces]
    moves = np.bincount(part[movable], minlength=PARTS)
    ring_entries = np.bincount(part[faces.ravel()], minlength=PARTS) * 2  # each corner adds two ring entries
    return part, moves, moves * MAX_VALENCE + ring_entries


def _compact(arr, V, node_base, made):
    """Move each part's nodes down to follow the earlier parts' (creation = node id) and fix the references."""
    at = V
    for lo, n in zip(node_base, made):
        shift = int(lo) - at
        if shift:
            for name in ("parent", "children"):
                a = arr[name]
                a[a >= lo] -= shift
            for a in arr.values():
                if a is not arr["nbs"]:
                    a[at:at + n] = a[lo:lo + n]
        at += n
    return at


def build_greedy(positions: np.ndarray, faces: np.ndarray, normals: np.ndarray, *, component=None,
                 target_base: int = 64, keep_boundary: bool = False, workers: int | None = None) -> Hierarchy:
    """The vertex hierarchy of a triangle mesh built in sequence (module docstring): the arguments and the result
    of ``lodprt.model.hierarchy_build.build_hierarchy`` (no progress reports: one launch per part). A vertex with
    more than ``CAP`` (128) neighbours takes part in no collapse. Raises LodprtError naming the bad input."""
    from lodprt.devices import load_kernels
    from lodprt.kernels import hierarchy_greedy as kh

    t0 = time.perf_counter()
    wp = warp()
    pos, work, nrm, group, pieces = _inputs(positions, faces, normals, component, target_base)
    V = len(pos)
    load_kernels("cpu", kh)
    m, s0 = _mesh(kh, pos, work, group, keep_boundary)
    part, moves, entries = _parts(pieces, m.movable.numpy().astype(bool), work)
    node_base = V + np.concatenate([[0], np.cumsum(moves)[:-1]]).astype(np.int64)
    nb_base = np.concatenate([[0], np.cumsum(entries)[:-1]]).astype(np.int64)
    t = _state(kh, V, nrm)
    nd, arr = _nodes(kh, V, nrm, int(moves.sum()), int(entries.sum()))
    part_wp = warp_view(part.astype(np.int32), wp.int32)
    launches = []
    for p in range(PARTS):
        s = s0 if p == 0 else _scratch(kh, 0)
        if p:  # seen / slot are per vertex and the parts share no vertex: one set for all
            s.seen, s.slot, s.seen2, s.slot2 = s0.seen, s0.slot, s0.seen2, s0.slot2
        q = _queue(kh, V, nb_base[p])
        launches.append((q, [m, s, q, t, nd, part_wp, p, int(node_base[p]), int(target_base), EDGE_WEIGHT,
                             FOLD_COS, SLIVER, MAX_VALENCE]))
    _run(wp, kh.greedy_build, [a for _, a in launches], workers)
    ctrs = [q.ctr.numpy() for q, _ in launches]
    if any(c[5] for c in ctrs):
        raise LodprtError("build_greedy: neighbour space exhausted (an internal sizing error)")
    made = [int(c[1]) for c in ctrs]
    N = _compact(arr, V, node_base, made)
    nbs = np.concatenate([arr["nbs"][nb_base[p]:int(ctrs[p][2])] for p in range(PARTS)])
    return _hierarchy(arr, N, V, nbs, max(int(c[8]) for c in ctrs), time.perf_counter() - t0)


def _run(wp, kernel, inputs, workers):
    """One launch per part, up to ``workers`` at once (default: one thread per part)."""
    at_once = len(inputs) if workers is None else max(1, min(int(workers), len(inputs)))

    def go(batch):
        for args in batch:
            wp.launch(kernel, dim=1, inputs=args, device="cpu")

    batches = [inputs[i::at_once] for i in range(at_once)]
    threads = [threading.Thread(target=go, args=(b,)) for b in batches[1:]]
    for th in threads:
        th.start()
    go(batches[0])
    for th in threads:
        th.join()


def _hierarchy(arr, N, V, nbs, rounds, seconds) -> Hierarchy:
    offsets = np.zeros(N + 1, np.int64)
    np.cumsum(arr["nb_count"][:N], out=offsets[1:])
    parent, children = arr["parent"][:N], arr["children"][:N]
    half = np.minimum(arr["half"][:N] + CONE_SLACK, np.pi).astype(np.float32)
    half[:V] = 0
    leaf_order, leaf_range = leaf_layout(parent, children, V)
    h = Hierarchy(num_vertices=V, parent=parent, children=children, vertex=arr["vertex"][:N],
                  creation=np.arange(N, dtype=np.int32), cone_axis=arr["axis"][:N].astype(np.float32),
                  cone_half_angle=half, radius=(arr["radius"][:N] * (1 + 1e-6)).astype(np.float32),
                  error_vector=arr["error"][:N].astype(np.float32), neighbour_offsets=offsets,
                  neighbours=nbs.astype(np.int32, copy=False), leaf_order=leaf_order, leaf_range=leaf_range,
                  levels=rounds, build_seconds=seconds, method="greedy")
    return h
