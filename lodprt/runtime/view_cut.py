"""View-dependent cut (SPEC 3 and 5; thesis 3.2, 3.4.2; D-5; seed 003 section 5, table 5.1): ``Cut``, a front of
active nodes of the vertex hierarchy, moved by single or batched splits and collapses under the El-Sana & Varshney
dependency rules, with forced refinement, and triangulated through the active ancestors. Rules and batching:
docs/HIERARCHY.md, docs/RUNTIME.md.
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model.hierarchy import Hierarchy, active_ancestors, concat_ranges, triangulate
from lodprt.runtime.device_inputs import host_array
from lodprt.runtime.node_bounds import leaf_rings


def leaf_order_adjacency(h: Hierarchy, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The original mesh's edges in CSR, rows in depth-first leaf order (so a subtree's edges are one slice), each
    row's neighbours ascending: (neighbours (E,) int32, offsets (V + 1,) int64). The rows of
    ``node_bounds.leaf_rings`` (every edge once per direction, by vertex) put in leaf order."""
    V = h.num_vertices
    v, q, _ = leaf_rings(faces)
    count = np.bincount(v, minlength=V)[:V]
    first = np.zeros(V + 1, np.int64)
    np.cumsum(count, out=first[1:])
    ptr = np.zeros(V + 1, np.int64)
    np.cumsum(count[h.leaf_order], out=ptr[1:])
    lo = first[h.leaf_order]
    return q[concat_ranges(lo, lo + count[h.leaf_order])], ptr


