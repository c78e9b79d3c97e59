"""The view cut's error for the whole frame (docs/RUNTIME.md "An error target for the frame"; E-1..E-4): an
estimate of the frame's mean squared error against the full mesh from the per-node S-2 bounds, and the steering of
the per-node bound toward a stated PSNR.

    E-1   SSE = sum over the cut's coarse nodes in view of m min(pi r_px^2, W H), m the mean over the node's leaves
          of the squared T-15 residual of its subtree's collapses (units of white squared; the samples' values
          combined as S-2's bounds are, M-5)
    E-2   N   = the pixels the cut's front-facing triangles cover (projected areas, at most W H)
    E-3   PSNR_est = -10 log10(SSE / N)                         (display units of white, as ``frame_error``)
    E-4   the bound b for the next frames: the largest bound whose cut's E-3 meets the target, searched by
          bisection in log b between the largest bound that met it and the smallest that missed (``Steering``);
          before both are known, the largest S-1 error e such that the coarse nodes at or under e add at most
          10^(-PSNR / 10) N to E-1 (the rest are refined), or, under SLACK of the budget, b raised by
          sqrt(budget / E-1) (at least RAISE); never by more than MAX_STEP at once

A coarse node's subtree loses what T-15 cannot rebuild from coarser vertices; the mean of that residual's square
over its leaves, spread over the pixels the node covers, estimates the squared error the node adds (the S-2 bound,
the largest residual, would bound it, but spreads one edge's step over a whole node and overestimates by orders of
magnitude). The geometric error is held to ``pixel_tolerance`` pixels apart, and E-2 counts twice the pixels where
front faces overlap. ``benchmarks/view_cut.py`` compares E-3 with the measured PSNR.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from lodprt.errors import LodprtError

#: E-4: raise the bound by this factor when the estimate is under SLACK of the budget; steps at most MAX_STEP
RAISE = 1.15
SLACK = 0.6
MAX_STEP = 4.0
#: E-4: after this many settled steering rounds the search forgets the bound that missed and probes upward again
REPROBE = 8
#: the lowest and highest bounds the steering may reach (units of white)
BOUND_RANGE = (1e-4, 8.0)


def check_target(psnr) -> float | None:
    """``psnr`` as a float in (0, 200] dB, or None (None or "off": no target); LodprtError naming the field
    otherwise."""
    if psnr is None or (isinstance(psnr, str) and psnr.strip().lower() == "off"):
        return None
    try:
        p = float(psnr)
    except (TypeError, ValueError):
        p = float("nan")
    if not math.isfinite(p) or not 0 < p <= 200:
        raise LodprtError(f"target_psnr {psnr}: must be a PSNR in dB in (0, 200], or 'off'")
    return p


def covered_pixels(positions: np.ndarray, triangles: np.ndarray, vp: np.ndarray, eye, width: int,
                   height: int, lit: np.ndarray | None = None) -> float:
    """E-2: the screen area in pixels of the triangles (indices into ``positions``) that face ``eye`` and lie in
    front of it, projected by ``vp`` (projection @ view), summed and capped at the screen's; with ``lit`` (per
    position, bool) only the triangles with a lit vertex (a frame's error is measured over the pixels either frame
    shows non-black, ``lodprt.display.error_figure.error_numbers``: an unlit region adds no pixel)."""
    if not len(triangles):
        return 0.0
    p = np.asarray(positions, np.float64)
    t = np.asarray(triangles, np.int64)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    front = (np.cross(b - a, c - a) * (np.asarray(eye, np.float64) - a)).sum(1) > 0
    if lit is not None:
        front &= np.asarray(lit, bool)[t].any(1)
    clip = np.c_[p, np.ones(len(p))] @ np.asarray(vp, np.float64).T
    w = clip[:, 3]
    ok = front & (w[t] > 1e-9).all(1)
    xy = clip[:, :2] / np.where(w > 1e-9, w, 1.0)[:, None] * (0.5 * np.array([width, height]))
    u, v, s = xy[t[ok, 0]], xy[t[ok, 1]], xy[t[ok, 2]]
    area = 0.5 * np.abs((v[:, 0] - u[:, 0]) * (s[:, 1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (s[:, 0] - u[:, 0]))
    return float(min(area.sum(), width * height))


def psnr(sse: float, covered: float) -> float:
    """E-3 (inf when the estimate is 0)."""
    if sse <= 0 or covered <= 0:
        return float("inf")
    return float(-10.0 * math.log10(min(sse / covered, 1.0)))


def steer(bound: float, target_psnr: float, err: np.ndarray, sse: np.ndarray, covered: float) -> float:
    """E-4's guess of the bound from one estimate: the largest S-1 error ``err`` whose coarse nodes' E-1 terms
    ``sse`` stay within the budget (the rest refined) when over it; the bound raised when under it (E-1 grows about
    as the bound squared, so by sqrt(budget / E-1), at least RAISE); never by more than MAX_STEP at once."""
    budget = 10.0 ** (-target_psnr / 10.0) * max(covered, 1.0)
    total = float(sse.sum())
    if total > budget:
        order = np.argsort(err, kind="stable")
        keep = np.cumsum(sse[order]) <= budget
        new = float(err[order][keep][-1]) if keep.any() else bound / MAX_STEP
        new = min(new, bound / RAISE)
    elif total < SLACK * budget:
        new = bound * max(RAISE, math.sqrt(budget / max(total, 1e-30)))
    else:
        new = bound
    new = min(max(new, bound / MAX_STEP), bound * MAX_STEP)
    return float(min(max(new, BOUND_RANGE[0]), BOUND_RANGE[1]))


class Steering:
    """E-4 as a search for the largest bound whose frame meets the target: the bounds tried so far bracket it,
    ``meets`` (the largest whose estimate reached the target) and ``misses`` (the smallest that did not), and the
    next bound is their geometric mean once both are known (bisection in log bound), ``steer``'s guess before. The
    search settles on ``meets`` when the bracket is narrower than ``1 + step``; a bracket the frame no longer obeys
    (the camera or the lights moved) gives way to the new estimate, ``reset`` forgets it after a jump, and after
    REPROBE settled rounds it probes upward again (a frame that got easier)."""

    def __init__(self, target_psnr: float, step: float = 0.1):
        self.target, self.step = float(target_psnr), float(step)
        self.meets: float | None = None
        self.misses: float | None = None
        self.rounds_settled = 0

    def reset(self) -> None:
        self.meets = self.misses = None
        self.rounds_settled = 0

    def settled(self) -> bool:
        return self.meets is not None and self.misses is not None and self.misses <= self.meets * (1 + self.step)

    def next_bound(self, bound: float, estimated_psnr: float, err: np.ndarray, sse: np.ndarray,
                   covered: float) -> float:
        """The bound for the next frames after the cut at ``bound`` was estimated at ``estimated_psnr`` (E-3)."""
        if estimated_psnr >= self.target:
            self.meets = bound if self.meets is None else max(self.meets, bound)
            if self.misses is not None and self.misses <= self.meets:
                self.misses = None  # the frame changed: a bound that missed meets now
        else:
            self.misses = bound if self.misses is None else min(self.misses, bound)
            if self.meets is not None and self.meets >= self.misses:
                self.meets = None
        if self.settled():
            if self.rounds_settled < REPROBE:
                self.rounds_settled += 1
                return float(self.meets)
            self.misses, self.rounds_settled = None, 0  # the frame may have got easier: probe upward again
        if self.meets is not None and self.misses is not None:
            return float(math.sqrt(self.meets * self.misses))
        new = steer(bound, self.target, err, sse, covered)
        if self.misses is None and estimated_psnr >= self.target:
            new = max(new, bound * RAISE)  # no bound has missed yet: probe upward
        if self.misses is not None:
            new = min(new, self.misses)
        if self.meets is not None:
            new = max(new, self.meets)
        return float(min(max(new, BOUND_RANGE[0]), BOUND_RANGE[1]))


def estimate(rt, positions: np.ndarray, triangles: np.ndarray, steering: Steering | None = None,
             lit: np.ndarray | None = None) -> tuple[float, float | None]:
    """(E-3 of the Runtime ``rt``'s current cut, E-4's bound for the next frames from ``steering`` or None without
    one) from
    the cut's coarse nodes (culling, footprint and S-1 error from ``Runtime.node_errors(detail_only=True)``, E-1 from
    ``node_mean_square``) and its mesh (``positions`` of its vertices, ``triangles`` indices into them)."""
    cam = rt.camera
    act = np.flatnonzero(rt.cut.active)
    nodes = act[act >= rt.h.num_vertices]
    ne = rt.node_errors(nodes, exact=False, detail_only=True)
    ms = node_mean_square(rt, nodes)
    area = np.clip(projected_area(rt, nodes), 1.0, float(cam.width * cam.height))  # at least the pixel it decides
    face, cell = screen_hits(rt)
    seen = rt.faces[face[face >= 0]]  # (hits, 3) leaves of the faces the rays met first
    hidden = np.ones(rt.h.num_nodes, bool)
    hidden[rt.cut.anc[seen.ravel()]] = False
    hidden = hidden[nodes] & (area >= 2.0 * cell)  # no ray met a node large enough to be met: hidden behind others
    sse = np.where(ne.culled | hidden, 0.0, ms * area)
    cov = cell * float(lit[seen].any(1).sum()) if lit is not None else \
        covered_pixels(positions, triangles, rt.vp, cam.eye, cam.width, cam.height)
    est = psnr(float(sse.sum()), cov)
    new = None if steering is None else steering.next_bound(rt.error_bound, est, ne.error, sse, cov)
    return est, new


#: E-2: about this many coverage rays per frame, one per square cell of the screen (at least a pixel)
COVERAGE_RAYS = 10_000


def coverage_stride(width: int, height: int) -> int:
    """E-2: the side in pixels of the square screen cells, one coverage ray each (about COVERAGE_RAYS)."""
    return max(1, int(math.sqrt(width * height / COVERAGE_RAYS)))


def screen_hits(rt) -> tuple[np.ndarray, float]:
    """E-2's rays: the first face of the store's full mesh (-1: none) that a primary ray through the centre of each
    ``coverage_stride`` square cell of the screen meets (``kernels.runtime.first_hits``, the scene's
    BVH), and the pixels one cell stands for."""
    import warp as wp

    from lodprt.kernels import runtime as kr

    cam = rt.camera
    stride = coverage_stride(cam.width, cam.height)
    cols, rows = max(1, -(-cam.width // stride)), max(1, -(-cam.height // stride))
    inv = np.linalg.inv(np.asarray(rt.vp, np.float64))
    eye = np.asarray(cam.eye, np.float64)

    def ray(x, y):  # direction from the eye through the near plane at NDC (x, y)
        q = inv @ np.array([x, y, -1.0, 1.0])
        return q[:3] / q[3] - eye

    corner = ray(-1.0, 1.0)
    du, dv = (ray(1.0, 1.0) - corner) / cols, (ray(-1.0, -1.0) - corner) / rows
    mesh = rt.scene_bvh()
    face = wp.zeros(cols * rows, dtype=wp.int32, device=rt.device)
    vec = lambda a: wp.vec3(*map(float, a))  # noqa: E731
    wp.launch(kr.first_hits, dim=cols * rows, inputs=[mesh.id, vec(eye), vec(corner), vec(du), vec(dv), cols],
              outputs=[face], device=rt.device)
    return face.numpy(), cam.width * cam.height / (cols * rows)


_SURFACE: dict = {}  # id(hierarchy) -> (weak reference to it, (N,) float32 surface area under each node)
#: faces whose areas are made at once
CHUNK = 1 << 18


def subtree_areas(h, positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N,) float32 the surface area under each node: a third of each face's area at each of its corners, summed
    over the node's leaves (float64 sums, ``CHUNK`` faces at a time)."""
    p, V = positions, h.num_vertices
    va = np.zeros(V)
    for a in range(0, len(faces), CHUNK):
        f = faces[a:a + CHUNK]
        third = np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]).astype(np.float64), axis=1)
        third /= 6.0  # half the cross product's length, a third at each corner
        for j in range(3):
            va += np.bincount(f[:, j], third, minlength=V)[:V]
    run = np.r_[0.0, np.cumsum(va[h.leaf_order])]
    return (run[h.leaf_range[:, 1]] - run[h.leaf_range[:, 0]]).astype(np.float32)


