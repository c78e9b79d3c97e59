"""Frames: what the run time hands the display (``Frame``), and frames made without a view cut: full-resolution
frames of a store (``full_frame``, ``StoreFrames`` for stores without a hierarchy) and the completed coefficients
or radiance under arbitrary point lights (T-12 interpolation, T-15 completion, T-7)."""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from lodprt.runtime.camera import Camera
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.inside import InsideCheck
from lodprt.runtime.lights import LightInterpolator, check_lights

log = logging.getLogger(__name__)


@dataclasses.dataclass
class Frame:
    """What one ``Runtime.update()`` produces for the display (all arrays are fresh copies).

    vertex_ids (A,) int32 original vertex of each active node some face uses (store vertex order; vertices no face
    uses are never drawn and not relit);
    positions (A, 3) float32 and normals (A, 3) float32 of those vertices;
    triangles (M, 3) int32 indices into ``positions`` (the view cut's mesh, degenerate faces dropped);
    coefficients (A, 3, ncoef) float32 SH coefficients over the view direction of the outgoing radiance, RGB,
    every light's interpolated and completed coefficients summed with its intensity applied (linear radiance);
    radiance (A, 3) float32 linear RGB radiance toward ``camera.eye`` (T-7 per vertex);
    lights (L, 3) float64 light positions as used (after clamping), light_colors (L, 3) float64 RGB intensities;
    camera the ``Camera``; stats a dict (triangles, active_nodes, nodes_touched, refined, coarsened, ms_cut,
    ms_triangulate, ms_relight, ms_total, ...);
    white the radiance its source shows as white (the ``Runtime``'s or ``StoreFrames``' fixed white point, one for
    every frame of the source, so that a sequence does not flicker; None for a frame made alone: the renderer then
    picks one from the frame).
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
    white: float | None = None

    def __repr__(self) -> str:
        return (f"Frame({len(self.positions):,} vertices, {len(self.triangles):,} triangles, {len(self.lights)} "
                f"light(s), eye {None if self.camera is None else tuple(round(x, 4) for x in self.camera.eye)})")


def display(radiance_over_white):
    """The screen intensity of a radiance in units of the white point as the thesis counts it (3.4.2.2): values
    above 1 show as 1, below 0 as 0, i.e. clip(x, 0, 1) (linear: no display gamma)."""
    return np.clip(np.asarray(radiance_over_white, np.float64), 0.0, 1.0)


def light_coefficients(store, lights, *, colors=None, weighting: str = "exact", outside: str = "clamp",
                       interpolation: str = DEFAULT_INTERPOLATION, device: str | None = None):
    """The completed coefficients of every vertex of ``store`` under point lights at (L, 3) positions, without a
    ``Runtime`` (stores baked without a hierarchy too): T-12 weights, T-15 completion, lights summed with their RGB
    intensities (``colors`` (L, 3) or one (3,) for all; default the bake's). ``interpolation`` "thesis" blends the
    samples' coefficients (T-12); the "direct" ones add the actual lights' direct term to the blended residuals
    (M-1..M-4, ``lodprt.runtime.direct_light``; Warp ``device``, default CUDA when present). Returns (lights clamped
    into the sampled region (L, 3), colours (L, 3), coefficients (V, 3, ncoef) float64)."""
    from lodprt.devices import resolve_device, warp
    from lodprt.runtime.direct_light import DirectLight, check_interpolation

    check_interpolation(interpolation)
    interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"], weighting=weighting,
                               outside=outside)
    pos, col = check_lights(lights, colors, store.intensity)
    pos, _ = interp.clamp(pos)
    idx, w, _ = interp.weights(pos)
    W = interp.rgb_weights(pos, col)
    direct = None if interpolation == "thesis" else DirectLight(store, resolve_device(device), interpolation)
    # as wide as the stored coefficients: 1 (y_0 of a diffuse-only store) or order^2
    out = np.zeros((store.num_vertices, 3, store.coefficients_per_vertex))
    used = np.flatnonzero(np.abs(W).sum(1) > 0)
    vis = np.zeros((store.num_vertices, max(len(used), 1)), np.uint8)
    reads = direct is None or direct.residual or direct.uses_visibility
    for u, j in enumerate(used if reads else []):
        c = store.coefficients(int(j))  # (V, C, ncoef), completed; C = 1 (grey) broadcasts over R, G, B
        if direct is not None:
            vis[:, u], c = direct.split(int(j), c)  # M-2: the residual R_j (GI stores)
        if direct is None or direct.residual:
            out += c * W[j][None, :, None]
    if direct is not None:
        wp = warp()
        slot = np.full(len(interp.samples), -1, np.int32)
        slot[used] = np.arange(len(used))
        ids = direct.referenced
        arr = wp.array(np.ascontiguousarray(out[ids], np.float32), dtype=wp.float32, device=direct.device)
        direct.add(ids, pos, col, np.where(w > 0, slot[idx], -1), w,
                   wp.array(vis, dtype=wp.uint8, device=direct.device), arr)  # M-1
        out[ids] = arr.numpy()
    return pos, col, out


def light_radiance(store, lights, eye, *, colors=None, weighting: str = "exact", outside: str = "clamp",
                   interpolation: str = DEFAULT_INTERPOLATION) -> np.ndarray:
    """(V, 3) float32 radiance toward ``eye`` of every vertex of ``store`` under point lights (``light_coefficients``;
    ``Runtime.radiance`` gives the same numbers)."""
    from lodprt.store.bake_store import radiance_toward

    _, _, coeffs = light_coefficients(store, lights, colors=colors, weighting=weighting, outside=outside,
                                      interpolation=interpolation)
    return radiance_toward(store.positions, store.normals, coeffs, eye, np.ones(3))


def full_frame(store, camera, *, lights=None, colors=None, sample: int | None = None,
               interpolation: str = DEFAULT_INTERPOLATION):
    """A ``lodprt.runtime.Frame`` with every referenced vertex of ``store`` and its completed coefficients.

    Either ``sample`` (one light exactly at light sample K, that sample's coefficients) or ``lights`` (L, 3)
    positions, each interpolated from its nearest samples (``lodprt.runtime.light_coefficients``: the run time's
    T-12 weights, clamped into the sampled region; ``interpolation`` as there). ``colors`` (L, 3) RGB
    intensities (default the store's); the frame's coefficients carry them (linear radiance).
    """
    from lodprt.store.bake_store import radiance_toward

    faces = store.faces
    ids = np.unique(faces.ravel()).astype(np.int32)
    remap = np.full(store.num_vertices, -1, np.int64)
    remap[ids] = np.arange(len(ids))
    if sample is not None and lights is not None:  # one or the other: the lights were dropped unseen
        from lodprt.errors import LodprtError

        raise LodprtError(f"full_frame: sample {sample!r} and lights given; give one (sample: the light at that "
                          "sample, lights: positions interpolated)")
    if sample is not None:
        store.check_sample(sample)
        lights, colors = check_lights(store.light_positions[sample], colors, store.intensity)
        coeffs = store.coefficients(sample)[ids] * colors[0][None, :, None]
    else:
        lights, colors, coeffs = light_coefficients(store, lights, colors=colors, interpolation=interpolation)
        coeffs = coeffs[ids]
    pos = store.positions[ids].astype(np.float32)
    nrm = store.normals[ids].astype(np.float32)
    rad = radiance_toward(pos, nrm, coeffs, camera.eye, np.ones(3))
    return Frame(vertex_ids=ids, positions=pos, normals=nrm, triangles=remap[faces].astype(np.int32),
                 coefficients=coeffs.astype(np.float32), radiance=rad, lights=lights.copy(),
                 light_colors=colors.copy(), camera=camera,
                 stats={"triangles": len(faces), "active_nodes": len(ids), "lod": False})


class StoreFrames:
    """The ``Runtime`` interface (set_lights, set_camera, set_lod, set_error_bound, update) over ``full_frame``,
    for stores baked without a hierarchy: always full resolution (no view cut)."""

    lod = False

    def __init__(self, store, interpolation: str = DEFAULT_INTERPOLATION, *, outside: str = "clamp"):
        self.store = store
        self.interpolation = interpolation
        self.white = None
        self.camera = None
        #: lights outside the box are clamped here, once per set_lights (one warning for the source's life)
        self.interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"], outside=outside)
        self._lights = store.light_positions[store.num_samples // 2][None, :]
        self._colors = None
        self.inside = InsideCheck(store)  # a light or eye inside a closed object: one warning each

    def set_lights(self, positions, colors=None) -> None:
        self.inside.check(np.asarray(positions, np.float64).reshape(-1, 3), "light")
        self._lights, self._colors = self.interp.clamp(np.asarray(positions, np.float64).reshape(-1, 3))[0], colors

    def set_camera(self, camera=None, target=None, *, eye=None, **fields) -> Camera:
        """As ``Runtime.set_camera``: a ``Camera`` or its fields, the target defaulting to the scene's centre."""
        from lodprt.runtime.camera import camera_for, scene_centre

        centre = None if target is not None or isinstance(camera, Camera) else scene_centre(self.store)
        self.camera = camera_for(camera, eye=eye, target=target, default_target=centre, **fields)
        self.inside.check(self.camera.eye, "eye")
        return self.camera

    def set_lod(self, enabled: bool) -> None:
        if enabled:
            log.warning("%s has no hierarchy: LOD is not available, showing full resolution", self.store.path)

    def set_error_bound(self, error_bound: float, alpha: float | None = None) -> None:
        pass

    def update(self):
        t0 = time.perf_counter()
        frame = full_frame(self.store, self.camera, lights=self._lights, colors=self._colors,
                           interpolation=self.interpolation)
        if self.white is None:  # the first frame's, kept for every later frame
            self.white = auto_white(frame.radiance)
        frame.white = self.white
        frame.stats["ms_total"] = 1e3 * (time.perf_counter() - t0)
        return frame


def auto_white(radiance) -> float:
    """The default white point: 99th percentile of the positive entries of ``radiance`` (1 when there are none).

    The one white rule: :func:`lodprt.runtime.samples.default_white` applies it to a whole store (the Runtime's
    white), the display to one frame's radiance when its source has no white of its own."""
    r = np.asarray(radiance, np.float64)
    pos = r[r > 0]
    return float(np.percentile(pos, 99)) if pos.size else 1.0


#: The largest exposure in stops either way: 2^100 stays well inside float32, which the shaders scale in.
EXPOSURE_LIMIT = 100.0


def check_white(white, prefix: str = "") -> None:
    """LodprtError naming ``{prefix}white`` unless it is a positive finite radiance (the one shown as white)."""
    from lodprt.errors import LodprtError

    if not (np.isfinite(white) and white > 0):
        raise LodprtError(f"{prefix}white {white:g}: must be a positive radiance (the one shown as white)")


def tone_scale(white, exposure, prefix: str = "") -> float:
    """The tone mapping's 2^exposure / white (display = clip(scale L, 0, 1)), or LodprtError naming
    ``{prefix}white`` / ``{prefix}exposure`` when white is not > 0, exposure not finite within +-EXPOSURE_LIMIT
    stops, or the scale beyond float32."""
    from lodprt.errors import LodprtError

    check_white(white, prefix)
    if not np.isfinite(exposure):
        raise LodprtError(f"tone mapping: {prefix}exposure {exposure!r}: must be finite")
    if abs(exposure) > EXPOSURE_LIMIT:
        raise LodprtError(f"tone mapping: {prefix}exposure {exposure!r}: at most {EXPOSURE_LIMIT:g} stops either way")
    scale = 2.0 ** float(exposure) / float(white)
    if not 0 < scale < float(np.finfo(np.float32).max):
        raise LodprtError(f"tone mapping: 2^{prefix}exposure / {prefix}white = {scale:g} is beyond float32; raise "
                          f"{prefix}white or lower {prefix}exposure")
    return scale

