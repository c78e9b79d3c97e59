"""Point-light local PRT bake (SPEC 4; thesis 2.2): per light sample, shadow rays -> Phong radiance projected on SH
over the view direction (T-6, closed-form specular lobe P-6) -> store; optionally only on the light cut (thesis
figure 8, :mod:`lodprt.precompute.light_cut`).

Samples are independent tasks (``jobs`` Python threads on the CPU, where a Warp launch releases the GIL; one after
another on CUDA). Left out: shadow rays of back-facing vertices, specular bands when no material has ks > 0, colour
channels when every material is grey (the light's RGB intensity is applied when reading), unreferenced vertices.
``bake(compress=CODEC)`` re-encodes the finished store with a lossy codec as format version 2
(:func:`compress_finished`, :mod:`lodprt.store.codecs`).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import logging
import math
import os
import threading
import time
import uuid
from typing import Callable

import numpy as np

from lodprt.devices import load_kernels, resolve_device
from lodprt.errors import Interrupted, LodprtError, is_whole
from lodprt.kernels.visibility import BACK_FACING, LIT, SHADOWED
from lodprt.model.scene import Scene
from lodprt.precompute.baker import Baker, bake_kernels, layout, material_tables, ray_offset
from lodprt.store.bake_store import FORMAT_VERSION, sample_group
from lodprt.store.white import sample_record
from lodprt.store.writer import FORMAT_NAME, StoreWriter

log = logging.getLogger(__name__)

#: the light cut's incident-angle threshold of ``bake`` and ``lodprt bake`` (degrees; T-11)
DEFAULT_THRESHOLD_DEG = 5.0


@dataclasses.dataclass
class BakeResult:
    """What a bake wrote and how long it took (``bake_seconds`` excludes kernel loading, ``load_seconds``)."""

    path: str | None
    sh_order: int
    coefficients_per_vertex: int
    channels: int
    bake_seconds: float
    load_seconds: float
    device: str
    samples: list[dict]
    hierarchy_seconds: float | None = None
    reused_samples: int = 0  # samples a resumed or extended bake found complete instead of baking them

    def __repr__(self) -> str:
        kept = sum(int(x.get("vertices_kept", 0)) for x in self.samples) / max(len(self.samples), 1)
        return (f"BakeResult({self.path!r}: {len(self.samples)} samples, SH order {self.sh_order}, "
                f"{kept:,.0f} vertices kept per sample, bake {self.bake_seconds:.2f} s on {self.device})")


@dataclasses.dataclass
class SampleJob:
    """One bake's light samples as independent tasks: everything a process needs to bake sample ``k`` and write its
    group into the partial store ``partial`` (None: no store). Threads of this process share one device state
    (:meth:`device_state`); a dask worker receives the job once and keeps its state for every task (:meth:`run`)."""

    scene: Scene
    tree: object | None  # the hierarchy, in light-cut mode only
    sh_order: int
    device: str
    threshold_deg: float | None
    partial: str | None
    gi: object  # lodprt.precompute.gi.GISettings
    token: str = dataclasses.field(default_factory=lambda: uuid.uuid4().hex)
    version: str = dataclasses.field(default_factory=lambda: _version())  # a worker must bake with the same lodprt

    def __post_init__(self):
        self.lights = self.scene.lights.positions

    def device_state(self):
        """(Baker, LightCut or None) of this job: BVH, material tables and the hierarchy's arrays on the device."""
        from lodprt.precompute.gi import attach

        baker = Baker(self.scene, self.sh_order, self.device, np.flatnonzero(self.scene.referenced).astype(np.int32))
        lightcut = None
        if self.threshold_deg is not None:
            from lodprt.precompute.light_cut import LightCut

            lightcut = LightCut(self.tree, baker.points, self.device)
        if self.gi.bounces:
            attach(baker, self.scene, self.gi, self.tree if lightcut is not None else None)
        return baker, lightcut

    def compute(self, baker: Baker, lightcut, k: int):
        """Bake light sample ``k``: (k, vertex ids, cut arrays, coefficients, visibility, seconds, statistics of the
        interreflection passes: each pass' mean radiance, recorded with the sample)."""
        t = time.perf_counter()
        extra = {}
        if lightcut is None:
            coeffs, visible = baker.sample(self.lights[k])
            kept = baker.ids_host
        else:
            kept, nodes, dark, coeffs, visible = baker.sample_cut(self.lights[k], lightcut, self.threshold_deg)
            extra = {"cut_nodes": nodes, "dark": dark}
        stats = {} if baker.gi is None else baker.gi.sample_attributes(self.lights[k])
        return k, kept, extra, coeffs, visible, time.perf_counter() - t, stats

    def write(self, k: int, kept, extra: dict, coeffs, visible, seconds: float, stats: dict | None = None) -> dict:
        """Check and record sample ``k``: its group (completion mark last) moves into the store whole."""
        from lodprt.store.sample_groups import SampleGroupWriter

        _check_finite(self.scene, k, self.lights[k], coeffs)
        if self.partial is None:
            return _record(None, k, kept, extra, coeffs, visible, seconds, stats)
        group = SampleGroupWriter(self.partial, k)
        try:
            info = _record(group, k, kept, extra, coeffs, visible, seconds, stats)
            group.finish()
        except BaseException:
            group.abort()
            raise
        return info

    def run(self, k: int) -> tuple[dict, float]:
        """Bake and write sample ``k`` in a worker process: (its statistics, seconds spent loading kernels now)."""
        baker, lightcut, load = self.worker_state()
        return self.write(*self.compute(baker, lightcut, k)), load

    def worker_state(self):
        """(Baker, LightCut or None, seconds spent loading kernels now) of this job in this worker process: made at
        the job's first task in the process and kept for the next ones (whole samples and vertex ranges alike)."""
        if _version() != self.version:
            raise LodprtError(f"a dask worker runs lodprt {_version()}, the client {self.version}: install the same "
                              "lodprt everywhere (the store records one version)")
        load = 0.0
        with _WORKER_LOCK:
            if _WORKER.get("token") != self.token:
                _WORKER.clear()  # one job at a time: the previous bake's device arrays go
                load = load_kernels(self.device, *bake_kernels())
                _WORKER.update(token=self.token, state=self.device_state())
            baker, lightcut = _WORKER["state"]
        return baker, lightcut, load


