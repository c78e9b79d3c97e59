"""Vertex hierarchy data (SPEC 3; thesis 3.2; Hoppe 97; El-Sana & Varshney 99): the ``Hierarchy`` arrays and the
read-only helpers every stage shares (node heights, active ancestors of a front, faces mapped through a front,
the dependency invariant of a legal cut).

Leaves are nodes ``0..V-1`` (node ``i`` is original vertex ``i``); each half-edge collapse ``v -> u`` adds the next
node, children ``(node(u), node(v))``, standing at ``u``; ``creation[k] = k`` (fine to coarse). Built by
``lodprt.model.hierarchy_build``; the view cut is ``lodprt.runtime.view_cut``. Definitions and the El-Sana &
Varshney rules: docs/HIERARCHY.md.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from lodprt.errors import LodprtError

@dataclasses.dataclass
class Hierarchy:
    """Binary vertex hierarchy over V original vertices and N nodes (docs/HIERARCHY.md for the definitions).

    parent (N,) int32, -1 for roots;  children (N, 2) int32, -1 for leaves (child 0 stands at the same vertex as
    the node: the survivor; child 1 at the collapsed vertex);  vertex (N,) int32 original vertex of each node;
    creation (N,) int32 El-Sana & Varshney creation number (= node id, fine to coarse);
    cone_axis (N, 3) float32 unit;  cone_half_angle (N,) float32 radians in [0, pi] (every leaf normal below is
    inside);  radius (N,) float32 (sphere at the node's position holding every leaf position below);
    error_vector (N, 3) float32 ``p - p'``: for the internal node a collapse ``v -> u`` created, the collapsed
    vertex ``p`` (position of ``v``) minus its closest point ``p'`` on the faces around ``u`` right after the
    collapse; zero for leaves;  neighbour_offsets (N+1,) int64 and neighbours (M,) int32 *original vertex ids*:
    for an internal node, the neighbours of the collapsed vertex ``v`` just before its collapse (``u`` included);
    empty for leaves;  leaf_order (V,) int32 leaves in depth-first order and leaf_range (N, 2) int64 so that the
    leaves under node ``k`` are ``leaf_order[leaf_range[k, 0]:leaf_range[k, 1]]``.
    """

    num_vertices: int
    parent: np.ndarray
    children: np.ndarray
    vertex: np.ndarray
    creation: np.ndarray
    cone_axis: np.ndarray
    cone_half_angle: np.ndarray
    radius: np.ndarray
    error_vector: np.ndarray
    neighbour_offsets: np.ndarray
    neighbours: np.ndarray
    leaf_order: np.ndarray
    leaf_range: np.ndarray
    levels: int = 0
    build_seconds: float = 0.0
    method: str = "rounds"  # the build that made it (``hierarchy_build.METHODS``)

    ARRAYS = (
        "parent",
        "children",
        "vertex",
        "creation",
        "cone_axis",
        "cone_half_angle",
        "radius",
        "error_vector",
        "neighbour_offsets",
        "neighbours",
        "leaf_order",
        "leaf_range",
    )
    DTYPES = {
        "parent": np.int32,
        "children": np.int32,
        "vertex": np.int32,
        "creation": np.int32,
        "cone_axis": np.float32,
        "cone_half_angle": np.float32,
        "radius": np.float32,
        "error_vector": np.float32,
        "neighbour_offsets": np.int64,
        "neighbours": np.int32,
        "leaf_order": np.int32,
        "leaf_range": np.int64,
    }

    @property
    def num_nodes(self) -> int:
        return len(self.parent)

    @property
    def roots(self) -> np.ndarray:
        """(R,) int32 nodes without a parent: the base mesh's vertices and the isolated (unreferenced) ones."""
        return np.flatnonzero(self.parent < 0).astype(np.int32)

    @property
    def depth(self) -> int:
        """Longest root-to-leaf path, in edges (0 when nothing collapsed)."""
        if "_depth" not in self.__dict__:
            self.__dict__["_depth"] = int(node_heights(self).max(initial=0))
        return self.__dict__["_depth"]

    def remember_depth(self, depth: int) -> None:
        """Record the depth already known (the build computes every node's height), so ``depth`` needs no pass
        over the nodes."""
        self.__dict__["_depth"] = int(depth)

    def collapsed_neighbours(self, node: int) -> np.ndarray:
        """Original ids of the collapsed vertex's neighbours just before the collapse that created ``node``."""
        return self.neighbours[self.neighbour_offsets[node] : self.neighbour_offsets[node + 1]]

    def leaves(self, node: int) -> np.ndarray:
        """Original vertices (= leaf nodes) below ``node``, ``node`` itself for a leaf."""
        lo, hi = self.leaf_range[node]
        return self.leaf_order[lo:hi]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The persistent arrays (``ARRAYS``, dtypes ``DTYPES``); ``from_arrays`` restores them bit for bit."""
        return {name: getattr(self, name) for name in self.ARRAYS}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], **attrs) -> "Hierarchy":
        """Rebuild from ``to_arrays``' dict (``leaf_order``/``leaf_range`` are recomputed when absent)."""
        need = [n for n in cls.ARRAYS if n not in ("leaf_order", "leaf_range")]
        missing = [n for n in need if n not in arrays]
        if missing:
            raise LodprtError(f"hierarchy arrays missing: {', '.join(missing)}")
        d = {n: np.asarray(arrays[n]) for n in cls.ARRAYS if n in arrays}
        bad = [f"{n} is {d[n].dtype}, not {np.dtype(t)}" for n, t in cls.DTYPES.items() if n in d and d[n].dtype != t]
        if bad:
            raise LodprtError(f"hierarchy arrays of the wrong type: {'; '.join(bad)}")
        N = len(d["parent"])
        shapes = {"children": (N, 2), "vertex": (N,), "creation": (N,), "cone_axis": (N, 3), "cone_half_angle": (N,),
                  "radius": (N,), "error_vector": (N, 3), "neighbour_offsets": (N + 1,)}
        bad = [f"{n} {d[n].shape} (expected {s})" for n, s in shapes.items() if d[n].shape != s]
        if bad:
            raise LodprtError(f"hierarchy arrays of the wrong shape: {'; '.join(bad)}")
        broken = broken_link(d["parent"], d["children"], d["creation"])
        if broken is not None:
            raise LodprtError(f"hierarchy arrays inconsistent: {broken}")
        num_vertices = int((d["children"][:, 0] < 0).sum())
        if "leaf_order" not in d or "leaf_range" not in d:
            d["leaf_order"], d["leaf_range"] = leaf_layout(d["parent"], d["children"], num_vertices)
        return cls(num_vertices=num_vertices, **d, **attrs)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.to_arrays().values()))


