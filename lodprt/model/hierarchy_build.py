"""Vertex hierarchy build (SPEC 3; thesis 3.2, figures 5-7 and 10; Hoppe 97; El-Sana & Varshney 99; tag H-R):
``build_hierarchy``. Its default, ``method="sequential"``, hands the mesh to ``lodprt.model.hierarchy_greedy`` (tag
H-G: the same collapses, costs, rules and node attributes, made one at a time); the rest of this module is the
rounds build (``method="rounds"``, and the rounds of ``"pymeshlab"``).

The rounds' steps: input checks; mesh groups (connected components, split further by ``component``); topology
(boundary, non-manifold vertices, read from the first round's one-rings) and Garland-Heckbert quadrics (summed per
vertex by the ``plane_sums`` kernel); rounds of parallel half-edge collapses ``v -> u`` (figure 5;
``lodprt.model.hierarchy_rounds``: QEM order, link condition, boundary rules, valence, fold-over (figure 6) and
sliver tests), each collapse creating the next node (creation number = node id, fine to coarse) with its normal
cone, bounding radius (figure 7) and error vector (figure 10, ``lodprt.model.hierarchy_attributes``) computed in
the round that makes it; the leaf layout. Every array is sized once (int32/float32 outputs, float64 only for the
geometry of live vertices); there is no per-vertex Python object. Details: docs/HIERARCHY.md, docs/SCALE.md.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Callable

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.model.hierarchy import Hierarchy, concat_ranges, leaf_layout
from lodprt.model.hierarchy_attributes import merge_cones
from lodprt.model.hierarchy_inputs import BOUNDARY_WEIGHT, CONE_SLACK, checked_inputs
from lodprt.model.hierarchy_levels import mesh_groups
from lodprt.launches import KernelThreads, warp_view
from lodprt.model.hierarchy_rounds import QUADRIC_ENTRIES, CollapseRounds, one_rings
from lodprt.model.meshio import referenced_mask

log = logging.getLogger(__name__)

#: the build stops after a round that made fewer collapses than this fraction of the vertices that may still
#: collapse (the tail: a round costs what the live mesh costs, for next to nothing)
MIN_ROUND = 1e-2
#: the build stops after at most this many rounds (a bound only: it stops long before, docs/HIERARCHY.md)
MAX_ROUNDS = 2000
#: the builds ``build_hierarchy(method=...)`` offers: the QEM collapses one at a time in Warp kernels, one thread
#: per mesh unit (``lodprt.model.hierarchy_greedy``, the default), rounds of parallel QEM collapses, or the same rounds
#: replaying pymeshlab's chained QEM halvings level by level (docs/HIERARCHY.md)
METHODS = ("sequential", "rounds", "pymeshlab")


def check_method(method) -> str:
    """``method`` when it is one of ``METHODS``; LodprtError naming the choices otherwise."""
    if method not in METHODS:
        raise LodprtError(f"hierarchy method {method!r}: choose one of {', '.join(METHODS)}")
    return method


def _plane_quadrics(q: np.ndarray, planes: np.ndarray, weight: np.ndarray, corners: list[np.ndarray]) -> None:
    """Add ``weight x plane plane^T`` (planes (K, 4)) to the quadrics (V, 10) of each vertex list in ``corners``,
    one entry at a time (bincount: no (K, 4, 4) temporaries)."""
    V = q.shape[0]
    for k, (r, c) in enumerate(QUADRIC_ENTRIES):
        w = weight * planes[:, r] * planes[:, c]
        for idx in corners:
            q[:, k] += np.bincount(idx, weights=w, minlength=V)


def _face_sums(q: np.ndarray, planes: np.ndarray, weight: np.ndarray, fstart, corner, threads) -> None:
    """Set the quadrics ``q`` (V, 10) to the sum of ``weight x plane plane^T`` (planes (F, 4)) over the faces at
    each vertex (``plane_sums`` on the corner CSR ``fstart``, ``corner``: the sums ``_plane_quadrics`` gives, bit for
    bit on the CPU)."""
    wp = warp()
    from lodprt.kernels import hierarchy as kh

    threads.launch(kh.plane_sums, len(q), [warp_view(fstart, wp.int64), warp_view(corner, wp.int32),
                                           warp_view(planes, wp.float64), warp_view(weight, wp.float64),
                                           warp_view(q, wp.float64)], work=fstart)


def _boundary_faces(work: np.ndarray, fstart: np.ndarray, corner: np.ndarray, a: np.ndarray, b: np.ndarray):
    """(K,) the face holding each edge ``a[i] b[i]`` of one face, found among ``a``'s corners."""
    lo, hi = fstart[a], fstart[a + 1]
    k = concat_ranges(lo, hi)
    edge = np.repeat(np.arange(len(a)), hi - lo)
    f = corner[k] // 3
    hit = (work[f] == b[edge][:, None]).any(1)
    return f[hit][np.argsort(edge[hit], kind="stable")]