_WORKER: dict = {}  # SampleJob.worker_state's device state in this process
_WORKER_LOCK = threading.Lock()


def bake_settings(scene: Scene, sh_order: int, device: str, threshold_deg, hierarchy: bool, gi) -> dict:
    """The root attributes a bake records before any work, which a resumed or extended bake must match
    (``lodprt.store.resume``): what decides the coefficients, and the scene's fingerprint."""
    from lodprt.store.resume import fingerprint

    ncoef, channels = layout(scene, sh_order)
    return {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "lodprt_version": _version(),
            "mode": "full" if threshold_deg is None else "cut", "threshold_deg": threshold_deg, "sh_order": sh_order,
            "coefficients_per_vertex": ncoef, "channels": channels, "device": device,
            "ray_offset": ray_offset(scene), "with_hierarchy": bool(hierarchy), "fingerprint": fingerprint(scene),
            **(gi.attributes() if gi.bounces else {})}


def bake(
    scene: Scene,
    out: str | os.PathLike | None,
    *,
    sh_order: int = 4,
    device: str | None = None,
    overwrite: bool = False,
    jobs: int | None = None,
    hierarchy: bool = True,
    threshold_deg: float | None = DEFAULT_THRESHOLD_DEG,
    full: bool = False,
    tree=None,
    progress: Callable[[int, int], None] | None = None,
    hierarchy_progress: Callable[[int, int], None] | None = None,
    bounces: int = 0,
    bounce_threshold: float = 1e-3,
    gi_rays: int = 64,
    indirect_threshold_deg: float | None = 10.0, indirect_tolerance: float | None = None,
    resume: bool = False,
    add_samples: bool = False,
    workers: int | None = None,
    scheduler: str | None = None, compress: str = "none",
    hierarchy_method: str = "sequential", vertex_range: int | None = None,
) -> BakeResult:
    """Bake light samples of ``scene`` and write the store at ``out``.

    Per sample, only the vertices of the light-dependent cut with the incident-angle threshold ``threshold_deg``
    (default 5 degrees, as ``lodprt bake``; ``lodprt.precompute.light_cut``; needs the hierarchy); ``full=True``
    (or ``threshold_deg=None``) bakes every referenced vertex (full resolution, ``lodprt bake --full``), and so
    does ``hierarchy=False`` with the default threshold (``--no-hierarchy``: no hierarchy, no light cut).
    With ``hierarchy`` the vertex hierarchy (``lodprt.model.hierarchy_build``) is built first (or ``tree`` is used) and
    stored under ``hierarchy/``; ``hierarchy_method`` picks its build (``build_hierarchy(method=...)``:
    "sequential", the default, "rounds" or "pymeshlab"; docs/HIERARCHY.md).
    ``out=None`` bakes without writing (benchmarks). ``progress(done, total)`` is called after each sample,
    ``hierarchy_progress(collapses, total)`` while the hierarchy is built.
    Raises StoreError before any work when ``out`` exists and ``overwrite`` is false.
    ``bounces`` > 0 adds diffuse interreflection (docs/GI.md, ``lodprt.precompute.gi.GISettings`` for the others).
    ``resume`` continues the killed bake of ``out`` (or finds it finished); ``add_samples`` extends the store at
    ``out`` to the scene's light grid; ``workers`` (a local dask cluster of that many processes) or ``scheduler``
    (the address of one) bakes the samples on dask.distributed, ``jobs`` threads per local worker
    (docs/DISTRIBUTED.md; ``vertex_range`` N splits a sample of over N baked vertices into vertex-range tasks).
    The store is the same, array for array, whichever way it was made.
    """
    from lodprt.precompute.gi import GISettings, gi_attributes

    gi = GISettings(bounces, bounce_threshold, gi_rays, indirect_threshold_deg, indirect_tolerance=indirect_tolerance)
    device = resolve_device(device)
    threshold_deg = light_cut_threshold(threshold_deg, full=full, hierarchy=hierarchy)
    check_hierarchy(hierarchy, threshold_deg, hierarchy_method)
    check_sh_order(sh_order)
    check_jobs(jobs)
    codec = bake_codec(compress, *layout(scene, sh_order), out)
    from lodprt.precompute.distributed import check_cluster  # dask itself is imported only for a cluster

    cluster = check_cluster(workers=workers, scheduler=scheduler, threads=jobs, vertex_range=vertex_range,
                            bounces=gi.bounces)
    if (cluster or resume or add_samples) and out is None:
        raise LodprtError("workers, scheduler, resume and add_samples need a store to write (out)")
    target = None
    if out is not None:
        from lodprt.store.resume import BakeTarget

        settings = bake_settings(scene, sh_order, device, threshold_deg, hierarchy, gi)
        target = BakeTarget(out, overwrite=overwrite, resume=resume, add_samples=add_samples, settings=settings,
                            lights=scene.lights)
        if target.finished is not None:  # nothing left to bake; encoded as asked, or now
            return BakeResult(**finished_as_asked(target, out, codec))
    try:
        # plan: kernels, the scene and the hierarchy (each skipped when a resumed store has it complete)
        load_seconds = 0.0 if cluster else load_kernels(device, *bake_kernels())
        t0 = time.perf_counter()
        hierarchy_seconds, built = None, 0.0
        if hierarchy:
            stored = target is not None and target.complete("hierarchy")  # read back: its build time is not ours
            tree, hierarchy_seconds = _hierarchy(scene, tree, target, hierarchy_progress, hierarchy_method)
            built = 0.0 if stored else hierarchy_seconds
        job = SampleJob(scene, tree if threshold_deg is not None else None, sh_order, device, threshold_deg,
                        None if target is None else str(target.partial.resolve()), gi)
        baker, lightcut = _store_plan(job, target, tree if hierarchy else None, hierarchy_seconds, cluster)
        # launch: the light samples still to bake, each written as it finishes
        total = len(job.lights)
        todo = list(range(total)) if target is None else target.todo()
        step = None if progress is None else (lambda done, _n: progress(total - len(todo) + done, total))
        if cluster:
            from lodprt.precompute.distributed import run_on_cluster

            infos, load_seconds = run_on_cluster(job, todo, workers=workers, scheduler=scheduler, threads=jobs,
                                                 progress=step, vertex_range=vertex_range)
        else:
            infos = _run_samples(job, baker, lightcut, todo, jobs, step)
        samples = [infos[k] if k in infos else target.recorded(k) for k in range(total)]
        # bake_seconds counts the light samples and the store; the hierarchy reports its own time
        bake_seconds = time.perf_counter() - t0 - built
        ncoef, channels = layout(scene, sh_order)
        result = BakeResult(
            path=None if out is None else str(out),
            sh_order=sh_order,
            coefficients_per_vertex=ncoef,
            channels=channels,
            bake_seconds=bake_seconds,
            load_seconds=load_seconds,
            device=device,
            samples=samples,
            hierarchy_seconds=hierarchy_seconds,
            reused_samples=total - len(todo),
        )
        # write: the root attributes, then the store moves into place
        if target is not None:
            extra = {} if not gi.bounces else gi_attributes(gi, result.samples)
            _write_root(target.writer, scene, result, threshold_deg, ray_offset(scene), extra)
            target.finish()
            result.samples = compress_finished(out, codec, result.samples)
        return result
    except BaseException as exc:
        if target is not None:
            settle(exc, out, target)
        raise


