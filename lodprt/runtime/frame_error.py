"""The view cut's error for the whole frame (docs/RUNTIME.md "An error target for the frame"; E-1..E-5): the
frame's mean squared error against the full mesh, on every pixel or a grid of primary rays, the steering of the
per-node bound toward a stated PSNR in motion, and the refinement of a still frame where its error is.

    E-1   MSE = the mean over the covered rays of the squared difference, clipped at white and averaged over RGB,
          between the full mesh and the cut's mesh where one primary ray per screen cell meets each
          (``sampled_error``): the face met, its corners relit under the current lights (T-7, M-1; the cut's as
          the frame relit them), their positions, normals and coefficients interpolated at the hit and evaluated
          toward the eye, as the renderer draws a fragment (``kernels.runtime.hit_radiance``)
    E-2   the rays: one per pixel (the first frame, a still one) or per square cell of about COVERAGE_RAYS cells
          (in motion), halved while fewer than MIN_COVERED of them are covered (``screen_hits``,
          ``kernels.runtime.first_hits`` on the full mesh's BVH, ``reference``, and on a BVH of the cut's mesh);
          covered: either mesh non-black there
    E-3   PSNR_est = -10 log10(MSE)                         (display units of white, as ``error_numbers``)
    E-4   the bound b for the next frames: the largest bound whose cut's E-3 meets the target, searched by
          bisection in log b between the largest bound that met it and the smallest that missed (``Steering``);
          before both are known, the largest S-1 error e such that the coarse nodes at or under e stay within
          the budget 10^(-PSNR / 10) N (the sampled squared error N MSE shared out over the cut's coarse nodes in
          proportion to a model of their terms: the mean over each node's leaves of the squared T-15 residual of
          its subtree's collapses times its projected area; the rest are refined), or, under SLACK of the budget,
          b raised by sqrt(budget / SSE) (at least RAISE); never by more than MAX_STEP at once
    E-5   a still frame (``pin``): from the coarsest bound, split the coarse nodes carrying the most of E-1 on
          every pixel (each ray's to the coarse corners of the face it meets first, in the cut's mesh or the
          full one) until they cover the excess over 10^(-PSNR / 10) N; measure again; repeat

E-1 measures the frame's own error the way ``lodprt.display.compare`` measures it, on a sample of its pixels:
shading (the cut's coarse triangles interpolate what the full mesh's fine ones resolve), shadow edges, highlights
and silhouettes alike, under the actual lights rather than the light samples' bounds, so it is neither a bound nor a
model. Sampled on every pixel it is the measured error (to the pixel or two where a ray and the rasteriser
disagree at an edge); on the default grid its error is the sampling's, largest where a few pixels of silhouette
carry much of the error. ``benchmarks/view_cut.py`` compares E-3 with the measured PSNR.
"""

from __future__ import annotations

import dataclasses
import math
import weakref

import numpy as np


