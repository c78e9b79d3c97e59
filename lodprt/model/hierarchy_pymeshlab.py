"""The seed of ``build_hierarchy(method="pymeshlab")`` (SPEC 3; thesis 3.2; design card: pymeshlab's QEM ordering
seeds the vertex hierarchy): ``removal_levels``, the pymeshlab halving at which each vertex disappears, computed
with bounded memory.

Every group (connected component, split by ``component``) is decimated on its own; a group of more than
``TILE_VERTICES`` vertices is cut into spatial tiles (faces by centroid, on a grid over its two longest extents),
each tile decimated with its border vertices (those shared with another tile) locked, then the tiles' last meshes,
stitched back into one mesh of about the border's size, are decimated again (tiled again when still too big), their
levels numbered after the tiles'. So pymeshlab never holds more than one tile (about 2.3 KB per vertex of it) per
process. The parts run on worker processes (``python -m lodprt.model.hierarchy_pymeshlab``: fresh interpreters, not
copies of the caller's memory, fed over pipes by one thread each) when they are several and hold at least
``PARALLEL_VERTICES`` vertices in all. Details: docs/HIERARCHY.md.
"""

from __future__ import annotations

import concurrent.futures
import logging
import math
import os
import pickle
import queue
import subprocess
import sys

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model.hierarchy_levels import halvings
from lodprt.model.hierarchy_rounds import NEVER
from lodprt.model.meshio import referenced_mask

log = logging.getLogger(__name__)

#: a group with more vertices is decimated in tiles of about this many vertices
TILE_VERTICES = 50_000
#: parts holding fewer vertices in all are decimated in this process (a spawned worker costs about a second)
PARALLEL_VERTICES = 100_000
#: at most this many halvings per part
MAX_LEVELS = 40


def decimate_part(positions, faces, locked, target_base: int, keep_boundary: bool):
    """One part (worker): positions (n, 3), faces (F, 3) local ids, locked (n,) bool or None. Returns the level
    (n,) int32 at which each vertex left the chain of halvings (0: never), the faces (F_L, 3) int64 (local ids)
    after the last level, and the number of levels."""
    level = np.zeros(len(positions), np.int32)
    alive = np.ones(len(positions), bool)
    last, count = np.asarray(faces, np.int64), 0
    for count, f in enumerate(halvings(positions, faces, target_base=target_base, max_levels=MAX_LEVELS,
                                       keep_boundary=keep_boundary, locked=locked), 1):
        now = referenced_mask(len(positions), f)
        level[alive & ~now] = count  # nested: each level is decimated from the one before
        alive &= now
        last = f
    return level, last, count


