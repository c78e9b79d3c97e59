"""Relighting of the run time (SPEC 5; thesis 3.4.1, T-12, T-15, T-7; M-1..M-4): the current point lights, the
light samples they use (completed on demand, ``SampleCache``) and the per-vertex coefficients and radiance of a
set of vertices under them, by the chosen interpolation (``lodprt.runtime.direct_light.INTERPOLATIONS``):

* ``"direct"`` (default) and its variants: the actual light's direct radiance in closed form times its visibility,
  plus, on a GI store, the interpolated residual of the samples (M-1, M-2; ``kernels.direct.direct_light`` after
  ``kernels.runtime.relight`` over the residuals);
* ``"thesis"``: the samples' radiance blended by the T-12 weights (``kernels.runtime.relight``).
"""

from __future__ import annotations

import numpy as np

from lodprt.runtime.device_inputs import host_array, zeros
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION, DirectLight, check_interpolation
from lodprt.runtime.inside import InsideCheck
from lodprt.runtime.lights import LightInterpolator, check_lights
from lodprt.runtime.samples import SampleCache


class Relighting:
    """Lights, light samples and relighting over one bake store on one Warp device.

    After ``set_lights``: ``positions`` (L, 3) and ``colors`` (L, 3) as used (clamped), ``clamped`` how many were
    moved into the sampled region, ``weights`` (S, 3) every sample's RGB weight (lights summed), ``used_samples``
    the samples with a weight and ``used_slots`` the cache slots holding them, ``light_samples`` / ``light_weights``
    (L, k) each light's nearest samples and their T-12 weights.
    """

    def __init__(self, store, device: str, *, interpolation: str = DEFAULT_INTERPOLATION, weighting: str = "exact",
                 outside: str = "clamp", cache_bytes: int | None = None, progress=None):
        self.store, self.device = store, device
        self.interpolation = check_interpolation(interpolation)
        self.interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"],
                                        weighting=weighting, outside=outside)
        self.direct = None if interpolation == "thesis" else DirectLight(store, device, interpolation)
        #: a light or an eye inside a closed object is warned about once each (``lodprt.runtime.inside``)
        self.inside = InsideCheck(store)
        d = self.direct
        #: the lighting reads the samples' coefficients: T-12, or M-1's residual on a GI store
        self.uses_samples = d is None or d.residual
        # T-15 per sample when the lights first use it (SPEC 5), float32 slots, vertex-major (V, slots, C, ncoef);
        # with a direct term the slots hold each sample's residual R_j (GI stores) and its visibility (M-2)
        split = d.split if d is not None and (d.residual or d.uses_visibility) else None
        # the view cut's per-node bounds bound the error of the field drawn at each sample: S_j where the lighting
        # reads the coefficients; otherwise (M-1 on a direct-only store) the slots keep none, no sample is completed,
        # and the bounds come from D_j V_j exact at every referenced vertex (``DirectLight.direct_field``), not the
        # light cut's completion
        self.samples = SampleCache(store, cache_bytes=cache_bytes, progress=progress, split=split,
                                   field=None if self.uses_samples else d.direct_field)
        self.channels, self.ncoef = self.samples.C, self.samples.n
        self.weights = None
        self.rays = 0  # shadow rays the last relight cast (M-3)
        self.frame_lit = None  # which lights reach each vertex of the last relight_vertices (M-6), or None
        self._vis = None  # device copy of the samples' visibility and the cache version it holds
        self._vis_version = -1
        self._bracket = None  # bracket_mask of the current lights, and the cache version it was made for

    def set_lights(self, positions, colors=None) -> None:
        """Point lights at (L, 3) positions with (L, 3) RGB intensities (default: the bake's intensity each);
        outside the sampled region clamped with a warning, or an error (``outside``)."""
        pos, col = check_lights(positions, colors, self.store.intensity)
        self.inside.check(pos, "light")  # where asked for, before any clamping
        pos, moved = self.interp.clamp(pos)  # refuses, or warns the first time a light is clamped
        idx, w, _ = self.interp.weights(pos)
        W = np.zeros((len(self.interp.samples), 3))
        np.add.at(W, idx.ravel(), (w[:, :, None] * col[:, None, :]).reshape(-1, 3))  # lights add (thesis 3.4.1)
        self.positions, self.colors, self.clamped = pos, col, int(moved.sum())
        self.light_samples, self.light_weights = idx, w
        self.weights = W
        self.used_samples = np.flatnonzero(np.abs(W).sum(1) > 0)
        self.used_slots = self.samples.ensure(self.used_samples)  # completes the samples not held yet (T-15)
        self._bracket = None

    def watch_eye(self, camera):
        """``camera``, its eye checked against the scene's closed objects (one warning for the first inside)."""
        self.inside.check(camera.eye, "eye")
        return camera

    def slot_of_sample(self) -> np.ndarray:
        """(S,) int32 the cache slot holding each light sample in use, -1 for the others."""
        slot = np.full(len(self.interp.samples), -1, np.int32)
        slot[self.used_samples] = self.used_slots
        return slot

    def light_slots(self) -> np.ndarray:
        """(L, k) int32 the cache slot of each light's samples, -1 where the sample has no weight: the samples whose
        visibility decides the light's ("direct-agree" M-3, "direct-blend" M-4)."""
        return np.where(self.light_weights > 0, self.slot_of_sample()[self.light_samples], -1).astype(np.int32)

    def bracket_mask(self) -> np.ndarray:
        """(slots,) int32: 1 for the cache slots of the samples around each light (``bracketing``), whose S-2
        detail the direct path's view cut takes at full weight (M-5). Made once for the lights and the cache's
        slots (a frame's view errors ask for it on every pass)."""
        if self._bracket is not None and self._bracket[0] == self.samples.version:
            return self._bracket[1]
        mask = np.zeros(max(self.samples.slots, 1), np.int32)
        near = bracketing(self.interp.samples, self.positions, self.light_samples, self.light_weights)
        chosen = self.slot_of_sample()[self.light_samples[near]]
        mask[chosen[chosen >= 0]] = 1
        mask.flags.writeable = False  # shared by the calls until the lights or the slots change
        self._bracket = (self.samples.version, mask)
        return mask

    def visibility_array(self):
        """The samples' visibility (V, slots) uint8 on the device, as the cache holds it now."""
        from lodprt.devices import warp

        if self.samples.split is None:  # "direct" on a direct-only store reads no sample visibility
            from lodprt.devices import warp as warp_

            if self._vis is None:
                self._vis = warp_().zeros((1, 1), dtype=warp_().uint8, device=self.device)
            return self._vis
        if self._vis_version != self.samples.version:
            wp, dev = warp(), self.device
            self._vis = wp.array(self.samples.visibility, dtype=wp.uint8, device=dev, copy=dev != "cpu")
            self._vis_version = self.samples.version
        return self._vis

    def add_direct(self, vid, coeffs, *, eye=None, radiance=None, eye_basis=None, launch=None) -> None:
        """M-1: add the direct term of the current lights to ``coeffs`` (A, 3, ncoef) of vertices ``vid`` (Warp
        arrays; and to ``radiance`` (A, 3) toward ``eye``, with ``eye_basis`` the basis toward it when known);
        ``launch`` splits the kernel over rows."""
        if self.direct is None:
            return
        self.rays = self.direct.add(vid, self.positions, self.colors, self.light_slots(), self.light_weights,
                                    self.visibility_array(), coeffs, eye=eye, radiance=radiance, eye_basis=eye_basis,
                                    threads=launch)

    def lit_rows(self, count: int) -> np.ndarray | None:
        """(count,) int32: which lights reached each vertex of the last ``relight_vertices`` (bit per light, M-6),
        or None without a direct term (T-12) or when that relight had another number of rows."""
        lit = self.frame_lit
        return lit if lit is not None and len(lit) == count else None

    def relight_vertices(self, vid: np.ndarray, eye, arrays: dict, frame_inputs, launch) -> tuple[np.ndarray,
                                                                                                  np.ndarray]:
        """(A, 3, ncoef) interpolated coefficients and (A, 3) radiance toward ``eye`` of vertices ``vid`` under the
        current lights (``lodprt.kernels.runtime.relight``, T-7; with a direct term, over the samples' residuals,
        then ``kernels.direct.direct_light``: M-1). ``arrays``: the device's "positions", "normals" and "coeffs"
        (the sample slots); ``frame_inputs()``: the slots in use and every slot's weight on the device;
        ``launch(kernel, rows, inputs, outputs)`` splits a kernel over rows."""
        from lodprt.devices import warp
        from lodprt.kernels import runtime as kr

        wp, dev = warp(), self.device
        A = len(vid)
        self.frame_lit = None
        if not self.uses_samples:  # M-1 on a direct-only store: the direct term alone
            coef = zeros((A, 3, self.ncoef), np.float32, wp.float32, dev)
            rad = zeros((A, 3), np.float32, wp.float32, dev)
            if A:
                self.add_direct(vid, coef, eye=eye, radiance=rad, launch=launch)
                self.frame_lit = self.direct.lit  # kept apart: coefficients() relights other vertices
            return coef.numpy(), rad.numpy()
        coef = wp.empty((A, 3, self.ncoef), dtype=wp.float32, device=dev)  # every entry is written
        rad = wp.empty((A, 3), dtype=wp.float32, device=dev)
        if A:
            used, weights = frame_inputs()
            basis = wp.empty((A, self.ncoef), dtype=wp.float32, device=dev)  # toward the eye, filled by relight
            launch(kr.relight, A, [
                host_array(vid, np.int32, wp.int32, dev), arrays["positions"], arrays["normals"],
                wp.vec3(*map(float, eye)), used, weights, arrays["coeffs"], basis], [coef, rad])
            self.add_direct(vid, coef, eye=eye, radiance=rad, eye_basis=basis, launch=launch)  # M-1
            self.frame_lit = None if self.direct is None else self.direct.lit
        return coef.numpy(), rad.numpy()

    def coefficients(self, vertex_ids) -> np.ndarray:
        """(K, 3, ncoef) float32 RGB coefficients of the current lights at ``vertex_ids``: ``sum_j W[j, c] C_j``
        over the completed light samples (T-12 weights, intensities applied), plus the direct term (M-1)."""
        from lodprt.devices import warp

        ids = np.asarray(vertex_ids, np.int64)
        if not self.uses_samples:  # a direct-only store under M-1: the direct term alone
            out = np.zeros((len(ids), 3, self.ncoef), np.float32)
        else:
            c = self.samples.coeffs[ids[:, None], self.used_slots[None, :]]  # (K, U, C, ncoef)
            w = self.weights[self.used_samples].astype(np.float32)  # (U, 3)
            if self.channels == 1:
                out = np.einsum("kui,uc->kci", c[:, :, 0], w, optimize=True)
            else:
                out = np.einsum("kuci,uc->kci", c, w, optimize=True)
        ref = self.store.referenced[ids] if self.direct is not None else np.zeros(len(ids), bool)
        if ref.any():  # a vertex no face uses reads 0: no direct term either
            wp = warp()
            arr = wp.array(np.ascontiguousarray(out[ref], np.float32), dtype=wp.float32, device=self.device)
            self.add_direct(ids[ref].astype(np.int32), arr)
            out[ref] = arr.numpy()
        return out


def bracketing(samples: np.ndarray, lights: np.ndarray, idx: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(L, k) bool: whether sample ``idx[l, j]`` is the nearest sample with a weight in its octant about light l
    (octant: the signs of sample - light per axis, 0 counting as +): the samples that surround the light as far as
    the samples do (on a regular grid, the corners of the light's cell; along an axis of one layer, the layer)."""
    d = samples[idx] - lights[:, None, :]  # (L, k, 3)
    octant = ((d < 0) * np.array([1, 2, 4])).sum(2)
    dist = np.where(weights > 0, np.linalg.norm(d, axis=2), np.inf)
    out = np.zeros(idx.shape, bool)
    for o in range(8):
        here = (octant == o) & np.isfinite(dist)
        best = np.argmin(np.where(here, dist, np.inf), axis=1)
        rows = np.flatnonzero(here.any(1))
        out[rows, best[rows]] = True
    return out
