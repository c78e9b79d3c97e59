"""The ``Runtime`` (SPEC 5; thesis 3.4, T-12..T-15; seed 003 section 5; S-1, S-2 beyond the thesis): relight a
baked scene with moving point lights and move a view-dependent cut of the vertex hierarchy every frame.

    rt = lodprt.Runtime(lodprt.open_store("bunny.zarr"))          # ScreenCriterion(), bound 0.8 of white
    rt.set_lights([(0.1, 0.28, 0.0)], colors=[(1.0, 0.9, 0.8)])
    rt.set_camera((0, 0.3, 0.6), (0, 0.1, 0), fov=40, width=800, height=600)
    frame = rt.update()          # Frame: positions, triangles, coefficients, radiance, stats

A frame: light weights (T-12), refine/coarsen passes over the cut's candidates with errors from the Warp kernel
``kernels.runtime.view_errors`` (T-13 culling; S-1/S-2 or T-14), incremental triangulation, relighting of the
active vertices (T-7). The parts have modules of their own: the criterion (``lodprt.runtime.criteria``: its
settings, the per-node bounds it reads, its kernel inputs), when to refresh errors and how to move the cut
(``lodprt.runtime.refinement``: ``ErrorCache``, ``CutRefinement``), the lights, their samples and the relighting
(``lodprt.runtime.relighting``); the ``Runtime`` holds them, the device arrays and the camera, and runs the
frame. The equations and the measured behaviour are in docs/RUNTIME.md and docs/THEORY.md.
"""

from __future__ import annotations

import logging
import math
import os
import time

import numpy as np

from lodprt.errors import LodprtError
from lodprt.launches import ROWS_MIN, KernelThreads
from lodprt.runtime import frame_error, node_bounds
from lodprt.runtime.node_bounds import NodeErrors, scaled_error_vectors
from lodprt.runtime.budgets import FrameBudgets
from lodprt.runtime.criteria import Criterion, ThesisCriterion, resolve_criterion, retuned
from lodprt.runtime.camera import Camera, camera_for, camera_jump, clip_planes, scene_centre, view_projection
from lodprt.runtime.device_inputs import host_array
from lodprt.runtime.frames import Frame
from lodprt.runtime.refinement import HYSTERESIS, CutRefinement, ErrorCache
from lodprt.runtime.settings import check_bound, check_max_passes
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.relighting import Relighting
from lodprt.runtime.samples import default_white
from lodprt.runtime.shadow_edges import follow_shadow_edges
from lodprt.runtime.triangulation import CutMesh
from lodprt.runtime.view_cut import Cut
from lodprt.store.bake_store import as_store

log = logging.getLogger(__name__)

#: a camera move of more than JUMP of its distance to the target, or a change of the light weights by more than
#: LIGHT_JUMP of their sum, counts as a jump
JUMP, LIGHT_JUMP = 0.1, 0.4
#: E-4's rounds on the first frame with a target_psnr, and E-5's rounds of pins on it and a still one (each
#: converges the cut)
FIRST_ROUNDS = 12
#: M-6: rounds of the first frame that refine along the actual light's shadow edges (each relights the cut and
#: splits the nodes whose triangles straddle an edge by more than the bound)
EDGE_ROUNDS = 24
#: E-4: the relative change of the bound below which the steering keeps it
STEER_STEP = 0.1