class Cut:
    """A front of active nodes: every original vertex has exactly one active ancestor-or-self.

    ``active`` (N,) bool; ``anc`` (V,) int32 each original vertex's active node (change them through the methods:
    ``nodes`` is kept between moves). ``refine``/``coarsen`` apply the
    El-Sana & Varshney rules (docs/HIERARCHY.md) and return False, changing nothing, when a rule forbids the step;
    they raise LodprtError for a node id that does not exist. Their cost follows the node's subtree (its leaves
    are one slice of a depth-first order, their original edges one slice of a CSR table), never the mesh.
    """

    def __init__(self, hierarchy: Hierarchy, faces: np.ndarray, active: np.ndarray):
        self.h = hierarchy
        V = hierarchy.num_vertices
        faces = np.asarray(faces)
        if faces.ndim != 2 or faces.shape[1] != 3 or (len(faces) and (faces.min() < 0 or faces.max() >= V)):
            raise LodprtError(f"Cut: faces must be (F, 3) indices into the hierarchy's {V} vertices")
        self.faces = np.ascontiguousarray(faces, np.int32)
        self.active = np.asarray(active, bool).copy()
        self._nbr, self._ptr = leaf_order_adjacency(hierarchy, self.faces)
        self.anc = np.ascontiguousarray(active_ancestors(hierarchy, self.active), np.int32)
        self._dev: dict = {}  # per Warp device: the arrays of the sequential kernels (``_device_arrays``)
        self._active_nodes: np.ndarray | None = None  # ``nodes`` until the cut moves (``moved``)

    @classmethod
    def full(cls, hierarchy: Hierarchy, faces) -> "Cut":
        """The cut of all leaves: the original mesh."""
        a = np.zeros(hierarchy.num_nodes, bool)
        a[: hierarchy.num_vertices] = True
        return cls(hierarchy, faces, a)

    @classmethod
    def base(cls, hierarchy: Hierarchy, faces) -> "Cut":
        """The cut of all roots: the base mesh (plus isolated vertices)."""
        a = np.zeros(hierarchy.num_nodes, bool)
        a[hierarchy.roots] = True
        return cls(hierarchy, faces, a)

    @property
    def leaf_adjacency(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The original edges as (vertex of each row (V,) int32 = the leaf order, offsets (V+1,) int64, neighbours
        (E,) int32): ``node_bounds.vertex_adjacency``'s edges, rows in leaf order (shared, not copied)."""
        return self.h.leaf_order, self._ptr, self._nbr

    @property
    def edge_offsets(self) -> np.ndarray:
        """(V+1,) int64 CSR offsets of the original edges, rows in depth-first leaf order: the edges leaving the
        leaves of node ``k`` are entries ``edge_offsets[leaf_range[k, 0]]:edge_offsets[leaf_range[k, 1]]``."""
        return self._ptr

    @property
    def nodes(self) -> np.ndarray:
        """(A,) int32 the active nodes, ascending (read-only: kept until the cut moves, a frame asks for it several
        times)."""
        nodes = self._active_nodes
        if nodes is None:
            nodes = np.flatnonzero(self.active).astype(np.int32)
            nodes.flags.writeable = False
            self._active_nodes = nodes
        return nodes

    def moved(self) -> None:
        """The cut's ``active`` changed: ``nodes`` is found again when next asked for (every method that moves the
        cut calls it)."""
        self._active_nodes = None

    def _check(self, node: int) -> int:
        node = int(node)
        if not 0 <= node < self.h.num_nodes:
            raise LodprtError(f"node {node} does not exist (the hierarchy has {self.h.num_nodes} nodes)")
        return node

    def neighbours(self, node: int) -> np.ndarray:
        """(K,) int32 active nodes adjacent to ``node`` in the cut's mesh (an inactive node: its leaves' active
        neighbours), i.e. the active ancestors of the original neighbours of its leaves, itself excluded."""
        lo, hi = self.h.leaf_range[self._check(node)]
        n = np.unique(self.anc[self._nbr[self._ptr[lo] : self._ptr[hi]]])
        return n[n != node]

    def blockers_of_refine(self, node: int) -> np.ndarray:
        """Active neighbours that forbid splitting ``node``: created after it (El-Sana & Varshney, thesis 3.2)."""
        nb = self.neighbours(node)
        return nb[self.h.creation[nb] > self.h.creation[node]]

    def can_refine(self, node: int) -> bool:
        """Split rule: ``node`` active and internal, every active neighbour created before it."""
        h = self.h
        node = self._check(node)
        if not self.active[node] or h.children[node, 0] < 0:
            return False
        return bool((h.creation[self.neighbours(node)] < h.creation[node]).all())

    def can_coarsen(self, node: int) -> bool:
        """Collapse rule: both children of ``node`` active, every active neighbour of theirs has a parent created
        after ``node`` (a root's missing parent counts as later)."""
        node = self._check(node)
        c0 = self.h.children[node, 0]
        if c0 < 0 or not (self.active[c0] and self.active[self.h.children[node, 1]]):
            return False
        return not len(self.blockers_of_coarsen(node))

    def blockers_of_coarsen(self, node: int) -> np.ndarray:
        """Active neighbours of ``node``'s two active children that forbid collapsing them into ``node``: their
        parent was created no later than ``node`` (empty when the collapse is allowed or the children are not
        both active). The children's leaves are ``node``'s leaves: one slice, one pass."""
        h = self.h
        node = self._check(node)
        c0, c1 = h.children[node]
        if c0 < 0 or not (self.active[c0] and self.active[c1]):
            return np.zeros(0, np.int32)
        lo, hi = h.leaf_range[node]
        nb = np.unique(self.anc[self._nbr[self._ptr[lo] : self._ptr[hi]]])
        nb = nb[(nb != c0) & (nb != c1)]
        par = h.parent[nb]
        later = np.where(par < 0, np.iinfo(np.int32).max, h.creation[np.maximum(par, 0)])
        return nb[later <= h.creation[node]].astype(np.int32)

    def try_coarsen(self, node: int) -> np.ndarray:
        """Collapse the children of ``node`` when allowed; returns the blockers (empty: it collapsed, or there was
        nothing to collapse because the children are not both active)."""
        h = self.h
        node = self._check(node)
        c0, c1 = h.children[node]
        if c0 < 0 or not (self.active[c0] and self.active[c1]):
            return np.zeros(0, np.int32)
        b = self.blockers_of_coarsen(node)
        if not len(b):
            self._collapse(node)
        return b

    def refine(self, node: int) -> bool:
        """Split ``node`` into its two children when the split rule allows; returns whether it did."""
        if not self.can_refine(node):
            return False
        c0, c1 = self.h.children[node]
        self.moved()
        self.active[node] = False
        self.active[c0] = self.active[c1] = True
        for c in (c0, c1):
            lo, hi = self.h.leaf_range[c]
            self.anc[self.h.leaf_order[lo:hi]] = c
        return True

    def coarsen(self, node: int) -> bool:
        """Collapse the two active children of ``node`` into it when the collapse rule allows; returns whether
        it did."""
        if not self.can_coarsen(node):
            return False
        self._collapse(node)
        return True

    def _collapse(self, node: int) -> None:
        c0, c1 = self.h.children[node]
        self.moved()
        self.active[c0] = self.active[c1] = False
        self.active[node] = True
        lo, hi = self.h.leaf_range[node]
        self.anc[self.h.leaf_order[lo:hi]] = node

    def _edge_segments(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For many nodes at once: (seg, nb) the index into ``nodes`` and the active node at the far end of every
        original edge leaving the nodes' leaves (one CSR slice per node, concatenated)."""
        lr = self.h.leaf_range[nodes]
        lo, hi = self._ptr[lr[:, 0]], self._ptr[lr[:, 1]]
        return np.repeat(np.arange(len(nodes)), hi - lo), self.anc[self._nbr[concat_ranges(lo, hi)]]

    def _set_leaves(self, nodes: np.ndarray) -> None:
        """anc of every leaf under each of ``nodes`` becomes that node (vectorised over the nodes' slices)."""
        lr = self.h.leaf_range[nodes]
        self.anc[self.h.leaf_order[concat_ranges(lr[:, 0], lr[:, 1])]] = np.repeat(nodes, lr[:, 1] - lr[:, 0])

    def _split(self, nodes: np.ndarray) -> None:
        """Make the children of ``nodes`` active in their place (no rule checked: the callers did)."""
        ch = self.h.children[nodes].ravel()
        self.moved()
        self.active[nodes] = False
        self.active[ch] = True
        self._set_leaves(ch)

    def refine_many(self, nodes) -> np.ndarray:
        """Split every node of ``nodes`` whose split rule holds now, all at once; returns the (K,) bool mask of the
        nodes split. Simultaneous splits stay legal: a split only replaces a node by children created before it,
        so a neighbour's rule (every active neighbour created before it) still holds afterwards."""
        h = self.h
        nodes = np.asarray(nodes, np.int64)
        ok = self.active[nodes] & (h.children[nodes, 0] >= 0)
        cand = nodes[ok]
        if len(cand):
            seg, nb = self._edge_segments(cand)
            bad = (nb != cand[seg]) & (h.creation[nb] > h.creation[cand[seg]])
            legal = np.bincount(seg[bad], minlength=len(cand)) == 0
            self._split(cand[legal])
            ok[np.flatnonzero(ok)[~legal]] = False
        return ok

    def coarsen_many(self, nodes) -> tuple[np.ndarray, np.ndarray]:
        """Collapse the children of every node of ``nodes`` whose collapse rule holds now, all at once; returns
        (done (K,) bool, blocker (K,) int64: one active neighbour forbidding the collapse, -1 where none). Two
        collapses that are both allowed never touch each other (if their children were adjacent, each rule would
        need the other parent created later), so doing them together is legal."""
        h = self.h
        nodes = np.asarray(nodes, np.int64)
        c = h.children[nodes]
        ok = (c[:, 0] >= 0) & self.active[np.maximum(c[:, 0], 0)] & self.active[np.maximum(c[:, 1], 0)]
        blocker = np.full(len(nodes), -1, np.int64)
        cand = nodes[ok]
        if len(cand):
            seg, nb = self._edge_segments(cand)
            cc = h.children[cand[seg]]
            par = h.parent[nb]
            later = np.where(par < 0, np.iinfo(np.int64).max, h.creation[np.maximum(par, 0)].astype(np.int64))
            bad = (nb != cc[:, 0]) & (nb != cc[:, 1]) & (later <= h.creation[cand[seg]])
            legal = np.bincount(seg[bad], minlength=len(cand)) == 0
            first = np.full(len(cand), -1, np.int64)
            first[seg[bad][::-1]] = nb[bad][::-1]  # the first blocker of each node
            go = cand[legal]
            ch = h.children[go]
            self.moved()
            self.active[ch.ravel()] = False
            self.active[go] = True
            self._set_leaves(go)
            where = np.flatnonzero(ok)
            blocker[where] = first
            ok[where[~legal]] = False
        return ok, blocker

    def force_refine_many(self, nodes, *, max_rounds: int | None = None) -> int:
        """Forced refinement of many active nodes at once (seed 003, table 5.1): rounds that split every node of
        the set whose split rule holds (as ``refine_many``) and add to the set the active neighbours that block
        the others (created later, so coarser). A blocked node remembers one blocker and is looked at again only
        once that blocker has been split, so a large subtree is not rescanned every round. Each round splits at
        least the latest-created node of the set (its neighbours are all older). ``max_rounds`` stops early (the
        cut is legal after every round; what is left can be forced later). Returns the number of splits."""
        h = self.h
        want = np.unique(np.asarray(nodes, np.int64))
        want = want[self.active[want] & (h.children[want, 0] >= 0)]
        rep = np.full(len(want), -1, np.int64)  # a blocker seen last time (-1: look now)
        splits = rounds = 0
        while len(want) and (max_rounds is None or rounds < max_rounds):
            rounds += 1
            look = (rep < 0) | ~self.active[np.maximum(rep, 0)]
            scan = want[look]
            seg, nb = self._edge_segments(scan)
            bad = (nb != scan[seg]) & (h.creation[nb] > h.creation[scan[seg]])
            legal = np.bincount(seg[bad], minlength=len(scan)) == 0
            go = scan[legal]
            self._split(go)
            splits += len(go)
            first = np.full(len(scan), -1, np.int64)
            first[seg[bad][::-1]] = nb[bad][::-1]
            rep[look] = first
            keep = self.active[want]
            want, rep = want[keep], rep[keep]
            new = np.setdiff1d(np.unique(nb[bad]), want)
            new = new[self.active[new]]  # a blocker split this round is gone; its children show up when looked at
            want = np.concatenate([want, new])
            rep = np.concatenate([rep, np.full(len(new), -1, np.int64)])
            if not len(go) and not len(new) and not ((rep < 0) | ~self.active[np.maximum(rep, 0)]).any():
                for k in want:  # cannot happen for a valid cut: fall back to one at a time
                    splits += self.force_refine(int(k))
                break
        return splits

    def force_refine(self, node: int) -> int:
        """Make ``node``'s split happen (seed 003, table 5.1 forced refinement): activate it by splitting its
        active ancestor down to it, each split first splitting, recursively, every neighbour the split rule needs
        split. Returns the number of splits made (0 when ``node`` is already split). Raises LodprtError for a
        leaf (nothing to split)."""
        h = self.h
        node = self._check(node)
        if h.children[node, 0] < 0:
            raise LodprtError(f"node {node} is a leaf: nothing to split")
        splits = 0
        if not self.active[node]:
            a = int(self.anc[h.leaves(node)[0]])
            if h.creation[a] < h.creation[node]:
                return 0  # a descendant is active: node is already split
            path = []
            k = node
            while k != a:
                k = int(h.parent[k])
                path.append(k)
            for k in path[::-1]:  # from the active ancestor down to node's parent
                splits += self._force_split(k)
        return splits + self._force_split(node)

    def _force_split(self, node: int) -> int:
        stack = [node]
        splits = 0
        while stack:
            k = stack[-1]
            if not self.active[k]:
                stack.pop()
                continue
            blockers = self.blockers_of_refine(k)
            if len(blockers):  # coarser neighbours first; their creation numbers grow, so this ends
                stack.extend(int(b) for b in blockers)
                continue
            if not self.refine(k):
                raise LodprtError(f"forced refinement of node {k} failed")  # cannot happen: rule checked above
            splits += 1
            stack.pop()
        return splits

    # -- sequential kernels (``lodprt.kernels.view_cut``): the frame loop's moves -----------------------------------
    def _device_arrays(self, device: str) -> dict:
        """The hierarchy, the edge table and the cut's state as Warp arrays on ``device``, made once. On the CPU
        ``active`` and ``anc`` alias this cut's numpy arrays; elsewhere they are copied over and back per call."""
        if device not in self._dev:
            from lodprt.devices import warp

            wp = warp()
            h = self.h
            # read-only inputs: on the CPU they wrap the arrays already held (no second copy, docs/SCALE.md)
            i32 = lambda a: wp.array(np.ascontiguousarray(a, np.int32), dtype=wp.int32, device=device,  # noqa: E731
                                     copy=device != "cpu")
            i2 = lambda a: wp.array(np.ascontiguousarray(a, np.int32), dtype=wp.int32, ndim=2, device=device,  # noqa: E731
                                    copy=device != "cpu")
            i64 = lambda a, ndim: wp.array(np.ascontiguousarray(a, np.int64), dtype=wp.int64, ndim=ndim,  # noqa: E731
                                           device=device, copy=device != "cpu")
            d = {"children": i2(h.children), "parent": i32(h.parent), "creation": i32(h.creation),
                 "leaf_order": i32(h.leaf_order), "leaf_range": i64(h.leaf_range, 2), "edge_ptr": i64(self._ptr, 1),
                 "edge_nbr": i32(self._nbr), "stack": wp.empty(max(h.num_nodes, 1), dtype=wp.int32, device=device),
                 "result": wp.zeros(3, dtype=wp.int32, device=device)}
            if device == "cpu":
                d["active"] = wp.array(self.active.view(np.uint8), dtype=wp.uint8, device=device, copy=False)
                d["anc"] = wp.array(self.anc, dtype=wp.int32, device=device, copy=False)
            self._dev[device] = d
        d = self._dev[device]
        if device != "cpu":
            from lodprt.devices import warp

            wp = warp()
            d["active"] = wp.array(self.active.view(np.uint8), dtype=wp.uint8, device=device)
            d["anc"] = wp.array(self.anc, dtype=wp.int32, device=device)
        return d

    def _device_back(self, d: dict, device: str) -> None:
        self.moved()  # the sequential kernels moved the cut (in place on the CPU)
        if device != "cpu":
            self.active.view(np.uint8)[:] = d["active"].numpy()
            self.anc[:] = d["anc"].numpy()

    def coarsen_list(self, nodes, *, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
        """Collapse the children of each node of ``nodes`` in turn where the collapse rule holds at that moment
        (``lodprt.kernels.view_cut.coarsen_list``, one thread); returns (done (K,) bool, blocker (K,) int64: an
        active neighbour forbidding the collapse, -1 where none). Like ``coarsen_many`` but sequential: a collapse
        may enable or forbid the next, and every step is checked against the cut as it is then."""
        from lodprt.devices import warp
        from lodprt.kernels import view_cut as kv

        wp = warp()
        nodes = self._node_list(nodes)
        K = len(nodes)
        if not K:
            return np.zeros(0, bool), np.zeros(0, np.int64)
        d = self._device_arrays(device)
        done = wp.zeros(K, dtype=wp.uint8, device=device)
        blocker = wp.zeros(K, dtype=wp.int32, device=device)
        wp.launch(kv.coarsen_list, dim=1, inputs=[
            host_array(nodes, np.int32, wp.int32, device), d["children"], d["parent"], d["creation"],
            d["leaf_order"], d["leaf_range"], d["edge_ptr"], d["edge_nbr"], d["active"], d["anc"]],
            outputs=[done, blocker], device=device)
        self._device_back(d, device)
        return done.numpy().astype(bool), blocker.numpy().astype(np.int64)

    def force_refine_list(self, nodes, *, max_splits: int | None = None, device: str = "cpu") -> int:
        """Forced refinement of each node of ``nodes`` in turn (seed 003 table 5.1; ``lodprt.kernels.view_cut.
        force_refine_list``, one thread): a node still active and internal is split, its coarser blocking
        neighbours first, recursively. ``max_splits`` stops taking new nodes once that many splits are made (the
        rest can be forced later: the cut is legal after every split). Returns the number of splits."""
        from lodprt.devices import warp
        from lodprt.kernels import view_cut as kv

        wp = warp()
        nodes = self._node_list(nodes)
        if not len(nodes):
            return 0
        d = self._device_arrays(device)
        wp.launch(kv.force_refine_list, dim=1, inputs=[
            host_array(nodes, np.int32, wp.int32, device), -1 if max_splits is None else int(max_splits),
            d["children"], d["creation"], d["leaf_order"], d["leaf_range"], d["edge_ptr"], d["edge_nbr"],
            d["active"], d["anc"], d["stack"]], outputs=[d["result"]], device=device)
        self._device_back(d, device)
        splits, _, overflow = d["result"].numpy().tolist()
        if overflow:  # cannot happen: the stack holds as many nodes as the hierarchy
            raise LodprtError("forced refinement: the dependency chain outgrew its stack")
        return int(splits)

    def _node_list(self, nodes) -> np.ndarray:
        nodes = np.asarray(nodes, np.int64).ravel()
        if len(nodes) and (nodes.min() < 0 or nodes.max() >= self.h.num_nodes):
            bad = nodes[(nodes < 0) | (nodes >= self.h.num_nodes)][0]
            raise LodprtError(f"node {int(bad)} does not exist (the hierarchy has {self.h.num_nodes} nodes)")
        return nodes.astype(np.int32)

    def triangles(self, *, return_index: bool = False):
        """Faces of the cut's mesh in original vertex ids (vertex of each active ancestor), degenerate ones
        dropped; with ``return_index`` also the original face of each."""
        return triangulate(self.h, self.faces, self.anc, return_index=return_index)