#: E-4: raise the bound by this factor when the estimate is under SLACK of the budget; steps at most MAX_STEP
RAISE = 1.15
SLACK = 0.6
MAX_STEP = 4.0
#: E-4: after this many settled steering rounds the search forgets the bound that missed and probes upward again
REPROBE = 8
#: the lowest and highest bounds the steering may reach (units of white)
BOUND_RANGE = (1e-4, 8.0)


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
    search settles on ``meets`` when the bracket is narrower than ``1 + step`` and an estimate at ``meets`` has met
    the target since the last miss (``settled``); a bracket the frame no longer obeys
    (the camera or the lights moved) gives way to the new estimate, ``reset`` forgets it after a jump, and after
    REPROBE settled rounds it probes upward again (a frame that got easier)."""

    def __init__(self, target_psnr: float, step: float = 0.1):
        self.target, self.step = float(target_psnr), float(step)
        self.meets: float | None = None
        self.misses: float | None = None
        self.rounds_settled = 0
        self.confirmed = False  # the last estimate was made at ``meets`` and met the target

    def reset(self) -> None:
        self.meets = self.misses = None
        self.rounds_settled = 0
        self.confirmed = False

    def bracketed(self) -> bool:
        """Whether the bounds that met and missed lie within ``1 + step`` of each other."""
        return self.meets is not None and self.misses is not None and self.misses <= self.meets * (1 + self.step)

    def settled(self) -> bool:
        """Bracketed, and the cut at ``meets`` met the target at its last estimate: the cut a bound gives depends
        on the bounds before it (a node refines above the bound and collapses at or under bound / 1.25), so a
        bound that met on the way up is estimated again on the way down before the search rests there."""
        return self.bracketed() and self.confirmed

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
        self.confirmed = estimated_psnr >= self.target and bound == self.meets
        if self.bracketed() and not self.confirmed:
            self.rounds_settled = 0
            return float(self.meets)  # estimate the cut at the bound that met once more, as it stands now
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


def estimate(rt, vid: np.ndarray, triangles: np.ndarray, steering: Steering | None = None,
             coefficients: np.ndarray | None = None, *, stride: int | None = None) -> tuple[float, float | None, int]:
    """(E-3 of the Runtime ``rt``'s current cut, E-4's bound for the next frames from ``steering`` or None without
    one, the cells' side in pixels it sampled): E-1 sampled on E-2's rays (``sampled_error``: the cut's mesh, ``vid``
    (A,) its vertices, ``triangles`` indices into them, ``coefficients`` their relit ones when the frame has them,
    against the full mesh, both relit under the current lights; ``stride``: the cells' side in pixels, default
    ``coverage_stride``, 1 on every pixel; halved while fewer than MIN_COVERED rays meet what either mesh shows,
    ``finer``); E-4 shares it out over the cut's coarse nodes in proportion to their modelled terms (culling,
    footprint and S-1 error from ``Runtime.node_errors(detail_only=True)``, the residual from
    ``node_mean_square``)."""
    cam = rt.camera
    ref = reference(rt, stride)
    sample = sampled_error(rt, vid, triangles, ref, coefficients)
    while sample.covered < MIN_COVERED and (finer := ray_stride(cam.width, cam.height, ref.stride // 2)) < ref.stride:
        ref = reference(rt, finer)  # E-2: a scene small on screen gets a finer grid, down to every pixel
        sample = sampled_error(rt, vid, triangles, ref, coefficients)
    cov = ref.cell * sample.covered
    est = sample.psnr()
    if steering is None:
        return est, None, ref.stride
    act = np.flatnonzero(rt.cut.active)
    nodes = act[act >= rt.h.num_vertices]
    ne = rt.node_errors(nodes, exact=False, detail_only=True)
    ms = node_mean_square(rt, nodes)
    area = np.clip(projected_area(rt, nodes), 1.0, float(cam.width * cam.height))  # at least the pixel it decides
    seen = rt.faces[ref.face[ref.face >= 0]]  # (hits, 3) leaves of the faces the rays met first
    hidden = np.ones(rt.h.num_nodes, bool)
    hidden[rt.cut.anc[seen.ravel()]] = False
    hidden = hidden[nodes] & (area >= 2.0 * ref.cell)  # no ray met a node large enough to be met: hidden behind others
    sse = np.where(ne.culled | hidden, 0.0, ms * area)
    model = float(sse.sum())
    if model > 0:  # E-4: the nodes' shares of the sampled error, in proportion to their modelled terms
        sse *= sample.mean * cov / model
    return est, steering.next_bound(rt.error_bound, est, ne.error, sse, cov), ref.stride


#: E-4: frames between two estimates of a moving frame's error while the steering searches (twice as many once
#: it has settled)
ESTIMATE_FRAMES = 4


class EstimateSchedule:
    """Which frames estimate E-1, and how: the first frame refines where its error is on every pixel (E-5,
    ``Runtime.update``'s pin rounds); in motion, E-4's steering every ESTIMATE_FRAMES frames on E-2's grid (every
    2 ESTIMATE_FRAMES once settled; a jump of the camera or the lights forgets the bounds tried and waits for its
    turn); the first still frame (camera and lights as the last frame's: ``moved`` unset by ``set_camera``,
    ``set_lights``) runs E-5 once more (``confirmed``), and no estimate follows while it stays still (it would not
    change)."""

    def __init__(self):
        self.moved, self.confirmed = True, False

    def begin(self, frame: int, settle: bool, jumped: bool, steering: "Steering | None") -> tuple[bool, bool]:
        """(whether frame number ``frame`` estimates, whether it is still); resets ``steering`` on the first
        frame (``settle``) and a jump."""
        still = not self.moved and not settle
        if self.moved or settle:
            self.confirmed = False
        if steering is not None and (settle or jumped):
            steering.reset()
        self.moved = False
        if still:
            return not self.confirmed, True
        every = ESTIMATE_FRAMES * (2 if steering is not None and steering.settled() else 1)
        return settle or frame % every == 0, False


@dataclasses.dataclass(frozen=True)
class SampledError:
    """E-1 on the screen grid: ``mean`` the mean over the covered rays of the squared display difference (units of
    white squared, channels averaged, both clipped at white), ``covered`` the rays either mesh shows non-black."""

    mean: float
    covered: int

    @classmethod
    def of(cls, d2: np.ndarray, covered: np.ndarray) -> "SampledError":
        """From the per-ray squared differences ``d2`` and where either mesh is non-black (``ray_errors``)."""
        n = int(covered.sum())
        return cls(float(d2.sum()) / n if n else 0.0, n)

    def psnr(self) -> float:
        """E-3 of the sample (inf when it is 0)."""
        return psnr(self.mean * self.covered, self.covered)


@dataclasses.dataclass(frozen=True)
class Reference:
    """E-1's full-mesh side for one camera, lights and grid (``reference``): per ray of E-2's grid of ``stride``
    pixel cells (``cell`` pixels each), the first face of the full mesh it meets (``face``, -1: none), where on it
    (``bary``) and what the renderer draws there (``drawn`` (R, 3) radiance, 0 where it meets none)."""

    stride: int
    face: np.ndarray
    bary: np.ndarray
    drawn: np.ndarray
    cell: float


#: the last ``Reference`` made for each Runtime, with its key: the first frame's steering rounds and a still
#: camera's frames estimate cut after cut against the same full mesh, camera and lights
_REFERENCE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def reference(rt, stride: int | None) -> Reference:
    """E-1's full-mesh side on the grid of ``stride`` pixel cells (``ray_stride``; None: ``coverage_stride``'s)
    for the Runtime ``rt``'s camera and lights: the rays' first faces (``screen_hits``), their corners relit
    (``Runtime.relit``) and drawn as fragments (``hit_radiance``); made again only when the grid, the camera or
    the lights changed."""
    stride = ray_stride(rt.camera.width, rt.camera.height, stride)
    key = (stride, rt.camera, np.asarray(rt.light_positions, np.float64).tobytes(),
           np.asarray(rt.light_colors, np.float64).tobytes())
    held = _REFERENCE.get(rt)
    if held is not None and held[0] == key:
        return held[1]
    face, bary, cell = screen_hits(rt, stride=stride)
    hit = face >= 0
    ids, inverse = distinct_ids(rt.faces[face[hit]], rt.h.num_vertices)
    rows = np.full((len(face), 3), -1, np.int32)
    rows[hit] = inverse.reshape(-1, 3)
    coef = relit_rows(rt, ids)
    ref = Reference(stride, face, bary, hit_radiance(rt, rows, bary, ids, coef), cell)
    _REFERENCE[rt] = (key, ref)
    return ref


def distinct_ids(values: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(values, return_inverse=True)`` of ids in ``[0, n)``: (the distinct ids ascending (K,) int64,
    ``values``' rows among them, flat), by marking a table of ``n`` instead of sorting when there are at least
    n / 16 values (every pixel's hits: sorting 3 per ray costs more than a pass over the vertices; a grid's few
    rays on a huge mesh are sorted)."""
    flat = np.asarray(values, np.int64).ravel()
    if 16 * len(flat) < n:
        ids, inverse = np.unique(flat, return_inverse=True)
        return ids, inverse.ravel()
    mark = np.zeros(n, bool)
    mark[flat] = True
    ids = np.flatnonzero(mark)
    lut = np.empty(n, np.int64)
    lut[ids] = np.arange(len(ids))
    return ids, lut[flat]