def _topology(positions: np.ndarray, work: np.ndarray, threads: KernelThreads):
    """QEM quadrics (V, 10) (Garland-Heckbert: sum over incident faces of area x p p^T, p = (n, -n.x), plus
    ``BOUNDARY_WEIGHT`` x |e|^2 x the plane through each boundary edge perpendicular to its face), boundary (V,)
    bool, frozen (V,) bool: vertices on a non-manifold edge (more than two faces) or at a non-manifold boundary
    vertex (bow tie), which take part in no collapse; and the one-rings of ``work`` (``one_rings``: the edges and
    the faces on each), which the first round uses again."""
    V = len(positions)
    p = positions
    q = np.zeros((V, 10))
    boundary = np.zeros(V, bool)
    frozen = np.zeros(V, bool)
    if not len(work):
        return q, boundary, frozen, None
    p0 = p[work[:, 0]]
    cr = np.cross(p[work[:, 1]] - p0, p[work[:, 2]] - p0)
    dbl = np.linalg.norm(cr, axis=1)
    n = np.divide(cr, dbl[:, None], out=np.zeros_like(cr), where=dbl[:, None] > 0)
    del cr
    plane = np.concatenate([n, -(n * p0).sum(1, keepdims=True)], axis=1)
    del p0
    rings = one_rings(work, np.bincount(work.ravel(), minlength=V), threads)
    fstart, corner, dst, count, start, end = rings
    _face_sums(q, plane, 0.5 * dbl, fstart, corner, threads)
    del plane, dbl
    # undirected edges: the faces on each (the one-rings' counts), one face of each
    deg = end - start[:-1]
    src = np.repeat(np.arange(V, dtype=np.int64), deg)
    at = concat_ranges(start[:-1], end)
    nb, ecount = dst[at], count[at]
    del at
    bcount = np.bincount(src[ecount == 1], minlength=V)
    boundary = bcount > 0
    frozen[src[ecount > 2]] = True  # non-manifold edge (both ends: the rings are symmetric)
    frozen |= (bcount != 0) & (bcount != 2)  # non-manifold boundary vertex (bow tie)
    once = (ecount == 1) & (nb > src)  # each boundary edge a < b once, ordered by (a, b)
    if once.any():
        a, b = src[once], nb[once].astype(np.int64)
        d = p[b] - p[a]
        m = np.cross(d, n[_boundary_faces(work, fstart, corner, a, b)])
        lm = np.linalg.norm(m, axis=1)
        m = np.divide(m, lm[:, None], out=np.zeros_like(m), where=lm[:, None] > 0)
        bp = np.concatenate([m, -(m * p[a]).sum(1, keepdims=True)], axis=1)
        _plane_quadrics(q, bp, BOUNDARY_WEIGHT * (d * d).sum(1), [a, b])
    if frozen.any():
        log.info("hierarchy: %d vertices on non-manifold edges or vertices stay uncollapsed", int(frozen.sum()))
    return q, boundary, frozen, rings


