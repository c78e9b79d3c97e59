"""Vertex hierarchy build (SPEC 3; thesis 3.2, figures 5-7 and 10; Hoppe 97; El-Sana & Varshney 99):
``build_hierarchy``.

Steps: input checks; levels from pymeshlab (``lodprt.model.hierarchy_levels``); mesh topology and QEM quadrics;
replay of the levels as true binary half-edge collapses ``v -> u`` (figure 5; link condition, boundary rules,
valence, fold-over (figure 6) and sliver tests), each creating the next node (creation number = node id, fine to
coarse); cones, radii and error vectors of the nodes (``lodprt.model.hierarchy_attributes``). The collapse order
and legality rules are spelled out in docs/HIERARCHY.md.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Callable

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model.hierarchy import Hierarchy, leaf_layout
from lodprt.model.hierarchy_attributes import cones_and_radii, error_vectors
from lodprt.model.hierarchy_levels import levels_from_chain, mesh_groups, pymeshlab_chain, representative_scores

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


# ---------------------------------------------------------------------------------------------------------------
# pass 2 helpers: edges and QEM quadrics


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



def _checked_inputs(positions, faces, normals, component, target_base):
    """The inputs as float64 positions, int64 faces, unit float64 normals and (V,) int components (zeros when
    ``component`` is None); raises LodprtError naming the bad input."""
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
    return positions, faces, normals, comp


def _topology(positions: np.ndarray, work: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """QEM quadrics (V, 4, 4), boundary (V,) bool and frozen (V,) bool: vertices on a non-manifold edge (more than
    two faces) or at a non-manifold boundary vertex (bow tie), which take part in no collapse."""
    V = len(positions)
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
    return quadric, boundary, frozen


class _CollapseReplay:
    """Pass 2 (thesis figure 5): the levels replayed as binary half-edge collapses on a mutable copy of the mesh,
    recording the nodes they create. Faces are lists and incidence sets of Python scalars: on 3-vectors the loop is
    faster than numpy."""

    def __init__(self, positions, work, quadric, boundary, frozen, comp, level, keep_boundary, progress):
        V = len(positions)
        self.V = V
        self.positions = positions
        self.quadric = quadric  # summed into the survivor at every collapse
        self.frozen = frozen
        self.comp = comp
        self.level = level
        self.progress = progress
        self.F = work.tolist()
        self.face_alive = [True] * len(self.F)
        self.incident: list[set] = [set() for _ in range(V)]
        for fi, f in enumerate(self.F):
            for x in f:
                self.incident[x].add(fi)
        self.P = positions.tolist()
        self.bnd = boundary.tolist()
        self.frz = frozen.tolist()
        stay = (frozen | boundary) if keep_boundary else frozen  # never collapsed (may still receive a collapse)
        self.stay_l = stay.tolist()
        self.cmp_ = comp.tolist()
        # the level a vertex is due, deferrals included
        self.eff = np.where(level > 0, level, _INF_LEVEL).astype(np.int64)
        self.eff_l = self.eff.tolist()
        self.node_of = list(range(V))
        self.parent: list[int] = [-1] * V
        self.children: list[tuple[int, int]] = []
        self.vertex: list[int] = []
        self.nb_offsets = [0]
        self.nb_flat: list[int] = []
        self.err_v: list[int] = []
        self.err_count: list[int] = []
        self.err_faces: list[int] = []
        self.total = int((level > 0).sum())
        self.done = self.hinted = 0
        self.live = list(range(len(self.F)))
        self.pending: list[int] = []

    def ring(self, v):
        """The current neighbours of ``v`` (a set of vertex ids)."""
        F = self.F
        s = set()
        for fi in self.incident[v]:
            s.update(F[fi])
        s.discard(v)
        return s

    def legal(self, v, u, Nv):
        """The faces (shared, moved) of a legal collapse ``v -> u`` (docs/HIERARCHY.md), None when illegal."""
        F, P = self.F, self.P
        bnd = self.bnd
        shared = []
        moved = []
        for fi in self.incident[v]:
            f = F[fi]
            if f[0] == u or f[1] == u or f[2] == u:
                shared.append(fi)
            else:
                moved.append(fi)
        ns = len(shared)
        if ns != (1 if bnd[v] else 2):  # boundary vertices only along boundary edges, interior along interior ones
            return None
        Nu = self.ring(u)
        union = len(Nv | Nu) - 2  # u's valence after the collapse
        if union < (2 if bnd[u] else 3) or union > MAX_VALENCE:
            return None
        # link condition: common neighbours = the third corners of the faces on edge uv (Hoppe 96, Dey et al.)
        if len(Nv & Nu) != ns:
            return None
        # fold-over (thesis figure 6) and slivers, on every face that moves
        fold_cos = FOLD_COS
        sliver2 = SLIVER * SLIVER
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
                return None
            l1 = e1x * e1x + e1y * e1y + e1z * e1z
            l2 = e2x * e2x + e2y * e2y + e2z * e2z
            dx, dy, dz = cx - bx, cy - by, cz - bz
            l3 = dx * dx + dy * dy + dz * dz
            lmax = l1 if l1 > l2 else l2
            lmax = lmax if lmax > l3 else l3
            if n2 <= sliver2 * lmax * lmax:
                return None
        return shared, moved

    def apply(self, v, u, Nv, shared, moved):
        """Make the collapse ``v -> u`` and record the node it creates (children: the survivor's node, then v's)."""
        F, incident = self.F, self.incident
        for fi in shared:
            for x in F[fi]:
                if x != v:
                    incident[x].discard(fi)
            self.face_alive[fi] = False
        inc_u = incident[u]
        for fi in moved:
            f = F[fi]
            f[f.index(v)] = u
            inc_u.add(fi)
        incident[v] = set()
        self.quadric[u] += self.quadric[v]
        V = self.V
        node = V + len(self.children)
        cu, cv = self.node_of[u], self.node_of[v]
        self.parent[cu] = node
        self.parent[cv] = node
        self.parent.append(-1)
        self.children.append((cu, cv))  # Hoppe 97 vertex hierarchy: child 0 the survivor, child 1 the collapsed vertex
        self.vertex.append(u)
        self.nb_flat.extend(sorted(Nv))
        self.nb_offsets.append(len(self.nb_flat))
        self.node_of[u] = node
        self.err_v.append(v)
        self.err_count.append(len(inc_u))
        for fi in inc_u:
            self.err_faces.extend(F[fi])
        self.done += 1
        if self.progress is not None and self.done % 4096 == 0:
            self.progress(self.done, self.total)

    def try_collapse(self, v, u, Nv):
        """Collapse v -> u when legal; returns whether it did."""
        faces = self.legal(v, u, Nv)
        if faces is None:
            return False
        self.apply(v, u, Nv, *faces)
        return True

    def candidates(self, L):
        """The vertices due at level ``L`` (deferred ones first) that can collapse; the others (kept or unused)
        become targets for every later level."""
        cands = self.pending + np.flatnonzero(self.level == L).tolist()
        for v in cands:
            if self.stay_l[v] or not self.incident[v]:
                self.eff[v] = self.eff_l[v] = _INF_LEVEL  # never collapses: stays a target for later levels
        return [v for v in cands if self.eff_l[v] < _INF_LEVEL]

    def moves(self, cands, L, hint_keys, hint_score):
        """Candidate moves (v, u) on the current mesh in the order they are tried, vectorised: v by its own
        (cheapest) QEM cost, within v pymeshlab's representative first, then by cost. Returns (vs, us, scores) as
        lists and the candidates with no move at all."""
        V, positions, quadric, comp = self.V, self.positions, self.quadric, self.comp
        self.live = [fi for fi in self.live if self.face_alive[fi]]
        F = self.F
        fa = np.array([F[fi] for fi in self.live], np.int64).reshape(-1, 3)
        src = np.concatenate([fa[:, 0], fa[:, 1], fa[:, 2], fa[:, 1], fa[:, 2], fa[:, 0]])
        dst = np.concatenate([fa[:, 1], fa[:, 2], fa[:, 0], fa[:, 0], fa[:, 1], fa[:, 2]])
        is_cand = np.zeros(V, bool)
        is_cand[cands] = True
        may_target = (self.eff > L) & ~self.frozen
        sel = is_cand[src] & may_target[dst] & (comp[src] == comp[dst])
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
        order = np.lexsort((cost, -score, vs, own[vs]))
        failed = [v for v in cands if own[v] == np.inf]
        return vs[order].tolist(), us[order].tolist(), score[order].tolist(), failed

    def first_pass(self, cands, L, hint_keys, hint_score):
        """Each candidate's first legal move, in ``moves`` order; returns the candidates that found none."""
        vs_o, us_o, sc_o, failed = self.moves(cands, L, hint_keys, hint_score)
        i, n = 0, len(vs_o)
        while i < n:
            v = vs_o[i]
            j = i
            while j < n and vs_o[j] == v:
                j += 1
            Nv = self.ring(v)
            for k in range(i, j):
                if self.try_collapse(v, us_o[k], Nv):
                    self.hinted += sc_o[k] > 0
                    break
            else:
                failed.append(v)
            i = j
        return failed

    def retry(self, failed, L, hint_keys, hint_score):
        """Up to two more tries for what failed, once the level's other collapses have changed its neighbourhood
        (moves recomputed per vertex, same order); returns what still failed."""
        V, positions, quadric = self.V, self.positions, self.quadric
        eff_l, frz, cmp_ = self.eff_l, self.frz, self.cmp_
        hint = None
        for _ in range(2):
            if not failed:
                break
            if hint is None:
                hint = dict(zip(hint_keys.tolist(), hint_score.tolist()))
            still = []
            progressed = False
            for v in failed:
                Nv = self.ring(v)
                opts = []
                for u in Nv:
                    if eff_l[u] > L and not frz[u] and cmp_[u] == cmp_[v]:
                        hu = np.append(positions[u], 1.0)
                        e2 = float(((positions[u] - positions[v]) ** 2).sum())
                        c = float(hu @ (quadric[u] + quadric[v]) @ hu) + EDGE_WEIGHT * e2 * e2
                        opts.append((-hint.get(v * V + u, 0.0), c, u))
                opts.sort()
                for _, _, u in opts:
                    if self.try_collapse(v, u, Nv):
                        progressed = True
                        break
                else:
                    still.append(v)
            failed = still
            if not progressed:
                break
        return failed

    def run(self, work, chain):
        """Replay every level of ``chain`` (pymeshlab's meshes after each level; ``work`` before the first), then
        up to ``EXTRA_LEVELS`` more for the deferred vertices. A vertex with no legal collapse in its level is
        deferred to the next one; what nothing can remove stays in the base mesh."""
        levels = len(chain)
        L = 0
        while True:
            L += 1
            if L > levels and (not self.pending or L > levels + EXTRA_LEVELS):
                break
            cands = self.candidates(L)
            if not cands:
                self.pending = []
                continue
            before = self.done
            hint_keys, hint_score = (
                representative_scores(self.V, chain[L - 2] if L >= 2 else work, chain[L - 1]) if L <= levels
                else (np.zeros(0, np.int64), np.zeros(0))
            )
            failed = self.first_pass(cands, L, hint_keys, hint_score)
            self.pending = self.retry(failed, L, hint_keys, hint_score)
            for v in self.pending:  # deferred to the next level
                self.eff[v] = self.eff_l[v] = L + 1
            log.debug("hierarchy level %d: %d collapses, %d deferred", L, self.done - before, len(self.pending))
            if L > levels and self.done == before:
                break
        if self.progress is not None:
            self.progress(self.done, self.total)
        log.info("hierarchy: %d of %d collapses went where pymeshlab's faces pointed", self.hinted, self.done)
        if self.pending:
            log.info("hierarchy: %d vertices pymeshlab removed found no legal collapse and stay in the base",
                     len(self.pending))