def broken_link(parent: np.ndarray, children: np.ndarray, creation: np.ndarray, chunk: int = 1 << 20) -> str | None:
    """None when every node with a parent is one of that parent's two children and was created before it (the
    order the cut's dependency rules read), else a description of the first node that is not. Checked in chunks of
    ``chunk`` nodes (a bounded temporary on big hierarchies)."""
    N = len(parent)
    for lo in range(0, N, chunk):
        p = parent[lo:lo + chunk]
        c = lo + np.flatnonzero(p >= 0)
        q = p[c - lo].astype(np.int64)
        if len(q) and (q.max() >= N):
            k = int(c[np.argmax(q >= N)])
            return f"node {k} has parent {int(parent[k])}, past the {N} nodes"
        bad = ((children[q, 0] != c) & (children[q, 1] != c)) | (creation[q] <= creation[c])
        if bad.any():
            k = int(c[np.argmax(bad)])
            return (f"node {k} has parent {int(parent[k])}, whose children are {children[parent[k]].tolist()} "
                    f"(creation {int(creation[k])} and {int(creation[parent[k]])})")
    return None


def depth_levels(parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes grouped by their distance from their root: (N,) int64 node ids in order of depth (roots first, stable
    within a depth) and (D + 2,) int64 bounds, the nodes at depth ``d`` being ``order[bounds[d]:bounds[d + 1]]``.

    Vectorised list ranking (pointer jumping over ``parent``: log2(depth) passes), then a counting sort."""
    parent = np.asarray(parent)
    N = len(parent)
    depth = (parent >= 0).astype(np.int64)
    up = parent.astype(np.int64)
    while True:
        go = np.flatnonzero(up >= 0)
        if not len(go):
            break
        nxt = up[go]
        depth[go] += depth[nxt]  # right-hand sides are read before the writes: one synchronous jump
        up[go] = up[nxt]
    order = np.argsort(depth, kind="stable")
    bounds = np.searchsorted(depth[order], np.arange(int(depth.max(initial=0)) + 2))
    return order, bounds


def node_heights(h: Hierarchy) -> np.ndarray:
    """(N,) int32 height of every node: 0 for leaves, 1 + the higher child's height above (vectorised, deepest
    nodes first)."""
    return _heights(h.parent, h.children)


def _heights(parent, children) -> np.ndarray:
    out = np.zeros(len(parent), np.int32)
    order, bounds = depth_levels(parent)
    for lo, hi in zip(bounds[-2::-1], bounds[:0:-1]):
        k = order[lo:hi]
        k = k[children[k, 0] >= 0]
        out[k] = 1 + np.maximum(out[children[k, 0]], out[children[k, 1]])
    return out


def leaf_layout(parent, children, V) -> tuple[np.ndarray, np.ndarray]:
    """Leaves (V,) int32 in depth-first order (child 0 first, roots in id order) and each node's [lo, hi) range
    (N, 2) int64 into it.

    parent (N,), children (N, 2) as in ``Hierarchy``, V the number of leaves; the leaves under node ``k`` are
    ``order[range[k, 0]:range[k, 1]]``, so a subtree's leaves are one slice. Vectorised: leaf counts bottom-up and
    range starts top-down, one depth at a time (``depth_levels``)."""
    parent = np.asarray(parent)
    children = np.asarray(children)
    N = len(parent)
    order, bounds = depth_levels(parent)
    count = np.zeros(N, np.int64)
    count[children[:, 0] < 0] = 1
    for lo, hi in zip(bounds[-2::-1], bounds[:0:-1]):  # deepest first
        k = order[lo:hi]
        k = k[children[k, 0] >= 0]
        count[k] = count[children[k, 0]] + count[children[k, 1]]
    rng = np.zeros((N, 2), np.int64)
    roots = order[bounds[0] : bounds[1]]  # stable sort: roots in id order
    rng[roots, 0] = np.cumsum(count[roots]) - count[roots]
    for lo, hi in zip(bounds[:-2], bounds[1:-1]):  # shallowest first
        k = order[lo:hi]
        k = k[children[k, 0] >= 0]
        c0, c1 = children[k, 0], children[k, 1]
        rng[c0, 0] = rng[k, 0]
        rng[c1, 0] = rng[k, 0] + count[c0]
    rng[:, 1] = rng[:, 0] + count
    leaf = np.flatnonzero(children[:, 0] < 0)
    out = np.zeros(V, np.int32)
    out[rng[leaf, 0]] = leaf
    return out, rng


def active_ancestors(h: Hierarchy, active: np.ndarray) -> np.ndarray:
    """(V,) int32 the active ancestor-or-self of each original vertex, by vectorised pointer jumping over the
    parent array (log2(depth) passes over the N nodes).

    Raises LodprtError when ``active`` (N,) bool is not a front (a vertex with no, or two, active ancestors).
    """
    N, V = h.num_nodes, h.num_vertices
    active = np.asarray(active, bool)
    if active.shape != (N,):
        raise LodprtError(f"not a valid cut: active must be ({N},) bool, got {active.shape}")
    par = np.where(h.parent >= 0, h.parent, N).astype(np.int64)
    # jump[k]: k itself when active, else the next node up; N is a sentinel above every root
    jump = np.append(np.where(active, np.arange(N), par), N)
    while True:
        nxt = jump[jump]
        if np.array_equal(nxt, jump):
            break
        jump = nxt
    anc = jump[:V]
    if (anc == N).any():
        bad = int(np.flatnonzero(anc == N)[0])
        raise LodprtError(f"not a valid cut: vertex {bad} has no active ancestor")
    act = np.flatnonzero(active)
    above = jump[par[act]]  # the nearest active node strictly above each active node
    if (above != N).any():
        k = int(act[np.flatnonzero(above != N)[0]])
        raise LodprtError(f"not a valid cut: vertex {int(h.leaves(k)[0])} has two active ancestors "
                          f"({k} and {int(above[above != N][0])})")
    return anc.astype(np.int32)


def map_faces(h: Hierarchy, faces: np.ndarray, anc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces (F, 3) mapped through each vertex's active ancestor to original vertex ids (int32), and (F,) bool:
    not degenerate (three different vertices)."""
    f = h.vertex[anc[np.asarray(faces, np.int64)]].astype(np.int32)
    return f, distinct_corners(f)


