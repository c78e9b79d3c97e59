"""How the run time moves the view cut from frame to frame (docs/RUNTIME.md, temporal coherence): ``ErrorCache``
decides when a candidate node's error (T-13 culling; S-1/S-2 or T-14, from ``Runtime.node_errors``) is evaluated
again, and ``CutRefinement`` makes the refine/coarsen passes over the cut's candidates until it settles
(``lodprt.runtime.view_cut.Cut``'s sequential kernels make each move legal).
"""

from __future__ import annotations

import numpy as np

#: splits per pass after the first frame: the most wanted nodes (largest error) are forced first, the rest wait for
#: the next frame, so that no frame stalls on a burst of refinement (the first frame converges in full)
FRAME_SPLITS = 4096
#: a candidate whose cached error is far from the bound (outside [bound / NEAR, bound * NEAR]) is evaluated again
#: every REFRESH_FRAMES frames (a rotating slice each frame); nearer ones, new ones and every node after a jump of
#: the camera or the lights (``refresh_all``) are evaluated every frame
REFRESH_FRAMES = 4
NEAR = 2.0
#: a node is collapsed only when its error is at most bound / HYSTERESIS (and split above the bound): a node near
#: the bound does not flip every frame as the camera moves, which would cost collapses, splits and retriangulation
HYSTERESIS = 1.25
#: a failed collapse of a node with more original edges under it than this backs off for a few frames
BACKOFF_EDGES = 20_000


class ErrorCache:
    """When to refresh errors: per node, culled, error and the frame they belong to. Errors depend on the frame's
    camera and lights only, so each node is evaluated at most once a frame, and, once the cut has converged and
    with no jump since (``refresh_all`` False), one far from the bound only every REFRESH_FRAMES frames."""

    def __init__(self, num_nodes: int):
        self.frame = 0
        self.culled = np.zeros(num_nodes, bool)
        self.err = np.zeros(num_nodes, np.float32)  # the kernel's float32 errors (4 bytes a node: docs/SCALE.md)
        self.stamp = np.full(num_nodes, -1, np.int32)
        self.refresh_all = True  # the next frame evaluates every candidate (set by jumps and new bounds)

    def forget(self) -> None:
        """Evaluate every candidate again, this frame's too (the kernel stops adding terms once a node's error is
        over the bound, so an error cached under a much lower bound may be short of the node's error under a
        higher one: E-5 moves the bound to the coarsest and back)."""
        self.stamp[:] = -1
        self.refresh_all = True

    def lookup(self, nodes: np.ndarray, bound: float, evaluate, coherent: bool) -> tuple[np.ndarray, np.ndarray]:
        """(culled, error) of ``nodes``, evaluating (``evaluate(nodes) -> (culled, error)``) those due this frame:
        all not evaluated this frame, or with ``coherent`` (converged, no jump) only the new, the stale, this
        frame's slice and the ones near ``bound``."""
        fresh = self.stamp[nodes] != self.frame
        if coherent and not self.refresh_all:
            e = self.err[nodes]
            due = (self.stamp[nodes] < 0) | (self.frame - self.stamp[nodes] >= REFRESH_FRAMES)
            due |= (nodes + self.frame) % REFRESH_FRAMES == 0
            due |= ~self.culled[nodes] & (e * NEAR > bound) & (e < bound * NEAR)
            fresh &= due
        if fresh.any():
            new = nodes[fresh]
            c, e = evaluate(new)
            self.culled[new], self.err[new], self.stamp[new] = c, e, self.frame
        return self.culled[nodes], self.err[nodes].astype(np.float64)