def projected_area(rt, nodes: np.ndarray) -> np.ndarray:
    """The pixels each node's surface covers: its area in the scene (a third of each face at each of its leaves)
    foreshortened by its normal cone's axis toward the eye (at least 0.2; 0.5 for cones wider than 60 degrees) and
    scaled by (focal / depth)^2."""
    h = rt.h
    known = _SURFACE.get(id(h))
    if known is None or known[0]() is not h:
        _SURFACE[id(h)] = (weakref.ref(h), subtree_areas(h, rt.positions, rt.faces))
    area = _SURFACE[id(h)][1][nodes]
    p = rt.node_pos(nodes)
    v = np.asarray(rt.camera.eye, np.float64)[None] - p
    dist = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
    cos = np.abs((rt.axis[nodes] * v).sum(1)) / dist
    cos = np.where(rt.half[nodes] > math.radians(60), 0.5, np.maximum(cos, 0.2))
    depth = np.maximum(np.c_[p, np.ones(len(p))] @ rt.vp[3], 1e-9)
    return area * cos * (rt.focal_px() / depth) ** 2


def derive_mean_square(rt, levels: list | None = None) -> None:
    """E-1's per-sample mean squared residual per internal node (``node_bounds.detail_mean_square``), made with
    each sample the Runtime's cache holds from now on (the Runtime asks for it before its first sample: made
    then with each sample's field, not again)."""
    from lodprt.runtime import node_bounds

    cache, h = rt.samples, rt.h
    if "detail_ms" not in cache.derived:
        plan, white = rt.store.completion_plan(), rt.white
        levels = node_bounds.height_levels(h) if levels is None else levels
        cache.derive("detail_ms", lambda c: node_bounds.detail_mean_square(h, c, white, plan, levels),
                     h.num_nodes - h.num_vertices, (cache.C,), np.float32)


