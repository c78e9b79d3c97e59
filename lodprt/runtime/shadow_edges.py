"""The actual light's shadow edges in the view cut (M-6; docs/RUNTIME.md "Lights anywhere"): the per-node bounds
S-2 are made from the light samples, whose shadows lie elsewhere than the actual light's when a light sits between
them (a thin occluder's shadow moves farther than a node between two samples, and no sample marks the nodes the
actual shadow edge crosses). The direct path (M-3) already casts a shadow ray from every drawn vertex toward every
light, so the frame knows where the cut's own triangles straddle the actual light's shadow edges:

    M-6   e_shadow(n) = c(A_n) max over the cut triangles at n's vertex whose vertices disagree in which lights
          reach them of max_c |L_a - L_b| / white          (L the drawn radiance of the triangle's vertices a, b)

with ``c(A)`` S-1's area weight (1 up to ``A_ref`` pixels, ``sqrt(A / A_ref)`` above, ``A`` the pixels of the
node's projected bounding sphere, as ``kernels.runtime.view_errors`` weighs S-2). The run time takes ``max(S-1, e_shadow)`` for the active node of each such
vertex (a refine candidate) and for its parent (a coarsen candidate: the collapse that would merge the two sides),
so the cut refines along the actual edge until the step each triangle straddles weighs at most the bound, over the
frames that follow (each frame's relight tells the next where the edge is).
"""

from __future__ import annotations

import numpy as np


def area_weight(pixels: np.ndarray, area_ref: float) -> np.ndarray:
    """S-1's ``c(A)``: 1 up to ``area_ref`` pixels (a node in view decides at least one pixel), ``sqrt(A /
    area_ref)`` above."""
    a = np.asarray(pixels, np.float64)
    return np.where(a > area_ref, np.sqrt(a / max(area_ref, 1e-30)), 1.0)


def sphere_pixels(centres: np.ndarray, radii: np.ndarray, vp: np.ndarray, focal_px: float) -> np.ndarray:
    """The pixels ``pi r_px^2`` of bounding spheres on screen, ``r_px = r f / depth`` (1e18 when the eye is inside
    one or it lies behind the eye), as ``kernels.runtime.view_errors`` measures a node's footprint."""
    p = np.asarray(centres, np.float64)
    row = np.asarray(vp, np.float64)[3]
    depth = p @ row[:3] + row[3]  # the clip w of (p, 1)
    r = np.asarray(radii, np.float64)
    fp = np.where(depth > r, np.minimum(r * focal_px / np.maximum(depth, 1e-30), 1e9), 1e9)
    return np.pi * fp * fp


def straddling_steps(tri: np.ndarray, lit: np.ndarray, radiance: np.ndarray, white: float) -> np.ndarray:
    """M-6's step at each drawn vertex (A,): the largest ``max_c |L_a - L_b| / white`` over the triangles of
    ``tri`` (T, 3, indices into the A drawn vertices) at that vertex whose vertices disagree in ``lit`` (A,) (which
    lights reach them); 0 where no such triangle meets the vertex."""
    A = len(lit)
    step = np.zeros(A)
    if not len(tri) or not A:
        return step
    t = np.asarray(tri)
    m = np.take(np.asarray(lit), t)  # np.take: faster than fancy indexing
    cross = np.flatnonzero((m[:, 0] != m[:, 1]) | (m[:, 0] != m[:, 2]))
    if not len(cross):
        return step
    t = np.take(t, cross, axis=0)
    r = np.take(np.asarray(radiance), t, axis=0).astype(np.float64) / max(float(white), 1e-30)  # (T', 3, 3)
    a, b, c = r[:, 0], r[:, 1], r[:, 2]  # a channel's largest |L_a - L_b| is its largest less its least
    d = np.maximum(a, np.maximum(b, c)) - np.minimum(a, np.minimum(b, c))  # (T', 3 channels)
    d = np.maximum(d[:, 0], np.maximum(d[:, 1], d[:, 2]))  # (elementwise: numpy's max over a short axis is slow)
    np.maximum.at(step, t.ravel(), np.repeat(d, 3))
    return step


def shadow_edge_errors(h, anc: np.ndarray, vid: np.ndarray, step: np.ndarray, pixels) -> tuple[np.ndarray,
                                                                                              np.ndarray]:
    """M-6 per node: (nodes (K,) int64, e_shadow (K,) float64) for the internal active nodes of the drawn vertices
    ``vid`` (A,) with a positive ``step`` (A,) and their parents, ``anc`` the cut's active ancestor of every leaf
    and ``pixels(nodes) -> (K,)`` S-1's weight ``c(A)`` of each node. A parent takes its children's largest step."""
    V = h.num_vertices
    hit = step > 0
    if not hit.any():
        return np.zeros(0, np.int64), np.zeros(0)
    node = np.asarray(anc, np.int64)[np.asarray(vid, np.int64)[hit]]
    s = step[hit]
    par = h.parent[node]
    keys = np.concatenate([node[node >= V], par[par >= 0]])
    vals = np.concatenate([s[node >= V], s[par >= 0]])
    if not len(keys):
        return np.zeros(0, np.int64), np.zeros(0)
    nodes, inv = np.unique(keys, return_inverse=True)
    best = np.zeros(len(nodes))
    np.maximum.at(best, inv, vals)
    return nodes, best * pixels(nodes)


def follow_shadow_edges(rt, vid: np.ndarray, tri: np.ndarray, rad: np.ndarray) -> bool:
    """M-6 for the ``Runtime`` ``rt`` from the relight of its cut's vertices ``vid`` (triangles ``tri``, radiance
    ``rad``): the errors of the nodes whose cut triangles straddle the actual lights' shadow edges, for the next
    refinement passes (``CutRefinement.extra``; screen criterion, direct path, LOD on). Returns whether one of them
    is over the bound (the cut must move)."""
    lit = rt.lighting.lit_rows(len(vid))
    ref = rt.refinement
    if lit is None or not rt.lod or rt.criterion.name != "screen":
        ref.extra = None
        return False
    step = straddling_steps(tri, lit, rad, rt.white)
    cam = rt.camera
    area_ref = rt.criterion.area_ref(cam.width, cam.height)
    focal = rt.focal_px()

    def weight(nodes):
        return area_weight(sphere_pixels(rt.node_pos(nodes), rt.radius[nodes], rt.vp, focal), area_ref)

    nodes, err = shadow_edge_errors(rt.h, rt.cut.anc, vid, step, weight)
    ref.set_extra(nodes, err)
    over = bool((err > rt.error_bound).any())
    ref.dirty = ref.dirty or over
    return over
