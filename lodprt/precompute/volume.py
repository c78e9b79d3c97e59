"""Volumetric self-transfer bake (patent 4.3; V-1..V-5 in docs/VOLUMES.md) with the Warp kernels of
``lodprt.kernels.volume``: per voxel a transfer vector per channel whose dot product with the lighting's SH
coefficients is the radiance the voxel scatters toward any direction (isotropic phase function).

    direct (V-3):     M^0_i(p) = albedo/(4 pi) sum_r w A(p -> p + D s_r) y_i(s_r)
    bounce b (V-4):   M^b(p)   = albedo/(4 pi) sum_r w sum_steps A(p -> x) (1 - e^(-sigma(x) dt)) M^(b-1)(x)

The bounce is the patent's scattering pass ``M_q^b += A(p -> q) M_p^(b-1)`` written as gathering (A is symmetric,
A(p -> q) = A(q -> p)): each voxel collects along its own random directions what the previous pass scatters,
so no two threads write one voxel (no atomics, the same result on every device and thread count). Written as a
``lodprt-volume`` store (:mod:`lodprt.store.volume_store`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from lodprt.devices import load_kernels, resolve_device, warp
from lodprt.launches import launch_ranges
from lodprt.deprecation import renamed_arguments
from lodprt.errors import LodprtError, is_whole
from lodprt.precompute.transfer import fibonacci_directions
from lodprt.store.volume_store import prepare_volume_destination, write_volume_store

log = logging.getLogger(__name__)

#: default largest march step as a fraction of the smallest voxel edge
STEP_FRACTION = 0.5
#: most march steps a ray may take across the box's diagonal: a smaller step is refused (1e-9 ran without end)
MAX_MARCH_STEPS = 2**20


def check_step(volume, step, name: str = "step") -> float:
    """The march step of ``volume`` (None: STEP_FRACTION of the smallest voxel edge); LodprtError naming ``name``
    unless it is a positive number giving at most MAX_MARCH_STEPS steps across the box's diagonal."""
    if step is None:
        return STEP_FRACTION * float(volume.voxel_size.min())
    value = float(step)
    if not np.isfinite(value) or value <= 0:
        raise LodprtError(f"{name} {value:g}: must be a positive number of scene units")
    diagonal = float(np.linalg.norm(np.asarray(volume.hi, np.float64) - volume.lo))
    if diagonal / value > MAX_MARCH_STEPS:
        raise LodprtError(f"{name} {value:g}: {diagonal / value:.3g} march steps across the box's diagonal "
                          f"({diagonal:.4g}), more than {MAX_MARCH_STEPS:,} (2^20); give {name} "
                          f">= {diagonal / MAX_MARCH_STEPS:.3g}")
    return value


def volume_kernels() -> tuple:
    """The Warp modules a volume bake launches (for ``lodprt.devices.load_kernels``)."""
    warp()
    from lodprt.kernels import volume as kv

    return (kv,)


