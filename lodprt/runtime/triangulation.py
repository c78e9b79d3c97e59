"""The cut's mesh, kept up to date incrementally (T-3.2; ``lodprt.kernels.view_cut.retriangulate``): each frame
only the original faces around vertices whose active ancestor changed are mapped again, and the non-degenerate
faces are kept as a dense list, so a frame's triangulation costs what changed (and one numpy comparison per
vertex to find it) instead of a pass over every original face. ``lodprt.model.hierarchy.triangulate`` is the
reference (the same faces, in another order)."""

from __future__ import annotations

import concurrent.futures
import threading
import time

import numpy as np

from lodprt.devices import warp
from lodprt.model.hierarchy import Hierarchy, vertex_corners


class IncrementalTriangulation:
    """The faces of a mesh mapped through a cut's active ancestors, updated by ``faces(anc)`` each frame.

    h: the hierarchy; faces (F, 3) original vertex ids; device: the Warp device of the kernel (on the CPU its
    state aliases numpy arrays; elsewhere it stays on the device and ``anc`` is copied over per call)."""

    def __init__(self, h: Hierarchy, faces: np.ndarray, device: str = "cpu"):
        wp = warp()
        self.device = device
        faces = np.ascontiguousarray(faces, np.int32).reshape(-1, 3)
        V, F = h.num_vertices, len(faces)
        ptr, corner = vertex_corners(faces, V)  # faces around each original vertex (CSR)
        # read-only inputs: on the CPU they wrap the int32 arrays (the caller's faces, the hierarchy's vertex)
        i32 = lambda a: wp.array(np.ascontiguousarray(a, np.int32), dtype=wp.int32, device=device,  # noqa: E731
                                 copy=device != "cpu")
        self._in = [i32(ptr), i32(corner // 3), wp.array(faces, dtype=wp.int32, ndim=2, device=device,
                                                         copy=device != "cpu"), i32(h.vertex)]
        self._seen = np.full(V, -1, np.int32)  # anc at the last call (-1: never)
        self._state = [wp.zeros((F, 3), dtype=wp.int32, device=device),
                       wp.full(F, -1, dtype=wp.int32, device=device),
                       wp.zeros(F, dtype=wp.int32, device=device), wp.zeros(1, dtype=wp.int32, device=device)]
        self._stamp = wp.full(F, -1, dtype=wp.int32, device=device)  # the call that last mapped each face
        self.calls = 0  # kernel calls so far: the number of the last, which a face's stamp compares with

    def update(self, anc: np.ndarray) -> bool:
        """Map again the faces around the vertices whose active ancestor in ``anc`` (V,) changed since the last call
        (T-3.2); whether any did (False: the faces are the last call's)."""
        from lodprt.kernels import view_cut as kv

        wp = warp()
        anc = np.ascontiguousarray(anc, np.int32)
        moved = np.flatnonzero(anc != self._seen).astype(np.int32)
        if not len(moved):
            return False
        a = wp.array(anc, dtype=wp.int32, device=self.device, copy=self.device != "cpu")
        if self.calls == np.iinfo(np.int32).max:  # call numbers start again (after two billion updates)
            self._stamp.fill_(-1)
            self.calls = 0
        self.calls += 1
        wp.launch(kv.retriangulate, dim=1, inputs=[wp.array(moved, dtype=wp.int32, device=self.device),
                                                   *self._in, a, *self._state, self._stamp, self.calls],
                  device=self.device)
        # seen only once mapped: an interruption before this line leaves them to map again (the kernel is idempotent)
        self._seen[moved] = anc[moved]
        return True

    def faces(self, anc: np.ndarray | None = None) -> np.ndarray:
        """(M, 3) int32 original vertex ids of the non-degenerate faces for the active ancestors ``anc`` (V,) (None:
        those of the last ``update``)."""
        from lodprt.kernels import view_cut as kv

        if anc is not None:
            self.update(anc)
        wp = warp()
        fmap, slot, live, count = self._state
        n = int(count.numpy()[0])
        if self.device == "cpu":  # the state is host memory: a numpy gather
            return np.take(fmap.numpy(), live.numpy()[:n], axis=0)  # np.take: faster than fancy indexing
        out = wp.empty((n, 3), dtype=wp.int32, device=self.device)
        if n:  # gathered where the state lives: only the cut's faces come back from the device
            wp.launch(kv.gather_live, dim=n, inputs=[live, fmap], outputs=[out], device=self.device)
        return out.numpy()


