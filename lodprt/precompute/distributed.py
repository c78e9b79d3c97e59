"""Distributed bake on dask.distributed (docs/DISTRIBUTED.md): the light samples of a bake are dask tasks.

:func:`run_on_cluster` starts a ``LocalCluster`` of ``workers`` processes (``threads`` threads each, default 1) or
connects to the running cluster at ``scheduler`` (``tcp://host:port``). The job
(:class:`lodprt.precompute.bake.SampleJob`: the scene, the hierarchy in light-cut mode, the settings and the path
of the partial store) is scattered to every worker once (``broadcast``), not sent with each task. A task is one
light sample: the worker bakes it with its device state (BVH, material tables, light-cut arrays, Warp kernels
loaded), made at its first task and kept for the next ones, and writes the sample's group straight into the partial
store, complete with its mark (``lodprt.store.sample_groups``). Only the sample's statistics (a few numbers) come
back to the client, whose progress bar follows the finished tasks. A worker killed mid-task loses nothing: the
scheduler runs the task again elsewhere, and the group it was assembling never reached ``samples/``.

Every worker must see the store's folder at the client's path (one machine, or a shared file system). With
``vertex_range`` N, a sample of more than N baked vertices is split into tasks of vertex ranges on different workers
and one task that joins them and writes the group (:mod:`lodprt.precompute.vertex_ranges`).
"""

from __future__ import annotations

import contextlib
import logging
from typing import Callable

from lodprt.errors import LodprtError
from lodprt.precompute.vertex_ranges import check_store_visible, check_vertex_range, row_ranges, submit_ranges

log = logging.getLogger(__name__)

#: how to get the optional dependency
INSTALL = "pip install 'lodprt[distributed]'"


def dask_distributed():
    """The ``distributed`` module; LodprtError saying how to install it when it is missing."""
    try:
        import distributed
    except ImportError as exc:
        raise LodprtError(f"--workers / --scheduler bake on dask.distributed, which is not installed: {INSTALL}") from exc
    return distributed


def check_cluster(*, workers: int | None, scheduler: str | None, threads: int | None, vertex_range: int | None = None,
                  bounces: int = 0) -> bool:
    """Whether the bake runs on a cluster (``workers`` or ``scheduler``), refusing wrong options before any work;
    ``vertex_range`` needs a cluster and no interreflection (``bounces`` 0). Imports dask only for a cluster."""
    check_vertex_range(vertex_range, bounces=bounces)
    if workers is None and scheduler is None:
        if vertex_range is not None:
            raise LodprtError(f"--vertex-range / vertex_range {vertex_range}: splits light samples into dask tasks; "
                              "give --workers N or --scheduler ADDRESS too")
        return False
    check_options(workers=workers, scheduler=scheduler, threads=threads)
    return True


def check_options(*, workers: int | None, scheduler: str | None, threads: int | None):
    """Refuse a wrong combination of options (or a missing dask) before any work; returns ``distributed``."""
    distributed = dask_distributed()
    if (workers is None) == (scheduler is None):
        raise LodprtError("distributed bake: give either --workers N (a local cluster) or --scheduler ADDRESS")
    if workers is not None and workers < 1:
        raise LodprtError(f"--workers {workers}: must be >= 1")
    if threads is not None and threads < 1:
        raise LodprtError(f"--jobs {threads}: must be >= 1")
    return distributed