class CutRefinement:
    """How to move the cut: refine/coarsen passes over its candidates (split above the bound, collapse at or
    below bound / HYSTERESIS), with the state that carries over frames (blocked collapses, back-off)."""

    def __init__(self, h, cut, device: str, max_passes: int):
        self.h, self.cut, self.device, self.max_passes = h, cut, device, int(max_passes)
        self.blocker = np.full(h.num_nodes, -1, np.int32)  # a finer neighbour that blocked this collapse
        self.fails = np.zeros(h.num_nodes, np.int8)  # failed collapses in a row, and when to try again
        lr = h.leaf_range
        edges = cut.edge_offsets[lr[:, 1]] - cut.edge_offsets[lr[:, 0]]
        self.subtree_edges = edges.astype(np.int32) if len(edges) and edges.max() < 2**31 else edges
        self.retry_at = np.zeros(h.num_nodes, np.int32)
        self.converged_once = False
        self.dirty, self.settled = True, False  # something changed since the cut settled; it has settled
        #: (N,) errors that add to the criterion's this frame (M-6: the actual light's shadow edges), or None
        self.extra: np.ndarray | None = None
        self.extra_nodes: np.ndarray | None = None  # where ``set_extra`` last wrote it
        #: (N,) nodes kept split whatever their error (E-5: where a still frame's measured error is), and how many
        self.pinned, self.pins = np.zeros(h.num_nodes, bool), 0
        #: (N,) M-7: the error each node was split for at this view, these lights and this criterion (0: none); the
        #: coarsen test reads at least it. ``split_nodes``: where it is set (cleared there only: a moving camera
        #: forgets every frame, and a memset of every node would cost a big scene's frame)
        self.split_for, self.split_nodes = np.zeros(h.num_nodes, np.float32), []

    def reset(self, cut) -> None:
        """Start again from ``cut`` (LOD switched): the first frame converges in full."""
        self.cut = cut
        self.converged_once = False
        self.blocker[:] = -1
        self.fails[:] = 0
        self.retry_at[:] = 0
        self.pin(None)

    def forget_splits(self) -> None:
        """M-7: the camera, the lights or the criterion (its bound, alpha) moved, or E-5 starts again: the errors
        the nodes were split for no longer hold."""
        if self.split_nodes:
            self.split_for[np.concatenate(self.split_nodes)] = 0.0
            self.split_nodes = []

    def set_extra(self, nodes: np.ndarray, err: np.ndarray) -> None:
        """``extra`` this frame: ``err`` at ``nodes``, 0 elsewhere (only the last frame's nodes are cleared)."""
        if self.extra is None or len(self.extra) != self.h.num_nodes:
            self.extra, self.extra_nodes = np.zeros(self.h.num_nodes, np.float32), None
        if self.extra_nodes is not None:
            self.extra[self.extra_nodes] = 0.0
        self.extra[nodes] = err
        self.extra_nodes = np.asarray(nodes, np.int64)

    def pin(self, nodes: np.ndarray | None) -> None:
        """E-5: keep ``nodes`` split from now on (None: pin none any more); the cut moves again."""
        if nodes is None:
            self.pinned[:] = False
            self.forget_splits()
        else:
            self.pinned[nodes] = True
        self.pins = int(self.pinned.sum()) if nodes is not None else 0
        self.dirty = True

    def one_pass(self, errors: ErrorCache, evaluate, bound: float, *, backoff: bool = False) -> tuple[int, int, int]:
        """One refinement pass over the candidate lists; returns (refined, coarsened, nodes touched). With
        ``backoff``, a failed collapse of a node whose subtree has more than BACKOFF_EDGES original edges is not
        tried again for 2, 4, ... 32 frames (a try scans them all); smaller ones are tried again as soon as their
        blocker has gone."""
        h, cut = self.h, self.cut
        V = h.num_vertices
        act = cut.nodes
        rc = act[act >= V]  # Refine-Candidates
        par = h.parent[act]
        first = (par >= 0) & (h.children[np.maximum(par, 0), 0] == act)  # each parent once, through its child 0
        par = par[first]
        cc = par[cut.active[h.children[par, 1]]]  # Coarsen-Candidates: both children active
        nodes = np.concatenate([rc, cc])
        if not len(nodes):
            return 0, 0, 0
        culled, err = errors.lookup(nodes, bound, evaluate, self.converged_once)
        if self.extra is not None:  # M-6: a node at the actual light's shadow edge refines, its parent stays split
            err = np.maximum(err, self.extra[nodes])
        k, frame = len(rc), errors.frame
        own = err[:k]  # the refine candidates' own errors (pins aside): what a split is made for (M-7)
        err = np.concatenate([own, np.maximum(err[k:], self.split_for[cc])])  # M-7: at least what it was split for
        err = np.where(self.pinned[nodes], np.inf, err)  # E-5: a pinned node refines, and never collapses
        want_refine = (~culled[:k] | self.pinned[rc]) & (err[:k] > bound)  # E-5: a pinned node's pixels were seen
        want_coarsen = (culled[k:] & ~self.pinned[cc]) | (err[k:] * HYSTERESIS <= bound)
        refined = coarsened = touched = 0
        # a collapse found blocked waits until the finer neighbour found blocking it is gone (one per node);
        # collapses, then forced splits, are made in turn by the sequential kernels (Cut.coarsen_list /
        # force_refine_list), each checked against the cut as it is then
        todo = cc[want_coarsen]
        blk = self.blocker[todo]
        todo = todo[(blk < 0) | ~cut.active[np.maximum(blk, 0)]]
        if backoff:
            todo = todo[self.retry_at[todo] <= frame]
        touched += len(todo)
        if len(todo):
            done, blocker = cut.coarsen_list(todo, device=self.device)
            self.blocker[todo] = np.where(done, -1, blocker)
            big = self.subtree_edges[todo] > BACKOFF_EDGES
            self.fails[todo] = np.where(done | ~big, 0, np.minimum(self.fails[todo] + 1, 5))
            self.retry_at[todo] = frame + np.where(done | ~big, 0, 2 ** self.fails[todo].astype(np.int64))
            coarsened += int(done.sum())
        order = np.argsort(-err[:k][want_refine], kind="stable")
        split, split_err = rc[want_refine][order], own[want_refine][order]
        split, split_err = split[cut.active[split]], split_err[cut.active[split]]
        touched += len(split)
        if len(split):  # largest error first; blocked ones forced, their coarser blockers split first
            # once the cut has converged a pass makes at most FRAME_SPLITS splits (the rest wait a frame), so that
            # no frame stalls; the first frame converges in full
            n = cut.force_refine_list(split, max_splits=FRAME_SPLITS if self.converged_once else None,
                                      device=self.device)
            refined += n
            touched += max(n - len(split), 0)
            gone = ~cut.active[split]  # M-7: split now (a forced blocker's split is not recorded: not for its error)
            self.split_for[split[gone]] = np.maximum(self.split_for[split[gone]], split_err[gone])
            self.split_nodes.append(split[gone])
        return refined, coarsened, touched

    def converge(self, errors: ErrorCache, evaluate, bound: float, max_passes: int | None,
                 enabled: bool = True) -> tuple[int, int, int, int]:
        """Refinement passes until the cut settles or ``max_passes`` (default: max_passes after the first frame,
        all it takes before): (refined, coarsened, nodes touched, passes); ``enabled`` False (LOD off) keeps the
        cut."""
        refined = coarsened = touched = passes = 0
        if enabled and (self.dirty or not self.settled):  # nothing changed since a settled cut: keep it
            limit = max_passes if max_passes is not None else (self.max_passes if self.converged_once else 10_000)
            self.settled = False
            for _ in range(int(limit)):
                r, c, t = self.one_pass(errors, evaluate, bound,
                                        backoff=self.converged_once and limit <= self.max_passes)
                passes += 1
                refined, coarsened, touched = refined + r, coarsened + c, touched + t
                if r == 0 and c == 0:
                    self.settled = True
                    break
            self.converged_once = True
            errors.refresh_all = False
        self.dirty = False
        return refined, coarsened, touched, passes