def tiles(positions: np.ndarray, faces: np.ndarray, tile_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Spatial tiles of one group: (F,) int64 tile of each face (by its centroid, on a grid over the two longest
    extents of the group's box, about ``tile_vertices`` vertices a tile) and the border (V,) bool: vertices used
    by faces of two tiles or more."""
    ids = np.unique(faces)
    p = positions[ids]
    lo, ext = p.min(0), np.ptp(p, 0)
    a, b = np.argsort(ext)[::-1][:2]  # the longest and the second longest axes
    count = math.ceil(len(ids) / tile_vertices)
    ka = min(count, max(1, round(math.sqrt(count * ext[a] / max(ext[b], 1e-12 * ext[a], 1e-300)))))
    kb = math.ceil(count / ka)
    c = positions[faces].mean(1)
    ta = np.clip(((c[:, a] - lo[a]) / max(ext[a], 1e-300) * ka).astype(np.int64), 0, ka - 1)
    tb = np.clip(((c[:, b] - lo[b]) / max(ext[b], 1e-300) * kb).astype(np.int64), 0, kb - 1)
    tile = ta * kb + tb
    V = len(positions)
    first = np.full(V, np.iinfo(np.int64).max)
    last = np.full(V, -1)
    for k in range(3):
        np.minimum.at(first, faces[:, k], tile)
        np.maximum.at(last, faces[:, k], tile)
    return tile, (last >= 0) & (first != last)


def _run(parts: list, target_base: int, keep_boundary: bool, workers: int | None) -> list:
    """``decimate_part`` of every part (positions, faces, locked), on worker processes when it pays."""
    if workers is None:
        workers = os.cpu_count() or 1
    workers = min(workers, len(parts))
    size = sum(len(p[0]) for p in parts)
    if workers <= 1 or size < PARALLEL_VERTICES:
        return [decimate_part(*p, target_base, keep_boundary) for p in parts]
    log.info("hierarchy: pymeshlab on %d parts (%d vertices), %d processes", len(parts), size, workers)
    todo = queue.SimpleQueue()
    for k in sorted(range(len(parts)), key=lambda k: -len(parts[k][0])):  # largest first: the workers stay busy
        todo.put(k)
    out: list = [None] * len(parts)

    def drive() -> None:  # one worker process, fed part after part over its pipes
        # a fresh interpreter (not a fork of this process's memory, nor a re-run of the caller's __main__)
        proc = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        try:
            while True:
                try:
                    k = todo.get_nowait()
                except queue.Empty:
                    break
                pickle.dump((parts[k], target_base, keep_boundary), proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                proc.stdin.flush()
                out[k] = pickle.load(proc.stdout)
        finally:
            proc.stdin.close()
            proc.wait()
        if proc.returncode:
            raise LodprtError(f"hierarchy: a pymeshlab worker process failed (exit status {proc.returncode})")

    with concurrent.futures.ThreadPoolExecutor(workers) as pool:
        for fut in [pool.submit(drive) for _ in range(workers)]:
            fut.result()
    return out


def serve() -> None:
    """The worker loop (``python -m lodprt.model.hierarchy_pymeshlab``): a part from stdin, its
    ``decimate_part`` result to stdout, until stdin closes."""
    src = sys.stdin.buffer
    dst = os.fdopen(os.dup(1), "wb")  # the results' pipe; anything else printed (pymeshlab's C++ too) goes to stderr
    os.dup2(2, 1)
    while True:
        try:
            part, target_base, keep_boundary = pickle.load(src)
        except EOFError:
            return
        pickle.dump(decimate_part(*part, target_base, keep_boundary), dst, protocol=pickle.HIGHEST_PROTOCOL)
        dst.flush()


def removal_levels(positions: np.ndarray, faces: np.ndarray, group: np.ndarray, *, target_base: int = 64,
                   keep_boundary: bool = False, workers: int | None = None,
                   tile_vertices: int | None = None) -> tuple[np.ndarray, int]:
    """(V,) int32 the level of chained pymeshlab halvings at which each vertex is removed (``NEVER`` when it never
    is, or no face of its group uses it) and the number of levels (module docstring).

    positions (V, 3), faces (F, 3) original ids, group (V,) the groups ``hierarchy_levels.mesh_groups`` gives
    (faces spanning two groups take no part). ``workers``: processes for the parts (default: every core; 1 runs
    them here); ``tile_vertices`` (default ``TILE_VERTICES``) the size above which a group is tiled."""
    tile_vertices = TILE_VERTICES if tile_vertices is None else int(tile_vertices)
    V = len(positions)
    level = np.full(V, NEVER, np.int32)
    g = group[faces[:, 0]]
    inside = (group[faces[:, 1]] == g) & (group[faces[:, 2]] == g)
    order = np.argsort(g[inside], kind="stable")
    f = faces[inside][order]
    cuts = np.flatnonzero(np.diff(g[inside][order])) + 1
    items = [(part, 0, True) for part in np.split(f, cuts) if len(part) > target_base]  # (faces, offset, may tile)
    top = 0
    while items:
        parts, owner, stitched = [], [], []
        for k, (fk, offset, may_tile) in enumerate(items):
            ids = np.unique(fk)
            if not may_tile or len(ids) <= tile_vertices:
                parts.append((positions[ids], np.searchsorted(ids, fk), None))
                owner.append((k, ids, offset))
                continue
            tile, border = tiles(positions, fk, tile_vertices)
            for t in np.unique(tile):
                ft = fk[tile == t]
                tid = np.unique(ft)
                parts.append((positions[tid], np.searchsorted(tid, ft), border[tid]))
                owner.append((k, tid, offset))
            stitched.append(k)
        results = _run(parts, target_base, keep_boundary, workers)
        rest: dict[int, list] = {k: [] for k in stitched}
        depth: dict[int, int] = {k: 0 for k in stitched}
        for (k, ids, offset), (lv, last, count) in zip(owner, results):
            gone = lv > 0
            level[ids[gone]] = offset + lv[gone]
            top = max(top, offset + count)
            if k in rest:
                rest[k].append(ids[last])
                depth[k] = max(depth[k], count)
        nxt = []
        for k in stitched:  # the tiles' last meshes, stitched: their borders and what the tiles kept
            fk, offset, _ = items[k]
            again = np.concatenate(rest[k])
            shrunk = len(np.unique(again)) < 0.9 * len(np.unique(fk))  # else decimate it whole (no more tiles)
            if len(again) > target_base:
                nxt.append((again, offset + depth[k], shrunk))
        items = nxt
    return level, top


if __name__ == "__main__":
    serve()