class CutMesh:
    """The cut's mesh as a frame draws it: (vertex ids (A,) int32 ascending, triangles (M, 3) indices into them),
    read-only, kept while no active ancestor moves (they make the cut's nodes).

    The vertices need the cut's nodes only, the triangles the triangulation (T-3.2, one thread on the CPU): with
    ``background``, ``start`` makes them on a worker thread while the caller relights the vertices on the cores,
    and ``take`` waits for them. The cut must not move in between; ``wait`` (the next frame, before it moves the
    cut) waits for a mesh still in the making, after an interruption too."""

    def __init__(self, h: Hierarchy, faces: np.ndarray, referenced: np.ndarray, device: str = "cpu", *,
                 background: bool = False):
        self.h, self.referenced = h, referenced
        self.triangulation = IncrementalTriangulation(h, faces, device)
        self.mesh: tuple | None = None
        self._lock = threading.Lock()  # one maker at a time: the worker's, or the caller's after it
        self.background = bool(background)
        self._pool = concurrent.futures.ThreadPoolExecutor(1) if background else None
        self._pending: concurrent.futures.Future | None = None
        self.waited = 0.0  # seconds the last ``take`` waited for the worker
        self._vertices: tuple | None = None  # (nodes, their vertices): ``vertices``' last, for a read-only nodes

    def vertices(self, nodes: np.ndarray) -> np.ndarray:
        """(A,) int32 ascending, read-only: the vertices of ``nodes`` that a face uses (one never drawn is not
        relit). Kept for the same ``nodes`` object (``Cut.nodes`` until the cut moves): the frame's relighting and
        the worker's triangles ask for the same."""
        last = self._vertices
        if last is not None and last[0] is nodes:
            return last[1]
        vid = np.sort(self.h.vertex[nodes]).astype(np.int32)  # ascending: gathers walk memory forward
        vid = vid[self.referenced[vid]]
        vid.flags.writeable = False
        if not nodes.flags.writeable:  # an array that cannot change under the same object
            self._vertices = (nodes, vid)
        return vid

    def __call__(self, cut) -> tuple[np.ndarray, np.ndarray]:
        """The mesh of ``cut`` now (in this thread)."""
        self.wait()
        return self._make(cut)

    def _make(self, cut) -> tuple[np.ndarray, np.ndarray]:
        with self._lock:
            if self.triangulation.update(cut.anc):
                self.mesh = None  # until remade below: an interruption before then must not leave the old one
            if self.mesh is None:
                vid = self.vertices(cut.nodes)
                lut = np.full(self.h.num_vertices, -1, np.int32)
                lut[vid] = np.arange(len(vid), dtype=np.int32)
                tri = np.take(lut, self.triangulation.faces())
                vid.flags.writeable = tri.flags.writeable = False
                self.mesh = (vid, tri)
            return self.mesh

    def start(self, cut) -> None:
        """Begin the mesh of ``cut`` on the worker thread (in this one without ``background``)."""
        self.wait()
        if self._pool is None:
            self(cut)
        else:
            self._pending = self._pool.submit(self._make, cut)

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh ``start`` began (its error, if it raised); ``waited``: how long this waited for it."""
        self.waited = 0.0
        if self._pending is None:  # made in start, in this thread
            return self.mesh
        t = time.perf_counter()
        try:
            return self._pending.result()
        finally:  # interrupted while it waited: the worker still runs, and ``wait`` waits for it
            if self._pending.done():
                self._pending = None
            self.waited = time.perf_counter() - t

    def wait(self) -> None:
        """Wait for a mesh still in the making (its error is dropped: the next call makes the mesh again)."""
        if self._pending is not None:
            concurrent.futures.wait([self._pending])
            self._pending = None
