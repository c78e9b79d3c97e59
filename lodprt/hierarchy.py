"""Vertex hierarchy (SPEC 3; thesis 3.2, figures 5-7 and 10; Hoppe 97; El-Sana & Varshney 99).

Built in two passes:

1. **Levels from pymeshlab.** QEM edge collapse (``meshing_decimation_quadric_edge_collapse`` with
   ``optimalplacement=False``, so survivors keep their original, bit-identical positions) halves the face count
   level after level, each level decimated from the previous one (chained, hence nested survivor sets), the
   original vertex id carried in the vertex scalar (``autoclean`` renumbers vertices). A vertex gets the level at
   which it disappears; what pymeshlab never removes forms the base mesh.
2. **True binary half-edge collapses.** Level by level, the vertices pymeshlab removed there are collapsed, in the
   order of their own QEM cost (Garland-Heckbert quadrics, boundary edges guarded by perpendicular planes), each
   into the current neighbour that costs least among the legal ones. A collapse ``v -> u`` is legal when it keeps
   the link condition (no non-manifold result), moves a boundary vertex only along a boundary edge into a boundary
   vertex, and turns no triangle over (every moved face keeps a normal within 90 degrees of its old one and a
   non-zero area). A vertex with no legal collapse waits for the next level; after the last, it stays in the base.

Each collapse ``v -> u`` creates node ``P`` with children ``(node(u), node(v))`` standing at original vertex ``u``
(Hoppe 97 vertex hierarchy with half-edge collapses: every node sits at an original vertex). Leaves are nodes
``0..V-1`` (node ``i`` is original vertex ``i``); internal nodes are ``V, V+1, ...`` in collapse order.

**Creation numbers** (``creation``) are the node ids: consecutive in the order the hierarchy is built, so they grow
from fine to coarse (leaves first, roots last), as in El-Sana & Varshney, whose rules then read (thesis 3.2):

* split ``P`` only when every active neighbour ``n`` of ``P`` has ``creation[n] < creation[P]`` (no neighbour is
  coarser than when ``P`` was created);
* collapse the children of ``P`` only when every active neighbour ``n`` of the two children has
  ``creation[parent[n]] > creation[P]`` (no neighbour is finer than when ``P`` was created; a root counts as
  infinitely late).

The coarse-to-fine order of the vertex splits (Hoppe's progressive-mesh order) is ``N - 1 - creation``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from typing import Callable

import numpy as np

from lodprt.errors import LodprtError

log = logging.getLogger(__name__)

#: a moved face must keep its normal within this cosine of the old one (0 = 90 degrees)
FOLD_COS = 0.0
#: weight of the boundary-preserving planes relative to the face quadrics
BOUNDARY_WEIGHT = 100.0


@dataclasses.dataclass
class Hierarchy:
    """Binary vertex hierarchy over V original vertices and N nodes.

    parent (N,) int32, -1 for roots;  children (N, 2) int32, -1 for leaves (child 0 stands at the same vertex);
    vertex (N,) int32 original vertex of each node;  creation (N,) int32 (= node id, fine to coarse);
    cone_axis (N, 3) float32 unit;  cone_half_angle (N,) float32 radians (every leaf normal below is inside);
    radius (N,) float32 (sphere at the node's position holding every leaf position below);
    error_vector (N, 3) float32 ``p - p'``: for an internal node, the collapsed vertex minus its closest point on
    the faces around the survivor right after the collapse; zero for leaves;
    neighbour_offsets (N+1,) int64 and neighbours (int32 original vertex ids): for an internal node, the neighbours
    of the collapsed vertex just before its collapse (the survivor included); empty for leaves;
    leaf_order (V,) int32 leaves in depth-first order and leaf_range (N, 2) int64 so that the leaves under node
    ``k`` are ``leaf_order[leaf_range[k, 0]:leaf_range[k, 1]]``.
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

    @property
    def num_nodes(self) -> int:
        return len(self.parent)

    @property
    def roots(self) -> np.ndarray:
        return np.flatnonzero(self.parent < 0).astype(np.int32)

    @property
    def depth(self) -> int:
        """Longest root-to-leaf path, in edges."""
        d = np.zeros(self.num_nodes, np.int32)
        for k in range(self.num_nodes - 1, self.num_vertices - 1, -1):  # parents before children
            c = self.children[k]
            d[c] = d[k] + 1
        return int(d[: self.num_vertices].max()) if self.num_vertices else 0

    def collapsed_neighbours(self, node: int) -> np.ndarray:
        """Original ids of the collapsed vertex's neighbours just before the collapse that created ``node``."""
        return self.neighbours[self.neighbour_offsets[node] : self.neighbour_offsets[node + 1]]

    def leaves(self, node: int) -> np.ndarray:
        lo, hi = self.leaf_range[node]
        return self.leaf_order[lo:hi]

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in self.ARRAYS}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], **attrs) -> "Hierarchy":
        missing = [n for n in cls.ARRAYS if n not in arrays]
        if missing:
            raise LodprtError(f"hierarchy arrays missing: {', '.join(missing)}")
        num_vertices = len(arrays["leaf_order"])
        return cls(num_vertices=num_vertices, **{n: np.asarray(arrays[n]) for n in cls.ARRAYS}, **attrs)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.to_arrays().values()))


