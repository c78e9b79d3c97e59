"""Vertex-range tasks of a distributed bake (docs/DISTRIBUTED.md, "Vertex ranges"): one light sample of many vertices
as several dask tasks, each baking a contiguous range of the sample's vertices on its worker, and one task that
joins them and writes the sample's group with the in-process writer.

The unit is the *baked vertex*: the scene's referenced vertices in ascending order (one shadow ray each; one row of
a full-resolution sample). With ``vertex_range`` N, a sample of R > N baked vertices is split into ceil(R / N)
ranges ``[i N, min((i + 1) N, R))`` (the last one shorter when N does not divide R); R <= N stays one task.

* Full resolution: task i casts the shadow rays (T-8) and shades (T-9, T-10) the rows of range i alone.
* Light cut: the cut (T-11) is a bottom-up pass over the whole hierarchy that needs the visibility of every vertex,
  so it stays whole: task i casts the shadow rays of range i, one cut task joins the visibility and computes the
  cut on its worker, then task i shades the cut's rows whose vertices lie in range i (the cut's rows are ascending
  vertex ids, so they are a contiguous run of at most N rows).
* The assembling task concatenates the rows in range order and hands them to ``SampleJob.write``: the group's
  arrays, its statistics and its default-white record (DW-1) come from the whole sample's rows, as in-process,
  and the group moves into the partial store whole (``lodprt.store.sample_groups``), so a resumed bake sees a
  sample either complete or absent, as before.

The store equals an in-process bake's byte for byte because every kernel computes each vertex alone (no reduction
across vertices): a row does not depend on the launch that computed it. Interreflection (``bounces`` > 0) gathers
over every vertex of a sample and is refused with vertex ranges.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np

from lodprt.errors import LodprtError, is_whole


def check_vertex_range(vertex_range, *, bounces: int = 0) -> None:
    """Refuse a ``vertex_range`` that is not an integer >= 1 (None: off), or one with interreflection."""
    if vertex_range is None:
        return
    if not is_whole(vertex_range, 1, integer_type=True):
        raise LodprtError(f"--vertex-range / vertex_range {vertex_range!r}: must be an integer >= 1 (the most baked "
                          "vertices of a light sample one dask task computes; not given: whole samples)")
    if bounces:
        raise LodprtError(f"--vertex-range / vertex_range {vertex_range}: the interreflection passes (bounces "
                          f"{bounces}) gather over every vertex of a sample, so such a sample is one task; bake "
                          "with one or the other")


def row_ranges(rows: int, size: int) -> list[tuple[int, int]]:
    """The ceil(rows / size) ranges ``(start, stop)`` of at most ``size`` rows covering ``0..rows``, in order."""
    return [(start, min(start + size, rows)) for start in range(0, rows, size)]


def check_store_visible(job) -> None:
    """Refuse to bake on a worker that does not see the partial store at the client's path."""
    if not Path(job.partial).is_dir():
        raise LodprtError(f"{job.partial}: the store being written is not visible on worker host "
                          f"{socket.gethostname()}; a distributed bake needs the client's folder on every worker "
                          "(one machine or a shared file system)")


def submit_ranges(client, shared, job, k: int, size: int, rows: int):
    """Submit the tasks of light sample ``k`` of ``job`` (scattered as ``shared``) split into vertex ranges of at
    most ``size`` of its ``rows`` baked vertices; the future of the assembling task, whose result is (k, the
    sample's statistics, the longest kernel loading of its tasks). Only that future is kept: the ranges' results
    are released once it has run. Tasks of earlier samples go first, and a sample's later stages before the next
    sample's ranges (dask priorities), so a sample's rows are not held long."""
    spans = row_ranges(rows, size)

    def submit(stage: int, fn, *args, key: str):
        return client.submit(fn, shared, k, *args, key=f"lodprt-{key}-{job.token}-{k:05d}",
                             priority=stage - 4 * k)

    if job.threshold_deg is None:
        parts = [submit(0, full_rows_task, a, b, key=f"rows-{i:05d}") for i, (a, b) in enumerate(spans)]
        return submit(3, assemble_full, *parts, key="assemble")
    seen = [submit(0, visibility_task, a, b, key=f"visibility-{i:05d}") for i, (a, b) in enumerate(spans)]
    cut = submit(1, cut_task, *seen, key="cut")
    parts = [submit(2, shade_task, cut, a, b, key=f"shade-{i:05d}") for i, (a, b) in enumerate(spans)]
    return submit(3, assemble_cut, cut, *parts, key="assemble")