def node_mean_square(rt, nodes: np.ndarray) -> np.ndarray:
    """E-1's per-pixel squared error of each coarse node under the current lights (units of white squared): the
    samples' mean squared completion residual (``node_bounds.detail_mean_square``, made with each sample) as RMS
    values combined like S-2's bounds: sum_j |W_jc| rms_jc for T-12, max over the samples around the light times
    sum_j |W_jc| for a direct interpolation (M-5); the largest channel, squared."""
    cache, h = rt.samples, rt.h
    derive_mean_square(rt)
    rms = np.sqrt(cache.derived["detail_ms"][0][nodes - h.num_vertices][:, rt.used_slots])  # (K, U, C)
    w = np.abs(rt.sample_weights[rt.used_samples])  # (U, 3)
    if rms.shape[2] == 1:
        rms = np.repeat(rms, 3, axis=2)
    if rt.interpolation == "thesis":
        per = (rms * w[None]).sum(1)
    else:
        near = rt.lighting.bracket_mask()[rt.used_slots].astype(bool)
        per = (rms[:, near].max(1) if near.any() else rms.max(1)) * w.sum(0)[None]
    return per.max(1) ** 2


def toward_budget(bound: float, triangles: int, budget: int) -> float:
    """The bound steered toward a triangle budget: x1.25 above it, /1.1 under 80% of it, else unchanged."""
    if triangles > budget:
        return max(bound, 1e-4) * 1.25
    if triangles < 0.8 * budget:
        return bound / 1.1
    return bound