@contextlib.contextmanager
def cluster_client(*, workers: int | None = None, scheduler: str | None = None, threads: int | None = None):
    """A dask ``Client``: of a new ``LocalCluster`` of ``workers`` processes with ``threads`` threads each, or of
    the running scheduler at ``scheduler``. The local cluster is shut down on leaving."""
    distributed = check_options(workers=workers, scheduler=scheduler, threads=threads)
    with contextlib.ExitStack() as stack:
        stack.enter_context(_quiet("distributed", "tornado"))  # their INFO lines would drown lodprt's under -v
        if scheduler is not None:
            try:
                client = stack.enter_context(distributed.Client(scheduler, timeout=30))
            except (OSError, TimeoutError, ValueError) as exc:
                raise LodprtError(f"--scheduler {scheduler}: cannot connect to a dask scheduler there ({exc})") from exc
        else:
            # memory_limit=0: dask's memory manager would pause or kill a worker holding a big scene; the bake's
            # memory is known (one scene copy and one sample per worker thread)
            cluster = stack.enter_context(distributed.LocalCluster(
                n_workers=workers, threads_per_worker=threads or 1, processes=True, memory_limit=0))
            client = stack.enter_context(distributed.Client(cluster))
        yield client


@contextlib.contextmanager
def _quiet(*names: str):
    """Raise the level of the loggers ``names`` to WARNING for the duration."""
    loggers = [logging.getLogger(name) for name in names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(max(lg.getEffectiveLevel(), logging.WARNING))
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def dashboard_note(client) -> str:
    """The dashboard's address, and how to get it served when bokeh (which serves it) is missing."""
    import importlib.util

    served = importlib.util.find_spec("bokeh") is not None
    return client.dashboard_link + ("" if served else " (not served: pip install 'bokeh>=3.1' to see it)")


def _sample_task(job, k: int) -> tuple[int, dict, float]:
    """A dask task: bake and write light sample ``k`` of ``job`` on this worker."""
    check_store_visible(job)
    info, load_seconds = job.run(k)
    return k, info, load_seconds


def run_on_cluster(job, todo: list[int], *, workers: int | None = None, scheduler: str | None = None,
                   threads: int | None = None, progress: Callable[[int, int], None] | None = None,
                   vertex_range: int | None = None) -> tuple[dict[int, dict], float]:
    """Bake the light samples ``todo`` of ``job`` (a ``SampleJob`` with a partial store) on a dask cluster.

    Returns the statistics of each sample (by index) and the longest kernel loading of a worker.
    ``progress(done, len(todo))`` follows the finished tasks. A lost cluster raises a ``LodprtError`` marked
    ``resumable``: the samples finished so far stay in the partial store for ``bake --resume``.
    ``vertex_range`` N: a sample of more than N baked vertices is split into vertex-range tasks (module doc).
    """
    distributed = dask_distributed()
    if job.partial is None:
        raise LodprtError("distributed bake: the workers write the store, so it needs one (out)")
    with cluster_client(workers=workers, scheduler=scheduler, threads=threads) as client:
        log.info("dask dashboard: %s; %d workers", dashboard_note(client), len(client.scheduler_info()["workers"]))
        if not todo:
            return {}, 0.0
        shared = client.scatter(job, broadcast=True, hash=False)  # once per worker, not once per task
        rows = int(job.scene.referenced.sum())  # the baked vertices of every sample
        if vertex_range is not None and rows > vertex_range:
            log.info("light samples of %d baked vertices: %d vertex-range tasks of at most %d each", rows,
                     len(row_ranges(rows, vertex_range)), vertex_range)
            futures = [submit_ranges(client, shared, job, k, vertex_range, rows) for k in todo]
        else:
            futures = [client.submit(_sample_task, shared, k, key=f"lodprt-sample-{job.token}-{k:05d}")
                       for k in todo]
        infos: dict[int, dict] = {}
        load = 0.0
        try:
            for done, fut in enumerate(distributed.as_completed(futures), 1):
                k, info, seconds = fut.result()
                infos[k], load = info, max(load, seconds)
                if progress is not None:
                    progress(done, len(todo))
        except (distributed.KilledWorker, OSError, TimeoutError) as exc:
            error = LodprtError(f"distributed bake: the cluster failed ({type(exc).__name__}: {exc}); the "
                                f"{len(infos)} samples finished now are kept: run the same bake with --resume")
            error.resumable = True
            raise error from exc
        finally:
            client.cancel(futures)
        return infos, load