def full_rows_task(job, k: int, start: int, stop: int) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Rows ``start:stop`` of full-resolution sample ``k``: (coefficients, visibility, seconds, kernel loading)."""
    baker, _lightcut, load = job.worker_state()
    t = time.perf_counter()
    coeffs, visible = baker.sample_rows(job.lights[k], start, stop)
    return coeffs, visible, time.perf_counter() - t, load


def visibility_task(job, k: int, start: int, stop: int) -> tuple[np.ndarray, float, float]:
    """Visibility of the baked vertices ``start:stop`` for light sample ``k``: (states, seconds, kernel loading)."""
    baker, _lightcut, load = job.worker_state()
    t = time.perf_counter()
    visible = baker.visibility_rows(job.lights[k], start, stop)
    return visible, time.perf_counter() - t, load


def cut_task(job, k: int, *parts) -> dict:
    """The light cut of sample ``k`` from the visibility ``parts`` of its ranges, in order (``Baker.light_cut``):
    the cut's vertex ids, nodes, dark flags and visibility states, the whole visibility, seconds and loading."""
    baker, lightcut, load = job.worker_state()
    t = time.perf_counter()
    vis = np.concatenate([p[0] for p in parts])
    ids, nodes, dark, states = baker.light_cut(job.lights[k], lightcut, job.threshold_deg, vis)
    return {"ids": ids, "nodes": nodes, "dark": dark, "states": states, "visible": vis,
            "seconds": time.perf_counter() - t + sum(p[1] for p in parts), "load": max([load, *(p[2] for p in parts)])}


def shade_task(job, k: int, cut: dict, start: int, stop: int) -> tuple[np.ndarray, float, float]:
    """Coefficients of the rows of ``cut`` whose vertices are the baked vertices ``start:stop`` (a contiguous run:
    the cut's ids ascend): (coefficients, seconds, kernel loading)."""
    baker, _lightcut, load = job.worker_state()
    t = time.perf_counter()
    lo, hi = cut_rows(cut["ids"], baker.ids_host, start, stop)
    coeffs = baker.shade_rows(job.lights[k], cut["ids"][lo:hi], cut["states"][lo:hi])
    return coeffs, time.perf_counter() - t, load


def cut_rows(ids: np.ndarray, baked: np.ndarray, start: int, stop: int) -> tuple[int, int]:
    """The rows ``lo:hi`` of the ascending cut vertex ids ``ids`` that lie in ``baked[start:stop]`` (ascending)."""
    if start >= stop:
        return 0, 0
    lo = int(np.searchsorted(ids, baked[start], side="left"))
    hi = int(np.searchsorted(ids, baked[stop - 1], side="right"))
    return lo, hi


def assemble_full(job, k: int, *parts) -> tuple[int, dict, float]:
    """Join the range ``parts`` of full-resolution sample ``k`` and write its group: (k, statistics, loading)."""
    check_store_visible(job)
    baker, _lightcut, load = job.worker_state()
    coeffs = np.concatenate([p[0] for p in parts])
    visible = np.concatenate([p[1] for p in parts])
    info = job.write(k, baker.ids_host, {}, coeffs, visible, sum(p[2] for p in parts), {})
    return k, info, max([load, *(p[3] for p in parts)])


def assemble_cut(job, k: int, cut: dict, *parts) -> tuple[int, dict, float]:
    """Join the shaded ``parts`` of light-cut sample ``k`` and write its group: (k, statistics, loading)."""
    check_store_visible(job)
    _baker, _lightcut, load = job.worker_state()
    coeffs = np.concatenate([p[0] for p in parts])
    if len(coeffs) != len(cut["ids"]):
        raise LodprtError(f"light sample {k}: the vertex ranges shaded {len(coeffs)} rows of a cut of "
                          f"{len(cut['ids'])}")
    extra = {"cut_nodes": cut["nodes"], "dark": cut["dark"]}
    info = job.write(k, cut["ids"], extra, coeffs, cut["visible"], cut["seconds"] + sum(p[1] for p in parts), {})
    return k, info, max([load, cut["load"], *(p[2] for p in parts)])