class _Nodes:
    """The hierarchy arrays, sized once for every possible collapse, filled round by round (H-R)."""

    def __init__(self, V: int, normals: np.ndarray, most: int):
        N = V + most
        self.V, self.count = V, V
        self.parent = np.full(N, -1, np.int32)
        self.children = np.full((N, 2), -1, np.int32)
        self.vertex = np.arange(N, dtype=np.int32)
        self.axis = np.zeros((N, 3), np.float32)
        self.axis[:V] = normals
        self.half = np.zeros(N, np.float32)
        self.radius = np.zeros(N, np.float32)
        self.error = np.zeros((N, 3), np.float32)
        self.nb_count = np.zeros(N, np.int64)
        self.nb_chunks: list[np.ndarray] = []
        self.depth = 0

    def add(self, st: CollapseRounds, cur: dict, v, u, nb_count, nb, error) -> None:
        """Record the round's collapses ``v -> u`` (local ids, made in this order): nodes, cones and radii
        (figure 7, merged from the float64 cones standing at u and v), error vectors ``error`` (figure 10)."""
        k = self.count + np.arange(len(v))
        at = slice(self.count, self.count + len(v))  # the nodes k, consecutive
        cu, cv = st.node[u], st.node[v]
        self.parent[cu] = k
        self.parent[cv] = k
        self.children[at, 0] = cu
        self.children[at, 1] = cv
        self.vertex[at] = st.gid[u]
        st.node[u] = k
        axis, half = merge_cones(cur["axis"][u], cur["half"][u], cur["axis"][v], cur["half"][v])
        pu, pv = st.pos[u], st.pos[v]
        radius = np.maximum(cur["radius"][u], cur["radius"][v] + np.linalg.norm(pv - pu, axis=1))
        height = 1 + np.maximum(cur["height"][u], cur["height"][v])
        cur["axis"][u], cur["half"][u], cur["radius"][u], cur["height"][u] = axis, half, radius, height
        self.axis[at] = axis
        self.half[at] = np.minimum(half + CONE_SLACK, math.pi)
        self.radius[at] = radius * (1 + 1e-6)  # float32 rounding must not cut a leaf off
        self.error[at] = error
        self.nb_count[at] = nb_count
        self.nb_chunks.append(st.gid[nb])
        self.depth = max(self.depth, int(height.max(initial=0)))
        self.count += len(v)

    def hierarchy(self, levels: int) -> Hierarchy:
        """The ``Hierarchy`` of the collapses made; the arrays are shrunk in place to the nodes made (no copy)."""
        N, V = self.count, self.V
        offsets = np.zeros(N + 1, np.int64)
        np.cumsum(self.nb_count[:N], out=offsets[1:])
        self.nb_count = None
        neighbours = np.concatenate(self.nb_chunks) if self.nb_chunks else np.zeros(0, np.int32)
        self.nb_chunks = []
        arrays = {"parent": self.parent, "children": self.children, "vertex": self.vertex, "cone_axis": self.axis,
                  "cone_half_angle": self.half, "radius": self.radius, "error_vector": self.error}
        for a in arrays.values():
            a.resize((N,) + a.shape[1:], refcheck=False)  # sized once for every possible collapse: trim the rest
        leaf_order, leaf_range = leaf_layout(self.parent, self.children, V)
        h = Hierarchy(
            num_vertices=V, **arrays,
            creation=np.arange(N, dtype=np.int32),  # El-Sana & Varshney numbering: consecutive in build order
            neighbour_offsets=offsets, neighbours=neighbours.astype(np.int32, copy=False),
            leaf_order=leaf_order, leaf_range=leaf_range, levels=levels,
        )
        h.remember_depth(self.depth)
        return h


def _next_phase(st: CollapseRounds, phases: int) -> bool:
    """Move a seeded build to its next phase (after the last level: the plain rounds, ``phase`` None); False when
    the plain rounds are done."""
    if st.phase is None:
        return False
    st.phase = st.phase + 1 if st.phase < phases else None
    return True


def _rounds(st: CollapseRounds, nodes: _Nodes, normals, target_base, progress, total, phases: int = 0) -> int:
    """Rounds of collapses (rule H-R) until every group is at its base size, a round makes no collapse (then no
    movable vertex has a legal move: ``CollapseRounds.select``) or only the tail is left (``MIN_ROUND``); returns
    the rounds. A seeded build (``phases`` levels, ``CollapseRounds.seed``) runs these rounds once per level, the
    vertices removed by that level collapsing into its survivors, then once more unrestricted."""
    cur = {"axis": normals[st.gid].copy(), "half": np.zeros(st.n), "radius": np.zeros(st.n),
           "height": np.zeros(st.n, np.int32)}
    rounds = 0
    size = st.n
    st.phase = 1 if phases else None
    for _ in range(MAX_ROUNDS):
        st.finish_groups(target_base)
        movable = np.count_nonzero(st.due())
        if not movable:
            if _next_phase(st, phases):
                continue
            break
        fcount = st.corner_counts()
        if st.n > 64 and np.count_nonzero(fcount == 0) * 2 > size:
            used = fcount > 0  # half of the vertices have gone: the rounds cost what the live mesh costs
            cur = st.compact(cur, used)
            fcount = fcount[used]
            size = st.n
        dst, count, start, end = st.adjacency(fcount)
        v, u = st.select(dst, count, start, end)
        if not len(v):
            if _next_phase(st, phases):
                continue
            break
        nb_count = end[v] - start[v]
        nb = dst[concat_ranges(start[v], end[v])]  # v's neighbours before the collapse, sorted
        del dst, count, start, end
        error = st.errors(v, u)
        st.apply(v, u)
        nodes.add(st, cur, v, u, nb_count, nb, error)
        rounds += 1
        # the tail: a whole round over the live mesh for next to nothing
        if len(v) < MIN_ROUND * movable and not _next_phase(st, phases):
            break
        log.debug("hierarchy round %d: %d collapses, %d faces left", rounds, len(v), len(st.faces))
        if progress is not None:
            progress(nodes.count - nodes.V, total)
    return rounds