def relit_rows(rt, ids: np.ndarray) -> np.ndarray:
    """(K, 3, ncoef) float32 coefficients of vertices ``ids`` (K,) under the Runtime ``rt``'s current lights
    (``Runtime.relit``; none: (0, 3, 1))."""
    return rt.relit(ids)[0] if len(ids) else np.zeros((0, 3, 1), np.float32)


def sampled_error(rt, vid: np.ndarray, triangles: np.ndarray, ref: Reference,
                  coefficients: np.ndarray | None = None) -> SampledError:
    """E-1 over E-2's rays (``ray_errors``): the mean squared difference over the covered rays."""
    return SampledError.of(*ray_errors(rt, vid, triangles, ref, coefficients)[:2])


def ray_errors(rt, vid: np.ndarray, triangles: np.ndarray, ref: Reference,
               coefficients: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """E-1 per ray of E-2's grid: the full mesh's radiance there (``ref``: ``reference``) against the cut's (the
    same ray through the cut's mesh: ``vid`` (A,) its vertices, ``triangles`` (M, 3) indices into them,
    ``coefficients`` (A, 3, ncoef) their relit ones if the frame has them, else the corners the rays meet are
    relit here), each as the renderer draws a fragment: the face's corners relit under the current lights (T-7
    with M-1), their positions, normals and coefficients interpolated at the hit and evaluated toward the eye
    (``kernels.runtime.hit_radiance``). Returns (R,) the squared difference, both clipped at white, averaged over
    RGB, in units of white squared (0 where neither is non-black), (R,) covered: either non-black (what
    ``lodprt.display.error_figure.error_numbers`` averages over the pixels), (R,) the row of ``triangles`` each
    ray met (-1: none) and (R, 3) the hit's weights of its corners."""
    vid = np.asarray(vid, np.int64)
    drawn = np.zeros_like(ref.drawn)
    cface, cbary = np.full(len(ref.face), -1, np.int32), np.zeros((len(ref.face), 3), np.float32)
    if len(triangles):
        cface, cbary = screen_hits(rt, cut_bvh(rt, vid, triangles), stride=ref.stride)[:2]
        chit = cface >= 0
        corners = np.asarray(triangles, np.int64)[cface[chit]]  # (hits, 3) rows of vid
        rows = np.full((len(cface), 3), -1, np.int32)
        if coefficients is None:  # relight the corners the rays meet
            ids, inverse = distinct_ids(vid[corners], rt.h.num_vertices)
            rows[chit] = inverse.reshape(-1, 3)
            coef = relit_rows(rt, ids)
        else:  # the cut's rows as the frame relit them
            ids, coef = vid, np.asarray(coefficients)
            rows[chit] = corners
        drawn = hit_radiance(rt, rows, cbary, ids, coef)
    d2, covered = clipped_squares(drawn, ref.drawn, rt.white)
    return d2, covered, cface, cbary


def pin(rt, vid: np.ndarray, triangles: np.ndarray, coefficients: np.ndarray | None) -> tuple[float, np.ndarray]:
    """E-3 of the Runtime ``rt``'s current cut on every pixel (``ray_errors``) and E-5's nodes to split so that it
    meets ``rt.target_psnr`` (``pinned_nodes``; empty when it meets it)."""
    ref = reference(rt, 1)
    d2, covered, cface, cbary = ray_errors(rt, vid, triangles, ref, coefficients)
    sample = SampledError.of(d2, covered)
    budget = 10.0 ** (-rt.target_psnr / 10.0) * sample.covered * ref.cell
    return sample.psnr(), pinned_nodes(rt, vid, triangles, ref, d2, (cface, cbary), budget)


def pinned_nodes(rt, vid: np.ndarray, triangles: np.ndarray, ref: Reference, d2: np.ndarray, cut_hits: tuple,
                 budget: float) -> np.ndarray:
    """E-5: the coarse nodes of the current cut to split so that the frame meets its budget of squared error
    (``budget``: ``10^(-P / 10)`` times the covered pixels): each ray's squared difference ``d2`` (``ray_errors``,
    on every pixel) goes to the mesh the ray meets first, the cut's (``cut_hits``: the face of ``triangles`` over
    ``vid`` and the hit's weights) or the full one (``ref``; a cut drawn in front of the full mesh, or a surface
    the cut lost), shared equally by the coarse active nodes (``Runtime.cut.anc`` of the corners) of the face it
    met there; the nodes with the largest shares, largest first, until their sum covers the excess over the
    budget (a node pinned already is not chosen again). Empty when the frame meets it."""
    excess = float(d2.sum()) * ref.cell - budget
    if excess <= 0:
        return np.zeros(0, np.int64)
    h, anc = rt.h, rt.cut.anc
    err = np.zeros(h.num_nodes)
    cface, cbary = cut_hits
    tri = np.asarray(triangles, np.int64)
    corners = (np.asarray(vid, np.int64)[tri[cface[cface >= 0]]], rt.faces[ref.face[ref.face >= 0]])
    depth = [np.full(len(d2), np.inf), np.full(len(d2), np.inf)]  # where each ray meets the cut's mesh, the full
    for k, (hit, bary) in enumerate(((cface >= 0, cbary), (ref.face >= 0, ref.bary))):
        w, p = np.asarray(bary[hit], np.float64), rt.positions[corners[k]]
        at = w[:, 0, None] * p[:, 0] + w[:, 1, None] * p[:, 1]  # the hit point: its corners weighted
        at += w[:, 2, None] * p[:, 2]
        at -= np.asarray(rt.camera.eye, np.float64)
        depth[k][hit] = np.linalg.norm(at, axis=1)
    nearer = depth[0] <= depth[1]  # the surface the ray meets first is the one in error
    for k, hit in enumerate((cface >= 0, ref.face >= 0)):
        nodes = anc[corners[k]]  # (hits, 3) active nodes at the face's corners
        coarse = nodes >= h.num_vertices
        mine = (nearer if k == 0 else ~nearer)[hit]
        share = np.where(mine, d2[hit], 0.0) * ref.cell / np.maximum(coarse.sum(1), 1)
        err += np.bincount(nodes[coarse], np.broadcast_to(share[:, None], nodes.shape)[coarse], h.num_nodes)
    order = np.flatnonzero((err > 0) & ~rt.refinement.pinned)  # a pinned node that is still active: not again
    order = order[np.argsort(-err[order], kind="stable")]
    return order[: int(np.searchsorted(np.cumsum(err[order]), excess)) + 1]


def clipped_squares(a: np.ndarray, b: np.ndarray, white: float) -> tuple[np.ndarray, np.ndarray]:
    """(the squared difference of radiance ``a`` against ``b`` (..., 3), both clipped at ``white``, in units of
    white squared, averaged over RGB, 0 where both are black; where either is non-black)."""
    a, b, white = np.asarray(a), np.asarray(b), float(white)
    # the channels taken one by one: a reduction over an axis of 3 costs numpy several times the arithmetic
    covered = (np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2]) > 0) | \
        (np.maximum(np.maximum(b[..., 0], b[..., 1]), b[..., 2]) > 0)
    x = np.minimum(a.astype(np.float64), white)
    x -= np.minimum(b.astype(np.float64), white)
    x *= x
    d2 = np.asarray((x[..., 0] + x[..., 1] + x[..., 2]) / 3.0 / white**2)  # the mean over RGB
    d2[~covered] = 0.0
    return d2, covered


