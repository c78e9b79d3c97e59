"""Mesh groups for the hierarchy build, and pymeshlab's chained QEM halvings (SPEC 3; thesis 3.2).

``mesh_groups`` gives the groups ``lodprt.model.hierarchy_build`` builds independently (connected components, split
further by ``component``). ``halvings`` decimates one mesh level after level with ``optimalplacement=False``
(survivors keep their original, bit-identical positions; levels are nested), optionally with locked vertices; the
pymeshlab build seeds its rounds with it (``lodprt.model.hierarchy_pymeshlab``). ``pymeshlab_chain`` /
``pymeshlab_levels`` run it on whole groups and give the level at which each vertex disappears;
``representative_scores`` reads from two consecutive levels which survivor gained a removed vertex's edges: the
reference QEM decimation for comparisons (one halving of a whole mesh needs about 2.3 KB per vertex,
docs/SCALE.md). Details: docs/HIERARCHY.md.
"""

from __future__ import annotations

import logging

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.model.hierarchy import concat_ranges
from lodprt.model.meshio import referenced_mask

log = logging.getLogger(__name__)


def mesh_groups(V: int, faces: np.ndarray, component: np.ndarray | None = None) -> np.ndarray:
    """(V,) int64 group of every vertex: the connected components of the mesh, split further by ``component``
    (edges between different ``component`` values do not connect), numbered in the order of their smallest vertex
    id (as scipy's ``connected_components`` numbers them). Each group is decimated on its own. Union-find in one
    Warp thread (``lodprt.kernels.hierarchy_prepare.components``): a few milliseconds for a million faces."""
    from lodprt.devices import load_kernels
    from lodprt.kernels import hierarchy_prepare as kp
    from lodprt.launches import warp_view

    wp = warp()
    f = np.ascontiguousarray(faces, np.int32).reshape(-1, 3)
    if component is None:
        label = np.zeros(1, np.int32)
    else:
        label = np.asarray(component).reshape(-1)
        if label.dtype.kind not in "iub" or (len(label) and (label.min() < -2**31 or label.max() >= 2**31)):
            label = np.unique(label, return_inverse=True)[1].reshape(-1)  # any labels: their ranks
        label = np.ascontiguousarray(label, np.int32)
    if len(f) and (f.min() < 0 or f.max() >= V):
        raise LodprtError(f"mesh_groups: faces refer to vertices outside [0, {V})")
    if component is not None and len(label) != V:
        raise LodprtError(f"mesh_groups: component has {len(label)} entries for {V} vertices")
    group = np.zeros(V, np.int32)
    if V:
        load_kernels("cpu", kp)
        wp.launch(kp.components, dim=1, inputs=[warp_view(f, wp.int32), warp_view(label, wp.int32),
                                                int(component is not None),
                                                warp_view(np.empty(V, np.int32), wp.int32),
                                                warp_view(group, wp.int32)], device="cpu")
    return group.astype(np.int64)


def halvings(positions: np.ndarray, faces: np.ndarray, *, target_base: int, max_levels: int, keep_boundary: bool,
             locked: np.ndarray | None = None):
    """Chained pymeshlab QEM halvings of one mesh (positions (n, 3), faces (F, 3) local ids, every vertex used):
    yields the faces (F_L, 3) int64, in the same local ids, after each level, level 1 first.

    ``optimalplacement=False``: survivors keep their original, bit-identical positions, so every level is a set of
    half-edge collapses of the one before; the vertex scalar carries the id through ``autoclean``'s renumbering
    (exact below 2^53). ``locked`` (n,) bool: vertices no collapse may remove or move (a tile's border): only
    faces whose three corners are free are selected and simplified (``selected=True``). Stops at ``target_base``
    faces, when a halving removes less than 10% of the faces, or when pymeshlab refuses the mesh (logged)."""
    import pymeshlab

    n = len(positions)
    ids = np.arange(n, dtype=np.float64)
    ms = pymeshlab.MeshSet()
    scalar = ids if locked is None else np.where(locked, -(ids + 1), ids)  # a locked id is stored as -(id + 1)
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(positions, np.float64),
                               face_matrix=np.ascontiguousarray(faces, np.int32), v_scalar_array=scalar))
    nf = len(faces)
    for level in range(max_levels):
        if nf <= target_base:
            break
        if locked is not None:  # faces with all three corners free (inclusive: every corner selected)
            ms.compute_selection_by_condition_per_vertex(condselect="(q >= 0)")
            ms.compute_selection_transfer_vertex_to_face(inclusive=True)
        try:
            ms.meshing_decimation_quadric_edge_collapse(
                targetfacenum=max(nf // 2, target_base),
                optimalplacement=False,  # survivors stay at their original positions
                preservetopology=True,
                preserveboundary=keep_boundary,
                planarquadric=True,  # flat regions (the floor) thin out evenly instead of vanishing at once
                qualitythr=0.3,  # 0 stalls (REFERENCES.md)
                autoclean=True,
                selected=locked is not None,
            )
        except Exception as exc:  # pymeshlab.PyMeshLabException on meshes it cannot handle
            log.warning("pymeshlab decimation stopped after %d levels: %s", level, exc)
            break
        mesh = ms.current_mesh()
        q = np.rint(mesh.vertex_scalar_array()).astype(np.int64)
        vid = np.where(q >= 0, q, -q - 1)
        new_nf = mesh.face_number()
        yield vid[mesh.face_matrix()] if new_nf else np.zeros((0, 3), np.int64)
        if new_nf > 0.9 * nf:
            break
        nf = new_nf


def _chain_one(positions: np.ndarray, faces: np.ndarray, target_base: int, max_levels: int,
               keep_boundary: bool) -> list[np.ndarray]:
    """Chained pymeshlab halvings of one group (faces in original ids), level 1 first, in original ids."""
    ids = np.unique(faces)
    local = np.searchsorted(ids, faces)
    return [ids[f] for f in halvings(positions[ids], local, target_base=target_base, max_levels=max_levels,
                                     keep_boundary=keep_boundary)]


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


def levels_from_chain(V: int, faces: np.ndarray, chain: list[np.ndarray]) -> np.ndarray:
    """(V,) int32 level at which each vertex leaves the chain (1-based), 0 when it never does (or no face uses it).

    faces (F, 3) the mesh before the first level, chain ``pymeshlab_chain``'s meshes (nested)."""
    level = np.zeros(V, np.int32)
    alive = referenced_mask(V, faces)
    for L, f in enumerate(chain, 1):
        now = referenced_mask(V, f)
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
    return levels_from_chain(len(positions), faces, chain), len(chain)


def representative_scores(V: int, before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    survive, was = referenced_mask(V, after), referenced_mask(V, before)
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

