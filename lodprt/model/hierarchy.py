"""Vertex hierarchy (SPEC 3; thesis 3.2, figures 5-7 and 10; Hoppe 97; El-Sana & Varshney 99).

Built in two passes:

1. **Levels from pymeshlab.** QEM edge collapse (``meshing_decimation_quadric_edge_collapse`` with
   ``optimalplacement=False``, so survivors keep their original, bit-identical positions) halves the face count
   level after level, each level decimated from the previous one (chained, hence nested survivor sets), the
   original vertex id carried in the vertex scalar (``autoclean`` renumbers vertices). A vertex gets the level at
   which it disappears; what pymeshlab never removes forms the base mesh. Verified by the tests: survivors are
   bit-identical, runs are deterministic, levels are nested.
2. **True binary half-edge collapses** (thesis figure 5). Level by level, the vertices pymeshlab removed there are
   collapsed in the order of their own QEM cost (Garland-Heckbert face quadrics plus perpendicular boundary planes;
   the cost of ``v`` is its cheapest move), each into a current neighbour ``u`` that survives the level: first the
   neighbour that pymeshlab's next-level faces point at (the survivor that gained ``v``'s edges), then the others
   by cost. A collapse ``v -> u`` is legal when

   * ``u`` and ``v`` belong to the same component (``component``: the floor never merges with an object),
   * the link condition holds (the common neighbours of ``u`` and ``v`` are exactly the third corners of the one
     or two faces on edge ``uv``) and ``u`` keeps a valence of 3 (2 on a boundary): the result stays manifold,
   * a boundary vertex moves only along a boundary edge (into a boundary vertex); an interior vertex only along
     an interior edge,
   * no moved face turns over (its normal stays within 90 degrees of its normal before the collapse) or becomes
     a sliver (twice its area below ``SLIVER`` times its longest edge squared).

   Vertices on non-manifold edges (more than two faces) or at non-manifold boundary vertices take part in no
   collapse. A vertex with no legal collapse in its level is retried after the level's other collapses, then
   deferred to the next level (and to up to ``EXTRA_LEVELS`` levels after pymeshlab's last); what nothing can
   remove stays in the base mesh.

**Nodes** (Hoppe 97 vertex hierarchy with half-edge collapses: every node stands at an original vertex). Leaves are
nodes ``0..V-1`` (node ``i`` is original vertex ``i``). Each collapse ``v -> u`` creates the next node ``P``
(ids ``V, V+1, ...`` in collapse order) with children ``(node(u), node(v))`` and ``vertex[P] = u``. Roots (no
parent) are the base mesh plus the vertices no face uses (isolated roots, leaf = root).

**Creation numbers and the El-Sana & Varshney dependency rules (thesis 3.2).** New nodes are numbered
consecutively as the hierarchy is built, i.e. in collapse order, fine to coarse: ``creation[k] = k`` (leaves
``0..V-1`` first, every parent after both its children, roots of the coarsest collapses last). With this numbering
the thesis' rules read, and ``Cut`` applies them exactly:

* **vertex split** of active ``P`` (into its children): every active neighbour ``n`` of ``P`` has
  ``creation[n] < creation[P]``: no neighbour is coarser than the mesh was when ``P`` was created;
* **edge collapse** of the active children of ``P`` (into ``P``): every active neighbour ``n`` of the two children
  has ``creation[parent[n]] > creation[P]`` (a root's missing parent counts as later than everything): no neighbour
  is finer than the mesh was when ``P`` was created.

Numbering the other way (coarse to fine, Hoppe's progressive-mesh order ``N - 1 - creation``) would reverse both
inequalities.
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

#: a moved face must keep its normal within this cosine of its old one (0 = 90 degrees)
FOLD_COS = 0.0
#: twice a moved face's area below SLIVER x its longest edge squared makes it a degenerate sliver
SLIVER = 1e-3
#: weight of the Garland-Heckbert boundary planes relative to the face quadrics
BOUNDARY_WEIGHT = 100.0
#: weight of |uv|^4 added to the QEM cost of v -> u: on flat regions (zero quadric error) the shortest edge wins,
#: instead of whichever neighbour comes first (which grows fans around a few vertices and deep hierarchies)
EDGE_WEIGHT = 1e-3
#: no collapse may leave the survivor with more neighbours (keeps fans and deep chains from forming)
MAX_VALENCE = 24
#: levels tried after pymeshlab's last for the vertices deferred so far
EXTRA_LEVELS = 4
#: slack (radians) added to every stored cone half-angle to cover float32 rounding of axis and angle
CONE_SLACK = 1e-6

_INF_LEVEL = 1 << 30  # a base vertex survives every level


@dataclasses.dataclass
class Hierarchy:
    """Binary vertex hierarchy over V original vertices and N nodes (module docstring for the definitions).

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
        num_vertices = int((d["children"][:, 0] < 0).sum())
        if "leaf_order" not in d or "leaf_range" not in d:
            d["leaf_order"], d["leaf_range"] = _leaf_layout(d["parent"], d["children"], num_vertices)
        return cls(num_vertices=num_vertices, **d, **attrs)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.to_arrays().values()))


def node_heights(h: Hierarchy) -> np.ndarray:
    """(N,) int32 height of every node: 0 for leaves, 1 + the higher child's height above (creation order)."""
    out = [0] * h.num_nodes
    ch = h.children.tolist()
    for k in range(h.num_vertices, h.num_nodes):  # children always precede their parent
        a, b = ch[k]
        ha, hb = out[a], out[b]
        out[k] = 1 + (ha if ha > hb else hb)
    return np.asarray(out, np.int32)


# ---------------------------------------------------------------------------------------------------------------
# pass 1: levels from pymeshlab


