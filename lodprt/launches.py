"""CPU kernel launches sliced over the cores. A Warp launch on the CPU runs on one thread and releases the
interpreter lock, so slices of one pass launched from several Python threads run at once; each slice writes only
its own items' outputs, so the result is what one launch gives.

* ``KernelThreads``: this thread and a pool, slices of about equal work taken as threads come free (the hierarchy's
  collapse rounds, the completion plan's weights, the run time's per-sample bounds and direct light);
* ``launch_ranges``: one contiguous range per thread, or one launch on CUDA (the transfer, volume and neighbourhood
  bakes);
* ``run_jobs``: jobs of unequal, unknown cost (the sequential hierarchy build's tiles and components), some waiting
  for others, on a few threads, the longest estimated first;
* ``warp_view``: a zero-copy Warp view of a CPU numpy array.
"""

from __future__ import annotations

import collections
import concurrent.futures
import heapq
import os
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from lodprt.devices import warp

#: the device of ``KernelThreads`` and ``warp_view``: host work, next to numpy
DEVICE = "cpu"
#: a pass over fewer items runs as one launch (a launch costs tens of microseconds): ``KernelThreads``
SPLIT_MIN = 8192
#: the same for the run time's per-row passes (``KernelThreads.slices``' ``least``, one slice per thread), whose
#: rows cost about a microsecond each (a node's view errors, a vertex's direct light with its shadow ray): two
#: slices pay from about a thousand rows (benchmarks/runtime.py's orbit, 2 cores: the default's median frame 12.2-12.5
#: ms, against 13.2-13.8 with SLICES per thread and 13.7-14.1 from SPLIT_MIN rows)
ROWS_MIN = 1024
#: slices of a pass per thread, at most (``KernelThreads.launch``)
SLICES = 4


def warp_view(a: np.ndarray, dtype):
    """A Warp view of the CPU array ``a`` (bool viewed as uint8; contiguous, no copy when it already is)."""
    a = np.ascontiguousarray(a)
    if a.dtype == bool:
        a = a.view(np.uint8)
    return warp().array(a, dtype=dtype, device=DEVICE, copy=False)