def clipped_mse(a: np.ndarray, b: np.ndarray, white: float) -> tuple[float, int]:
    """(mean squared difference, entries it is over) of ``clipped_squares`` over the entries where either is
    non-black: E-1's and the measured frame error's (``lodprt.display.error_figure.error_numbers``) PSNR is
    -10 log10 of it."""
    d2, covered = clipped_squares(a, b, white)
    n = int(covered.sum())
    return (float(d2.sum()) / n if n else 0.0), n


def hit_radiance(rt, corner_rows: np.ndarray, bary: np.ndarray, ids: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """(R, 3) float32 what the renderer draws at each ray's hit (``kernels.runtime.hit_radiance``, sliced over the
    cores): ``corner_rows`` (R, 3) rows of ``ids`` (the corner vertices) and of their relit ``coef`` (K, 3, ncoef),
    -1 where the ray met nothing; ``bary`` (R, 3) the hit's weights."""
    import warp as wp

    from lodprt.kernels import runtime as kr

    R = len(corner_rows)
    if not len(ids) or not R:
        return np.zeros((R, 3), np.float32)
    dev, copy = rt.device, rt.device != "cpu"
    arr = lambda a, dtype: wp.array(np.ascontiguousarray(a, np.float32 if dtype != wp.int32 else np.int32),  # noqa
                                    dtype=dtype, device=dev, copy=copy)
    coef = np.ascontiguousarray(coef, np.float32)
    rad = wp.empty((R, 3), dtype=wp.float32, device=dev)  # hit_radiance writes every row (0 for no hit)
    rt.launch_rows(kr.hit_radiance, R, [
        arr(corner_rows, wp.int32), arr(bary, wp.vec3), arr(rt.positions[ids], wp.vec3),
        arr(rt.normals[ids], wp.vec3), wp.array(coef, dtype=wp.float32, device=dev, copy=copy),
        wp.vec3(*map(float, rt.camera.eye)), wp.empty((R, coef.shape[2]), dtype=wp.float32, device=dev)], [rad])
    return rad.numpy()


def cut_bvh(rt, vid: np.ndarray, triangles: np.ndarray):
    """Warp mesh (BVH) of a cut's mesh on the Runtime ``rt``'s device: vertices ``positions[vid]``, faces
    ``triangles`` (indices into ``vid``), for E-1's rays."""
    import warp as wp

    pts = np.ascontiguousarray(rt.positions[np.asarray(vid, np.int64)], np.float32)
    return wp.Mesh(points=wp.array(pts, dtype=wp.vec3, device=rt.device),
                   indices=wp.array(np.ascontiguousarray(triangles, np.int32).ravel(), dtype=wp.int32,
                                    device=rt.device))


#: E-1, E-2: about this many primary rays per frame, one per square cell of the screen (at least a pixel)
COVERAGE_RAYS = 30_000
#: E-2: the fewest rays of the grid that must meet what either mesh shows: with fewer (a scene small on screen, or
#: none met: an E-3 of inf), the grid is halved until they do or it is every pixel, where the sample is the frame
MIN_COVERED = 2_000
#: E-2: at most this many rays in a frame's estimate, on every pixel up to a 4096 x 4096 frame (the full mesh's side,
#: kept for the camera, holds 28 bytes a ray: about 470 MB); a larger frame takes a ray every few pixels each way
MAX_RAYS = 1 << 24


def ray_stride(width: int, height: int, stride: int | None = None) -> int:
    """E-2: the side in pixels of the cells of a ``width`` x ``height`` frame's rays: ``stride`` (1: every pixel;
    None: ``coverage_stride``), widened so that the frame has at most MAX_RAYS of them."""
    stride = coverage_stride(width, height) if stride is None else max(1, int(stride))
    return max(stride, math.ceil(math.sqrt(width * height / MAX_RAYS)))


def coverage_stride(width: int, height: int) -> int:
    """E-2: the side in pixels of the square screen cells, one ray each (about COVERAGE_RAYS)."""
    return max(1, int(math.sqrt(width * height / COVERAGE_RAYS)))


def screen_hits(rt, mesh=None, stride: int | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """E-1, E-2's rays: the first face of ``mesh`` (default the store's full mesh: ``Runtime.scene_bvh``, face ids
    as in ``faces``; -1: none) that a primary ray through the centre of each square cell of ``stride`` pixels
    (default ``coverage_stride``; 1: every pixel's centre) of the screen meets, the hit's barycentric weights of
    that face's corners (``kernels.runtime.first_hits``), and the pixels one cell stands for."""
    import warp as wp

    from lodprt.kernels import runtime as kr

    cam = rt.camera
    stride = ray_stride(cam.width, cam.height, stride)
    cols, rows = max(1, -(-cam.width // stride)), max(1, -(-cam.height // stride))
    inv = np.linalg.inv(np.asarray(rt.vp, np.float64))
    eye = np.asarray(cam.eye, np.float64)

    def ray(x, y):  # direction from the eye through the near plane at NDC (x, y)
        q = inv @ np.array([x, y, -1.0, 1.0])
        return q[:3] / q[3] - eye

    corner = ray(-1.0, 1.0)
    du, dv = (ray(1.0, 1.0) - corner) / cols, (ray(-1.0, -1.0) - corner) / rows
    mesh = rt.scene_bvh() if mesh is None else mesh
    face = wp.empty(cols * rows, dtype=wp.int32, device=rt.device)  # first_hits writes every cell (-1: no hit)
    bary = wp.empty(cols * rows, dtype=wp.vec3, device=rt.device)
    vec = lambda a: wp.vec3(*map(float, a))  # noqa: E731
    rt.launch_rows(kr.first_hits, cols * rows, [mesh.id, vec(eye), vec(corner), vec(du), vec(dv), cols],
                   [face, bary])  # sliced over the cores on the CPU
    return face.numpy(), bary.numpy(), cam.width * cam.height / (cols * rows)


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
        mean_square = node_bounds.detail_mean_square  # kept as float16, rounded up (``float16_up``)
        cache.derive("detail_ms", lambda c: node_bounds.float16_up(mean_square(h, c, white, plan, levels)),
                     h.num_nodes - h.num_vertices, (cache.C,), np.float16)


def node_mean_square(rt, nodes: np.ndarray) -> np.ndarray:
    """E-1's per-pixel squared error of each coarse node under the current lights (units of white squared): the
    samples' mean squared completion residual (``node_bounds.detail_mean_square``, made with each sample) as RMS
    values combined like S-2's bounds: sum_j |W_jc| rms_jc for T-12, max over the samples around the light times
    sum_j |W_jc| for a direct interpolation (M-5); the largest channel, squared."""
    cache, h = rt.samples, rt.h
    if not len(rt.used_samples):  # every light black (zero colours): no sample carries weight, nothing to miss
        return np.zeros(len(nodes), np.float64)
    derive_mean_square(rt)
    rms = np.sqrt(cache.derived["detail_ms"][0][nodes - h.num_vertices][:, rt.used_slots].astype(np.float32))
    w = np.abs(rt.sample_weights[rt.used_samples])  # (U, 3)
    if rms.shape[2] == 1:
        rms = np.repeat(rms, 3, axis=2)
    if rt.interpolation == "thesis":
        per = (rms * w[None]).sum(1)
    else:
        near = rt.lighting.bracket_mask()[rt.used_slots].astype(bool)
        per = (rms[:, near].max(1) if near.any() else rms.max(1)) * w.sum(0)[None]
    return per.max(1) ** 2