def mesh_groups(V: int, faces: np.ndarray, component: np.ndarray | None = None) -> np.ndarray:
    """(V,) int64 group of every vertex: the connected components of the mesh, split further by ``component``
    (edges between different ``component`` values do not connect). Each group is decimated on its own."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]) if len(faces) else np.zeros((0, 2), np.int64)
    if component is not None:
        e = e[component[e[:, 0]] == component[e[:, 1]]]
    g = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(V, V))
    return connected_components(g, directed=False)[1].astype(np.int64)


def _chain_one(positions: np.ndarray, faces: np.ndarray, target_base: int, max_levels: int,
               keep_boundary: bool) -> list[np.ndarray]:
    """Chained pymeshlab halvings of one group (faces in original ids), level 1 first, in original ids."""
    import pymeshlab

    ids = np.unique(faces)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.ascontiguousarray(positions[ids], np.float64),
            face_matrix=np.searchsorted(ids, faces).astype(np.int32),
            v_scalar_array=ids.astype(np.float64),  # original ids survive autoclean's renumbering (exact below 2^53)
        )
    )
    out: list[np.ndarray] = []
    nf = len(faces)
    for _ in range(max_levels):
        if nf <= target_base:
            break
        try:
            ms.meshing_decimation_quadric_edge_collapse(
                targetfacenum=max(nf // 2, target_base),
                optimalplacement=False,  # survivors stay at their original positions
                preservetopology=True,
                preserveboundary=keep_boundary,
                planarquadric=True,  # flat regions (the floor) thin out evenly instead of vanishing at once
                qualitythr=0.3,  # 0 stalls (REFERENCES.md)
                autoclean=True,
            )
        except Exception as exc:  # pymeshlab.PyMeshLabException on meshes it cannot handle
            log.warning("pymeshlab decimation stopped after %d levels: %s", len(out), exc)
            break
        mesh = ms.current_mesh()
        vid = np.rint(mesh.vertex_scalar_array()).astype(np.int64)
        new_nf = mesh.face_number()
        out.append(vid[mesh.face_matrix()] if new_nf else np.zeros((0, 3), np.int64))
        if new_nf > 0.9 * nf:
            break
        nf = new_nf
    return out


def pymeshlab_chain(
    positions: np.ndarray, faces: np.ndarray, *, groups: np.ndarray | None = None, target_base: int = 64,
    keep_boundary: bool = True, max_levels: int = 40,
) -> list[np.ndarray]:
    """The mesh after each level of chained pymeshlab QEM halvings: faces (F_L, 3) int64 in *original* vertex
    ids, level 1 first.

    Every group (``mesh_groups``; default: the connected components) is decimated on its own, so that a cheap
    flat floor does not vanish in the first halving of a mesh that also holds a curved object. Each level is
    decimated from the previous one to half its faces (``optimalplacement=False``: survivors keep their original
    positions; the vertex scalar carries the original id through ``autoclean``'s renumbering). A group stops at
    ``target_base`` faces, when a halving removes less than 10% of its faces (pymeshlab cannot reduce further),
    or when pymeshlab refuses it (logged; its base is then larger). Faces spanning two groups never change.
    """
    faces = np.asarray(faces, np.int64)
    V = len(positions)
    if groups is None:
        groups = mesh_groups(V, faces)
    fg = groups[faces[:, 0]]
    mixed = (groups[faces[:, 1]] != fg) | (groups[faces[:, 2]] != fg)
    fixed = [faces[mixed]]
    chains = []
    order = np.argsort(np.where(mixed, -1, fg), kind="stable")
    sg = np.where(mixed, -1, fg)[order]
    cuts = np.flatnonzero(np.diff(sg)) + 1
    for part in np.split(order, cuts):
        if not len(part) or mixed[part[0]]:
            continue
        f = faces[part]
        c = _chain_one(positions, f, target_base, max_levels, keep_boundary) if len(f) > target_base else []
        if c:
            chains.append([f] + c)
        else:
            fixed.append(f)
    levels = max((len(c) - 1 for c in chains), default=0)
    return [np.concatenate(fixed + [c[min(L, len(c) - 1)] for c in chains]) for L in range(1, levels + 1)]


def _levels_from_chain(V: int, faces: np.ndarray, chain: list[np.ndarray]) -> np.ndarray:
    """(V,) int32 level at which each vertex leaves the chain (1-based), 0 when it never does (or no face uses it)."""
    level = np.zeros(V, np.int32)
    alive = np.zeros(V, bool)
    alive[faces.ravel()] = True
    for L, f in enumerate(chain, 1):
        now = np.zeros(V, bool)
        now[f.ravel()] = True
        level[alive & ~now] = L
        alive &= now  # nested by construction: each level is decimated from the previous one
    return level


def pymeshlab_levels(
    positions: np.ndarray, faces: np.ndarray, *, target_base: int = 64, keep_boundary: bool = True,
    max_levels: int = 40,
) -> tuple[np.ndarray, int]:
    """Removal level (V,) int32 of every vertex from chained pymeshlab QEM halvings (0: never removed), and the
    number of levels (``pymeshlab_chain``)."""
    faces = np.asarray(faces, np.int64)
    chain = pymeshlab_chain(positions, faces, target_base=target_base, keep_boundary=keep_boundary,
                            max_levels=max_levels)
    return _levels_from_chain(len(positions), faces, chain), len(chain)


def _representative_scores(V: int, before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How strongly pymeshlab's faces say that removed ``v`` went to surviving neighbour ``u``.

    For each pair (v removed between meshes ``before`` and ``after``, u a surviving neighbour of v in ``before``):
    the number of v's other surviving neighbours ``w`` to which ``u`` gained an edge (a half-edge collapse
    ``v -> u`` turns every edge ``vw`` into ``uw``). Returns sorted keys ``v * V + u`` (int64) and scores, only
    pairs with a positive score.
    """

    def edge_keys(f):
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        return np.unique(e[:, 0] * V + e[:, 1])

    if not len(before) or not len(after):
        return np.zeros(0, np.int64), np.zeros(0)
    e_before, e_after = edge_keys(before), edge_keys(after)
    gained = np.setdiff1d(e_after, e_before, assume_unique=True)
    survive = np.zeros(V, bool)
    survive[after.ravel()] = True
    was = np.zeros(V, bool)
    was[before.ravel()] = True
    removed = was & ~survive
    a, b = e_before // V, e_before % V
    src, dst = np.r_[a, b], np.r_[b, a]
    keep = removed[src] & survive[dst]
    src, dst = src[keep], dst[keep]
    o = np.argsort(src, kind="stable")
    src, dst = src[o], dst[o]
    start = np.searchsorted(src, np.arange(V + 1))
    # every pair (v, u) against every other surviving neighbour w of the same v
    cnt = start[src + 1] - start[src]
    i = np.repeat(np.arange(len(src)), cnt)
    j = concat_ranges(start[src], start[src + 1])
    u, w = dst[i], dst[j]
    ok = u != w
    lo, hi = np.minimum(u, w), np.maximum(u, w)
    hit = np.zeros(len(i), bool)
    hit[ok] = np.isin(lo[ok] * V + hi[ok], gained)
    score = np.bincount(i, weights=hit, minlength=len(src))
    pos = score > 0
    keys = src[pos] * V + dst[pos]
    o = np.argsort(keys)
    return keys[o], score[pos][o]


# ---------------------------------------------------------------------------------------------------------------
# pass 2: half-edge collapses


def _quadrics(positions: np.ndarray, faces: np.ndarray, edge_key: np.ndarray, edge_count: np.ndarray,
              edge_face: np.ndarray) -> np.ndarray:
    """(V, 4, 4) Garland-Heckbert quadrics: sum over incident faces of area * p p^T (plane p = (n, -n.x)), plus
    ``BOUNDARY_WEIGHT`` x |e|^2 x the plane through each boundary edge perpendicular to its face."""
    V = len(positions)
    p = positions
    cr = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    dbl = np.linalg.norm(cr, axis=1)
    n = np.divide(cr, dbl[:, None], out=np.zeros_like(cr), where=dbl[:, None] > 0)
    plane = np.concatenate([n, -(n * p[faces[:, 0]]).sum(1, keepdims=True)], axis=1)
    kf = 0.5 * dbl[:, None, None] * plane[:, :, None] * plane[:, None, :]
    q = np.zeros((V, 4, 4))
    for k in range(3):
        np.add.at(q, faces[:, k], kf)
    once = edge_count == 1
    if once.any():
        a, b = edge_key[once] // V, edge_key[once] % V
        d = p[b] - p[a]
        m = np.cross(d, n[edge_face[once]])
        lm = np.linalg.norm(m, axis=1)
        m = np.divide(m, lm[:, None], out=np.zeros_like(m), where=lm[:, None] > 0)
        bp = np.concatenate([m, -(m * p[a]).sum(1, keepdims=True)], axis=1)
        kb = (BOUNDARY_WEIGHT * (d * d).sum(1))[:, None, None] * bp[:, :, None] * bp[:, None, :]
        np.add.at(q, a, kb)
        np.add.at(q, b, kb)
    return q


def _edges(faces: np.ndarray, V: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges as sorted keys ``a * V + b`` (a < b), how many faces use each, and one face using each."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys = e[:, 0] * V + e[:, 1]
    uk, first, counts = np.unique(keys, return_index=True, return_counts=True)
    return uk, counts, first % max(len(faces), 1)


def build_hierarchy(
    positions: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    *,
    component: np.ndarray | None = None,
    target_base: int = 64,
    keep_boundary: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Hierarchy:
    """Build the binary vertex hierarchy of a triangle mesh (module docstring).

    positions (V, 3) float, faces (F, 3) int, normals (V, 3) unit vertex normals (the leaves' cones);
    component (V,) int: vertices of different components never collapse into each other (e.g. ``Scene.object_id``:
    the floor and each object); target_base: the face count at which pymeshlab's chained halvings stop (the base
    mesh is that size or larger where collapses are refused); ``progress(done, total)`` reports collapses against
    the number pymeshlab suggested. Open boundaries, several components, non-manifold edges, duplicated vertices
    and faces with a repeated corner are accepted (module docstring); unreferenced vertices become isolated roots.
    Raises LodprtError naming the bad input otherwise.
    """
    t0 = time.perf_counter()
    positions = np.asarray(positions, np.float64)
    normals = np.asarray(normals, np.float64)
    faces = np.asarray(faces)
    if positions.ndim != 2 or positions.shape[1] != 3 or normals.shape != positions.shape:
        raise LodprtError(f"build_hierarchy: positions and normals must both be (V, 3), got {positions.shape} and "
                          f"{normals.shape}")
    V = len(positions)
    if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
        raise LodprtError(f"build_hierarchy: faces must be an (F, 3) integer array, got {faces.shape} {faces.dtype}")
    faces = faces.astype(np.int64)
    if len(faces) and (faces.min() < 0 or faces.max() >= V):
        raise LodprtError(f"build_hierarchy: faces index vertices {faces.min()}..{faces.max()} outside 0..{V - 1}")
    if V >= 2**31 - 1 or 2 * V >= 2**31:
        raise LodprtError(f"build_hierarchy: {V} vertices do not fit int32 node ids")
    if not np.isfinite(positions).all():
        raise LodprtError("build_hierarchy: non-finite vertex positions")
    if not np.isfinite(normals).all():
        raise LodprtError("build_hierarchy: non-finite vertex normals")
    if component is None:
        comp = np.zeros(V, np.int64)
    else:
        comp = np.asarray(component)
        if comp.shape != (V,) or not np.issubdtype(comp.dtype, np.integer):
            raise LodprtError(f"build_hierarchy: component must be a (V,) = ({V},) integer array, got "
                              f"{comp.shape} {comp.dtype}")
    if int(target_base) < 1:
        raise LodprtError(f"build_hierarchy: target_base must be >= 1 face, got {target_base}")
    nrm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(nrm > 0, normals / np.where(nrm > 0, nrm, 1), [0.0, 1.0, 0.0])

    # faces with a repeated corner carry no area or orientation: they take no part in the collapses
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    work = faces[good]
    groups = mesh_groups(V, work, None if component is None else comp)
    chain = pymeshlab_chain(positions, work, groups=groups, target_base=int(target_base), keep_boundary=keep_boundary)
    levels = len(chain)
    level = _levels_from_chain(V, work, chain)

    # topology: boundary vertices, and vertices where the surface is not a manifold (never collapsed)
    ekey, ecount, eface = _edges(work, V)
    quadric = _quadrics(positions, work, ekey, ecount, eface)
    boundary = np.zeros(V, bool)
    frozen = np.zeros(V, bool)
    if len(ekey):
        a, b = ekey // V, ekey % V
        bcount = np.bincount(np.r_[a[ecount == 1], b[ecount == 1]], minlength=V)
        boundary = bcount > 0
        frozen[a[ecount > 2]] = frozen[b[ecount > 2]] = True  # non-manifold edge
        frozen |= (bcount != 0) & (bcount != 2)  # non-manifold boundary vertex (bow tie)
    if frozen.any():
        log.info("hierarchy: %d vertices on non-manifold edges or vertices stay uncollapsed", int(frozen.sum()))

    # mutable mesh: faces as lists, incidence as sets (Python scalars: the loop is faster than numpy on 3-vectors)
    F = work.tolist()
    face_alive = [True] * len(F)
    incident: list[set] = [set() for _ in range(V)]
    for fi, f in enumerate(F):
        for x in f:
            incident[x].add(fi)
    P = positions.tolist()
    bnd = boundary.tolist()
    frz = frozen.tolist()
    stay = (frozen | boundary) if keep_boundary else frozen  # never collapsed (may still receive a collapse)
    stay_l = stay.tolist()
    cmp_ = comp.tolist()
    eff = np.where(level > 0, level, _INF_LEVEL).astype(np.int64)  # the level a vertex is due, deferrals included
    eff_l = eff.tolist()
    node_of = list(range(V))
    parent: list[int] = [-1] * V
    children: list[tuple[int, int]] = []
    vertex: list[int] = []
    nb_offsets = [0]
    nb_flat: list[int] = []
    err_v: list[int] = []
    err_count: list[int] = []
    err_faces: list[int] = []
    total = int((level > 0).sum())
    done = hinted = 0
    live = list(range(len(F)))
    fold_cos = FOLD_COS
    max_valence = MAX_VALENCE
    sliver2 = SLIVER * SLIVER

    def ring(v):
        s = set()
        for fi in incident[v]:
            s.update(F[fi])
        s.discard(v)
        return s

    def try_collapse(v, u, Nv):
        """Collapse v -> u when legal (module docstring); returns whether it did."""
        nonlocal done
        shared = []
        moved = []
        for fi in incident[v]:
            f = F[fi]
            if f[0] == u or f[1] == u or f[2] == u:
                shared.append(fi)
            else:
                moved.append(fi)
        ns = len(shared)
        if ns != (1 if bnd[v] else 2):  # boundary vertices only along boundary edges, interior along interior ones
            return False
        Nu = ring(u)
        union = len(Nv | Nu) - 2  # u's valence after the collapse
        if union < (2 if bnd[u] else 3) or union > max_valence:
            return False
        # link condition: common neighbours = the third corners of the faces on edge uv (Hoppe 96, Dey et al.)
        if len(Nv & Nu) != ns:
            return False
        # fold-over (thesis figure 6) and slivers, on every face that moves
        ux, uy, uz = P[u]
        vx, vy, vz = P[v]
        for fi in moved:
            f = F[fi]
            if f[0] == v:
                b, c = f[1], f[2]
            elif f[1] == v:
                b, c = f[2], f[0]
            else:
                b, c = f[0], f[1]
            bx, by, bz = P[b]
            cx, cy, cz = P[c]
            # old normal (b - v) x (c - v), new normal (b - u) x (c - u)
            e1x, e1y, e1z = bx - vx, by - vy, bz - vz
            e2x, e2y, e2z = cx - vx, cy - vy, cz - vz
            ox, oy, oz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            e1x, e1y, e1z = bx - ux, by - uy, bz - uz
            e2x, e2y, e2z = cx - ux, cy - uy, cz - uz
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            n2 = nx * nx + ny * ny + nz * nz
            if ox * nx + oy * ny + oz * nz <= fold_cos * math.sqrt(n2 * (ox * ox + oy * oy + oz * oz)):
                return False
            l1 = e1x * e1x + e1y * e1y + e1z * e1z
            l2 = e2x * e2x + e2y * e2y + e2z * e2z
            dx, dy, dz = cx - bx, cy - by, cz - bz
            l3 = dx * dx + dy * dy + dz * dz
            lmax = l1 if l1 > l2 else l2
            lmax = lmax if lmax > l3 else l3
            if n2 <= sliver2 * lmax * lmax:
                return False
        # apply
        for fi in shared:
            for x in F[fi]:
                if x != v:
                    incident[x].discard(fi)
            face_alive[fi] = False
        inc_u = incident[u]
        for fi in moved:
            f = F[fi]
            f[f.index(v)] = u
            inc_u.add(fi)
        incident[v] = set()
        quadric[u] += quadric[v]
        node = V + len(children)
        cu, cv = node_of[u], node_of[v]
        parent[cu] = node
        parent[cv] = node
        parent.append(-1)
        children.append((cu, cv))  # Hoppe 97 vertex hierarchy: child 0 the survivor, child 1 the collapsed vertex
        vertex.append(u)
        nb_flat.extend(sorted(Nv))
        nb_offsets.append(len(nb_flat))
        node_of[u] = node
        err_v.append(v)
        err_count.append(len(inc_u))
        for fi in inc_u:
            err_faces.extend(F[fi])
        done += 1
        if progress is not None and done % 4096 == 0:
            progress(done, total)
        return True

    def may_target(L):
        return (eff > L) & ~frozen

    pending: list[int] = []
    L = 0
    while True:
        L += 1
        if L > levels and (not pending or L > levels + EXTRA_LEVELS):
            break
        cands = pending + np.flatnonzero(level == L).tolist()
        for v in cands:
            if stay_l[v] or not incident[v]:
                eff[v] = eff_l[v] = _INF_LEVEL  # never collapses: stays a target for later levels
        cands = [v for v in cands if eff_l[v] < _INF_LEVEL]
        if not cands:
            pending = []
            continue
        before = done
        hint_keys, hint_score = (
            _representative_scores(V, chain[L - 2] if L >= 2 else work, chain[L - 1]) if L <= levels
            else (np.zeros(0, np.int64), np.zeros(0))
        )
        # candidate moves (v, u) on the current mesh, costs and pymeshlab hints, vectorised
        live = [fi for fi in live if face_alive[fi]]
        fa = np.array([F[fi] for fi in live], np.int64).reshape(-1, 3)
        src = np.concatenate([fa[:, 0], fa[:, 1], fa[:, 2], fa[:, 1], fa[:, 2], fa[:, 0]])
        dst = np.concatenate([fa[:, 1], fa[:, 2], fa[:, 0], fa[:, 0], fa[:, 1], fa[:, 2]])
        is_cand = np.zeros(V, bool)
        is_cand[cands] = True
        sel = is_cand[src] & may_target(L)[dst] & (comp[src] == comp[dst])
        keys = np.unique(src[sel] * V + dst[sel])
        vs, us = keys // V, keys % V
        h = np.concatenate([positions[us], np.ones((len(us), 1))], axis=1)
        cost = np.einsum("ki,kij,kj->k", h, quadric[vs] + quadric[us], h)
        cost += EDGE_WEIGHT * (((positions[us] - positions[vs]) ** 2).sum(1)) ** 2
        score = np.zeros(len(keys))
        if len(hint_keys):
            at = np.minimum(np.searchsorted(hint_keys, keys), len(hint_keys) - 1)
            score = np.where(hint_keys[at] == keys, hint_score[at], 0.0)
        own = np.full(V, np.inf)
        np.minimum.at(own, vs, cost)
        # v by its own (cheapest) cost; within v the pymeshlab representative first, then by cost
        order = np.lexsort((cost, -score, vs, own[vs]))
        vs_o, us_o, sc_o = vs[order].tolist(), us[order].tolist(), score[order].tolist()
        failed = [v for v in cands if own[v] == np.inf]
        i, n = 0, len(vs_o)
        while i < n:
            v = vs_o[i]
            j = i
            while j < n and vs_o[j] == v:
                j += 1
            Nv = ring(v)
            for k in range(i, j):
                if try_collapse(v, us_o[k], Nv):
                    hinted += sc_o[k] > 0
                    break
            else:
                failed.append(v)
            i = j
        # retry what failed once the level's other collapses have changed its neighbourhood
        hint = None
        for _ in range(2):
            if not failed:
                break
            if hint is None:
                hint = dict(zip(hint_keys.tolist(), hint_score.tolist()))
            still = []
            progressed = False
            for v in failed:
                Nv = ring(v)
                opts = []
                for u in Nv:
                    if eff_l[u] > L and not frz[u] and cmp_[u] == cmp_[v]:
                        hu = np.append(positions[u], 1.0)
                        e2 = float(((positions[u] - positions[v]) ** 2).sum())
                        c = float(hu @ (quadric[u] + quadric[v]) @ hu) + EDGE_WEIGHT * e2 * e2
                        opts.append((-hint.get(v * V + u, 0.0), c, u))
                opts.sort()
                for _, _, u in opts:
                    if try_collapse(v, u, Nv):
                        progressed = True
                        break
                else:
                    still.append(v)
            failed = still
            if not progressed:
                break
        pending = failed
        for v in pending:  # deferred to the next level
            eff[v] = eff_l[v] = L + 1
        log.debug("hierarchy level %d: %d collapses, %d deferred", L, done - before, len(pending))
        if L > levels and done == before:
            break
    if progress is not None:
        progress(done, total)
    log.info("hierarchy: %d of %d collapses went where pymeshlab's faces pointed", hinted, done)
    if pending:
        log.info("hierarchy: %d vertices pymeshlab removed found no legal collapse and stay in the base", len(pending))

    N = V + len(children)
    parent_a = np.asarray(parent, np.int32)
    children_a = np.full((N, 2), -1, np.int32)
    vertex_a = np.arange(N, dtype=np.int32)
    if children:
        children_a[V:] = children
        vertex_a[V:] = vertex
    axis, half, radius, height = _cones_and_radii(positions, normals, children_a, vertex_a, V)
    error = np.zeros((N, 3))
    if N > V:
        error[V:] = _error_vectors(positions, np.asarray(err_v, np.int64), np.asarray(err_count, np.int64),
                                   np.asarray(err_faces, np.int64).reshape(-1, 3))
    leaf_order, leaf_range = _leaf_layout(parent_a, children_a, V)
    hier = Hierarchy(
        num_vertices=V,
        parent=parent_a,
        children=children_a,
        vertex=vertex_a,
        creation=np.arange(N, dtype=np.int32),  # El-Sana & Varshney numbering: consecutive in build order
        cone_axis=axis.astype(np.float32),
        cone_half_angle=np.minimum(half + CONE_SLACK, math.pi).astype(np.float32),
        radius=(radius * (1 + 1e-6)).astype(np.float32),  # float32 rounding must not cut a leaf off
        error_vector=error.astype(np.float32),
        neighbour_offsets=np.concatenate([np.zeros(V, np.int64), np.asarray(nb_offsets, np.int64)]),
        neighbours=np.asarray(nb_flat, np.int32),
        leaf_order=leaf_order,
        leaf_range=leaf_range,
        levels=levels,
    )
    hier.__dict__["_depth"] = int(height.max(initial=0))
    hier.build_seconds = time.perf_counter() - t0
    log.info("hierarchy: %d vertices, %d nodes, %d roots, depth %d, %d pymeshlab levels, %.1f s", V, N,
             len(hier.roots), hier.depth, levels, hier.build_seconds)
    return hier


# ---------------------------------------------------------------------------------------------------------------
# per-node attributes


def _cones_and_radii(positions, normals, children, vertex, V):
    """Normal cones (figure 7), bounding radii and heights, bottom-up one height at a time (vectorised).

    A parent's cone is the minimal cone enclosing its two children's cones, so it holds every leaf normal below;
    its radius is the larger of child radius + distance from the parent's position to the child's.
    """
    N = len(children)
    axis = np.zeros((N, 3))
    half = np.zeros(N)
    radius = np.zeros(N)
    axis[:V] = normals
    height = [0] * N
    ch = children.tolist()
    for k in range(V, N):  # creation order: children first
        a, b = ch[k]
        ha, hb = height[a], height[b]
        height[k] = 1 + (ha if ha > hb else hb)
    height = np.asarray(height, np.int32)
    if N > V:
        internal = np.arange(V, N)
        order = internal[np.argsort(height[V:], kind="stable")]
        bounds = np.searchsorted(height[order], np.arange(1, height.max() + 2))
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            k = order[lo:hi]
            c0, c1 = children[k, 0], children[k, 1]
            axis[k], half[k] = _merge_cones(axis[c0], half[c0], axis[c1], half[c1])
            p = positions[vertex[k]]
            r0 = radius[c0] + np.linalg.norm(positions[vertex[c0]] - p, axis=1)
            r1 = radius[c1] + np.linalg.norm(positions[vertex[c1]] - p, axis=1)
            radius[k] = np.maximum(r0, r1)
    return axis, half, radius, height


def _merge_cones(a1, t1, a2, t2):
    """Minimal cones (M, 3) axes, (M,) half-angles holding cones (a1, t1) and (a2, t2) (unit axes, radians).

    If one cone holds the other, it is the answer; otherwise the half-angle is (g + t1 + t2) / 2 (g the angle
    between the axes) and the axis is a1 turned toward a2 by that minus t1; at pi the cone is the whole sphere.
    """
    c = (a1 * a2).sum(1)
    g = np.arctan2(np.linalg.norm(np.cross(a1, a2), axis=1), c)  # well conditioned near 0 and pi
    t = 0.5 * (g + t1 + t2)
    perp = a2 - c[:, None] * a1
    pn = np.linalg.norm(perp, axis=1)
    tiny = pn < 1e-12
    if tiny.any():  # (anti)parallel axes: any direction perpendicular to a1 will do
        e = np.where((np.abs(a1[tiny, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        alt = np.cross(a1[tiny], e)
        perp[tiny] = alt
        pn[tiny] = np.linalg.norm(alt, axis=1)
    perp /= pn[:, None]
    ang = (t - t1)[:, None]
    axis = np.cos(ang) * a1 + np.sin(ang) * perp
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    in1 = g + t2 <= t1
    in2 = ~in1 & (g + t1 <= t2)
    axis = np.where(in1[:, None], a1, np.where(in2[:, None], a2, axis))
    half = np.where(in1, t1, np.where(in2, t2, t))
    full = half >= math.pi
    axis[full] = a1[full]
    return axis, np.minimum(half, math.pi)


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest points (M, 3) on triangles (a, b, c) to points p, all (M, 3) (Ericson, Real-Time Collision
    Detection 5.1.5); degenerate triangles fall back to their closest edge or corner."""
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
    out = a + ab * (vb / safe)[:, None] + ac * (vc / safe)[:, None]  # interior
    with np.errstate(divide="ignore", invalid="ignore"):
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        out = np.where(m[:, None], a + ab * np.where(m, d1 / np.where(d1 - d3 != 0, d1 - d3, 1), 0)[:, None], out)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        out = np.where(m[:, None], a + ac * np.where(m, d2 / np.where(d2 - d6 != 0, d2 - d6, 1), 0)[:, None], out)
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        den = (d4 - d3) + (d5 - d6)
        out = np.where(m[:, None], b + (c - b) * np.where(m, (d4 - d3) / np.where(den != 0, den, 1), 0)[:, None], out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)  # corner regions take precedence
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)
    # a zero-area triangle: the closest of its three edges' closest points
    flat = ~(np.abs(denom) > 0)
    if flat.any():
        best = None
        for s, e in ((a, b), (b, c), (c, a)):
            d = e[flat] - s[flat]
            dd = (d * d).sum(1)
            tt = np.clip(((p[flat] - s[flat]) * d).sum(1) / np.where(dd > 0, dd, 1), 0, 1)
            q = s[flat] + d * tt[:, None]
            dist = ((p[flat] - q) ** 2).sum(1)
            if best is None:
                best, bq = dist, q
            else:
                take = dist < best
                best, bq = np.where(take, dist, best), np.where(take[:, None], q, bq)
        out[flat] = bq
    return out


def _error_vectors(positions, pv, counts, tris) -> np.ndarray:
    """Figure 10: ``p - p'`` for each collapse, p the collapsed vertex ``pv`` (C,), p' its closest point on the
    ``counts`` (C,) faces ``tris`` (sum counts, 3) around the survivor right after the collapse."""
    out = np.zeros((len(pv), 3))
    has = counts > 0
    if not len(tris):
        return out
    p = positions[np.repeat(pv, counts)]
    q = _closest_on_triangles(p, positions[tris[:, 0]], positions[tris[:, 1]], positions[tris[:, 2]])
    d2 = ((p - q) ** 2).sum(1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    idx = np.flatnonzero(has)
    best = np.minimum.reduceat(d2, starts[idx])
    seg = np.repeat(np.arange(len(idx)), counts[idx])
    hits = np.flatnonzero(d2 == best[seg])
    first = np.full(len(idx), -1)
    first[seg[hits][::-1]] = hits[::-1]  # the first closest face of each collapse
    out[idx] = p[first] - q[first]
    return out


def _leaf_layout(parent, children, V) -> tuple[np.ndarray, np.ndarray]:
    """Leaves (V,) int32 in depth-first order (child 0 first) and each node's [lo, hi) range (N, 2) int64 into it."""
    N = len(parent)
    order: list[int] = []
    rng = np.zeros((N, 2), np.int64)
    lo_l = [0] * N
    hi_l = [0] * N
    ch = children.tolist()
    stack = [(int(r), False) for r in np.flatnonzero(parent < 0)[::-1]]
    while stack:
        k, closing = stack.pop()
        if closing:
            hi_l[k] = len(order)
            continue
        lo_l[k] = len(order)
        c0, c1 = ch[k]
        if c0 < 0:
            order.append(k)
            hi_l[k] = len(order)
        else:
            stack.append((k, True))
            stack.append((c1, False))
            stack.append((c0, False))
    rng[:, 0] = lo_l
    rng[:, 1] = hi_l
    return np.asarray(order, np.int32), rng


# ---------------------------------------------------------------------------------------------------------------
# cuts


class Cut:
    """A front of active nodes: every original vertex has exactly one active ancestor-or-self.

    ``active`` (N,) bool; ``anc`` (V,) int32 each original vertex's active node. ``refine``/``coarsen`` apply the
    El-Sana & Varshney rules (module docstring) and return False, changing nothing, when a rule forbids the step;
    they raise LodprtError for a node id that does not exist. Their cost follows the node's subtree (its leaves
    are one slice of a depth-first order, their original edges one slice of a CSR table), never the mesh.
    """

    def __init__(self, hierarchy: Hierarchy, faces: np.ndarray, active: np.ndarray):
        self.h = hierarchy
        self.faces = np.asarray(faces, np.int64)
        V = hierarchy.num_vertices
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or (len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= V)):
            raise LodprtError(f"Cut: faces must be (F, 3) indices into the hierarchy's {V} vertices")
        self.active = np.asarray(active, bool).copy()
        # original adjacency in CSR, rows in depth-first leaf order, so a subtree's edges are one slice
        f = self.faces
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]], f[:, [1, 0]], f[:, [2, 1]], f[:, [0, 2]]])
        e = np.unique(e[e[:, 0] != e[:, 1]], axis=0)
        rank = np.empty(V, np.int64)
        rank[hierarchy.leaf_order] = np.arange(V)
        e = e[np.argsort(rank[e[:, 0]], kind="stable")]
        self._nbr = e[:, 1].astype(np.int32)
        self._ptr = np.searchsorted(rank[e[:, 0]], np.arange(V + 1))
        self.anc = active_ancestors(hierarchy, self.active)

    @classmethod
    def full(cls, hierarchy: Hierarchy, faces) -> "Cut":
        """The cut of all leaves: the original mesh."""
        a = np.zeros(hierarchy.num_nodes, bool)
        a[: hierarchy.num_vertices] = True
        return cls(hierarchy, faces, a)

    @classmethod
    def base(cls, hierarchy: Hierarchy, faces) -> "Cut":
        """The cut of all roots: the base mesh (plus isolated vertices)."""
        a = np.zeros(hierarchy.num_nodes, bool)
        a[hierarchy.roots] = True
        return cls(hierarchy, faces, a)

    @property
    def nodes(self) -> np.ndarray:
        """(A,) int32 the active nodes."""
        return np.flatnonzero(self.active).astype(np.int32)

    def _check(self, node: int) -> int:
        node = int(node)
        if not 0 <= node < self.h.num_nodes:
            raise LodprtError(f"node {node} does not exist (the hierarchy has {self.h.num_nodes} nodes)")
        return node

    def neighbours(self, node: int) -> np.ndarray:
        """(K,) int32 active nodes adjacent to ``node`` in the cut's mesh (an inactive node: its leaves' active
        neighbours), i.e. the active ancestors of the original neighbours of its leaves, itself excluded."""
        lo, hi = self.h.leaf_range[self._check(node)]
        n = np.unique(self.anc[self._nbr[self._ptr[lo] : self._ptr[hi]]])
        return n[n != node]

    def blockers_of_refine(self, node: int) -> np.ndarray:
        """Active neighbours that forbid splitting ``node``: created after it (El-Sana & Varshney, thesis 3.2)."""
        nb = self.neighbours(node)
        return nb[self.h.creation[nb] > self.h.creation[node]]

    def can_refine(self, node: int) -> bool:
        """Split rule: ``node`` active and internal, every active neighbour created before it."""
        h = self.h
        node = self._check(node)
        if not self.active[node] or h.children[node, 0] < 0:
            return False
        return bool((h.creation[self.neighbours(node)] < h.creation[node]).all())

    def can_coarsen(self, node: int) -> bool:
        """Collapse rule: both children of ``node`` active, every active neighbour of theirs has a parent created
        after ``node`` (a root's missing parent counts as later)."""
        node = self._check(node)
        c0 = self.h.children[node, 0]
        if c0 < 0 or not (self.active[c0] and self.active[self.h.children[node, 1]]):
            return False
        return not len(self.blockers_of_coarsen(node))

    def blockers_of_coarsen(self, node: int) -> np.ndarray:
        """Active neighbours of ``node``'s two active children that forbid collapsing them into ``node``: their
        parent was created no later than ``node`` (empty when the collapse is allowed or the children are not
        both active). The children's leaves are ``node``'s leaves: one slice, one pass."""
        h = self.h
        node = self._check(node)
        c0, c1 = h.children[node]
        if c0 < 0 or not (self.active[c0] and self.active[c1]):
            return np.zeros(0, np.int32)
        lo, hi = h.leaf_range[node]
        nb = np.unique(self.anc[self._nbr[self._ptr[lo] : self._ptr[hi]]])
        nb = nb[(nb != c0) & (nb != c1)]
        par = h.parent[nb]
        later = np.where(par < 0, np.iinfo(np.int32).max, h.creation[np.maximum(par, 0)])
        return nb[later <= h.creation[node]].astype(np.int32)

    def try_coarsen(self, node: int) -> np.ndarray:
        """Collapse the children of ``node`` when allowed; returns the blockers (empty: it collapsed, or there was
        nothing to collapse because the children are not both active)."""
        h = self.h
        node = self._check(node)
        c0, c1 = h.children[node]
        if c0 < 0 or not (self.active[c0] and self.active[c1]):
            return np.zeros(0, np.int32)
        b = self.blockers_of_coarsen(node)
        if not len(b):
            self._collapse(node)
        return b

    def refine(self, node: int) -> bool:
        """Split ``node`` into its two children when the split rule allows; returns whether it did."""
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
        """Collapse the two active children of ``node`` into it when the collapse rule allows; returns whether
        it did."""
        if not self.can_coarsen(node):
            return False
        self._collapse(node)
        return True

    def _collapse(self, node: int) -> None:
        c0, c1 = self.h.children[node]
        self.active[c0] = self.active[c1] = False
        self.active[node] = True
        lo, hi = self.h.leaf_range[node]
        self.anc[self.h.leaf_order[lo:hi]] = node

    def _edge_segments(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For many nodes at once: (seg, nb) the index into ``nodes`` and the active node at the far end of every
        original edge leaving the nodes' leaves (one CSR slice per node, concatenated)."""
        lr = self.h.leaf_range[nodes]
        lo, hi = self._ptr[lr[:, 0]], self._ptr[lr[:, 1]]
        return np.repeat(np.arange(len(nodes)), hi - lo), self.anc[self._nbr[concat_ranges(lo, hi)]]

    def _set_leaves(self, nodes: np.ndarray) -> None:
        """anc of every leaf under each of ``nodes`` becomes that node (vectorised over the nodes' slices)."""
        lr = self.h.leaf_range[nodes]
        self.anc[self.h.leaf_order[concat_ranges(lr[:, 0], lr[:, 1])]] = np.repeat(nodes, lr[:, 1] - lr[:, 0])

    def _split(self, nodes: np.ndarray) -> None:
        """Make the children of ``nodes`` active in their place (no rule checked: the callers did)."""
        ch = self.h.children[nodes].ravel()
        self.active[nodes] = False
        self.active[ch] = True
        self._set_leaves(ch)

    def refine_many(self, nodes) -> np.ndarray:
        """Split every node of ``nodes`` whose split rule holds now, all at once; returns the (K,) bool mask of the
        nodes split. Simultaneous splits stay legal: a split only replaces a node by children created before it,
        so a neighbour's rule (every active neighbour created before it) still holds afterwards."""
        h = self.h
        nodes = np.asarray(nodes, np.int64)
        ok = self.active[nodes] & (h.children[nodes, 0] >= 0)
        cand = nodes[ok]
        if len(cand):
            seg, nb = self._edge_segments(cand)
            bad = (nb != cand[seg]) & (h.creation[nb] > h.creation[cand[seg]])
            legal = np.bincount(seg[bad], minlength=len(cand)) == 0
            self._split(cand[legal])
            ok[np.flatnonzero(ok)[~legal]] = False
        return ok

    def coarsen_many(self, nodes) -> tuple[np.ndarray, np.ndarray]:
        """Collapse the children of every node of ``nodes`` whose collapse rule holds now, all at once; returns
        (done (K,) bool, blocker (K,) int64: one active neighbour forbidding the collapse, -1 where none). Two
        collapses that are both allowed never touch each other (if their children were adjacent, each rule would
        need the other parent created later), so doing them together is legal."""
        h = self.h
        nodes = np.asarray(nodes, np.int64)
        c = h.children[nodes]
        ok = (c[:, 0] >= 0) & self.active[np.maximum(c[:, 0], 0)] & self.active[np.maximum(c[:, 1], 0)]
        blocker = np.full(len(nodes), -1, np.int64)
        cand = nodes[ok]
        if len(cand):
            seg, nb = self._edge_segments(cand)
            cc = h.children[cand[seg]]
            par = h.parent[nb]
            later = np.where(par < 0, np.iinfo(np.int64).max, h.creation[np.maximum(par, 0)].astype(np.int64))
            bad = (nb != cc[:, 0]) & (nb != cc[:, 1]) & (later <= h.creation[cand[seg]])
            legal = np.bincount(seg[bad], minlength=len(cand)) == 0
            first = np.full(len(cand), -1, np.int64)
            first[seg[bad][::-1]] = nb[bad][::-1]  # the first blocker of each node
            go = cand[legal]
            ch = h.children[go]
            self.active[ch.ravel()] = False
            self.active[go] = True
            self._set_leaves(go)
            where = np.flatnonzero(ok)
            blocker[where] = first
            ok[where[~legal]] = False
        return ok, blocker

    def force_refine_many(self, nodes, *, max_rounds: int | None = None) -> int:
        """Forced refinement of many active nodes at once (seed 003, table 5.1): rounds that split every node of
        the set whose split rule holds (as ``refine_many``) and add to the set the active neighbours that block
        the others (created later, so coarser). A blocked node remembers one blocker and is looked at again only
        once that blocker has been split, so a large subtree is not rescanned every round. Each round splits at
        least the latest-created node of the set (its neighbours are all older). ``max_rounds`` stops early (the
        cut is legal after every round; what is left can be forced later). Returns the number of splits."""
        h = self.h
        want = np.unique(np.asarray(nodes, np.int64))
        want = want[self.active[want] & (h.children[want, 0] >= 0)]
        rep = np.full(len(want), -1, np.int64)  # a blocker seen last time (-1: look now)
        splits = rounds = 0
        while len(want) and (max_rounds is None or rounds < max_rounds):
            rounds += 1
            look = (rep < 0) | ~self.active[np.maximum(rep, 0)]
            scan = want[look]
            seg, nb = self._edge_segments(scan)
            bad = (nb != scan[seg]) & (h.creation[nb] > h.creation[scan[seg]])
            legal = np.bincount(seg[bad], minlength=len(scan)) == 0
            go = scan[legal]
            self._split(go)
            splits += len(go)
            first = np.full(len(scan), -1, np.int64)
            first[seg[bad][::-1]] = nb[bad][::-1]
            rep[look] = first
            keep = self.active[want]
            want, rep = want[keep], rep[keep]
            new = np.setdiff1d(np.unique(nb[bad]), want)
            new = new[self.active[new]]  # a blocker split this round is gone; its children show up when looked at
            want = np.concatenate([want, new])
            rep = np.concatenate([rep, np.full(len(new), -1, np.int64)])
            if not len(go) and not len(new) and not ((rep < 0) | ~self.active[np.maximum(rep, 0)]).any():
                for k in want:  # cannot happen for a valid cut: fall back to one at a time
                    splits += self.force_refine(int(k))
                break
        return splits

    def force_refine(self, node: int) -> int:
        """Make ``node``'s split happen (seed 003, table 5.1 forced refinement): activate it by splitting its
        active ancestor down to it, each split first splitting, recursively, every neighbour the split rule needs
        split. Returns the number of splits made (0 when ``node`` is already split). Raises LodprtError for a
        leaf (nothing to split)."""
        h = self.h
        node = self._check(node)
        if h.children[node, 0] < 0:
            raise LodprtError(f"node {node} is a leaf: nothing to split")
        splits = 0
        if not self.active[node]:
            a = int(self.anc[h.leaves(node)[0]])
            if h.creation[a] < h.creation[node]:
                return 0  # a descendant is active: node is already split
            path = []
            k = node
            while k != a:
                k = int(h.parent[k])
                path.append(k)
            for k in path[::-1]:  # from the active ancestor down to node's parent
                splits += self._force_split(k)
        return splits + self._force_split(node)

    def _force_split(self, node: int) -> int:
        stack = [node]
        splits = 0
        while stack:
            k = stack[-1]
            if not self.active[k]:
                stack.pop()
                continue
            blockers = self.blockers_of_refine(k)
            if len(blockers):  # coarser neighbours first; their creation numbers grow, so this ends
                stack.extend(int(b) for b in blockers)
                continue
            if not self.refine(k):
                raise LodprtError(f"forced refinement of node {k} failed")  # cannot happen: rule checked above
            splits += 1
            stack.pop()
        return splits

    def triangles(self, *, return_index: bool = False):
        """Faces of the cut's mesh in original vertex ids (vertex of each active ancestor), degenerate ones
        dropped; with ``return_index`` also the original face of each."""
        return triangulate(self.h, self.faces, self.anc, return_index=return_index)


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
    return f, (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])


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