# ---------------------------------------------------------------------------------------------------------------
# pass 1: levels from pymeshlab


def pymeshlab_levels(
    positions: np.ndarray, faces: np.ndarray, *, min_faces: int = 64, max_levels: int = 40
) -> tuple[np.ndarray, int]:
    """Removal level of every vertex from chained pymeshlab QEM halvings; 0 for vertices never removed.

    Returns (level (V,) int32, number of levels). Stops when a halving removes less than 10% of the faces
    (pymeshlab cannot reduce further while preserving topology and boundaries) or at ``min_faces``.
    """
    import pymeshlab

    V = len(positions)
    referenced = np.zeros(V, bool)
    referenced[faces.ravel()] = True
    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.asarray(positions, np.float64),
            face_matrix=np.asarray(faces, np.int32),
            v_scalar_array=np.arange(V, dtype=np.float64),  # original ids survive autoclean's renumbering
        )
    )
    level = np.zeros(V, np.int32)
    alive = np.flatnonzero(referenced)
    nf = len(faces)
    levels = 0
    for lev in range(1, max_levels + 1):
        if nf <= min_faces:
            break
        ms.meshing_decimation_quadric_edge_collapse(
            targetfacenum=max(nf // 2, min_faces),
            optimalplacement=False,  # survivors stay at their original positions
            preservetopology=True,
            preserveboundary=True,
            qualitythr=0.3,
            autoclean=True,
        )
        mesh = ms.current_mesh()
        ids = np.rint(mesh.vertex_scalar_array()).astype(np.int64)
        gone = np.setdiff1d(alive, ids, assume_unique=False)
        level[gone] = lev
        alive = np.intersect1d(alive, ids)
        new_nf = mesh.face_number()
        levels = lev
        if new_nf > 0.9 * nf:
            break
        nf = new_nf
    return level, levels


# ---------------------------------------------------------------------------------------------------------------
# pass 2: half-edge collapses


def _face_quadrics(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 4, 4) Garland-Heckbert quadrics: sum over incident faces of area * p p^T, plane p = (n, -n.x)."""
    p = positions
    e1 = p[faces[:, 1]] - p[faces[:, 0]]
    e2 = p[faces[:, 2]] - p[faces[:, 0]]
    cr = np.cross(e1, e2)
    dbl_area = np.linalg.norm(cr, axis=1)
    ok = dbl_area > 0
    n = np.zeros_like(cr)
    n[ok] = cr[ok] / dbl_area[ok, None]
    plane = np.concatenate([n, -(n * p[faces[:, 0]]).sum(1, keepdims=True)], axis=1)
    kf = 0.5 * dbl_area[:, None, None] * plane[:, :, None] * plane[:, None, :]
    q = np.zeros((len(p), 4, 4))
    for k in range(3):
        np.add.at(q, faces[:, k], kf)
    return q, n


def _boundary_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boundary edges (E, 2) (used by exactly one face) and, for each, the face using it."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    fid = np.tile(np.arange(len(faces)), 3)
    key = np.sort(e, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inv.ravel()] == 1
    return e[once], fid[once]


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest points (M, 3) on triangles (a, b, c) to points p, all (M, 3) (Ericson, Real-Time Collision Detection)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    safe = np.where(np.abs(denom) > 0, denom, 1.0)
    v = vb / safe
    w = vc / safe
    out = a + ab * v[:, None] + ac * w[:, None]  # interior
    with np.errstate(divide="ignore", invalid="ignore"):
        # edge regions
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = np.where(m, d1 / np.where(d1 - d3 != 0, d1 - d3, 1), 0)
        out = np.where(m[:, None], a + ab * t[:, None], out)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = np.where(m, d2 / np.where(d2 - d6 != 0, d2 - d6, 1), 0)
        out = np.where(m[:, None], a + ac * t[:, None], out)
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        den = (d4 - d3) + (d5 - d6)
        t = np.where(m, (d4 - d3) / np.where(den != 0, den, 1), 0)
        out = np.where(m[:, None], b + (c - b) * t[:, None], out)
    # vertex regions last, they take precedence
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)
    return out


def build_hierarchy(
    positions: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    *,
    min_faces: int = 64,
    progress: Callable[[int, int], None] | None = None,
) -> Hierarchy:
    """Build the binary vertex hierarchy of a triangle mesh (module docstring).

    positions (V, 3), faces (F, 3) int, normals (V, 3) unit vertex normals (leaf cones). Several components, open
    boundaries, non-manifold edges and duplicated vertices are allowed (collapses that would worsen them are not
    taken); unreferenced vertices become isolated roots. ``progress(done, total)`` reports collapses.
    """
    t0 = time.perf_counter()
    positions = np.asarray(positions, np.float64)
    faces = np.asarray(faces, np.int64)
    normals = np.asarray(normals, np.float64)
    V = len(positions)
    if positions.ndim != 2 or positions.shape[1] != 3 or normals.shape != positions.shape:
        raise LodprtError(f"build_hierarchy: positions and normals must be (V, 3), got {positions.shape}, {normals.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or (len(faces) and (faces.min() < 0 or faces.max() >= V)):
        raise LodprtError(f"build_hierarchy: faces must be (F, 3) indices into {V} vertices")
    if not np.isfinite(positions).all():
        raise LodprtError("build_hierarchy: non-finite vertex positions")
    # faces with a repeated index carry no area or orientation: they take no part in the collapses
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    work_faces = faces[good]

    level, levels = pymeshlab_levels(positions, work_faces, min_faces=min_faces) if len(work_faces) else (np.zeros(V, np.int32), 0)

    quadric, face_normal = _face_quadrics(positions, work_faces)
    bedges, bface = _boundary_edges(work_faces)
    boundary = np.zeros(V, bool)
    boundary[bedges.ravel()] = True
    if len(bedges):
        # Garland-Heckbert boundary planes: through the edge, perpendicular to its face
        d = positions[bedges[:, 1]] - positions[bedges[:, 0]]
        n = np.cross(d, face_normal[bface])
        ln = np.linalg.norm(n, axis=1)
        ok = ln > 0
        n[ok] /= ln[ok, None]
        plane = np.concatenate([n, -(n * positions[bedges[:, 0]]).sum(1, keepdims=True)], axis=1)
        w = BOUNDARY_WEIGHT * (d * d).sum(1)
        kb = w[:, None, None] * plane[:, :, None] * plane[:, None, :]
        for k in range(2):
            np.add.at(quadric, bedges[:, k], kb)
    bset = {tuple(sorted(e)) for e in bedges.tolist()}

    # mutable mesh: faces as lists, incidence as sets
    F = [list(f) for f in work_faces.tolist()]
    incident: list[set] = [set() for _ in range(V)]
    for fi, f in enumerate(F):
        for x in f:
            incident[x].add(fi)
    pos = positions
    node_of = list(range(V))
    parent: list[int] = [-1] * V
    children: list[tuple[int, int]] = [(-1, -1)] * V
    vertex: list[int] = list(range(V))
    nb_offsets = [0] * (V + 1)
    nb_flat: list[int] = []
    err_faces: list[tuple[int, list]] = []  # (collapsed vertex, faces around survivor after collapse)
    removed = [False] * V
    boundary_l = boundary.tolist()
    total = int((level > 0).sum())
    done = 0

    def neighbours(x):
        s = set()
        for fi in incident[x]:
            s.update(F[fi])
        s.discard(x)
        return s

    def cost(v, u):
        q = quadric[v] + quadric[u]
        h = np.append(pos[u], 1.0)
        return float(h @ q @ h)

    def legal(v, u, nv):
        shared = [fi for fi in incident[v] if u in F[fi]]
        if not shared:
            return False
        # link condition: common neighbours are exactly the third vertices of the shared faces
        common = nv & neighbours(u)
        thirds = {x for fi in shared for x in F[fi] if x != u and x != v}
        if common != thirds or len(shared) > 2:
            return False
        if boundary_l[v]:
            if not boundary_l[u] or tuple(sorted((u, v))) not in bset:
                return False
        elif boundary_l[u] and len(shared) != 2:
            return False
        # no fold-over: every face that moves keeps its orientation and some area
        pu = pos[u]
        for fi in incident[v]:
            f = F[fi]
            if u in f:
                continue
            a, b, c = (pos[x] if x != v else pu for x in f)
            a0, b0, c0 = pos[f[0]], pos[f[1]], pos[f[2]]
            n_new = np.cross(b - a, c - a)
            n_old = np.cross(b0 - a0, c0 - a0)
            ln, lo = np.linalg.norm(n_new), np.linalg.norm(n_old)
            if ln <= 1e-12 * lo or ln == 0:
                return False
            if lo > 0 and np.dot(n_new, n_old) <= FOLD_COS * ln * lo:
                return False
        return True

    def collapse(v, u, nv):
        nonlocal done
        for fi in list(incident[v]):
            f = F[fi]
            if u in f:
                for x in f:
                    incident[x].discard(fi)
            else:
                F[fi] = [u if x == v else x for x in f]
                incident[u].add(fi)
        incident[v].clear()
        quadric[u] += quadric[v]
        removed[v] = True
        p_node = len(parent)
        parent.append(-1)
        cu, cv = node_of[u], node_of[v]
        parent[cu] = p_node
        parent[cv] = p_node
        children.append((cu, cv))
        vertex.append(u)
        nb_flat.extend(sorted(nv))
        nb_offsets.append(len(nb_flat))
        node_of[u] = p_node
        err_faces.append((v, [tuple(F[fi]) for fi in incident[u]]))
        done += 1

    pending: list[int] = []
    for lev in range(1, levels + 1):
        cand = pending + np.flatnonzero(level == lev).tolist()
        scored = []
        for v in cand:
            if removed[v] or not incident[v]:
                continue
            nv = neighbours(v)
            best = min((cost(v, u) for u in nv), default=math.inf)
            scored.append((best, v))
        scored.sort()
        pending = []
        for _, v in scored:
            nv = neighbours(v)
            options = sorted((cost(v, u), u) for u in nv)
            for _, u in options:
                if legal(v, u, nv):
                    collapse(v, u, nv)
                    break
            else:
                pending.append(v)  # wait for the next level; after the last it stays in the base
            if progress is not None and done % 4096 == 0:
                progress(done, total)
    if progress is not None:
        progress(done, total)

    N = len(parent)
    parent_a = np.asarray(parent, np.int32)
    children_a = np.asarray(children, np.int32).reshape(N, 2)
    vertex_a = np.asarray(vertex, np.int32)
    # normal cones and radii, bottom-up in creation order (children always precede their parent)
    axis = np.zeros((N, 3))
    half = np.zeros(N)
    radius = np.zeros(N)
    axis[:V] = normals
    for k in range(V, N):
        c0, c1 = children_a[k]
        axis[k], half[k] = _merge_cones(axis[c0], half[c0], axis[c1], half[c1])
        p = positions[vertex_a[k]]
        radius[k] = max(radius[c0] + np.linalg.norm(positions[vertex_a[c0]] - p), radius[c1] + np.linalg.norm(positions[vertex_a[c1]] - p))
    error = np.zeros((N, 3))
    if N > V:
        error[V:] = _error_vectors(positions, err_faces)
    leaf_order, leaf_range = _leaf_layout(parent_a, children_a, V)
    h = Hierarchy(
        num_vertices=V,
        parent=parent_a,
        children=children_a,
        vertex=vertex_a,
        creation=np.arange(N, dtype=np.int32),
        cone_axis=axis.astype(np.float32),
        cone_half_angle=half.astype(np.float32),
        radius=radius.astype(np.float32),
        error_vector=error.astype(np.float32),
        neighbour_offsets=np.asarray(nb_offsets, np.int64),
        neighbours=np.asarray(nb_flat, np.int32),
        leaf_order=leaf_order,
        leaf_range=leaf_range,
        levels=levels,
    )
    h.build_seconds = time.perf_counter() - t0
    log.info("hierarchy: %d nodes, %d roots, %d levels, %.1f s", N, len(h.roots), levels, h.build_seconds)
    return h


def _merge_cones(a1, t1, a2, t2) -> tuple[np.ndarray, float]:
    """Smallest cone holding cones (a1, t1) and (a2, t2) (unit axes, half-angles in radians), figure 7."""
    cos_g = max(-1.0, min(1.0, float(a1 @ a2)))
    g = math.acos(cos_g)
    if g + t2 <= t1:
        return a1, t1
    if g + t1 <= t2:
        return a2, t2
    t = 0.5 * (g + t1 + t2)
    if t >= math.pi or g >= math.pi - 1e-9:
        return a1, math.pi
    # rotate a1 toward a2 by (t - t1) in their common plane
    perp = a2 - cos_g * a1
    perp /= np.linalg.norm(perp)
    ang = t - t1
    axis = math.cos(ang) * a1 + math.sin(ang) * perp
    axis /= np.linalg.norm(axis)
    return axis, min(math.pi, t + 1e-6)  # a hair of slack for rounding


def _error_vectors(positions, err_faces) -> np.ndarray:
    """Figure 10: p - p' with p' the closest point to p on the faces around the survivor after the collapse."""
    counts = np.array([len(f) for _, f in err_faces])
    flat = np.array([t for _, f in err_faces for t in f], dtype=np.int64).reshape(-1, 3)
    pv = np.array([v for v, _ in err_faces], dtype=np.int64)
    out = np.zeros((len(err_faces), 3))
    has = counts > 0
    if flat.size:
        p = positions[np.repeat(pv, counts)]
        q = _closest_on_triangles(p, positions[flat[:, 0]], positions[flat[:, 1]], positions[flat[:, 2]])
        d2 = ((p - q) ** 2).sum(1)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        idx = np.flatnonzero(has)
        best = np.minimum.reduceat(d2, starts[idx])
        # the argmin inside each segment
        seg = np.repeat(np.arange(len(idx)), counts[idx])
        is_best = d2 == best[seg]
        first = np.full(len(idx), -1)
        hits = np.flatnonzero(is_best)
        first[seg[hits][::-1]] = hits[::-1]
        out[idx] = p[first] - q[first]
    return out


def _leaf_layout(parent, children, V) -> tuple[np.ndarray, np.ndarray]:
    """Leaves in depth-first order (child 0 first) and each node's [lo, hi) range into it."""
    N = len(parent)
    order = []
    rng = np.zeros((N, 2), np.int64)
    roots = np.flatnonzero(parent < 0)[::-1]
    stack = [(int(r), False) for r in roots]
    while stack:
        k, closing = stack.pop()
        if closing:
            rng[k, 1] = len(order)
            continue
        rng[k, 0] = len(order)
        if children[k, 0] < 0:
            order.append(k)
            rng[k, 1] = len(order)
        else:
            stack.append((k, True))
            stack.append((int(children[k, 1]), False))
            stack.append((int(children[k, 0]), False))
    return np.asarray(order, np.int32), rng


# ---------------------------------------------------------------------------------------------------------------
# cuts


class Cut:
    """A front of active nodes: every original vertex has exactly one active ancestor-or-self.

    ``anc`` (V,) holds each original vertex's active node. ``refine``/``coarsen`` apply the El-Sana & Varshney
    rules (module docstring) and return False, changing nothing, when a rule forbids the step; their cost follows
    the size of the node's subtree, not the mesh.
    """

    def __init__(self, hierarchy: Hierarchy, faces: np.ndarray, active: np.ndarray):
        self.h = hierarchy
        self.faces = np.asarray(faces, np.int64)
        self.active = np.asarray(active, bool).copy()
        V = hierarchy.num_vertices
        # original adjacency in CSR, rows in depth-first leaf order, so a subtree's edges are one slice
        f = self.faces
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]], f[:, [1, 0]], f[:, [2, 1]], f[:, [0, 2]]])
        e = e[e[:, 0] != e[:, 1]]
        rank = np.empty(V, np.int64)
        rank[hierarchy.leaf_order] = np.arange(V)
        e = np.unique(e, axis=0)
        e = e[np.argsort(rank[e[:, 0]], kind="stable")]
        self._nbr = e[:, 1].astype(np.int32)
        self._ptr = np.searchsorted(rank[e[:, 0]], np.arange(V + 1))
        self.anc = active_ancestors(hierarchy, self.active)

    @classmethod
    def full(cls, hierarchy: Hierarchy, faces) -> "Cut":
        a = np.zeros(hierarchy.num_nodes, bool)
        a[: hierarchy.num_vertices] = True
        return cls(hierarchy, faces, a)

    @classmethod
    def base(cls, hierarchy: Hierarchy, faces) -> "Cut":
        a = np.zeros(hierarchy.num_nodes, bool)
        a[hierarchy.roots] = True
        return cls(hierarchy, faces, a)

    def neighbours(self, node: int) -> np.ndarray:
        """Active nodes adjacent to ``node`` in the cut's mesh (node need not be active: its leaves' neighbours)."""
        lo, hi = self.h.leaf_range[node]
        n = self.anc[self._nbr[self._ptr[lo] : self._ptr[hi]]]
        n = np.unique(n)
        return n[n != node]

    def can_refine(self, node: int) -> bool:
        h = self.h
        if not self.active[node] or h.children[node, 0] < 0:
            return False
        return bool((h.creation[self.neighbours(node)] < h.creation[node]).all())

    def blockers_of_refine(self, node: int) -> np.ndarray:
        """Active neighbours that break the split rule (coarser than when ``node`` was created)."""
        nb = self.neighbours(node)
        return nb[self.h.creation[nb] > self.h.creation[node]]

    def can_coarsen(self, node: int) -> bool:
        h = self.h
        c0, c1 = h.children[node]
        if c0 < 0 or self.active[node] or not (self.active[c0] and self.active[c1]):
            return False
        nb = np.union1d(self.neighbours(c0), self.neighbours(c1))
        nb = nb[(nb != c0) & (nb != c1)]
        par = h.parent[nb]
        later = np.where(par < 0, np.iinfo(np.int32).max, h.creation[np.maximum(par, 0)])
        return bool((later > h.creation[node]).all())

    def refine(self, node: int) -> bool:
        """Split ``node`` into its two children when legal; returns whether it did."""
        if not self.can_refine(node):
            return False
        c0, c1 = self.h.children[node]
        self.active[node] = False
        self.active[c0] = self.active[c1] = True
        for c in (c0, c1):
            lo, hi = self.h.leaf_range[c]
            self.anc[self.h.leaf_order[lo:hi]] = c
        return True

    def coarsen(self, node: int) -> bool:
        """Collapse the two active children of ``node`` into it when legal; returns whether it did."""
        if not self.can_coarsen(node):
            return False
        c0, c1 = self.h.children[node]
        self.active[c0] = self.active[c1] = False
        self.active[node] = True
        lo, hi = self.h.leaf_range[node]
        self.anc[self.h.leaf_order[lo:hi]] = node
        return True

    def force_refine(self, node: int) -> None:
        """Make ``node``'s split happen: activate it (refining its ancestors), first splitting every neighbour
        the split rule needs split, recursively (seed 003, table 5.1 forced refinement)."""
        h = self.h
        if h.children[node, 0] < 0:
            raise LodprtError(f"node {node} is a leaf: nothing to split")
        if not self.active[node]:
            a = self.anc[h.leaves(node)[0]]
            if h.creation[a] < h.creation[node]:
                return  # already finer than node here
            path = []
            k = node
            while k != a:
                path.append(k)
                k = h.parent[k]
            for k in [a] + path[::-1][:-1]:
                self._force_split(k)
        self._force_split(node)

    def _force_split(self, node: int) -> None:
        stack = [node]
        while stack:
            k = stack[-1]
            if not self.active[k]:
                stack.pop()
                continue
            blockers = self.blockers_of_refine(k)
            if len(blockers):
                stack.extend(int(b) for b in blockers)
                continue
            if not self.refine(k):
                raise LodprtError(f"forced refinement of node {k} failed")  # cannot happen: rule checked above
            stack.pop()

    def triangles(self, *, return_index: bool = False):
        """Faces of the cut's mesh in original vertex ids (vertex of each active ancestor), degenerate ones dropped."""
        return triangulate(self.h, self.faces, self.anc, return_index=return_index)