def distinct_corners(f: np.ndarray) -> np.ndarray:
    """(F,) bool: the face's three corners are three different vertices (a face with a repeated corner has no
    area and takes no part in a collapse)."""
    return (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])


def vertex_corners(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The face corners around each of ``n`` vertices, as CSR: start (n + 1,) int64 and flat corner indices
    (3F,) int32 into ``faces.ravel()`` (face ``c // 3``, corner ``c % 3``), grouped by vertex, ascending within
    each vertex."""
    flat = np.asarray(faces).ravel()
    at = np.argsort(flat, kind="stable").astype(np.int32)
    start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=n), out=start[1:])
    return start, at


def concat_ranges(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The indices ``lo[0]..hi[0]-1, lo[1]..hi[1]-1, ...`` concatenated (int64), vectorised."""
    n = np.asarray(hi, np.int64) - np.asarray(lo, np.int64)
    return np.repeat(np.asarray(lo, np.int64) - np.cumsum(np.r_[0, n[:-1]]), n) + np.arange(int(n.sum()))


def triangulate(h: Hierarchy, faces: np.ndarray, anc: np.ndarray, *, return_index: bool = False):
    """Original faces mapped through each vertex's active ancestor (T-3.2), degenerate faces dropped, vectorised.

    faces (F, 3) original ids, anc (V,) active node per vertex (``active_ancestors``). Returns (M, 3) int32
    original vertex ids (``vertex`` of the active ancestors); with ``return_index`` also the (M,) original face
    of each.
    """
    f, keep = map_faces(h, faces, anc)
    if return_index:
        return f[keep].astype(np.int32), np.flatnonzero(keep)
    return f[keep].astype(np.int32)


def dependency_violations(h: Hierarchy, faces: np.ndarray, anc: np.ndarray) -> np.ndarray:
    """(K, 2) int32 pairs ``(a, b)`` of adjacent active nodes that break the invariant every legal cut keeps:
    ``creation[a] < creation[parent[b]]`` (a root's parent counts as later than everything).

    Legal steps keep it (El-Sana & Varshney, thesis 3.2): a split of ``P`` needs every active neighbour ``n``
    created before ``P``, the parent of both new children; a collapse into ``P`` needs every neighbour's parent
    created after ``P``, and the neighbours it leaves were created before the children's parent ``P``, hence
    before ``P``'s parent. The full and the base cut keep it. Adjacency: an original edge whose ends have
    different active ancestors (``anc`` from ``active_ancestors``). Empty for a legal cut.
    """
    f = np.asarray(anc)[np.asarray(faces, np.int64)]
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = e[e[:, 0] != e[:, 1]]
    e = np.unique(np.concatenate([e, e[:, ::-1]]), axis=0)
    a, b = e[:, 0], e[:, 1]
    pb = h.parent[b]
    later = np.where(pb < 0, np.iinfo(np.int64).max, h.creation[np.maximum(pb, 0)].astype(np.int64))
    return e[h.creation[a].astype(np.int64) >= later].astype(np.int32)