class VolumeGrid:
    """A :class:`lodprt.model.volume.Volume` on a Warp device: density array, box, march step."""

    def __init__(self, volume, *, device: str | None = None, step: float | None = None):
        wp = warp()
        self.volume = volume
        self.device = resolve_device(device)
        self.step = check_step(volume, step, "volume step")
        load_kernels(self.device, *volume_kernels())
        self.density = wp.array(volume.density, dtype=wp.float32, device=self.device)
        self.lo = wp.vec3(*volume.lo.astype(np.float32))
        self.hi = wp.vec3(*volume.hi.astype(np.float32))

    @property
    def voxels(self) -> int:
        return int(np.prod(self.volume.shape))

    def directions(self, rays: int):
        wp = warp()
        return wp.array(fibonacci_directions(rays).astype(np.float32), dtype=wp.vec3, device=self.device)

    def transmittance(self, origins, directions, lengths=None) -> np.ndarray:
        """A along segments (V-2): origins, directions (N, 3); lengths (N,) or None (to the box's boundary,
        V-3's D) -> (N,) float32."""
        from lodprt.kernels import volume as kv

        wp = warp()
        o = np.asarray(origins, np.float32).reshape(-1, 3)
        n = len(o)
        ln = np.full(n, -1.0, np.float32) if lengths is None else np.asarray(lengths, np.float32).reshape(n)
        out = wp.zeros(n, dtype=wp.float32, device=self.device)
        wp.launch(kv.segment_transmittance, dim=n, device=self.device, inputs=[
            self.density, self.lo, self.hi, self.step, wp.array(o, dtype=wp.vec3, device=self.device),
            wp.array(np.asarray(directions, np.float32).reshape(n, 3), dtype=wp.vec3, device=self.device),
            wp.array(ln, dtype=wp.float32, device=self.device)], outputs=[out])
        return out.numpy()

    def direct(self, order: int, rays: int, *, rotate: bool = False, seed: int = 0, jobs=None) -> np.ndarray:
        """sum_r w A(p -> p + D s_r) y_i(s_r) per voxel (V-3 without albedo/(4 pi)): (N, order^2) float32."""
        from lodprt.kernels import volume as kv

        wp = warp()
        n, k = self.voxels, order * order
        out = wp.zeros((n, k), dtype=wp.float32, device=self.device)
        scratch = wp.zeros((n, k), dtype=wp.float32, device=self.device)
        dirs = self.directions(rays)
        launch_ranges(kv.volume_direct, n, self.device, lambda first: [
            self.density, self.lo, self.hi, self.step, dirs, int(rotate), int(seed), int(first), scratch, out], jobs)
        return out.numpy()

    def bounce(self, previous: np.ndarray, rays: int, *, seed: int, rotate: bool = True, jobs=None) -> np.ndarray:
        """One gathering pass (V-4 without albedo/(4 pi)) over ``previous`` (X, Y, Z, K): (N, K) float32; the
        directions are turned per voxel by random rotations (``seed``) unless ``rotate`` is False."""
        from lodprt.kernels import volume as kv

        wp = warp()
        prev = np.ascontiguousarray(previous, np.float32)
        if prev.ndim != 4 or prev.shape[:3] != self.volume.shape:
            raise LodprtError(f"volume bounce: previous pass {prev.shape} does not fit the grid {self.volume.shape}")
        n, k = self.voxels, prev.shape[3]
        out = wp.zeros((n, k), dtype=wp.float32, device=self.device)
        wprev = wp.array(prev, dtype=wp.float32, device=self.device)
        dirs = self.directions(rays)
        launch_ranges(kv.volume_bounce, n, self.device, lambda first: [
            self.density, self.lo, self.hi, self.step, dirs, int(rotate), int(seed), int(first), wprev, out], jobs)
        return out.numpy()


def pass_energy(t: np.ndarray, density: np.ndarray) -> float:
    """Radiance a pass scatters under a unit white sky, sqrt(4 pi) M_0, averaged over channels and voxels weighted
    by their density (V-5; the plain mean when the grid is empty): the measure in which a pass is at most albedo
    times the previous one."""
    j = np.sqrt(4 * np.pi) * np.asarray(t, np.float64)[..., 0].mean(-1)
    w = np.asarray(density, np.float64)
    return float((j * w).sum() / w.sum()) if w.sum() > 0 else float(j.mean())


@dataclasses.dataclass
class VolumeTransfer:
    """Per-voxel transfer vectors and how they were made.

    transfer : (X, Y, Z, 3, order^2) float32, albedo/(4 pi) included, every pass summed
    energy   : per pass (direct first) its energy (V-5); passes: per pass its array when ``keep_passes``
    """

    transfer: np.ndarray
    order: int
    rays: int
    energy: list[float]
    passes: list[np.ndarray]
    seconds: float
    step: float
    threshold: float