def settle(exc: BaseException, out, target) -> None:
    """What a failed bake leaves: Ctrl-C keeps the partial folder and becomes ``Interrupted`` (saying so); a
    ``resumable`` cluster error keeps it too; any other error removes it (a full disk included)."""
    if isinstance(exc, KeyboardInterrupt) and not isinstance(exc, Interrupted):
        raise Interrupted(interrupted_message(out, target)) from exc
    if getattr(exc, "resumable", False):
        log.warning("%s: interrupted; the finished samples stay in %s for bake --resume", out, target.partial)
    elif not isinstance(exc, KeyboardInterrupt):
        target.abort()


def interrupted_message(out, target) -> str:
    """What a bake stopped by Ctrl-C says it left: the partial folder ``bake --resume`` continues, or the store."""
    partial = getattr(target, "partial", None)
    if partial is not None and partial.is_dir():
        done = len(target.positions) - len(target.todo())
        return (f"{out}: stopped; {done} finished light sample(s) stay in {partial.name}: run the same lodprt bake "
                "with --resume to finish it (a bake without --resume removes it)")
    return f"{out}: stopped after the store was written; it is complete"


def bake_codec(compress: str, ncoef: int, channels: int, out):
    """The codec of ``bake(compress=...)`` (``lodprt.store.codecs``), checked before any work."""
    from lodprt.store.codecs import check_layout, parse_codec

    codec = parse_codec(compress, "compress")
    check_layout(codec, channels, ncoef, "compress")
    if out is None and not codec.lossless:
        raise LodprtError(f"compress {codec.name}: needs a store to write (out)")
    return codec