def _assemble(positions, normals, replay: _CollapseReplay, levels: int) -> Hierarchy:
    """The ``Hierarchy`` of the collapses made: node arrays, cones, radii, error vectors and the leaf layout."""
    V = replay.V
    children = replay.children
    N = V + len(children)
    parent_a = np.asarray(replay.parent, np.int32)
    children_a = np.full((N, 2), -1, np.int32)
    vertex_a = np.arange(N, dtype=np.int32)
    if children:
        children_a[V:] = children
        vertex_a[V:] = replay.vertex
    axis, half, radius, height = cones_and_radii(positions, normals, children_a, vertex_a, V)
    error = np.zeros((N, 3))
    if N > V:
        error[V:] = error_vectors(positions, np.asarray(replay.err_v, np.int64),
                                  np.asarray(replay.err_count, np.int64),
                                  np.asarray(replay.err_faces, np.int64).reshape(-1, 3))
    leaf_order, leaf_range = leaf_layout(parent_a, children_a, V)
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
        neighbour_offsets=np.concatenate([np.zeros(V, np.int64), np.asarray(replay.nb_offsets, np.int64)]),
        neighbours=np.asarray(replay.nb_flat, np.int32),
        leaf_order=leaf_order,
        leaf_range=leaf_range,
        levels=levels,
    )
    hier.remember_depth(int(height.max(initial=0)))
    return hier


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
    """Build the binary vertex hierarchy of a triangle mesh (module docstring, docs/HIERARCHY.md).

    positions (V, 3) float, faces (F, 3) int, normals (V, 3) unit vertex normals (the leaves' cones);
    component (V,) int: vertices of different components never collapse into each other (e.g. ``Scene.object_id``:
    the floor and each object); target_base: the face count at which pymeshlab's chained halvings stop (the base
    mesh is that size or larger where collapses are refused); ``progress(done, total)`` reports collapses against
    the number pymeshlab suggested. Open boundaries, several components, non-manifold edges, duplicated vertices
    and faces with a repeated corner are accepted; unreferenced vertices become isolated roots.
    Raises LodprtError naming the bad input otherwise.
    """
    t0 = time.perf_counter()
    positions, faces, normals, comp = _checked_inputs(positions, faces, normals, component, target_base)
    V = len(positions)
    # faces with a repeated corner carry no area or orientation: they take no part in the collapses
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    work = faces[good]
    groups = mesh_groups(V, work, None if component is None else comp)
    chain = pymeshlab_chain(positions, work, groups=groups, target_base=int(target_base), keep_boundary=keep_boundary)
    levels = len(chain)
    level = levels_from_chain(V, work, chain)
    quadric, boundary, frozen = _topology(positions, work)
    replay = _CollapseReplay(positions, work, quadric, boundary, frozen, comp, level, keep_boundary, progress)
    replay.run(work, chain)
    hier = _assemble(positions, normals, replay, levels)
    hier.build_seconds = time.perf_counter() - t0
    log.info("hierarchy: %d vertices, %d nodes, %d roots, depth %d, %d pymeshlab levels, %.1f s", V, hier.num_nodes,
             len(hier.roots), hier.depth, levels, hier.build_seconds)
    return hier