class KernelThreads:
    """The threads one pass of a per-item kernel (a collapse round's, a completion plan's, a sample's bounds) is
    sliced over (a CPU launch releases the GIL, so the slices run at once): this thread and ``workers - 1`` pool
    threads (``workers`` None: every core this process may use). Each slice is a launch of ``dim`` ``b - a`` with
    ``first = a`` (the kernel's first argument); the outputs are what one launch gives, since each thread writes
    only its own items' outputs."""

    def __init__(self, workers: int | None):
        if workers is None:
            workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        self.workers = max(1, int(workers))
        self.pool = concurrent.futures.ThreadPoolExecutor(self.workers - 1) if self.workers > 1 else None

    def __enter__(self) -> "KernelThreads":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()
            self.pool = None

    def launch(self, kernel, dim: int, inputs: list, work: np.ndarray | None = None) -> None:
        """``kernel`` over items ``0..dim-1`` (``inputs`` after ``first``) on the CPU, in ``slices``."""
        wp = warp()
        self.slices(lambda a, b: wp.launch(kernel, dim=b - a, device=DEVICE, inputs=[a] + inputs), dim, work)

    def slices(self, run, dim: int, work: np.ndarray | None = None, most: int | None = None,
               least: int | None = None, per_thread: int = SLICES) -> None:
        """``run(a, b)`` over slices ``a:b`` of items ``0..dim-1`` of about equal ``work`` (cumulative (dim + 1,),
        e.g. the corner CSR start; None: equal counts), ``per_thread`` per thread (each thread takes the next slice
        when it is done with one: a core shared with another process does fewer); one slice below ``least``
        items (default SPLIT_MIN); with ``most``, no slice of more than ``most`` items (bounded per-slice
        buffers). ``run`` must write only its own items' outputs (a Warp CPU launch on views of them, say)."""
        parts = 1
        least = SPLIT_MIN if least is None else least
        if self.pool is not None and dim >= least:
            parts = min(max(int(per_thread), 1) * self.workers, max(self.workers, dim // max(int(least), 1)))
        if most is not None:
            parts = max(parts, -(-dim // max(int(most), 1)))
        if work is None:
            cuts = np.linspace(0, dim, parts + 1).astype(np.int64)
        else:
            cuts = np.searchsorted(work[: dim + 1], np.linspace(0, work[dim], parts + 1)).astype(np.int64)
            cuts[0], cuts[-1] = 0, dim
        todo = iter([(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:]) if b > a])
        lock = threading.Lock()

        def drain():
            while True:
                with lock:
                    ab = next(todo, None)
                if ab is None:
                    return
                run(*ab)

        futures = [self.pool.submit(drain) for _ in range(self.workers - 1)] if parts > 1 else []
        try:
            drain()
        finally:
            for f in futures:
                f.result()


def launch_ranges(kernel, n: int, device: str, inputs_for, jobs: int | None) -> None:
    """Launch ``kernel`` over items 0..n-1 in ``jobs`` contiguous ranges from as many Python threads on the CPU (a
    CPU launch runs on one thread and releases the GIL); ``inputs_for(first)`` gives the inputs of the range that
    starts at ``first``; ranges write disjoint rows, so the result does not depend on ``jobs``. One launch on CUDA."""
    wp = warp()
    jobs = (os.cpu_count() or 1) if jobs is None else max(1, int(jobs))
    if not device.startswith("cpu") or jobs == 1 or n < 2 * jobs:
        if n:
            wp.launch(kernel, dim=n, device=device, inputs=inputs_for(0))
        return
    edges = np.linspace(0, n, jobs + 1).astype(int)

    def run(k):
        a, b = int(edges[k]), int(edges[k + 1])
        if b > a:
            wp.launch(kernel, dim=b - a, device=device, inputs=inputs_for(a))

    with concurrent.futures.ThreadPoolExecutor(jobs) as pool:
        list(pool.map(run, range(jobs)))


@dataclass
class Job:
    """One job of ``run_jobs``: ``run(cache)`` does it (``cache``: a dict of its thread's own, kept between the
    thread's jobs); ``size`` its work in any unit, ``follow`` the size of the work waiting for it; jobs of one
    ``kind`` share a measured rate (seconds per size unit); it waits for ``waits`` jobs, and ``then`` lists the
    indices of the jobs that wait for it."""

    run: Callable[[dict], None]
    size: float
    kind: object = None
    follow: float = 0.0
    waits: int = 0
    then: list = field(default_factory=list)


def run_jobs(jobs: list[Job], workers: int, after: Callable[[], None] = lambda: None) -> None:
    """Run ``jobs`` on this thread and ``workers - 1`` more (a CPU launch releases the GIL): a free thread takes the
    ready job (none left to wait for) of the longest estimated time, ``(size + follow)`` times its kind's rate so far
    (a kind none of whose jobs has finished: the slowest rate known; ties: the first in ``jobs``), so that a costly
    kind's last jobs do not start last and keep one thread busy alone, and the work behind a long chain starts
    early; but first, the largest job of each kind of several jobs none of which has run yet, so that its rate is
    measured before the rest of that kind is placed. ``after()`` runs in the calling thread after each of its jobs,
    before it takes or waits for the next when another thread has finished one since (a progress bar moves while
    the caller waits), and at the end; the first error stops the rest and is raised here. The jobs must not depend on the
    order they run in."""
    lock = threading.Condition()
    waits = [j.waits for j in jobs]
    left, failed, rate, running = len(jobs), [], {}, [0]
    finished = [0]  # jobs finished so far, by any thread (the caller reports those it has not seen)
    jobs_of = collections.Counter(j.kind for j in jobs)
    busy = collections.Counter()  # kind -> its jobs running
    # ready jobs, longest first (ties: the first in ``jobs``): one heap per kind of several jobs (their rates differ),
    # one for the kinds of one job (never measured while ready: all at the slowest rate known)
    single, multi, count = [], {}, [0]
    # the slowest rate known and a kind that has it (None before any job has finished), kept as jobs finish: a max
    # over every kind's rate at each take would cost O(kinds) there, O(jobs^2) over thousands of small components
    slow = [None, None]

    def rate_of(kind) -> float:
        sec, n = rate[kind]
        return sec / max(n, 1e-300)

    def push(k):
        key = (-(jobs[k].size + jobs[k].follow), k)
        heapq.heappush(multi.setdefault(jobs[k].kind, []) if jobs_of[jobs[k].kind] > 1 else single, key)
        count[0] += 1

    for k, j in enumerate(jobs):
        if j.waits == 0:
            push(k)

    def take():
        slowest = 1.0 if slow[0] is None else slow[0]
        best = None  # (probe, estimate, -index, heap)
        for many, kind, heap in [(False, None, single), *((True, kind, h) for kind, h in multi.items())]:
            if not heap:
                continue
            size, k = -heap[0][0], heap[0][1]
            known = many and kind in rate
            # a kind of several jobs none of which has run yet goes first: its rate is then known for the others
            probe = many and not known and not busy[kind]
            cand = (probe, size * (rate_of(kind) if known else slowest), -k, heap)
            if best is None or cand[:3] > best[:3]:
                best = cand
        k = heapq.heappop(best[3])[1]
        count[0] -= 1
        busy[jobs[k].kind] += 1
        return k

    def work(caller=False):
        nonlocal left
        cache, seen = {}, 0
        while True:
            with lock:
                while not count[0] and left and not failed and not (caller and finished[0] != seen):
                    if not running[0]:  # nothing runs that could release a job: a cycle of waits
                        failed.append(RuntimeError("run_jobs: the jobs left wait for each other"))
                        lock.notify_all()
                        break
                    lock.wait()
                if not left or failed:
                    return
                if caller and finished[0] != seen:  # another thread's finished job: reported before the next
                    k, seen = None, finished[0]
                else:
                    k = take()
                    running[0] += 1
            if k is None:
                after()
                continue
            t = time.perf_counter()
            try:
                jobs[k].run(cache)
            except BaseException as e:  # noqa: BLE001 (raised in the calling thread)
                with lock:
                    running[0] -= 1
                    failed.append(e)
                    lock.notify_all()
                return
            with lock:
                running[0] -= 1
                busy[jobs[k].kind] -= 1
                kind = jobs[k].kind
                r = rate.setdefault(kind, [0.0, 0.0])
                r[0], r[1] = r[0] + time.perf_counter() - t, r[1] + float(jobs[k].size)
                now = rate_of(kind)
                if slow[0] is None or now >= slow[0]:
                    slow[:] = [now, kind]
                elif kind == slow[1]:  # the slowest kind got faster: the max over every kind again
                    slow[1] = max(rate, key=rate_of)
                    slow[0] = rate_of(slow[1])
                left -= 1
                finished[0] += 1
                if caller:
                    seen = finished[0]
                for d in jobs[k].then:
                    waits[d] -= 1
                    if waits[d] == 0:
                        push(d)
                lock.notify_all()
            if caller:
                after()

    threads = [threading.Thread(target=work) for _ in range(max(1, min(int(workers), len(jobs))) - 1)]
    for th in threads:
        th.start()
    try:
        work(caller=True)
    finally:
        for th in threads:
            th.join()
    if failed:
        raise failed[0]
    after()