def finished_as_asked(target, out, codec) -> dict:
    """``BakeResult``'s fields of a store that already holds the bake (``target.finished``): left as it is when
    encoded with ``codec`` or when no codec is asked (``none``: a finished encoded store is finished); encoded with
    ``codec`` now when it is still float32 (a bake --compress killed while re-encoding, then resumed); refused,
    before anything is said of it, when it is encoded with another codec."""
    from lodprt.store.sample_groups import group_attrs

    have = str((group_attrs(target.finished) or {}).get("codec", "none"))
    if have not in ("none", codec.name) and not codec.lossless:
        raise LodprtError(f"{out}: holds this bake encoded with codec {have}, not {codec.name}: re-encode it with "
                          f"lodprt compress {out} -o OUT --codec {codec.name}")
    summary = target.summary(codec=have)
    if have == "none" and not codec.lossless:
        summary["samples"] = compress_finished(out, codec, summary["samples"])
    return summary


def compress_finished(out, codec, samples: list[dict]) -> list[dict]:
    """Re-encode the finished store ``out`` in place with ``codec`` (none: leave it); the samples' statistics, with
    the encoded ``bytes``. Killed meanwhile, the finished float32 store stays at ``out`` (docs/FORMAT.md)."""
    if codec.lossless:
        return samples
    from lodprt.store.compress import compress_store

    return compress_store(out, out, codec, overwrite=True, option="compress")["samples"]


def light_cut_threshold(threshold_deg, *, full: bool, hierarchy: bool) -> float | None:
    """The light cut's threshold a bake uses (None: full resolution): ``full``, ``threshold_deg=None`` or no
    hierarchy with the default threshold mean full resolution; any other threshold is kept (and refused without
    the hierarchy by ``check_hierarchy``)."""
    if full or threshold_deg is None or (not hierarchy and threshold_deg == DEFAULT_THRESHOLD_DEG):
        return None
    return threshold_deg


def check_hierarchy(hierarchy: bool, threshold_deg, method: str, *, name: str = "threshold_deg") -> None:
    """Refuse a light cut without the hierarchy or with a bad threshold (called ``name`` in the message), and an
    unknown hierarchy build."""
    number = isinstance(threshold_deg, (int, float)) and not isinstance(threshold_deg, bool)
    if threshold_deg is not None and (not hierarchy or not number or not (threshold_deg >= 0)
                                      or not math.isfinite(threshold_deg)):
        raise LodprtError(
            f"{name} {threshold_deg!r}: the light cut needs the hierarchy and a finite threshold >= 0 degrees"
        )
    if hierarchy:
        from lodprt.model.hierarchy_build import check_method

        check_method(method)