def volume_transfer(grid: VolumeGrid, *, order: int = 3, rays: int = 128, bounces: int = 2, threshold: float = 1e-3,
                    rotate: bool = False, seed: int = 0, keep_passes: bool = False, progress=None,
                    jobs: int | None = None) -> VolumeTransfer:
    """Shadowed (V-3) plus ``bounces`` interreflected (V-4) passes at most, stopping once a pass' energy is below
    ``threshold`` times the direct pass'. ``rotate`` turns the direct pass' ray set per voxel (the bounce passes
    always do: random directions); ``progress(done, total)`` after each pass; ``jobs`` CPU threads."""
    if not is_whole(order, 1, 8):
        raise LodprtError(f"sh order {order!r}: the volume kernels offer orders 1..8")
    if not is_whole(rays, 1):
        raise LodprtError(f"rays {rays!r}: need at least one direction per voxel")
    if not is_whole(bounces, 0) or not np.isfinite(threshold) or threshold < 0:
        raise LodprtError(f"bounces {bounces!r} and threshold {threshold!r} must be >= 0")
    t0 = time.perf_counter()
    shape = grid.volume.shape
    k = order * order
    scale = (grid.volume.albedo / (4 * np.pi))[:, None]  # (3, 1)
    g = grid.direct(order, rays, rotate=rotate, seed=seed, jobs=jobs)
    cur = (scale[None] * g[:, None, :]).reshape(shape + (3, k)).astype(np.float32)
    total = cur.astype(np.float64)
    passes = [cur] if keep_passes else []
    energy = [pass_energy(cur, grid.volume.density)]
    if progress:
        progress(1, 1 + bounces)
    for b in range(bounces):
        if energy[0] <= 0:
            break
        out = grid.bounce(cur.reshape(shape + (3 * k,)), rays, seed=seed + b + 1, jobs=jobs)
        cur = (scale[None] * out.reshape(-1, 3, k)).reshape(shape + (3, k)).astype(np.float32)
        total += cur
        energy.append(pass_energy(cur, grid.volume.density))
        if keep_passes:
            passes.append(cur)
        if progress:
            progress(b + 2, 1 + bounces)
        log.info("volume bounce %d: energy %.4g (%.3g of direct)", b + 1, energy[-1], energy[-1] / energy[0])
        if energy[-1] < threshold * energy[0]:
            break
    return VolumeTransfer(total.astype(np.float32), order, rays, energy, passes, time.perf_counter() - t0, grid.step,
                          threshold)


@dataclasses.dataclass
class VolumeBake:
    path: Path | None
    transfer: VolumeTransfer
    load_seconds: float
    device: str


@renamed_arguments(order="sh_order", threshold="bounce_threshold")
def bake_volume(volume, out, *, sh_order: int = 3, rays: int = 128, bounces: int = 2, bounce_threshold: float = 1e-3,
                step: float | None = None, rotate: bool = False, seed: int = 0, environment=None,
                device: str | None = None, overwrite: bool = False, progress=None, jobs: int | None = None) -> VolumeBake:
    """Bake the volume's transfer vectors and write a ``lodprt-volume`` store to ``out`` (None: only return them).

    ``environment`` (an :class:`lodprt.model.environment.Environment`, optional) is stored as the default lighting.
    ``step``: largest march step in scene units (default half the smallest voxel edge).
    """
    device = resolve_device(device)
    if out is not None:
        prepare_volume_destination(out, overwrite=overwrite)
    t_load = load_kernels(device, *volume_kernels())
    grid = VolumeGrid(volume, device=device, step=step)
    res = volume_transfer(grid, order=sh_order, rays=rays, bounces=bounces, threshold=bounce_threshold, rotate=rotate,
                          seed=seed, progress=progress, jobs=jobs)
    bake = VolumeBake(None, res, t_load, device)
    if out is None:
        return bake
    env = None if environment is None else environment.stored(sh_order)
    bake.path = write_volume_store(
        Path(out), volume, overwrite=overwrite, transfer=res.transfer, environment=env,
        attrs=dict(source=str(volume.source), sh_order=int(sh_order), rays=int(rays), directions="spherical-fibonacci",
                   rotate_per_voxel=bool(rotate), seed=int(seed), phase="isotropic", step=float(res.step),
                   bounces=len(res.energy) - 1, bounce_threshold=float(bounce_threshold),
                   pass_energy=[float(e) for e in res.energy], bake_seconds=float(res.seconds),
                   load_seconds=float(t_load), device=device))
    return bake
