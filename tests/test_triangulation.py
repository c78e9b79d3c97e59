"""The run time's incremental triangulation (``lodprt.runtime.triangulation``, kernels ``retriangulate`` and
``gather_live``) against the vectorised reference ``lodprt.model.hierarchy.triangulate`` (T-3.2): after every cut
change, from the base up to the full mesh and back, the same set of faces."""

import numpy as np
import pytest

from lodprt.model.hierarchy import triangulate
from lodprt.runtime.triangulation import CutMesh, IncrementalTriangulation
from lodprt.runtime.view_cut import Cut

pytestmark = pytest.mark.warp_debug


def rows(tri: np.ndarray) -> np.ndarray:
    """Faces as a sorted array of rows (each rotated to start at its smallest id, orientation kept)."""
    tri = np.asarray(tri, np.int64).reshape(-1, 3)
    k = np.argmin(tri, axis=1)
    rot = np.stack([tri[np.arange(len(tri)), (k + i) % 3] for i in range(3)], 1)
    return rot[np.lexsort(rot.T[::-1])]


@pytest.mark.parametrize("calls", [0, np.iinfo(np.int32).max - 3])  # the call numbers start again mid-way
def test_incremental_faces_match_the_reference(bunny_floor, bunny_hierarchy, device, calls):
    """Random forced splits and collapses, several cut moves between calls, an unchanged call, LOD off (every leaf)
    and back to the base: every call gives exactly ``triangulate``'s faces (same orientation, no duplicates), and
    ``update`` reports a move exactly when the active ancestors changed. A face around several moved vertices is
    mapped once a call (its stamp), also when the call numbers wrap."""
    h, faces = bunny_hierarchy, bunny_floor.faces
    tri = IncrementalTriangulation(h, faces, device)
    tri.calls = int(calls)
    rng = np.random.default_rng(3)
    cut = Cut.base(h, faces)
    seen = None
    for step in range(8):
        # update says whether any active ancestor moved since the last call (the cache key of Runtime._cut_mesh)
        assert tri.update(cut.anc) == (seen is None or not np.array_equal(seen, cut.anc))
        seen = cut.anc.copy()
        got = tri.faces(cut.anc) if step % 2 else tri.faces()
        np.testing.assert_array_equal(rows(got), rows(triangulate(h, faces, cut.anc)))
        if step == 3:  # nothing moved: the same faces again
            assert not tri.update(cut.anc)
            np.testing.assert_array_equal(rows(tri.faces(cut.anc)), rows(got))
        act = np.flatnonzero(cut.active)
        inner = act[act >= h.num_vertices]
        cut.force_refine_list(rng.permutation(inner)[: max(len(inner) // 4, 1)], device="cpu")
        par = np.unique(h.parent[np.flatnonzero(cut.active)])
        cut.coarsen_list(rng.permutation(par[par >= 0])[:200], device="cpu")
    full = Cut.full(h, faces)
    np.testing.assert_array_equal(rows(tri.faces(full.anc)), rows(faces))
    base = Cut.base(h, faces)
    np.testing.assert_array_equal(rows(tri.faces(base.anc)), rows(triangulate(h, faces, base.anc)))


def test_gather_live_kernel(device):
    """``gather_live`` (the device-side gather of the live faces) returns the rows of the listed faces in order."""
    from lodprt.devices import warp
    from lodprt.kernels import view_cut as kv

    wp = warp()
    fmap = np.arange(30, dtype=np.int32).reshape(10, 3)
    live = np.array([7, 2, 9, 0, 5, 5], np.int32)  # the list is longer than the live count (4)
    out = wp.empty((4, 3), dtype=wp.int32, device=device)
    wp.launch(kv.gather_live, dim=4, inputs=[wp.array(live, dtype=wp.int32, device=device),
                                             wp.array(fmap, dtype=wp.int32, ndim=2, device=device)],
              outputs=[out], device=device)
    np.testing.assert_array_equal(out.numpy(), fmap[live[:4]])


@pytest.mark.parametrize("when", ["before", "after"])
def test_an_interrupted_update_maps_again(bunny_floor, bunny_hierarchy, device, monkeypatch, when):
    """An interruption (KeyboardInterrupt: Ctrl-C in a viewer or a notebook) just before or just after ``update``'s
    kernel leaves nothing stale: the vertices it was mapping count as moved until a call maps them (the kernel is
    idempotent), and the faces are ``triangulate``'s. Before, they were marked seen first, so an interruption before
    the launch kept the old faces for good."""
    from lodprt.devices import warp

    wp = warp()
    h, faces = bunny_hierarchy, bunny_floor.faces
    tri = IncrementalTriangulation(h, faces, device)
    cut = Cut.base(h, faces)
    assert tri.update(cut.anc)
    act = np.flatnonzero(cut.active)
    cut.force_refine_list(act[act >= h.num_vertices][:64], device="cpu")
    real = wp.launch

    def interrupted(*args, **kwargs):
        if when == "after":
            real(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(wp, "launch", interrupted)
    with pytest.raises(KeyboardInterrupt):
        tri.update(cut.anc)
    monkeypatch.undo()
    assert tri.update(cut.anc)  # still to be mapped
    np.testing.assert_array_equal(rows(tri.faces()), rows(triangulate(h, faces, cut.anc)))
    assert not tri.update(cut.anc)


def interrupted(*args, **kwargs):
    """Stands in for a call that Ctrl-C interrupts (KeyboardInterrupt)."""
    raise KeyboardInterrupt


def mesh_faces(mesh) -> np.ndarray:
    """A ``CutMesh`` mesh's triangles as rows of original vertex ids."""
    vid, tri = mesh
    return rows(vid[tri])


@pytest.mark.parametrize("background", [False, True])
def test_cut_mesh_made_on_a_worker_is_the_cut_mesh(bunny_floor, bunny_hierarchy, device, monkeypatch, background):
    """``CutMesh`` (the frame's mesh; on the CPU its triangles made on a worker thread while the frame relights):
    after each move of the cut, ``start`` then ``take`` gives ``triangulate``'s faces over exactly the cut's
    referenced vertices (ascending, as ``vertices`` gives them before the triangles are made); a mesh interrupted on
    the worker (KeyboardInterrupt inside ``faces``) raises from ``take`` and leaves nothing stale; a mesh started and
    never taken (a frame interrupted while it relit) is waited for by the next call."""
    h, faces, referenced = bunny_hierarchy, bunny_floor.faces, bunny_floor.referenced
    meshes = CutMesh(h, faces, referenced, device, background=background)
    cut = Cut.base(h, faces)
    rng = np.random.default_rng(5)

    def move():
        act = np.flatnonzero(cut.active)
        inner = act[act >= h.num_vertices]
        cut.force_refine_list(rng.permutation(inner)[: max(len(inner) // 3, 1)], device="cpu")

    def check(mesh):
        want = np.sort(h.vertex[cut.nodes])
        np.testing.assert_array_equal(mesh[0], want[referenced[want]])
        np.testing.assert_array_equal(mesh_faces(mesh), rows(triangulate(h, faces, cut.anc)))
        assert not mesh[0].flags.writeable and not mesh[1].flags.writeable

    for _ in range(3):
        move()
        vid = meshes.vertices(cut.nodes)
        meshes.start(cut)
        got = meshes.take()
        np.testing.assert_array_equal(got[0], vid)
        check(got)
        assert meshes.waited >= 0.0
    move()

    monkeypatch.setattr(IncrementalTriangulation, "faces", interrupted)
    with pytest.raises(KeyboardInterrupt):  # from take on the worker, from start without one
        meshes.start(cut)
        meshes.take()
    monkeypatch.undo()
    check(meshes(cut))  # the move was taken in, the mesh not made: made now
    move()
    meshes.start(cut)  # never taken
    check(meshes(cut))


def test_cut_mesh_interrupted_while_it_waits_waits_again(bunny_floor, bunny_hierarchy, monkeypatch):
    """A frame interrupted while ``take`` waits for the worker (Ctrl-C in the viewer): the worker still reads the
    cut, so the next frame's ``wait`` must wait for it before the cut moves (before, ``take`` forgot the worker
    and the next frame could move the cut under it)."""
    import concurrent.futures
    import threading

    h, faces, referenced = bunny_hierarchy, bunny_floor.faces, bunny_floor.referenced
    meshes = CutMesh(h, faces, referenced, "cpu", background=True)
    cut = Cut.base(h, faces)
    go, finished = threading.Event(), []
    real = IncrementalTriangulation.faces

    def held(self, *args, **kwargs):  # the worker's triangles, held until ``go``
        go.wait(10.0)
        out = real(self, *args, **kwargs)
        finished.append(True)
        return out

    monkeypatch.setattr(IncrementalTriangulation, "faces", held)
    meshes.start(cut)
    with monkeypatch.context() as m:
        m.setattr(concurrent.futures.Future, "result", interrupted)
        with pytest.raises(KeyboardInterrupt):
            meshes.take()
    assert not finished
    threading.Timer(0.2, go.set).start()
    meshes.wait()  # the next frame, before it moves the cut
    assert finished
    monkeypatch.undo()
    np.testing.assert_array_equal(mesh_faces(meshes(cut)), rows(triangulate(h, faces, cut.anc)))
