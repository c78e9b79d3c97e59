"""Lights between samples (docs/THEORY.md M-1..M-4, docs/RUNTIME.md "Lights anywhere"): the actual light's direct
Phong radiance in closed form times its visibility, plus the interpolated residual of the light samples.

    M-1   L(p, s; x) = D(p, s; x) V(p; x) + sum_j w_j R_j(p, s)
    M-2   R_j(p, s)  = S_j(p, s) - D(p, s; x_j) V_j(p)      (GI stores; 0 on a direct-only store)

``S_j`` is sample j's stored (completed, decoded) radiance and ``V_j`` its visibility, recast here with the bake's
kernel and ray offset, so that on a GI store ``R_j`` holds what has no closed form, the indirect light (with the
direct part's completion and codec error), and M-1 gives back ``S_j`` on a sample (``w_j = 1``). On a direct-only
store ``R_j`` would hold only that completion and codec error, which the exact direct term does not have: it is 0
there, and the result is the bake's own radiance at the actual light. ``D`` follows the actual light (distance,
N.L, the lobe toward the eye), and ``V`` is one shadow ray toward the light (or, "direct-agree", the samples'
state where they agree and a ray where they disagree, M-3), so shadows move with the light instead of
cross-fading.

INTERPOLATIONS names the run-time lighting paths: ``"direct"`` (default: M-1 with a shadow ray toward the light
for every vertex that faces it, so V is the bake's own visibility at the actual light), ``"direct-agree"`` (M-1
with M-3: the samples' state where they agree, a ray only where they disagree), ``"direct-blend"`` (M-1 with the
samples' visibility blended by the weights, no rays: M-4) and ``"thesis"`` (T-12: the samples' radiance blended).
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError
from lodprt.launches import KernelThreads
from lodprt.runtime.device_inputs import host_array, zeros

INTERPOLATIONS = ("direct", "direct-agree", "direct-blend", "thesis")
DEFAULT_INTERPOLATION = "direct"
#: referenced rows a slice of a sample's shadow rays and Phong SH takes at once (its buffers: 4 x C x ncoef bytes a row)
SLICE_ROWS = 1 << 18


def check_interpolation(name: str) -> str:
    """``name`` when it is one of INTERPOLATIONS, else LodprtError naming the choices."""
    if name not in INTERPOLATIONS:
        raise LodprtError(f"interpolation {name!r}: choose one of {', '.join(INTERPOLATIONS)}")
    return name


class DirectLight:
    """The scene of a bake store on a Warp device, for the direct term of M-1: BVH, materials, the bake's ray
    offset and falloff. ``split(sample, S)`` makes a sample's visibility and residual (M-2); ``add`` adds
    ``D V`` of the current lights to coefficients (and radiance) of a set of vertices."""

    def __init__(self, store, device: str, interpolation: str = DEFAULT_INTERPOLATION):
        from lodprt.devices import warp
        from lodprt.kernels import direct as kdirect
        from lodprt.precompute.baker import material_tables

        check_interpolation(interpolation)
        if interpolation == "thesis":
            raise LodprtError("DirectLight: the thesis interpolation has no direct term")
        wp = warp()
        self.wp, self.device, self.store = wp, device, store
        self.mode = {"direct": kdirect.RAYS, "direct-agree": kdirect.AGREE_OR_RAY, "direct-blend": kdirect.BLEND}[
            interpolation]
        self.ncoef = store.coefficients_per_vertex
        self.channels = int(store.root.attrs.get("channels", 1))
        order = store.sh_order
        materials = store.materials()
        tables = material_tables(materials, order, 3)
        stored = material_tables(materials, order, self.channels)  # the bake's tables
        # the store's float32 / int32 arrays as baked, wrapped (not copied) on the CPU: the Runtime holds the same
        share = lambda a, dtype, t: wp.array(np.ascontiguousarray(a, dtype), dtype=t, device=device,  # noqa: E731
                                             copy=device != "cpu")
        self.points = share(store.positions, np.float32, wp.vec3)
        self.normals = share(store.normals, np.float32, wp.vec3)
        self.indices = share(np.ascontiguousarray(store.faces, np.int32).ravel(), np.int32, wp.int32)
        self.mesh = wp.Mesh(points=self.points, indices=self.indices)
        self.material_id = share(store.read("scene/material_id"), np.int32, wp.int32)
        lights = store.lights()
        f32 = lambda a: wp.array(np.ascontiguousarray(a, np.float32), dtype=wp.float32, device=device)  # noqa: E731
        self.kd, self.ks, self.zonal = f32(tables["kd"]), f32(tables["ks"]), f32(tables["zonal"])
        self.kd_stored = f32(stored["kd"])  # the store's channels: the residual is in the store's layout
        self.offset = float(store.attrs["ray_offset"])  # the bake's, so that V_j is the bake's visibility
        self.falloff = 1 if lights.falloff == "inverse-square" else 0
        self.radius = float(lights.radius)
        self.referenced = np.flatnonzero(store.referenced).astype(np.int32)
        self.ref_ids = wp.array(self.referenced, dtype=wp.int32, device=device)
        self.num_vertices = store.num_vertices
        # M-2 carries light only where the store holds more than the direct term: GI stores (indirect light). On a
        # direct-only store R_j is the light cut's completion error and a codec's error alone, which the exact
        # direct term does not have: R_j = 0 there (the samples' visibility may still decide V, M-3 and M-4)
        self.residual = int(store.attrs.get("bounces", 0) or 0) > 0
        self.uses_visibility = self.mode != kdirect.RAYS
        self.lit = np.zeros(0, np.int32)  # the last ``add``'s rows: bit li where light li reaches them (M-6)
        self._scratch: list = [None, None]  # ``scratch``'s arrays, kept between frames

    # -- per sample (M-2) ----------------------------------------------------------------------------------------
    def _at_sample(self, sample: int, target: np.ndarray | None = None, sign: float = 1.0) -> np.ndarray:
        """Visibility states (V,) uint8 of light sample ``sample`` (the bake's shadow rays, kernels.visibility;
        unreferenced vertices BACK_FACING); with ``target`` (V, C, ncoef) float32, ``sign`` x D_j V_j (Phong SH,
        kernels.shading, in the store's channel layout) added to it at the referenced vertices. On the CPU in
        slices of at most ``SLICE_ROWS`` rows on every core, each with its own buffers (no (K, ...) copy)."""
        from lodprt.kernels import shading as kshade
        from lodprt.kernels import visibility as kvis

        wp, dev = self.wp, self.device
        light = wp.vec3(*map(float, self.store.light_positions[sample]))
        K = len(self.referenced)
        vis = wp.zeros(K, dtype=wp.uint8, device=dev)

        def rows(a, b):  # the bake's rays, then Phong SH, for referenced rows a:b (views: a slice writes its own)
            ids = self.ref_ids[a:b]
            wp.launch(kvis.shadow_rays, dim=b - a, inputs=[self.mesh.id, self.points, self.normals, ids, light,
                                                           self.offset], outputs=[vis[a:b]], device=dev)
            if target is None:
                return
            direct = wp.zeros((b - a, self.channels, self.ncoef), dtype=wp.float32, device=dev)
            scratch = wp.zeros((b - a, self.ncoef), dtype=wp.float32, device=dev)  # bands <= the output's
            wp.launch(kshade.phong_sh, dim=b - a, inputs=[self.points, self.normals, self.material_id, ids, vis[a:b],
                                                          self.kd_stored, self.ks, self.zonal, light, self.falloff,
                                                          self.radius, scratch], outputs=[direct], device=dev)
            ref, add = self.referenced[a:b], direct.numpy()
            if sign != 1.0:
                add *= np.float32(sign)
            # the rows of a slice are sorted and usually consecutive: added in place (a view) without a gather
            rows = slice(ref[0], ref[-1] + 1) if len(ref) and ref[-1] - ref[0] == len(ref) - 1 else ref
            target[rows] += add

        if dev == "cpu":  # a CPU launch runs on one thread: slices on every core
            with KernelThreads(None) as threads:
                threads.slices(rows, K, most=SLICE_ROWS)
        else:
            rows(0, K)
        states = np.full(self.num_vertices, int(kvis.BACK_FACING), np.uint8)
        states[self.referenced] = vis.numpy()
        return states

    def split(self, sample: int, coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(visibility (V,) uint8, residual (V, C, ncoef) float32) of light sample ``sample`` whose completed
        coefficients are ``coeffs`` (V, C, ncoef): M-2's R_j = S_j - D_j V_j at the referenced vertices
        (``_at_sample``), unreferenced vertices BACK_FACING with their coefficients as given. A GI store's only:
        a direct-only store keeps no coefficients and takes its visibility from ``direct_field``."""
        residual = np.array(coeffs, np.float32)
        return self._at_sample(sample, residual, -1.0), residual

    def direct_field(self, sample: int) -> tuple[np.ndarray, np.ndarray]:
        """(visibility states (V,) uint8, D_j V_j (V, C, ncoef) float32) of light sample ``sample``, 0 at the
        vertices no face uses: on a direct-only store the field M-1 draws with the light on the sample (the light
        cut's completion is linear between the vertices it kept, the drawn field is not), made without completing
        the sample."""
        out = np.zeros((self.num_vertices, self.channels, self.ncoef), np.float32)
        return self._at_sample(sample, out), out

    # -- per frame (M-1) -----------------------------------------------------------------------------------------
    def scratch(self, rows: int, ncoef: int, eye_basis=None) -> tuple:
        """``direct_light``'s scratch for ``rows`` rows: (basis, eye basis), each (rows, ncoef) float32 (the given
        ``eye_basis`` as the second when there is one, and then no second array is made). Kept between calls and
        grown by at least a quarter when a call needs more rows: the kernel writes a row of them before it reads
        it, and fresh ones would be new pages every frame (6.5 MB each on the full bunny scene). Not for two calls
        at once."""
        def kept(i: int):
            have = self._scratch[i]
            if have is None or have.shape[0] < rows or have.shape[1] != ncoef:
                size = max(rows, have.shape[0] * 5 // 4 if have is not None and have.shape[1] == ncoef else 0)
                have = self._scratch[i] = self.wp.empty((size, ncoef), dtype=self.wp.float32, device=self.device)
            return have[:rows]

        return kept(0), (kept(1) if eye_basis is None else eye_basis)

    def add(self, vid, lights, colors, light_slots, light_weights, sample_vis, coeffs, *, eye=None, radiance=None,
            eye_basis=None, threads=None) -> int:
        """Add ``D V`` of (L, 3) ``lights`` with (L, 3) ``colors`` to ``coeffs`` (A, 3, ncoef) (Warp array, rows
        aligned with ``vid``) and, with ``eye``, to ``radiance`` (A, 3) toward it. ``light_slots`` (L, K) are the
        columns of ``sample_vis`` (V, S) uint8 (Warp array) holding each light's samples, ``light_weights`` (L, K)
        their weights; ``eye_basis`` (A, >= ncoef), when given, already holds the SH basis toward the eye per row
        (``kernels.runtime.relight``'s scratch). ``threads``: a callable ``(kernel, rows, inputs, outputs)`` that launches split over rows
        with the first row as the kernel's offset (default: one launch). Returns the shadow rays cast; ``lit``
        then holds (A,) int32, bit ``li`` set where light ``li`` (< 31) reaches the row (M-6)."""
        from lodprt.kernels import direct as kdirect

        wp, dev = self.wp, self.device
        A = len(vid)
        self.lit = np.zeros(A, np.int32)
        if A == 0 or len(lights) == 0:
            return 0
        ncoef = coeffs.shape[2]
        with_rad = radiance is not None
        rad = radiance if with_rad else wp.zeros((1, 3), dtype=wp.float32, device=dev)
        rays = zeros(A, np.int32, wp.int32, dev)
        lit = zeros(A, np.int32, wp.int32, dev)
        e = np.zeros(3) if eye is None else np.asarray(eye, np.float64)
        inputs = [
            host_array(vid, np.int32, wp.int32, dev), self.points, self.normals,
            self.material_id, self.kd, self.ks, self.zonal, self.falloff, self.radius, self.mesh.id, self.offset,
            host_array(lights, np.float32, wp.vec3, dev), host_array(colors, np.float32, wp.vec3, dev),
            host_array(light_slots, np.int32, wp.int32, dev), host_array(light_weights, np.float32, wp.float32, dev),
            sample_vis, int(self.mode), wp.vec3(*map(float, e)), int(with_rad), int(eye_basis is not None),
            *self.scratch(A, ncoef, eye_basis),
        ]
        outputs = [coeffs, rad, rays, lit]
        if threads is None:
            wp.launch(kdirect.direct_light, dim=A, inputs=[0] + inputs, outputs=outputs, device=dev)
        else:
            threads(kdirect.direct_light, A, inputs, outputs)
        self.lit = lit.numpy()  # M-6: which lights reach each row (bit per light), for the view cut's shadow edges
        return int(rays.numpy().sum())

