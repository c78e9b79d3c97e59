"""Run time (SPEC 5; thesis 3.4, eq. 12-15; seed 003 section 5): relight a baked scene with moving point lights
and choose a view-dependent cut of the vertex hierarchy every frame.

    rt = lodprt.open("bunny.zarr").runtime(error_bound=0.25, alpha=0.6)
    rt.set_lights([(0.1, 0.28, 0.0)], colors=[(1.0, 0.9, 0.8)])
    rt.set_camera(eye=(0, 0.3, 0.6), target=(0, 0.1, 0), fov=40, width=800, height=600)
    frame = rt.update()          # Frame: positions, triangles, coefficients, radiance, stats

What a frame does (docs/RUNTIME.md has the full story):

1. **Lights** (T-12, ``lodprt.runtime.lights``): every light's weights over the light samples; the per-sample RGB factors
   ``W[j, c] = sum_l I_lc w_lj`` (several lights add, thesis 3.4.1).
2. **View cut** (T-13, T-14; seed 003 section 5): the cut of the vertex hierarchy is kept from frame to frame and
   only moved. Refine-Candidates are the active internal nodes, Coarsen-Candidates the nodes whose two children
   are both active. A candidate is *culled* when its normal cone faces away from the eye (T-13, widened by the
   angle its bounding sphere subtends) or its bounding sphere lies outside the view frustum; otherwise its error
   is ``alpha e_geo + (1 - alpha) e_lumi`` (T-14). Ready-to-refine: an active node, not culled, error above the
   bound; ready-to-coarsen: a Coarsen-Candidate that is culled or whose error is at most the bound. Splits whose
   El-Sana-Varshney dependencies are unmet are forced (their blockers split first, ``Cut.force_refine``);
   collapses whose dependencies are unmet wait. A frame makes up to ``max_passes`` such passes over the
   candidates (each pass costs the size of the cut, not of the mesh); the first frame converges from the base.
3. **Triangulation** of the cut (original faces through the active ancestors, degenerate ones dropped).
4. **Relighting**: the active vertices' completed coefficients, ``sum_j W[j, c] C_j`` (the light samples are
   completed once, T-15, when the Runtime is made), and the radiance toward the eye (T-7).

Errors (T-14): ``e_geo`` is the screen-space length of the node's error vector ``p - p'`` (both ends projected
with the camera; an end behind the eye counts as 1) over the screen diagonal, clamped to [0, 1]. ``e_lumi`` is the
spread (max - min) of the leaf radiances under the node for the current view and lights as the thesis counts
screen intensities (3.4.2.2: in units of the white ``white``, clipped to [0, 1]): ``display(L) = clip(L / white,
0, 1)``. It is bounded from per-node data made once: for each light sample the box (centre and half-width over the
node's leaves) of every SH coefficient, so that the leaves' radiance toward ``v`` (the direction from the node to
the eye) lies in ``[lo, hi] = sum_j W[j, c] sum_i (centre_jci y_i(v) -+ half_jci |y_i(v)|)`` for any light
interpolated from those samples (weights >= 0), and ``e_lumi = max_c display(hi_c) - display(lo_c)`` is at least
the true spread toward ``v``. It costs O(samples x coefficients) per candidate instead of a pass over the leaves.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import logging
import math
import os
import time
import typing

import numpy as np

from lodprt.model import sh
from lodprt.errors import LodprtError
from lodprt.model.hierarchy import Cut, concat_ranges, map_faces
from lodprt.runtime.lights import LightInterpolator

log = logging.getLogger(__name__)

#: rounds of forced refinement per pass after the first frame (each round splits what its dependencies allow)
FORCE_ROUNDS = 24
#: a failed collapse of a node with more original edges under it than this backs off for a few frames
BACKOFF_EDGES = 20_000
#: view-cut criteria: "screen" (S-1, docs/RUNTIME.md) bounds what reaches the screen; "thesis" is T-14
CRITERIA = ("screen", "thesis")
#: default error bound of each criterion: display units of white for "screen", T-14's blend for "thesis"
DEFAULT_ERROR_BOUND = {"screen": 0.2, "thesis": 0.25}
#: "screen": the geometric error on screen, pixels, that weighs as much as the default bound (the exchange rate
#: between pixels of displacement and units of white: 1 px = 0.2 of white at the default)
PIXEL_TOLERANCE = 1.0


class NodeErrors(typing.NamedTuple):
    """Per candidate node (K,): culled (T-13 or outside the frustum), error (the criterion's, compared with the
    bound), e_geo (error vector on screen over the diagonal, T-14), e_lumi (display spread of the leaves' radiance,
    T-14), footprint (bounding-sphere radius on screen, pixels), e_detail (S-2: the radiance toward the eye that
    completing the subtree from coarser vertices could miss, units of white). All 0 where culled."""

    culled: np.ndarray
    error: np.ndarray
    e_geo: np.ndarray
    e_lumi: np.ndarray
    footprint: np.ndarray
    e_detail: np.ndarray


@dataclasses.dataclass(frozen=True)
class Camera:
    """Perspective camera: right-handed, looks from ``eye`` at ``target``, ``up`` (default y) is up on screen,
    ``fov`` the vertical field of view in degrees, ``width`` x ``height`` pixels. ``near``/``far`` None: chosen
    from the scene's bounds."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 40.0
    width: int = 800
    height: int = 600
    near: float | None = None
    far: float | None = None

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            v = np.asarray(getattr(self, name), np.float64)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise LodprtError(f"camera {name}: expected 3 finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if not 0.0 < float(self.fov) < 180.0:
            raise LodprtError(f"camera fov: {self.fov} degrees; must lie strictly between 0 and 180")
        if int(self.width) < 1 or int(self.height) < 1:
            raise LodprtError(f"camera size: {self.width} x {self.height}; width and height must be >= 1")
        if self.near is not None and self.far is not None and not 0.0 < self.near < self.far:
            raise LodprtError(f"camera near/far: {self.near}, {self.far}; need 0 < near < far")


@dataclasses.dataclass
class Frame:
    """What one ``Runtime.update()`` produces for the display (all arrays are fresh copies).

    vertex_ids (A,) int32 original vertex of each active node (store vertex order);
    positions (A, 3) float32 and normals (A, 3) float32 of those vertices;
    triangles (M, 3) int32 indices into ``positions`` (the view cut's mesh, degenerate faces dropped);
    coefficients (A, 3, ncoef) float32 SH coefficients over the view direction of the outgoing radiance, RGB,
    every light's interpolated and completed coefficients summed with its intensity applied (linear radiance);
    radiance (A, 3) float32 linear RGB radiance toward ``camera.eye`` (T-7 per vertex);
    lights (L, 3) float64 light positions as used (after clamping), light_colors (L, 3) float64 RGB intensities;
    camera the ``Camera``; stats a dict (triangles, active_nodes, nodes_touched, refined, coarsened, ms_cut,
    ms_triangulate, ms_relight, ms_total, ...).
    """

    vertex_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    coefficients: np.ndarray
    radiance: np.ndarray
    lights: np.ndarray
    light_colors: np.ndarray
    camera: Camera
    stats: dict


def display(radiance_over_white):
    """The screen intensity of a radiance in units of the white point as the thesis counts it (3.4.2.2): values
    above 1 show as 1, below 0 as 0, i.e. clip(x, 0, 1) (linear: no display gamma)."""
    return np.clip(np.asarray(radiance_over_white, np.float64), 0.0, 1.0)


def clip_planes(view_proj: np.ndarray) -> np.ndarray:
    """(6, 4) inward frustum planes (a, b, c, d) with unit (a, b, c) from a 4x4 view-projection matrix
    (Gribb-Hartmann): a point x is inside when ``a x + b y + c z + d >= 0`` for all six."""
    m = np.asarray(view_proj, np.float64)
    planes = np.array([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]])
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