def check_sh_order(sh_order: int, *, name: str = "sh_order") -> None:
    """Refuse an SH order the float32 kernels do not cover (called ``name`` in the message)."""
    from lodprt.kernels import sh as ksh

    if not is_whole(sh_order, 1, ksh.MAX_KERNEL_ORDER, integer_type=True):
        raise LodprtError(f"{name} {sh_order!r}: a whole number from 1; the float32 kernels go up to order "
                          f"{ksh.MAX_KERNEL_ORDER}")


def check_jobs(jobs) -> None:
    """Refuse a thread count that is not a whole number >= 1 (None: the default)."""
    if jobs is not None and not is_whole(jobs, 1, integer_type=True):
        raise LodprtError(f"jobs {jobs!r}: the threads baking samples, a whole number >= 1 (or None)")


def _hierarchy(scene: Scene, tree, target, progress, method: str) -> tuple[object, float]:
    """The vertex hierarchy (the complete one of a resumed or extended store, ``tree``, or built now with
    ``method``) and its build seconds (``_write_plan`` stores it)."""
    from lodprt.model.hierarchy_build import build_hierarchy

    if target is not None and target.complete("hierarchy"):
        stored, seconds = target.hierarchy()
        if stored.method != method:  # the store stays one bake: its samples were cut on the stored hierarchy
            log.warning("%s: keeps the hierarchy it was baked with (%s), not a %s build: a resumed or extended bake "
                        "uses the store's hierarchy", target.path, stored.method, method)
        return stored, seconds
    t_h = time.perf_counter()
    if tree is None:
        tree = build_hierarchy(scene.positions, scene.faces, scene.normals, progress=progress, method=method)
    return tree, time.perf_counter() - t_h


def _store_plan(job: SampleJob, target, tree, seconds, cluster: bool) -> tuple:
    """Write the scene and the hierarchy ``tree`` (``_write_plan``) while the device state is made on a second
    thread (neither reads what the other makes; none for a cluster, whose workers make their own): (Baker,
    LightCut or None), or (None, None) for a cluster."""
    with concurrent.futures.ThreadPoolExecutor(1) as helper:
        state = None if cluster else helper.submit(job.device_state)
        if target is not None:
            _write_plan(target, job.scene, job.sh_order, tree, seconds)
        return (None, None) if state is None else state.result()


def _write_plan(target, scene: Scene, sh_order: int, tree, seconds) -> None:
    """The scene, then the hierarchy ``tree`` (None: a bake without one) under ``hierarchy/`` with the method that
    built it, each with its completion mark last; what a resumed store has complete already is not rewritten."""
    if not target.complete("scene"):
        _write_scene(target.writer, scene, sh_order)
        target.mark("scene")
    if tree is not None and not target.complete("hierarchy"):
        writer = target.writer
        for name, arr in tree.to_arrays().items():
            writer.array(f"hierarchy/{name}", arr, chunk_rows=1 << 18)
        writer.attrs("hierarchy", levels=tree.levels, seconds=seconds, roots=int(len(tree.roots)), depth=tree.depth,
                     method=tree.method)
        target.mark("hierarchy")


def _run_samples(job: SampleJob, baker: Baker, lightcut, todo: list[int], jobs: int | None, progress) -> dict:
    """Bake the light samples ``todo`` on ``jobs`` threads (default: every core on the CPU, 1 on CUDA), full
    resolution or on their light cuts; record each as it finishes. Returns their statistics by sample.

    At most ``2 * jobs`` samples are in flight (submitted, not yet written) and a written sample's arrays are
    dropped with its future, so the bake's memory does not grow with the number of samples (docs/SCALE.md)."""
    if jobs is None:
        jobs = (os.cpu_count() or 1) if baker.device == "cpu" else 1
    jobs = max(1, min(jobs, len(todo) or 1))
    samples: dict[int, dict] = {}
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=jobs)
    queue, pending = iter(todo), set()
    try:
        while True:
            for k in itertools.islice(queue, 2 * jobs - len(pending)):
                pending.add(pool.submit(job.compute, baker, lightcut, k))
            if not pending:
                break
            finished, pending = concurrent.futures.wait(pending, return_when=concurrent.futures.FIRST_COMPLETED)
            for fut in finished:
                k, *rest = fut.result()
                samples[k] = job.write(k, *rest)
                del rest  # this sample's arrays go now, not when the bake ends
                if progress is not None:
                    progress(len(samples), len(todo))
    except BaseException:  # Ctrl-C or an error: the samples not started are not baked
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return samples