class Runtime:
    """Relighting and view-dependent LOD over one bake store, kept by the caller across frames.

    criterion: a ``lodprt.runtime.criteria.Criterion`` (default ``ScreenCriterion()``: S-1 with S-2; or
    ``ThesisCriterion``: T-14) holding its settings, or its name ("screen", "thesis") with the settings as keywords:
    error_bound (refine above, coarsen at or below bound / HYSTERESIS; None: the criterion's default), alpha
    (T-14's weight of e_geo, "thesis"), pixel_tolerance and target_psnr ("screen": refine until the frame meets
    this estimated PSNR against the full mesh, E-1..E-5, ``error_bound`` the steering's start in motion; by
    default ``criteria.DEFAULT_TARGET_PSNR``, off ("off") when error_bound or triangle_budget is given alone);
    triangle_budget: when set, the bound is steered every frame (x1.25 above the budget, /1.1 below 80% of it)
    so that the triangle count settles under the budget (B-1); frame_ms: a frame-time budget in ms, a floor
    under the bound that rises while the frames in motion take longer (B-2, ``lodprt.runtime.budgets``); white:
    the radiance shown as 1.0 (default: the 99th percentile of the samples' view-averaged radiance); weighting /
    outside: light interpolation (``lodprt.runtime.lights``); max_passes: refinement passes per frame after the
    first; lod=False: the full mesh; device: the Warp device of the per-frame kernels (default: CUDA when present,
    else the CPU); cache_bytes: completed light samples (and their per-node bounds) kept at most, in bytes
    (default 1 GiB; never fewer than one frame's samples): a sample is completed (T-15) when the lights first give
    it a weight (``lodprt.runtime.samples.SampleCache``); progress(done, total): called as the light samples a
    frame needs are completed;
    interpolation: how a light between samples is lit (``lodprt.runtime.direct_light.INTERPOLATIONS``): "direct"
    (default: the light's direct Phong radiance in closed form times a shadow ray's visibility, plus the samples'
    interpolated residual, M-1, M-2), "direct-agree" (rays only where the samples disagree, M-3), "direct-blend"
    (no rays, M-4), or "thesis" (T-12: the samples' radiance blended).
    """

    def __init__(self, store, *, error_bound: float | None = None, alpha: float | None = None,
                 criterion: str | Criterion = "screen", pixel_tolerance: float | None = None,
                 triangle_budget: int | None = None, frame_ms: float | None = None,
                 white: float | None = None, weighting: str = "exact", outside: str = "clamp", max_passes: int = 1,
                 lod: bool = True, device: str | None = None, cache_bytes: int | None = None, progress=None,
                 interpolation: str = DEFAULT_INTERPOLATION, target_psnr: float | str | None = None):
        from lodprt.devices import resolve_device

        if triangle_budget is not None and target_psnr is None and criterion == "screen":
            target_psnr = "off"  # the budget steers the bound instead of the default target
        self._criterion = resolve_criterion(criterion, error_bound=error_bound, alpha=alpha,
                                            pixel_tolerance=pixel_tolerance, target_psnr=target_psnr)
        if self.criterion.steered() and triangle_budget is not None:
            raise LodprtError("target_psnr steers the screen criterion's bound: not with a triangle_budget")
        self.estimated_psnr = None  # E-3 of the last estimate (target_psnr set)
        self.estimate_stride = None  # the last estimate's cells, in pixels (1: every pixel; E-2)
        self.view_jumped = False  # the camera jumped since the last frame (set_camera)
        self.schedule = frame_error.EstimateSchedule()  # which frames estimate E-1, on the grid or every pixel
        self.motion_bound = None  # E-4's bound, kept aside while a still frame draws E-5's pinned cut
        #: E-4: the search for the largest bound whose frame meets target_psnr (None without a target)
        self.steering = frame_error.Steering(self.criterion.target_psnr, STEER_STEP) if self.criterion.steered() \
            else None
        self.device = resolve_device(device)
        self.store = store = as_store(store)  # a path is opened
        self.h = h = store.hierarchy()
        # the store's own arrays (read once, kept on the Store), float32 and int32: one copy of the geometry serves
        # the frames, the kernels (wrapped, not copied, on the CPU) and the direct light's BVH (docs/SCALE.md)
        self.faces = np.ascontiguousarray(store.faces, np.int32)
        self.positions = np.ascontiguousarray(store.positions, np.float32)
        self.normals = np.ascontiguousarray(store.normals, np.float32)
        self.bounds = np.array([self.positions.min(0), self.positions.max(0)], np.float64) if len(self.positions) \
            else np.zeros((2, 3))
        self.budgets = FrameBudgets(triangle_budget, frame_ms, lowest=frame_error.BOUND_RANGE[0],
                                    highest=frame_error.BOUND_RANGE[1])  # B-1, B-2
        self.max_passes = check_max_passes(max_passes)
        self.lod = bool(lod)
        self.order = store.sh_order
        # lights, their samples (T-15 on demand, SampleCache) and the interpolation (T-12 or M-1..M-4)
        self.lighting = Relighting(store, self.device, interpolation=interpolation, weighting=weighting,
                                   outside=outside, cache_bytes=cache_bytes, progress=progress)
        self.interpolation = self.lighting.interpolation
        self.interp, self.samples = self.lighting.interp, self.lighting.samples
        self.channels, self.ncoef = self.samples.C, self.samples.n
        self.white = float(white) if white is not None else default_white(store)
        if not self.white > 0 or not math.isfinite(self.white):
            raise LodprtError(f"white {white}: must be a positive finite radiance")
        self._synced = -1  # the sample cache's version the device arrays hold
        # per-node geometry for the error terms (float32, as the kernels read it; a node stands at its vertex, through
        # h.vertex, not stored per node); S-3: the error vector's direction at the subtree's accumulated deviation
        # (one collapse's vector measures one step; a coarse node stands for all the steps under it)
        self._levels = node_bounds.height_levels(h)
        self.error_vector = scaled_error_vectors(h, node_bounds.subtree_deviation(h, self._levels))
        self.axis = np.ascontiguousarray(h.cone_axis, np.float32)
        self.half = np.ascontiguousarray(h.cone_half_angle, np.float32)
        self.radius = np.ascontiguousarray(h.radius, np.float32)
        self._upload()
        cut = Cut.base(h, self.faces) if self.lod else Cut.full(h, self.faces)
        #: how the cut moves (refine/coarsen passes) and when a candidate's error is evaluated again
        self.refinement = CutRefinement(h, cut, self.device, self.max_passes)
        self.errors = ErrorCache(h.num_nodes)
        # the cut's mesh (T-3.2, what changed only); on the CPU made on a worker thread while a frame relights
        self._meshes = CutMesh(h, self.faces, self.store.referenced, self.device, background=self.device == "cpu")
        self.camera: Camera | None = None
        self._centre = None  # the default camera target, made on first use
        if self.lod:  # the bounds the criterion reads, made with each sample (counted in cache_bytes from the start)
            self._node_bounds(self.criterion.NODE_BOUNDS[0])
            if self.steering is not None:  # E-4's per-sample arrays, made with each sample from the first
                frame_error.derive_mean_square(self, self._levels)
        self.set_lights(self.interp.samples[len(self.interp.samples) // 2][None, :])

    # -- set-up ------------------------------------------------------------------------------------------------
    @property
    def cut(self) -> Cut:
        """The current view cut (``lodprt.runtime.view_cut.Cut``)."""
        return self.refinement.cut

    @property
    def box_centre(self) -> np.ndarray:
        """T-14 coefficient box centres (N - V, slots, C, ncoef) float16 (``node_bounds.coefficient_boxes``)."""
        return self._node_bounds("box_centre")

    @property
    def box_half(self) -> np.ndarray:
        """T-14 coefficient box half-widths (N - V, slots, C, ncoef) float16."""
        return self._node_bounds("box_half")

    @property
    def detail(self) -> np.ndarray:
        """S-2 detail bounds (N - V, slots, C) float16, rounded up (``lodprt.runtime.node_bounds.detail_bounds``,
        ``float16_up``)."""
        return self._node_bounds("detail")

    def _node_bounds(self, name: str) -> np.ndarray:
        """One of the per-node bounds, per sample slot, made for every completed sample once first asked for."""
        h, cache = self.h, self.samples
        key = "detail" if name == "detail" else "boxes"
        if key not in cache.derived:
            rows, levels, white = h.num_nodes - h.num_vertices, self._levels, self.white
            if key == "detail":
                # S-2 (b)'s edges: the Cut's leaf-order adjacency (the same edges, no second copy)
                plan, adj = self.store.completion_plan(), self.refinement.cut.leaf_adjacency
                bound = node_bounds.detail_bounds
                cache.derive("detail", lambda c: node_bounds.float16_up(bound(h, c, white, plan, adj, levels)),
                             rows, (self.channels,), np.float16)
            else:
                cache.derive("boxes", lambda c: node_bounds.coefficient_boxes(h, c, white, levels), rows,
                             (2, self.channels, self.ncoef), np.float16)
        arr = cache.derived[key][0]
        return arr if key == "detail" else arr[:, :, 0] if name == "box_centre" else arr[:, :, 1]

    def _sync_device(self) -> None:
        """The sample slots and their bounds on the device, as the cache holds them now (on the CPU the Warp arrays
        share the numpy memory; elsewhere a slot change uploads them again)."""
        if self._synced == self.samples.version:
            return
        wp, dev = self._wp, self.device
        self._d["coeffs"] = wp.array(self.samples.coeffs, dtype=wp.float32, device=dev, copy=dev != "cpu")
        for name in ("detail", "box_centre", "box_half"):
            if ("boxes" if name != "detail" else name) in self.samples.derived:
                arr = self._node_bounds(name)
                self._d[name] = wp.array(arr, dtype=wp.float16, device=dev, copy=dev != "cpu")
        self._synced = self.samples.version

    def _kernel_bounds(self, exact: bool) -> list:
        """The view_errors kernel's box_centre, box_half and detail arrays: the ones its criterion reads (the boxes
        too when ``exact``, which evaluates every term); a one-row placeholder, never indexed, for the others."""
        need = set(self.criterion.NODE_BOUNDS) | ({"box_centre", "box_half"} if exact else set())
        if "placeholder" not in self._d:
            self._d["placeholder"] = self._wp.zeros((1, 1, 1, self.ncoef), dtype=self._wp.float16, device=self.device)
            self._d["placeholder_detail"] = self._wp.zeros((1, 1, 1), dtype=self._wp.float16, device=self.device)
        out = []
        for name in ("box_centre", "box_half", "detail"):
            if name in need:
                self._node_bounds(name)
                self._sync_device()
            spare = "placeholder_detail" if name == "detail" else "placeholder"
            out.append(self._d[name] if name in need else self._d[spare])
        return out

    def _upload(self) -> None:
        """The per-frame kernels' read-only inputs, on the device once."""
        from lodprt.devices import warp

        wp = warp()
        dev = self.device
        self._threads = KernelThreads(min(os.cpu_count() or 1, 8)) if dev == "cpu" else None
        # on the CPU the Warp arrays wrap the float32 numpy arrays (no second copy)
        v3 = lambda a: wp.array(a, dtype=wp.vec3, device=dev, copy=dev != "cpu")  # noqa: E731
        f1 = lambda a: wp.array(a, dtype=wp.float32, device=dev, copy=dev != "cpu")  # noqa: E731
        i1 = lambda a: wp.array(np.ascontiguousarray(a, np.int32), dtype=wp.int32, device=dev,  # noqa: E731
                                copy=dev != "cpu")
        self._wp = wp
        self._d = {
            "vertex": i1(self.h.vertex), "children": i1(self.h.children),
            "error_vector": v3(self.error_vector), "axis": v3(self.axis), "half": f1(self.half),
            "radius": f1(self.radius), "positions": v3(self.positions), "normals": v3(self.normals),
        }

    def launch_rows(self, kernel, rows: int, inputs: list, outputs: list) -> None:
        """Launch ``kernel`` over ``rows`` rows, each launch taking its first row as ``offset``: on the CPU in slices
        over the cores (``lodprt.launches.KernelThreads``: a slice a core from ROWS_MIN rows), one launch on a GPU."""
        wp, dev = self._wp, self.device

        def run(a: int, b: int) -> None:
            wp.launch(kernel, dim=b - a, inputs=[a] + inputs, outputs=outputs, device=dev)

        if self._threads is None:
            run(0, rows)
        else:
            self._threads.slices(run, rows, least=ROWS_MIN, per_thread=1)

    def _frame_inputs(self) -> tuple:
        """The slots of the samples in use and every slot's RGB weight (0 for the others), on the device."""
        wp = self._wp
        self._sync_device()
        weights = np.zeros((self.samples.slots, 3), np.float32)
        weights[self.used_slots] = self.sample_weights[self.used_samples]
        return (host_array(self.used_slots, np.int32, wp.int32, self.device),
                host_array(weights, np.float32, wp.float32, self.device))

    @property
    def criterion(self) -> Criterion:
        """The view cut's criterion, with its settings (the steering replaces it with one of another bound)."""
        return self._criterion

    @criterion.setter
    def criterion(self, new: Criterion) -> None:
        if (new := retuned(self._criterion, new)) != self._criterion:  # only its bound and alpha change once made
            self.refinement.forget_splits()  # M-7: another bound (B-1, B-2, E-4, E-5) or alpha: other decisions
        self._criterion = new

    @property
    def error_bound(self) -> float:
        """The criterion's error bound (steered by a target_psnr or a triangle_budget)."""
        return self.criterion.error_bound

    @error_bound.setter
    def error_bound(self, value: float) -> None:
        self.criterion = self.criterion.with_bound(self.budgets.limit(value))  # B-2: never under the floor

    @property
    def triangle_budget(self) -> int | None:
        """B-1's triangle budget (None: none)."""
        return self.budgets.triangles

    @property
    def alpha(self) -> float:
        """T-14's weight of e_geo ("thesis"; the default 0.6 for a criterion without one)."""
        return getattr(self.criterion, "alpha", ThesisCriterion.alpha)

    @property
    def target_psnr(self) -> float | None:
        """The screen criterion's target (E-4), or None."""
        return getattr(self.criterion, "target_psnr", None)

    def set_error_bound(self, error_bound: float, alpha: float | None = None) -> None:
        """The criterion's error bound (>= 0; B-2's floor when under it, as every bound) and, when given, alpha in
        [0, 1] (T-14's weight of e_geo; checked and unread by a criterion without one)."""
        new = self.criterion.with_bound(self.budgets.limit(check_bound(error_bound)))  # B-2: never under the floor
        self.criterion = new if alpha is None else new.with_alpha(alpha)
        self.refinement.dirty = self.errors.refresh_all = True

    def set_lod(self, enabled: bool) -> None:
        """LOD off shows the full mesh (every leaf active); on starts again from the base mesh (no pins)."""
        self.lod = bool(enabled)
        self.refinement.reset(Cut.base(self.h, self.faces) if self.lod else Cut.full(self.h, self.faces))
        self.errors.refresh_all = self.view_jumped = True

    def set_lights(self, positions, colors=None) -> None:
        """Point lights at (L, 3) positions with (L, 3) RGB intensities (default: the bake's intensity each).
        Outside the sampled region: clamped with a warning, or an error (``outside``)."""
        lit, old = self.lighting, self.lighting.weights
        lit.set_lights(positions, colors)  # completes the samples not held yet (T-15)
        W = lit.weights
        self.refinement.dirty = True
        if old is None or old.shape != W.shape or np.abs(W - old).sum() > LIGHT_JUMP * max(np.abs(old).sum(), 1e-30):
            self.errors.refresh_all = True
        if self.camera is None or not (np.array_equal(lit.positions, self.light_positions)
                                       and np.array_equal(lit.colors, self.light_colors)):
            self.schedule.moved = True
            self.refinement.forget_splits()  # M-7
        self.light_positions, self.light_colors, self.lights_clamped = lit.positions, lit.colors, lit.clamped
        self.sample_weights, self.used_samples, self.used_slots = W, lit.used_samples, lit.used_slots

    def set_camera(self, camera=None, target=None, up=None, fov=None, width=None, height=None, near=None, far=None, *,
                   eye=None) -> Camera:
        """A ``Camera`` or its fields (the eye positional or ``eye=``; None: ``Camera``'s default, or beside a
        ``Camera`` its own); ``target`` None: the scene's centre, as the CLI."""
        old = self.camera
        if self._centre is None and target is None and not isinstance(camera, Camera):
            self._centre = scene_centre(self.store)
        self.camera = self.lighting.watch_eye(camera_for(camera, eye=eye, target=target, default_target=self._centre,
                                                         up=up, fov=fov, width=width, height=height, near=near, far=far))
        self.refinement.dirty = True
        self.schedule.moved = self.schedule.moved or self.camera != old
        if self.camera != old:
            self.refinement.forget_splits()  # M-7
        if old is None or camera_jump(old, self.camera, JUMP):
            self.errors.refresh_all = self.view_jumped = True
        self.vp = view_projection(self.camera, self.bounds)
        self.planes = clip_planes(self.vp)
        return self.camera

    # -- errors ------------------------------------------------------------------------------------------------
    def node_errors(self, nodes, *, exact: bool = True, detail_only: bool = False) -> NodeErrors:
        """For internal ``nodes`` (K,), a ``NodeErrors``: culled (T-13 back-facing or outside the frustum), the
        criterion's error (S-1 or T-14), e_geo, e_lumi, footprint, e_detail (all 0 where culled: a culled node is
        coarsened whatever its error); float32 Warp kernel
        (``lodprt.kernels.runtime.view_errors``) on the Runtime's device. ``exact=False`` (the frame loop) stops a
        node's evaluation once its refine/coarsen decision is known: its error is then an upper bound when at or
        under the bound, and e_lumi / e_detail read -1 where they were not needed; ``detail_only`` evaluates S-1 and
        S-2 in full but not T-14's e_lumi (the frame estimate, E-1)."""
        from lodprt.kernels import runtime as kr

        if self.camera is None:
            raise LodprtError("no camera: call set_camera(eye, target, ...) before update()")
        wp, dev, d = self._wp, self.device, self._d
        nodes = np.asarray(nodes, np.int32)
        K = len(nodes)
        outs = [wp.empty(K, dtype=wp.uint8, device=dev)] + [wp.empty(K, dtype=wp.float32, device=dev) for _ in range(5)]
        if K:
            cam = self.camera
            used, weights = self._frame_inputs()
            bounds = self._kernel_bounds(exact)
            measured = self.motion_bound is not None  # E-5's still cut: its every pixel measured
            mode, geo_rate, area_ref, alpha = self.criterion.kernel_inputs(cam.width, cam.height, measured)
            self.launch_rows(kr.view_errors, K, [
                host_array(nodes, np.int32, wp.int32, dev), self.h.num_vertices, d["positions"], d["vertex"],
                d["children"], d["error_vector"], d["axis"], d["half"], d["radius"],
                host_array(self.planes, np.float32, wp.vec4, dev),
                wp.mat44(*self.vp.astype(np.float32).ravel()), wp.vec3(*map(float, cam.eye)),
                0.5 * cam.width, 0.5 * cam.height, math.hypot(cam.width, cam.height), self.focal_px(), used, weights,
                *bounds, mode, int(self.interpolation != "thesis"),
                host_array(self.lighting.bracket_mask(), np.int32, wp.int32, dev),
                2 if detail_only else int(bool(exact)),
                float(self.error_bound), float(HYSTERESIS), geo_rate, area_ref, alpha,
                wp.empty((K, self.ncoef), dtype=wp.float32, device=dev),
            ], outs)
        culled, err, geo, lumi, foot, det = (o.numpy() for o in outs)
        return NodeErrors(culled.astype(bool), *(a.astype(np.float64) for a in (err, geo, lumi, foot, det)))

    def node_pos(self, nodes) -> np.ndarray:
        """(K, 3) float32 positions of the vertices of ``nodes`` (each node stands at its vertex)."""
        return self.positions[self.h.vertex[nodes]]

    def focal_px(self) -> float:
        """Focal length of the camera in pixels: (height / 2) / tan(fov / 2)."""
        return 0.5 * self.camera.height / math.tan(math.radians(self.camera.fov) / 2)

    # -- frames ------------------------------------------------------------------------------------------------
    def _converge(self, max_passes: int | None) -> tuple[int, int, int, int]:
        """``CutRefinement.converge`` with this frame's errors: (refined, coarsened, nodes touched, passes)."""
        evaluate = lambda nodes: self.node_errors(nodes, exact=False)[:2]  # noqa: E731
        return self.refinement.converge(self.errors, evaluate, self.error_bound, max_passes, enabled=self.lod)

    def _cut_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertex ids (A,) int32 ascending, triangles (M, 3) indices into them) of the current cut, read-only
        (``CutMesh``: kept while no active ancestor moves; a still cut, the full mesh with LOD off)."""
        return self._meshes(self.cut)

    def estimate_frame_error(self, vid: np.ndarray, tri: np.ndarray, coefficients: np.ndarray | None = None, *,
                             steer: bool = True, every_pixel: bool = False) -> None:
        """E-1..E-3 of the current cut (``estimated_psnr``; ``vid``, ``tri``: its mesh as ``_cut_mesh`` gives it,
        ``coefficients`` its relit ones or None; on E-2's grid, or every pixel) and, with a target_psnr and
        ``steer``, E-4: the bound for the next frames (``frame_error.Steering``, settled within STEER_STEP)."""
        stride = frame_error.ray_stride(self.camera.width, self.camera.height, 1 if every_pixel else None)
        self.estimated_psnr, new, self.estimate_stride = frame_error.estimate(
            self, vid, tri, self.steering if steer else None, coefficients, stride=stride)
        if new is not None and new != self.error_bound:
            self.error_bound, self.refinement.dirty = new, True

    def relit(self, vertex_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((K, 3, ncoef) coefficients, (K, 3) radiance toward the eye) float32 of ``vertex_ids``, as a frame relights
        (T-7 with M-1; any vertex), leaving the last frame's relighting state (M-6's lit lights) as it was."""
        lighting = self.lighting
        kept = lighting.frame_lit, None if lighting.direct is None else lighting.direct.lit
        try:
            return self._relight(np.asarray(vertex_ids, np.int64))
        finally:
            lighting.frame_lit = kept[0]
            if lighting.direct is not None:
                lighting.direct.lit = kept[1]

    def scene_bvh(self):
        """Warp mesh (BVH) of the store's triangles on the device, face ids as in ``faces`` (E-2's rays)."""
        d = self.lighting.direct
        if d is not None:
            return d.mesh
        if "bvh" not in self._d:
            wp = self._wp
            idx = wp.array(self.faces.ravel(), dtype=wp.int32, device=self.device, copy=self.device != "cpu")
            self._d["bvh"] = wp.Mesh(points=self._d["positions"], indices=idx)
        return self._d["bvh"]

    def update(self, *, max_passes: int | None = None) -> Frame:
        """Move the cut for the current camera and lights, triangulate it, relight it: a ``Frame``."""
        if self.camera is None:
            raise LodprtError("no camera: call set_camera(eye, target, ...) before update()")
        max_passes = None if max_passes is None else check_max_passes(max_passes)
        t0 = time.perf_counter()
        self.errors.frame += 1
        # E-5 on the first frame and a still one, E-4 on E-2's grid in motion: ``frame_error.EstimateSchedule``
        settle, jumped, self.view_jumped = not self.refinement.converged_once, self.view_jumped, False
        due, still = self.schedule.begin(self.errors.frame, settle, jumped, self.steering)
        estimating = self.lod and self.target_psnr is not None and due
        pinning = estimating and (settle or still)
        if pinning and settle:  # E-4 first: the bound the frames in motion start from
            self._steer_rounds()
        if pinning or (not still and self.motion_bound is not None):
            if pinning:  # E-5 from the coarsest bound; E-4's bound is kept for the frames in motion
                self.motion_bound = self.motion_bound or self.error_bound
                self.error_bound = frame_error.BOUND_RANGE[1]
            else:  # moving again: E-4's bound back, the pins dropped
                self.error_bound, self.motion_bound = self.motion_bound, None
            self.refinement.pin(None)
            self.errors.forget()
        self._meshes.wait()  # an interrupted frame's mesh still in the making: done before the cut moves
        refined, coarsened, touched, passes = self._converge(10_000 if pinning else max_passes)
        t1 = time.perf_counter()
        overlap = self.lod and not settle and not pinning and self._meshes.background  # in motion, on the CPU
        if overlap:  # the triangles on the worker thread, the vertices relit meanwhile (they need the nodes only)
            self._meshes.start(self.cut)
            vid = self._meshes.vertices(self.cut.nodes)
        else:
            vid, tri = self._cut_mesh()
        t2 = time.perf_counter()
        counts = (refined, coarsened, touched, passes)
        coef = rad = None
        if pinning:
            vid, tri, coef, rad, counts = self._pin_rounds(vid, tri, counts)
            self.schedule.confirmed = True
        steer = time.perf_counter() - t2  # the estimate and steering count as cut work
        if coef is None:
            try:
                coef, rad = self._relight(vid)
            finally:
                if overlap:
                    vid, tri = self._meshes.take()
        t3 = time.perf_counter()
        waited = self._meshes.waited if overlap else 0.0  # the triangulation's time not hidden by the relighting
        if estimating and not pinning:  # E-4 from this frame's relit cut; the bound moves for the next frames
            self.estimate_frame_error(vid, tri, coef)
        if settle:  # M-6: the first frame follows the light's shadow edges
            vid, tri, coef, rad, counts = self._edge_rounds(vid, tri, counts, (coef, rad))
        else:
            self._shadow_edges(vid, tri, rad)
        refined, coarsened, touched, passes = counts
        steer += time.perf_counter() - t3  # M-6 (and its first-frame rounds) count as cut work
        t3 = time.perf_counter()
        new = self.budgets.after_frame(self.error_bound, len(tri), 1e3 * (t3 - t0),  # B-1, B-2
                                       self.lod and not (estimating or settle or still), not (refined or coarsened))
        if new != self.error_bound:
            self.error_bound, self.refinement.dirty = new, True
        stats = {
            "triangles": int(len(tri)), "active_nodes": int(len(self.cut.nodes)), "vertices": int(len(vid)),
            "nodes_touched": int(touched), "refined": int(refined), "coarsened": int(coarsened),
            "passes": int(passes), "criterion": self.criterion.name,
            **self.criterion.settings(),  # the active criterion's knobs only (error_bound steered)
            "lights_clamped": int(self.lights_clamped),
            "shadow_rays": int(self.lighting.rays),  # M-3: rays cast toward the lights
            # E-3 of the cut (None without a target_psnr, and with LOD off: the full mesh has no error to estimate)
            "estimated_psnr_db": self.estimated_psnr if self.lod else None,
            "estimate_stride_px": self.estimate_stride if self.lod else None,  # its cells (1: every pixel)
            "pinned_nodes": self.refinement.pins,  # E-5 (first and still frames)
            **self.budgets.settings(),  # B-1, B-2: the budgets, and the bound's floor under a frame-time budget
            "ms_cut": 1e3 * (t1 - t0 + steer), "ms_triangulate": 1e3 * (t2 - t1 + waited),
            "ms_relight": 1e3 * (t3 - t2 - steer - waited), "ms_total": 1e3 * (t3 - t0),
        }
        return Frame(vertex_ids=vid.copy(), positions=np.take(self.positions, vid, axis=0),
                     normals=np.take(self.normals, vid, axis=0), triangles=tri.astype(np.int32),
                     coefficients=coef, radiance=rad.astype(np.float32), lights=self.light_positions.copy(),
                     light_colors=self.light_colors.copy(), camera=self.camera, stats=stats, white=self.white)

    def _steer_rounds(self) -> None:
        """E-4 on the first frame, on E-2's grid: converge, follow the light's shadow edges (M-6), estimate, until the
        steering settles (at most FIRST_ROUNDS rounds): the bound the frames in motion start from."""
        self._converge(10_000)
        vid, tri = self._cut_mesh()
        for _ in range(FIRST_ROUNDS):
            vid, tri, coef = self._edge_rounds(vid, tri, (0, 0, 0, 0))[:3]
            self.estimate_frame_error(vid, tri, coef)
            if not self.refinement.dirty:
                return
            self._converge(10_000)
            vid, tri = self._cut_mesh()

    def _pin_rounds(self, vid, tri, counts: tuple) -> tuple:
        """E-5 on the cut at the coarsest bound: split the nodes that carry the frame's error measured on every pixel
        (``frame_error.pin``) until it meets the target (at most FIRST_ROUNDS rounds). ``_edge_rounds``' tuple."""
        self.estimate_stride = frame_error.ray_stride(self.camera.width, self.camera.height, 1)
        for _ in range(FIRST_ROUNDS):
            coef, rad = self._relight(vid)
            self.estimated_psnr, nodes = frame_error.pin(self, vid, tri, coef)
            if not len(nodes):
                return vid, tri, coef, rad, counts
            self.refinement.pin(nodes)
            more = self._converge(10_000)
            counts = tuple(a + b for a, b in zip(counts, more))
            if not more[0] and not more[1]:  # the cut did not move: no pinned node could split
                return vid, tri, coef, rad, counts
            vid, tri = self._cut_mesh()
        self.estimate_frame_error(vid, tri, every_pixel=True, steer=False)  # E-3 of the cut drawn
        return vid, tri, None, None, counts

    def _edge_rounds(self, vid, tri, counts: tuple, relit: tuple | None = None) -> tuple:
        """M-6 on a first frame: relight the cut (unless ``relit`` holds its (coefficients, radiance)), then refine
        along the actual lights' shadow edges until no straddling step is over the bound (at most EDGE_ROUNDS
        rounds). Returns (vid, tri, coefficients, radiance, ``counts`` (refined, coarsened, touched, passes) plus
        this work's)."""
        coef, rad = self._relight(vid) if relit is None else relit
        if not self._shadow_edges(vid, tri, rad):
            return vid, tri, coef, rad, counts
        for _ in range(EDGE_ROUNDS):
            more = self._converge(10_000)
            counts = tuple(a + b for a, b in zip(counts, more))
            if not more[0] and not more[1]:
                break
            vid, tri = self._cut_mesh()  # the cut moved (collapses alone too): the frame draws the cut it leaves
            coef, rad = self._relight(vid)
            if not more[0] or not self._shadow_edges(vid, tri, rad):
                break
        return vid, tri, coef, rad, counts

    def _shadow_edges(self, vid: np.ndarray, tri: np.ndarray, rad: np.ndarray) -> bool:
        """M-6 from the relight of ``vid`` (``shadow_edges.follow_shadow_edges``): whether the cut must move."""
        return follow_shadow_edges(self, vid, tri, rad)

    def _relight(self, vid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, 3, ncoef) coefficients and (A, 3) radiance toward the eye of vertices ``vid``
        (``Relighting.relight_vertices``: T-7, with the direct term M-1)."""
        return self.lighting.relight_vertices(vid, self.camera.eye, self._d, self._frame_inputs, self.launch_rows)

    # -- full resolution ---------------------------------------------------------------------------------------
    def coefficients(self, vertex_ids=None) -> np.ndarray:
        """(K, 3, ncoef) float32 RGB coefficients of the current lights at ``vertex_ids`` (default: every vertex):
        ``sum_j W[j, c] C_j`` over the completed light samples (T-12 weights, intensities applied), plus the
        direct term of the interpolation (M-1; ``Relighting.coefficients``)."""
        ids = np.arange(self.h.num_vertices) if vertex_ids is None else np.asarray(vertex_ids, np.int64)
        return self.lighting.coefficients(ids)

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