def _as_camera(camera=None, **kw) -> Camera:
    if isinstance(camera, Camera):
        if kw:
            raise LodprtError("set_camera: pass either a Camera or its fields, not both")
        return camera
    if camera is not None:
        kw["eye"] = camera
    try:
        return Camera(**kw)
    except TypeError as exc:
        raise LodprtError(f"set_camera: {exc}") from exc


def view_projection(camera: Camera, bounds: np.ndarray) -> np.ndarray:
    """4x4 projection @ view of ``camera`` (OpenGL clip space), with the renderer's near and far planes
    (``lodprt.render.camera_matrices``) for the scene's bounds (2, 3): the cut culls with the planes that draw."""
    from lodprt.display.render import camera_matrices

    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    view, proj = camera_matrices(camera, corners)
    return proj @ view


class Runtime:
    """Relighting and view-dependent LOD over one bake store, kept by the caller across frames.

    criterion: "screen" (default; S-1: the luminance spread a node could show, weighted by the pixels it
    covers, and its geometric error in pixels against ``pixel_tolerance``, each against its own bound) or
    "thesis" (T-14: ``alpha e_geo + (1 - alpha) e_lumi``); error_bound: refine above, coarsen at or below (None:
    the criterion's default, DEFAULT_ERROR_BOUND; for "screen" in display units of white); alpha in [0, 1] weighs
    e_geo against e_lumi (T-14 only);
    triangle_budget: when set, the bound is steered every frame (x1.25 above the budget, /1.1 below 80% of it)
    so that the triangle count settles under the budget; white: the radiance shown as 1.0 (default: the 99th
    percentile of the samples' view-averaged radiance); weighting / outside: light interpolation
    (``lodprt.runtime.lights``); max_passes: refinement passes per frame after the first; lod=False: the full mesh;
    device: the Warp device of the per-frame kernels (default: CUDA when present, else the CPU);
    progress(done, total): called as the light samples are completed.
    """

    def __init__(self, store, *, error_bound: float | None = None, alpha: float = 0.6, criterion: str = "screen",
                 pixel_tolerance: float = PIXEL_TOLERANCE, triangle_budget: int | None = None,
                 white: float | None = None, weighting: str = "exact", outside: str = "clamp", max_passes: int = 2,
                 lod: bool = True, device: str | None = None, progress=None):
        from lodprt.devices import resolve_device

        if criterion not in CRITERIA:
            raise LodprtError(f"criterion {criterion!r}: choose one of {', '.join(CRITERIA)}")
        self.criterion = criterion
        p = float(pixel_tolerance)
        if not p > 0 or not math.isfinite(p):
            raise LodprtError(f"pixel_tolerance {pixel_tolerance}: must be a positive number of pixels")
        self.pixel_tolerance = p
        if error_bound is None:
            error_bound = DEFAULT_ERROR_BOUND[criterion]
        self.device = resolve_device(device)
        self.store = store
        self.h = h = store.hierarchy()
        self.faces = np.asarray(store.faces, np.int64)
        self.positions = np.asarray(store.positions, np.float64)
        self.normals = np.asarray(store.normals, np.float64)
        self.bounds = np.array([self.positions.min(0), self.positions.max(0)]) if len(self.positions) else np.zeros((2, 3))
        self.set_error_bound(error_bound, alpha)
        if triangle_budget is not None and int(triangle_budget) < 1:
            raise LodprtError(f"triangle_budget {triangle_budget}: must be >= 1")
        self.triangle_budget = None if triangle_budget is None else int(triangle_budget)
        if int(max_passes) < 1:
            raise LodprtError(f"max_passes {max_passes}: must be >= 1")
        self.max_passes = int(max_passes)
        self.lod = bool(lod)
        self.interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"],
                                        weighting=weighting, outside=outside)
        V = h.num_vertices
        S = store.num_samples
        self.order = store.sh_order
        # T-15 once per sample (cached, SPEC 5), float32, vertex-major (V, S, C, ncoef): a vertex's samples are
        # one contiguous block for the per-frame gathers
        first = store.complete(0).astype(np.float32)
        self.coeffs = np.empty((first.shape[0], S) + first.shape[1:], np.float32)
        self.coeffs[:, 0] = first
        for k in range(S):
            if k:
                self.coeffs[:, k] = store.complete(k)
            if progress:
                progress(k + 1, S)
        self.channels = self.coeffs.shape[2]
        self.ncoef = self.coeffs.shape[3]
        self.white = float(white) if white is not None else self._default_white()
        if not self.white > 0 or not math.isfinite(self.white):
            raise LodprtError(f"white {white}: must be a positive finite radiance")
        self._boxes = None  # per-node coefficient boxes for e_lumi, made when the view cut first needs them
        # per-node geometry for the error terms
        self.node_pos = self.positions[h.vertex]
        internal = h.children[:, 1] >= 0
        self.node_collapsed = np.where(internal[:, None], self.positions[h.vertex[np.maximum(h.children[:, 1], 0)]],
                                       self.node_pos)
        self.error_vector = h.error_vector.astype(np.float64)
        self.axis = h.cone_axis.astype(np.float64)
        self.half = h.cone_half_angle.astype(np.float64)
        self.radius = h.radius.astype(np.float64)
        self._upload()
        self.cut = Cut.base(h, self.faces) if self.lod else Cut.full(h, self.faces)
        self._converged_once = False
        self._blocker = np.full(h.num_nodes, -1, np.int64)  # a finer neighbour that blocked this collapse
        self._fails = np.zeros(h.num_nodes, np.int8)  # failed collapses in a row, and when to try again
        lr = h.leaf_range
        self._subtree_edges = self.cut._ptr[lr[:, 1]] - self.cut._ptr[lr[:, 0]]
        self._retry_at = np.zeros(h.num_nodes, np.int64)
        # faces around each original vertex (CSR), for the incremental triangulation
        fv = self.faces.ravel()
        order = np.argsort(fv, kind="stable")
        self._vf = (order // 3).astype(np.int64)
        self._vf_ptr = np.searchsorted(fv[order], np.arange(V + 1))
        self._tri_anc = None
        self._dirty, self._settled = True, False
        self._frame = 0  # errors cached per frame: culled, error and the frame they belong to
        self._culled = np.zeros(h.num_nodes, bool)
        self._err = np.zeros(h.num_nodes)
        self._stamp = np.full(h.num_nodes, -1, np.int64)
        self.camera: Camera | None = None
        self.set_lights(self.interp.samples[len(self.interp.samples) // 2][None, :])

    # -- set-up ------------------------------------------------------------------------------------------------
    @property
    def box_centre(self) -> np.ndarray:
        return self._ensure_boxes()[0]

    @property
    def box_half(self) -> np.ndarray:
        return self._ensure_boxes()[1]

    def _ensure_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._boxes is None:
            centre, half = self._coefficient_boxes()
            detail = self._detail_boxes()
            wp = self._wp
            self._d["box_centre"] = wp.array(centre, dtype=wp.float16, device=self.device)
            self._d["box_half"] = wp.array(half, dtype=wp.float16, device=self.device)
            self._d["detail"] = wp.array(detail, dtype=wp.float16, device=self.device)
            self._boxes = centre, half, detail
        return self._boxes

    def _detail_boxes(self) -> np.ndarray:
        """S-2 per light sample: for each internal node, the largest of (a) |C(v) - sum_j w_j C(q_j)| over the
        collapses in its subtree (T-15 weights over the ring the collapse removed v from) and (b) |C(v) - C(q)|
        over its leaves v and their original neighbours q, per coefficient, in units of ``white``:
        (N - V, S, C, ncoef) float16. (a) is zero where the completed field is linear (T-15 has linear precision);
        (b) is one edge's step, small on smooth fields and large at a shadow or highlight boundary that runs next
        to the subtree (between two subtrees, where neither's own collapses see it)."""
        from lodprt.model.completion import CHUNK

        h = self.h
        V, N = h.num_vertices, h.num_nodes
        _, S, C, n = self.coeffs.shape
        detail = np.zeros((N - V, S, C, n), np.float16)
        if N == V:
            return detail
        plan = self.store.completion_plan()
        c0, c1 = h.children[:, 0], h.children[:, 1]
        big = float(np.finfo(np.float16).max)
        ring_v, ring_q, starts = self._leaf_rings()
        for j in range(S):
            c = self.coeffs[:, j].reshape(V, C * n) / np.float32(self.white)
            d = np.zeros((N, C * n), np.float32)
            if len(ring_v):  # leaves: the largest step to an original neighbour (a shadow edge between subtrees)
                d[ring_v[starts]] = np.maximum.reduceat(np.abs(c[ring_v] - c[ring_q]), starts, axis=0)
            for start in range(0, N - V, CHUNK):  # plan row m is the collapse of node V + m
                rows = slice(start, min(start + CHUNK, N - V))
                r = max(int(plan.ring_len[rows].max()), 1)
                interp = np.einsum("mr,mrk->mk", plan.weights[rows, :r].astype(np.float32), c[plan.neighbours[rows, :r]])
                d[V + rows.start:V + rows.stop] = np.abs(c[plan.vertex[rows]] - interp)  # T-15 residual
            for nodes in self._levels():
                d[nodes] = np.maximum(d[nodes], np.maximum(d[c0[nodes]], d[c1[nodes]]))
            detail[:, j] = np.clip(d[V:], 0, big).reshape(N - V, C, n)
        return detail

    def _leaf_rings(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every original edge in both directions, sorted by its first vertex: (v, q, start of each v's run)."""
        f = self.faces
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        e = np.concatenate([e, e[:, ::-1]])
        e = e[e[:, 0] != e[:, 1]]
        e = e[np.argsort(e[:, 0], kind="stable")]
        starts = np.flatnonzero(np.r_[True, e[1:, 0] != e[:-1, 0]]) if len(e) else np.zeros(0, np.int64)
        return e[:, 0], e[:, 1], starts

    def _levels(self) -> list[np.ndarray]:
        """Internal nodes grouped by height (children always on lower levels), lowest first."""
        from lodprt.model.hierarchy import node_heights

        if getattr(self, "_levels_cache", None) is None:
            hk = node_heights(self.h)
            order = np.argsort(hk, kind="stable")
            bounds = np.searchsorted(hk[order], np.arange(1, hk.max() + 2))
            self._levels_cache = [order[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)]
        return self._levels_cache

    def _coefficient_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Per light sample, the box of every completed coefficient over each internal node's leaves, in units of
        ``white``: centre and half-width, each (N - V, S, C, ncoef) float16 (clipped to float16's range), made
        bottom-up one height level at a time (children always sit on lower levels)."""
        h = self.h
        V, N = h.num_vertices, h.num_nodes
        _, S, C, n = self.coeffs.shape
        centre = np.zeros((N - V, S, C, n), np.float16)
        half = np.zeros((N - V, S, C, n), np.float16)
        if N == V:
            return centre, half
        levels = self._levels()
        c0, c1 = h.children[:, 0], h.children[:, 1]
        big = float(np.finfo(np.float16).max)
        for j in range(S):
            mn = np.empty((N, C * n), np.float32)
            mn[:V] = self.coeffs[:, j].reshape(V, C * n) / np.float32(self.white)
            mx = mn.copy()
            for nodes in levels:
                mn[nodes] = np.minimum(mn[c0[nodes]], mn[c1[nodes]])
                mx[nodes] = np.maximum(mx[c0[nodes]], mx[c1[nodes]])
            centre[:, j] = np.clip(0.5 * (mx[V:] + mn[V:]), -big, big).reshape(N - V, C, n)
            half[:, j] = np.clip(0.5 * (mx[V:] - mn[V:]), 0, big).reshape(N - V, C, n)
        return centre, half

    def _upload(self) -> None:
        """The per-frame kernels' read-only inputs, on the device once."""
        from lodprt.devices import warp

        wp = warp()
        dev = self.device
        self._threads = max(1, min(os.cpu_count() or 1, 8))
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=self._threads) if self._threads > 1 else None
        v3 = lambda a: wp.array(np.ascontiguousarray(a, np.float32), dtype=wp.vec3, device=dev)  # noqa: E731
        f1 = lambda a: wp.array(np.ascontiguousarray(a, np.float32), dtype=wp.float32, device=dev)  # noqa: E731
        self._wp = wp
        self._d = {
            "node_pos": v3(self.node_pos), "node_collapsed": v3(self.node_collapsed),
            "error_vector": v3(self.error_vector), "axis": v3(self.axis), "half": f1(self.half),
            "radius": f1(self.radius), "positions": v3(self.positions), "normals": v3(self.normals),
            "coeffs": wp.array(self.coeffs, dtype=wp.float32, device=dev),
        }

    def _launch(self, kernel, rows: int, inputs: list, outputs: list) -> None:
        """Launch ``kernel`` over ``rows`` rows; on the CPU, split into one launch per core on threads (Warp runs a
        CPU launch on one thread and releases the GIL), each launch taking its first row as ``offset``."""
        wp = self._wp
        parts = self._threads if self.device == "cpu" and rows >= 2048 else 1
        if parts == 1:
            wp.launch(kernel, dim=rows, inputs=[0] + inputs, outputs=outputs, device=self.device)
            return
        cuts = np.linspace(0, rows, parts + 1).astype(int)
        futures = [self._pool.submit(wp.launch, kernel, dim=int(b - a), inputs=[int(a)] + inputs, outputs=outputs,
                                     device=self.device) for a, b in zip(cuts[:-1], cuts[1:])]
        for f in futures:
            f.result()

    def _frame_inputs(self) -> tuple:
        wp = self._wp
        used = wp.array(self._used.astype(np.int32), dtype=wp.int32, device=self.device)
        weights = wp.array(self.sample_weights.astype(np.float32), dtype=wp.float32, device=self.device)
        return used, weights

    def _default_white(self) -> float:
        dc = np.abs(self.coeffs[:, :, :, 0]).max(2) * sh.basis(np.array([0.0, 0.0, 1.0]), 1)[0]
        dc = dc * float(np.max(self.store.intensity))
        pos = dc[dc > 0]
        return float(np.percentile(pos, 99)) if pos.size else 1.0

    def set_error_bound(self, error_bound: float, alpha: float | None = None) -> None:
        """T-14 error bound (>= 0) and, when given, alpha in [0, 1]."""
        e = float(error_bound)
        if not e >= 0 or not math.isfinite(e):
            raise LodprtError(f"error_bound {error_bound}: must be a finite number >= 0")
        self.error_bound = e
        self._dirty = True
        if alpha is not None:
            a = float(alpha)
            if not 0.0 <= a <= 1.0:
                raise LodprtError(f"alpha {alpha}: must lie in [0, 1]")
            self.alpha = a

    def set_lod(self, enabled: bool) -> None:
        """LOD off shows the full mesh (every leaf active); on starts again from the base mesh."""
        self.lod = bool(enabled)
        self.cut = Cut.base(self.h, self.faces) if self.lod else Cut.full(self.h, self.faces)
        self._converged_once = False
        self._blocker[:] = -1
        self._fails[:] = 0
        self._retry_at[:] = 0
        self._dirty = True

    def set_lights(self, positions, colors=None) -> None:
        """Point lights at (L, 3) positions with (L, 3) RGB intensities (default: the bake's intensity each).
        Outside the sampled region: clamped with a warning, or an error (``outside``)."""
        pos = np.asarray(positions, np.float64)
        if pos.ndim == 1:
            pos = pos[None, :]
        if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) < 1:
            raise LodprtError(f"lights: expected (L, 3) positions with L >= 1, got shape {pos.shape}")
        if colors is None:
            col = np.repeat(np.asarray(self.store.intensity, np.float64)[None, :], len(pos), axis=0)
        else:
            col = np.asarray(colors, np.float64)
            if col.ndim == 1:
                col = col[None, :]
            if col.shape != pos.shape or not np.isfinite(col).all() or (col < 0).any():
                raise LodprtError(f"light colors: expected ({len(pos)}, 3) finite RGB intensities >= 0, got {col.tolist()}")
        pos, moved = self.interp.clamp(pos)  # warns (or refuses) once per call
        W = self.interp.rgb_weights(pos, col)  # lights add (thesis 3.4.1)
        self._dirty = True
        self.light_positions = pos
        self.light_colors = col
        self.lights_clamped = int(moved.sum())
        self.sample_weights = W
        self._used = np.flatnonzero(np.abs(W).sum(1) > 0)

    def set_camera(self, camera=None, target=None, up=(0.0, 1.0, 0.0), fov=40.0, width=800, height=600,
                   near=None, far=None) -> Camera:
        """A ``Camera`` or its fields (``set_camera(eye, target, up, fov, width, height)``)."""
        if isinstance(camera, Camera):
            self.camera = camera
        else:
            self.camera = _as_camera(camera, target=target, up=up, fov=fov, width=width, height=height,
                                     near=near, far=far)
        self._dirty = True
        self._vp = view_projection(self.camera, self.bounds)
        self._planes = clip_planes(self._vp)
        return self.camera

    # -- errors ------------------------------------------------------------------------------------------------
    def node_errors(self, nodes, *, exact: bool = True) -> NodeErrors:
        """For internal ``nodes`` (K,): culled (K,) bool (T-13 back-facing or outside the frustum), error (K,)
        ``alpha e_geo + (1 - alpha) e_lumi`` (T-14), e_geo (K,), e_lumi (K,) (all 0 where culled: a culled node
        is coarsened whatever its error); float32 Warp kernel
        (``lodprt.kernels.runtime.view_errors``) on the Runtime's device. ``exact=False`` (the frame loop) stops a
        node's evaluation once its refine/coarsen decision is known: its error is then an upper bound when at or
        under the bound, and e_lumi / e_detail read -1 where they were not needed."""
        from lodprt.kernels import runtime as kr

        if self.camera is None:
            raise LodprtError("no camera: call set_camera(eye, target, ...) before update()")
        wp, dev, d = self._wp, self.device, self._d
        nodes = np.asarray(nodes, np.int32)
        K = len(nodes)
        outs = [wp.zeros(K, dtype=wp.uint8, device=dev)] + [wp.zeros(K, dtype=wp.float32, device=dev) for _ in range(5)]
        if K:
            cam = self.camera
            used, weights = self._frame_inputs()
            self._ensure_boxes()
            self._launch(kr.view_errors, K, [
                wp.array(nodes, dtype=wp.int32, device=dev), self.h.num_vertices, d["node_pos"], d["node_collapsed"],
                d["error_vector"], d["axis"], d["half"], d["radius"],
                wp.array(self._planes.astype(np.float32), dtype=wp.vec4, device=dev),
                wp.mat44(*self._vp.astype(np.float32).ravel()), wp.vec3(*map(float, cam.eye)),
                0.5 * cam.width, 0.5 * cam.height, math.hypot(cam.width, cam.height), self._focal_px(), used, weights,
                d["box_centre"], d["box_half"], d["detail"], CRITERIA.index(self.criterion), int(bool(exact)),
                float(self.error_bound), self._geo_rate(), self.alpha, wp.empty((K, self.ncoef), dtype=wp.float32, device=dev),
            ], outs)
        culled, err, geo, lumi, foot, det = (o.numpy() for o in outs)
        return NodeErrors(culled.astype(bool), *(a.astype(np.float64) for a in (err, geo, lumi, foot, det)))

    def _geo_rate(self) -> float:
        """S-1: units of white per pixel of geometric error (the default bound per pixel tolerance)."""
        return DEFAULT_ERROR_BOUND["screen"] / self.pixel_tolerance

    def _focal_px(self) -> float:
        """Focal length of the camera in pixels: (height / 2) / tan(fov / 2)."""
        return 0.5 * self.camera.height / math.tan(math.radians(self.camera.fov) / 2)

    def _criterion(self, culled, e_geo, e_lumi, footprint, e_detail) -> np.ndarray:
        """The error compared with the bound (0 where culled): T-14 ``alpha e_geo + (1 - alpha) e_lumi`` for
        "thesis"; for "screen" (S-1) ``max(E0 g_px / tau_px, e_detail min(1, pi r_px^2))``: the
        geometric error in
        pixels at the exchange rate E0 / tau_px (E0 the default bound, tau_px the pixel tolerance: at the default
        bound a node refines when it moves anything by more than tau_px) and the luminance spread weighted by the
        share of a pixel the node's footprint covers (S-2: the completion residuals and edge steps under the node,
        not its spread: a smooth gradient spreads but interpolates well); one bound E then steers both."""
        if self.criterion == "thesis":
            err = self.alpha * e_geo + (1.0 - self.alpha) * e_lumi
        else:
            cam = self.camera
            g_px = e_geo * math.hypot(cam.width, cam.height)
            geo_term = g_px * self._geo_rate()
            err = np.maximum(geo_term, e_detail * np.minimum(1.0, np.pi * footprint ** 2))
        return np.where(culled, 0.0, err)

    def node_errors_reference(self, nodes) -> NodeErrors:
        """``node_errors`` in float64 numpy (the tests' reference for the kernel)."""
        if self.camera is None:
            raise LodprtError("no camera: call set_camera(eye, target, ...) before update()")
        nodes = np.asarray(nodes, np.int64)
        cam = self.camera
        eye = np.asarray(cam.eye)
        p = self.node_pos[nodes]
        r = self.radius[nodes]
        # outside the frustum: the bounding sphere is entirely behind one plane
        s = p @ self._planes[:, :3].T + self._planes[:, 3]
        outside = (s < -r[:, None]).any(1)
        # T-13 back-facing: every normal in the cone is more than 90 degrees from every direction to the eye
        v = eye - p
        d = np.linalg.norm(v, axis=1)
        vh = v / np.where(d > 0, d, 1.0)[:, None]
        ang = np.arccos(np.clip((vh * self.axis[nodes]).sum(1), -1.0, 1.0))
        spread = np.arcsin(np.clip(r / np.where(d > 0, d, 1.0), 0.0, 1.0))
        back = (d > r) & (ang > 0.5 * np.pi + self.half[nodes] + spread)
        culled = outside | back
        # e_geo: the error vector p - p' on screen over the screen diagonal
        a = self.node_collapsed[nodes]
        b = a - self.error_vector[nodes]
        ca = np.c_[a, np.ones(len(a))] @ self._vp.T
        cb = np.c_[b, np.ones(len(b))] @ self._vp.T
        tiny = 1e-12
        behind = (ca[:, 3] <= tiny) | (cb[:, 3] <= tiny)
        half_wh = 0.5 * np.array([cam.width, cam.height], np.float64)
        sa = ca[:, :2] / np.where(behind, 1.0, ca[:, 3])[:, None] * half_wh
        sb = cb[:, :2] / np.where(behind, 1.0, cb[:, 3])[:, None] * half_wh
        e_geo = np.where(behind, 1.0, np.linalg.norm(sa - sb, axis=1) / math.hypot(cam.width, cam.height))
        e_geo = np.clip(e_geo, 0.0, 1.0)
        # e_lumi: display-space spread bounded by the interval of the leaves' radiance toward the eye
        y = sh.basis(vh, self.order)[:, :self.box_centre.shape[3]]  # 1 (diffuse-only store) or order^2 wide
        hi = np.zeros((len(nodes), 3))
        lo = np.zeros((len(nodes), 3))
        det = np.zeros((len(nodes), 3))
        internal = nodes - self.h.num_vertices
        detail = self._ensure_boxes()[2]
        for j in self._used:
            mid = (self.box_centre[internal, j].astype(np.float64) * y[:, None, :]).sum(-1)  # (K, C)
            rad = (self.box_half[internal, j].astype(np.float64) * np.abs(y)[:, None, :]).sum(-1)
            w = self.sample_weights[j][None, :]  # C = 1 (grey) broadcasts over R, G, B
            hi += (mid + rad) * w
            lo += (mid - rad) * w
            det += (detail[internal, j].astype(np.float64) * np.abs(y)[:, None, :]).sum(-1) * np.abs(w)
        e_lumi = np.clip((display(hi) - display(lo)).max(1), 0.0, 1.0)
        depth = np.c_[p, np.ones(len(p))] @ self._vp[3]  # clip w of the node centre
        foot = np.where(depth > r, np.minimum(r * self._focal_px() / np.where(depth > r, depth, 1.0), 1e9), 1e9)
        e_geo, e_lumi = np.where(culled, 0.0, e_geo), np.where(culled, 0.0, e_lumi)  # culled: no error computed
        foot = np.where(culled, 0.0, foot)
        det = np.where(culled, 0.0, np.minimum(det.max(1), 1.0))
        return NodeErrors(culled, self._criterion(culled, e_geo, e_lumi, foot, det), e_geo, e_lumi, foot, det)

    # -- frames ------------------------------------------------------------------------------------------------
    def _pass(self, *, backoff: bool = False) -> tuple[int, int, int]:
        """One refinement pass over the candidate lists; returns (refined, coarsened, nodes touched). With
        ``backoff``, a failed collapse of a node whose subtree has more than BACKOFF_EDGES original edges is not
        tried again for 2, 4, ... 32 frames (a try scans them all); smaller ones are tried again as soon as their
        blocker has gone."""
        h, cut = self.h, self.cut
        V = h.num_vertices
        act = np.flatnonzero(cut.active)
        rc = act[act >= V]  # Refine-Candidates
        par = h.parent[act]
        par = np.unique(par[par >= 0])
        cc = par[cut.active[h.children[par, 0]] & cut.active[h.children[par, 1]]]  # Coarsen-Candidates
        nodes = np.concatenate([rc, cc])
        if not len(nodes):
            return 0, 0, 0
        # errors depend on the frame's camera and lights only: each node is evaluated once per frame
        fresh = self._stamp[nodes] != self._frame
        if fresh.any():
            new = nodes[fresh]
            c, e = self.node_errors(new, exact=False)[:2]
            self._culled[new], self._err[new], self._stamp[new] = c, e, self._frame
        culled, err = self._culled[nodes], self._err[nodes]
        k = len(rc)
        want_refine = ~culled[:k] & (err[:k] > self.error_bound)
        want_coarsen = culled[k:] | (err[k:] <= self.error_bound)
        refined = coarsened = touched = 0
        # a collapse found blocked waits until the finer neighbour found blocking it is gone (one per node);
        # allowed collapses and splits are made all at once (Cut.coarsen_many / refine_many)
        todo = cc[want_coarsen]
        blk = self._blocker[todo]
        todo = todo[(blk < 0) | ~cut.active[np.maximum(blk, 0)]]
        if backoff:
            todo = todo[self._retry_at[todo] <= self._frame]
        touched += len(todo)
        if len(todo):
            done, blocker = cut.coarsen_many(todo)
            self._blocker[todo] = np.where(done, -1, blocker)
            big = self._subtree_edges[todo] > BACKOFF_EDGES
            self._fails[todo] = np.where(done | ~big, 0, np.minimum(self._fails[todo] + 1, 5))
            self._retry_at[todo] = self._frame + np.where(done | ~big, 0, 2 ** self._fails[todo].astype(np.int64))
            coarsened += int(done.sum())
        split = rc[want_refine]
        split = split[np.argsort(-err[:k][want_refine], kind="stable")]
        split = split[cut.active[split]]
        touched += len(split)  # (refine_many skips nodes no longer active)
        if len(split):  # allowed splits at once; blocked ones forced, their blockers split first (all at once)
            # a long chain of forced splits is spread over frames (FORCE_ROUNDS rounds a pass) once the cut has
            # converged, so that no frame stalls; the first frame converges in full
            n = cut.force_refine_many(split, max_rounds=FORCE_ROUNDS if self._converged_once else None)
            refined += n
            touched += max(n - len(split), 0)
        return refined, coarsened, touched

    def update(self, *, max_passes: int | None = None) -> Frame:
        """Move the cut for the current camera and lights, triangulate it, relight it: a ``Frame``."""
        if self.camera is None:
            raise LodprtError("no camera: call set_camera(eye, target, ...) before update()")
        t0 = time.perf_counter()
        self._frame += 1
        refined = coarsened = touched = passes = 0
        if self.lod and (self._dirty or not self._settled):  # nothing changed since a settled cut: keep it
            limit = max_passes if max_passes is not None else (self.max_passes if self._converged_once else 10_000)
            self._settled = False
            for _ in range(int(limit)):
                r, c, t = self._pass(backoff=self._converged_once and limit <= self.max_passes)
                passes += 1
                refined, coarsened, touched = refined + r, coarsened + c, touched + t
                if r == 0 and c == 0:
                    self._settled = True
                    break
            self._converged_once = True
        self._dirty = False
        t1 = time.perf_counter()
        h = self.h
        vid = np.sort(h.vertex[self.cut.nodes]).astype(np.int32)  # ascending: gathers walk memory forward
        lut = np.full(h.num_vertices, -1, np.int32)
        lut[vid] = np.arange(len(vid), dtype=np.int32)
        tri = lut[self._triangles()]
        t2 = time.perf_counter()
        coef, rad = self._relight(vid)
        t3 = time.perf_counter()
        if self.triangle_budget is not None:  # steer the bound toward the budget
            if len(tri) > self.triangle_budget:
                self.error_bound = max(self.error_bound, 1e-4) * 1.25
                self._dirty = True
            elif len(tri) < 0.8 * self.triangle_budget:
                self.error_bound /= 1.1
                self._dirty = True
        stats = {
            "triangles": int(len(tri)),
            "active_nodes": int(len(vid)),
            "vertices": int(len(vid)),
            "nodes_touched": int(touched),
            "refined": int(refined),
            "coarsened": int(coarsened),
            "passes": int(passes),
            "error_bound": float(self.error_bound),
            "alpha": float(self.alpha),
            "lights_clamped": int(self.lights_clamped),
            "ms_cut": 1e3 * (t1 - t0),
            "ms_triangulate": 1e3 * (t2 - t1),
            "ms_relight": 1e3 * (t3 - t2),
            "ms_total": 1e3 * (t3 - t0),
        }
        return Frame(vertex_ids=vid, positions=self.positions[vid].astype(np.float32),
                     normals=self.normals[vid].astype(np.float32), triangles=tri.astype(np.int32),
                     coefficients=coef, radiance=rad.astype(np.float32), lights=self.light_positions.copy(),
                     light_colors=self.light_colors.copy(), camera=self.camera, stats=stats)

    def _relight(self, vid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, 3, ncoef) interpolated coefficients and (A, 3) radiance toward the eye of vertices ``vid``
        (``lodprt.kernels.runtime.relight``)."""
        from lodprt.kernels import runtime as kr

        wp, dev, d = self._wp, self.device, self._d
        A = len(vid)
        coef = wp.empty((A, 3, self.ncoef), dtype=wp.float32, device=dev)  # every entry is written
        rad = wp.empty((A, 3), dtype=wp.float32, device=dev)
        if A:
            used, weights = self._frame_inputs()
            self._launch(kr.relight, A, [
                wp.array(vid.astype(np.int32), dtype=wp.int32, device=dev), d["positions"], d["normals"],
                wp.vec3(*map(float, self.camera.eye)), used, weights, d["coeffs"],
                wp.empty((A, self.ncoef), dtype=wp.float32, device=dev)], [coef, rad])
        return coef.numpy(), rad.numpy()

    def _triangles(self) -> np.ndarray:
        """The cut's triangles in original vertex ids (T-3.2 triangulation), kept up to date incrementally: only
        the original faces around vertices whose active ancestor changed since the last frame are mapped again."""
        anc = self.cut.anc
        if self._tri_anc is None:
            self._fmap, self._flive = map_faces(self.h, self.faces, anc)
        else:
            moved = np.flatnonzero(anc != self._tri_anc)
            if len(moved):
                mark = np.zeros(len(self.faces), bool)  # faces around the moved vertices (a mask: no sort)
                mark[self._vf[concat_ranges(self._vf_ptr[moved], self._vf_ptr[moved + 1])]] = True
                fs = np.flatnonzero(mark)
                self._fmap[fs], self._flive[fs] = map_faces(self.h, self.faces[fs], anc)
        self._tri_anc = anc.copy()
        return self._fmap[self._flive]

    # -- full resolution ---------------------------------------------------------------------------------------
    def coefficients(self, vertex_ids=None) -> np.ndarray:
        """(K, 3, ncoef) float32 RGB coefficients of the current lights at ``vertex_ids`` (default: every vertex):
        ``sum_j W[j, c] C_j`` over the completed light samples (T-12 weights, intensities applied)."""
        ids = np.arange(self.h.num_vertices) if vertex_ids is None else np.asarray(vertex_ids, np.int64)
        u = self._used
        c = self.coeffs[ids[:, None], u[None, :]]  # (K, U, C, ncoef)
        w = self.sample_weights[u].astype(np.float32)  # (U, 3)
        if self.channels == 1:
            return np.einsum("kui,uc->kci", c[:, :, 0], w, optimize=True)
        return np.einsum("kuci,uc->kci", c, w, optimize=True)

    def radiance(self, eye) -> np.ndarray:
        """(V, 3) float32 radiance toward ``eye`` of every vertex under the current lights (full resolution,
        completed, interpolated); vertices no face uses read 0."""
        from lodprt.store.bake_store import radiance_toward

        return radiance_toward(self.positions, self.normals, self.coefficients(), eye, np.ones(3))

    def check(self) -> None:
        """Raise LodprtError unless the current cut is legal (``hierarchy.dependency_violations``)."""
        from lodprt.model.hierarchy import dependency_violations

        bad = dependency_violations(self.h, self.faces, self.cut.anc)
        if len(bad):
            raise LodprtError(f"the view cut violates {len(bad)} dependencies, e.g. nodes {bad[0].tolist()}")


def light_coefficients(store, lights, *, colors=None, weighting: str = "exact", outside: str = "clamp"):
    """The completed coefficients of every vertex of ``store`` under point lights at (L, 3) positions, without a
    ``Runtime`` (stores baked without a hierarchy too): T-12 interpolation, T-15 completion, lights summed with
    their RGB intensities (``colors`` (L, 3) or one (3,) for all; default the bake's). Returns (lights clamped
    into the sampled region (L, 3), colours (L, 3), coefficients (V, 3, ncoef) float64)."""
    interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"], weighting=weighting,
                               outside=outside)
    pos, _ = interp.clamp(lights)
    try:
        col = np.broadcast_to(store.intensity if colors is None else np.asarray(colors, np.float64), pos.shape)
    except ValueError:
        col = np.asarray(colors, np.float64)
    if col.shape != pos.shape or not np.isfinite(col).all() or (col < 0).any():
        raise LodprtError(f"light colors: expected ({len(pos)}, 3) finite RGB intensities >= 0, got {col.tolist()}")
    col = col.astype(np.float64)
    W = interp.rgb_weights(pos, col)
    # as wide as the stored coefficients: 1 (y_0 of a diffuse-only store) or order^2
    out = np.zeros((store.num_vertices, 3, store.coefficients_per_vertex))
    for j in np.flatnonzero(np.abs(W).sum(1) > 0):
        c = store.coefficients(int(j))  # (V, C, ncoef), completed; C = 1 (grey) broadcasts over R, G, B
        out += c * W[j][None, :, None]
    return pos, col, out


def light_radiance(store, lights, eye, *, colors=None, weighting: str = "exact", outside: str = "clamp") -> np.ndarray:
    """(V, 3) float32 radiance toward ``eye`` of every vertex of ``store`` under point lights (``light_coefficients``;
    ``Runtime.radiance`` gives the same numbers)."""
    from lodprt.store.bake_store import radiance_toward

    _, _, coeffs = light_coefficients(store, lights, colors=colors, weighting=weighting, outside=outside)
    return radiance_toward(store.positions, store.normals, coeffs, eye, np.ones(3))


def object_bounds(store) -> np.ndarray:
    """(2, 3) bounds of the scene's objects without the floor (all referenced vertices when only a floor)."""
    pos = np.asarray(store.positions)
    oid = np.asarray(store.read("scene/object_id"))
    names = list(store.root["scene"].attrs.get("object_names", []))
    used = np.zeros(len(pos), bool)
    used[np.asarray(store.faces).ravel()] = True
    keep = used.copy()
    if "floor" in names:
        keep &= oid != names.index("floor")
    p = pos[keep] if keep.any() else pos[used] if used.any() else pos
    return np.array([p.min(0), p.max(0)]) if len(p) else np.zeros((2, 3))


def camera_path(rt: "Runtime", path: str, frames: int, *, size=(800, 600), fov: float = 40.0, light_turns: float = 2.0):
    """Yields ``frames`` (Camera, lights (1, 3)) pairs: ``orbit`` circles the objects at 2.2 object sizes, 25
    degrees above them; ``dolly`` moves from 3 object sizes to 0.8 straight toward them; the light circles inside
    the sampled light box ``light_turns`` times over the path."""
    if path not in ("orbit", "dolly"):
        raise LodprtError(f"camera path {path!r}: choose 'orbit' or 'dolly'")
    b = object_bounds(rt.store)
    c = 0.5 * (b[0] + b[1])
    size_ = float(np.linalg.norm(b[1] - b[0])) or 1.0
    box = np.asarray(rt.store.root["lights"].attrs["box"], np.float64)
    lc, lh = 0.5 * (box[:3] + box[3:]), 0.5 * (box[3:] - box[:3])
    elev = math.radians(25.0)
    for k in range(int(frames)):
        t = k / max(int(frames), 1)
        if path == "orbit":
            a = 2.0 * math.pi * t
            dist = 2.2 * size_
        else:
            a = 0.6
            dist = size_ * (3.0 - 2.2 * t)
        eye = c + dist * np.array([math.cos(elev) * math.sin(a), math.sin(elev), math.cos(elev) * math.cos(a)])
        la = 2.0 * math.pi * light_turns * t
        light = lc + 0.8 * lh * np.array([math.cos(la), 0.0, math.sin(la)])
        yield Camera(eye=tuple(eye), target=tuple(c), fov=fov, width=int(size[0]), height=int(size[1])), light[None, :]