def _build(positions, work, normals, group, seed, phases: int, threads: KernelThreads, *, keep_boundary: bool,
           split: bool, target_base: int, progress) -> tuple[int, _Nodes]:
    """The topology, then the rounds (``_rounds``) on ``threads``: the rounds made and the nodes."""
    V = len(positions)
    quadric, boundary, frozen, rings = _topology(positions, work, threads)
    movable = referenced_mask(V, work) & ~frozen & ~(boundary if keep_boundary else np.zeros(V, bool))
    total = int(movable.sum())
    nodes = _Nodes(V, normals, total)
    st = CollapseRounds(np.arange(V, dtype=np.int32), positions, quadric, boundary, frozen, movable, group,
                        np.ascontiguousarray(work), split=split, threads=threads)
    del quadric, boundary, frozen, movable, group
    if rings is not None:
        st.prime(rings)  # the topology's one-rings are the first round's
        del rings
    if seed is not None:
        st.seed(seed)
        del seed
    return _rounds(st, nodes, normals, target_base, progress, total, phases), nodes


def build_hierarchy(
    positions: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    *,
    component: np.ndarray | None = None,
    target_base: int = 64,
    keep_boundary: bool = False,
    progress: Callable[[int, int], None] | None = None,
    method: str = "sequential",
    workers: int | None = None,
) -> Hierarchy:
    """Build the binary vertex hierarchy of a triangle mesh (module docstring, docs/HIERARCHY.md).

    positions (V, 3) float, faces (F, 3) int, normals (V, 3) unit vertex normals (the leaves' cones);
    component (V,) int: vertices of different components never collapse into each other (e.g. ``Scene.object_id``:
    the floor and each object); connected components are always built independently (each to its own base).
    target_base: a group stops collapsing once it has at most this many faces (the base mesh is larger where
    collapses are refused); keep_boundary: boundary vertices never collapse (the floor keeps its rim); by default
    they collapse along boundary edges, and the boundary planes of their quadrics keep straight outlines and
    their corners (docs/HIERARCHY.md);
    ``progress(done, total)`` reports collapses made against the number of vertices that may collapse. Open
    boundaries, several components, non-manifold edges, duplicated vertices and faces with a repeated corner are
    accepted; unreferenced vertices become isolated roots. Raises LodprtError naming the bad input otherwise.
    ``method``: ``"sequential"`` (the default) makes the collapses one at a time, cheapest class first, in Warp
    kernels on ``workers`` threads, one mesh unit each (``lodprt.model.hierarchy_greedy.build_greedy``: the same
    costs, legality rules and node attributes, about 3 evaluations per collapse); ``"rounds"`` makes them in rounds
    of parallel collapses ordered by the rounds' own QEM costs; ``"pymeshlab"`` replays pymeshlab's chained QEM
    halvings (``lodprt.model.hierarchy_pymeshlab``, on ``workers`` processes: default every core) level by level
    with the same rounds, collapses and node attributes (docs/HIERARCHY.md).
    The round kernels, too, run on ``workers`` threads (default every core; ``KernelThreads``): each build gives the
    same hierarchy, bit for bit, on any number.
    """
    t0 = time.perf_counter()
    check_method(method)
    if method == "sequential":
        from lodprt.model.hierarchy_greedy import build_greedy

        hier = build_greedy(positions, faces, normals, component=component, target_base=target_base,
                            keep_boundary=keep_boundary, workers=workers, progress=progress,
                            caller="build_hierarchy")
        log.info("hierarchy (sequential): %d vertices, %d nodes, %d roots, depth %d, %.1f s", hier.num_vertices,
                 hier.num_nodes, len(hier.roots), hier.depth, hier.build_seconds)
        return hier
    positions, faces, normals, comp = checked_inputs("build_hierarchy", positions, faces, normals, component,
                                                        target_base)
    V = len(positions)
    # faces with a repeated corner carry no area or orientation: they take no part in the collapses
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    work = faces[good] if not good.all() else faces
    del good
    group = mesh_groups(V, work, comp).astype(np.int32)
    seed, phases = None, 0
    if method == "pymeshlab":  # before the quadrics: pymeshlab's peak and the rounds' do not add up
        from lodprt.model.hierarchy_pymeshlab import removal_levels

        seed, phases = removal_levels(positions, work, group, target_base=int(target_base),
                                      keep_boundary=keep_boundary, workers=workers)
    threads = KernelThreads(workers)
    try:
        levels, nodes = _build(positions, work, normals, group, seed, phases, threads, keep_boundary=keep_boundary,
                               split=component is not None, target_base=int(target_base), progress=progress)
    finally:
        threads.close()
    hier = nodes.hierarchy(levels)
    hier.build_seconds = time.perf_counter() - t0
    hier.method = method
    log.info("hierarchy (%s): %d vertices, %d nodes, %d roots, depth %d, %d rounds (%d pymeshlab levels), %.1f s",
             method, V, hier.num_nodes, len(hier.roots), hier.depth, levels, phases, hier.build_seconds)
    return hier