def _write_root(writer: StoreWriter, scene: Scene, result: BakeResult, threshold_deg, offset: float,
                extra: dict) -> None:
    """The store's root attributes (docs/FORMAT.md); ``extra``: those of the interreflection settings."""
    writer.attrs(
        format=FORMAT_NAME,
        format_version=FORMAT_VERSION,
        lodprt_version=_version(),
        mode="full" if threshold_deg is None else "cut",
        threshold_deg=threshold_deg,
        sh_order=result.sh_order,
        coefficients_per_vertex=result.coefficients_per_vertex,
        channels=result.channels,
        bake_seconds=result.bake_seconds,
        load_seconds=result.load_seconds,
        device=result.device,
        source=scene.source,
        ray_offset=offset,
        hierarchy_seconds=result.hierarchy_seconds,
        **extra,
    )


def _record(writer: StoreWriter | None, k: int, kept, extra: dict, coeffs, visible, seconds: float,
            stats: dict | None = None) -> dict:
    """Write light sample ``k`` (when there is a store) and return its statistics (with ``stats``); the group's
    attributes add the sample's default-white record (``lodprt.store.white``, DW-1), not part of the statistics."""
    counts = np.bincount(visible, minlength=4)
    info = {
        **(stats or {}),
        "vertices_kept": int(len(kept)),
        "bytes": int(kept.nbytes + coeffs.nbytes + sum(a.nbytes for a in extra.values())),
        "seconds": float(seconds),
        "shadowed": int(counts[SHADOWED]),
        "lit": int(counts[LIT]),
        "back_facing": int(counts[BACK_FACING]),
    }
    if writer is not None:
        g = sample_group(k)
        writer.array(f"{g}/vertex_ids", kept, chunk_rows=1 << 18)
        writer.array(f"{g}/coefficients", coeffs, chunk_rows=1 << 16)
        for name, arr in extra.items():
            writer.array(f"{g}/{name}", arr, chunk_rows=1 << 18)
        writer.attrs(g, **info, **sample_record(coeffs))
    return info


def _check_finite(scene: Scene, k: int, light: np.ndarray, coeffs: np.ndarray) -> None:
    """Refuse to store NaN or infinite coefficients. Scene limits (lodprt.model.scene) keep float32 finite; this catches
    what they miss instead of writing a store that renders black or NaN."""
    bad = ~np.isfinite(coeffs).all(axis=tuple(range(1, coeffs.ndim)))  # per vertex; a cut may keep none
    if bad.any():
        raise LodprtError(
            f"{scene.source}: light sample {k} at {np.round(light, 6).tolist()}: {int(bad.sum())} vertices got NaN or "
            "infinite coefficients (float32 overflow); check the scene's scale, light radius, materials and intensity"
        )


def _version() -> str:
    from lodprt.version import __version__

    return __version__


def _write_scene(writer: StoreWriter, scene: Scene, sh_order: int) -> None:
    writer.array("scene/positions", scene.positions.astype(np.float32), chunk_rows=1 << 18)
    writer.array("scene/normals", scene.normals.astype(np.float32), chunk_rows=1 << 18)
    writer.array("scene/faces", scene.faces.astype(np.int32), chunk_rows=1 << 18)
    writer.array("scene/material_id", scene.material_id.astype(np.int32), chunk_rows=1 << 18)
    writer.array("scene/object_id", scene.object_id.astype(np.int32), chunk_rows=1 << 18)
    writer.attrs("scene", object_names=list(scene.object_names))
    tables = material_tables(scene.materials, sh_order, 3)
    writer.array("materials/kd", tables["kd"])
    writer.array("materials/ks", tables["ks"])
    writer.array("materials/shininess", tables["shininess"])
    lights = scene.lights
    writer.array("lights/positions", lights.positions.astype(np.float32))
    writer.attrs(
        "lights",
        grid=list(lights.grid),
        box=list(lights.box),
        intensity=list(lights.intensity),
        falloff=lights.falloff,
        radius=lights.radius,
    )