def active_ancestors(h: Hierarchy, active: np.ndarray) -> np.ndarray:
    """(V,) the active ancestor-or-self of each original vertex by vectorised pointer jumping.

    Raises LodprtError when ``active`` is not a front (a vertex with no or two active ancestors).
    """
    V = h.num_vertices
    cur = np.arange(V, dtype=np.int64)
    hit = active[cur]
    count = hit.astype(np.int32)
    result = np.where(hit, cur, -1)
    while True:  # one step up per pass; as many passes as the hierarchy is deep
        nxt = h.parent[cur]
        more = nxt >= 0
        if not more.any():
            break
        cur = np.where(more, nxt, cur)
        hit = more & active[cur]
        count += hit
        result = np.where(hit & (result < 0), cur, result)
    if (count != 1).any():
        bad = int(np.flatnonzero(count != 1)[0])
        raise LodprtError(f"not a valid cut: vertex {bad} has {int(count[bad])} active ancestors")
    return result.astype(np.int32)


def triangulate(h: Hierarchy, faces: np.ndarray, anc: np.ndarray, *, return_index: bool = False):
    """Original faces mapped through each vertex's active ancestor (T-3.2), degenerate faces dropped, vectorised.

    Returns (M, 3) int32 original vertex ids; with ``return_index`` also the (M,) original face of each.
    """
    f = h.vertex[anc[np.asarray(faces, np.int64)]]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    if return_index:
        return f[keep].astype(np.int32), np.flatnonzero(keep)
    return f[keep].astype(np.int32)
