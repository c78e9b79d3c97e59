"""Hierarchy build, one round of parallel half-edge collapses (SPEC 3; thesis 3.2, figures 5 and 6; tag H-R):
``CollapseRounds``.

A round looks at the whole current mesh at once, with the Warp kernels of ``lodprt.kernels.hierarchy`` on the CPU
(no per-vertex Python loop; the per-vertex and per-collapse passes sliced over the cores by
``lodprt.launches.KernelThreads``): the one-rings and face corners (``one_rings``, ``adjacency``); every movable
vertex ``v`` proposes its cheapest legal move ``v -> u`` (Garland-Heckbert QEM cost of ``u``'s position under the
summed quadrics, plus ``EDGE_WEIGHT |uv|^4``; legal: link condition, valence, boundary rules, fold-over, slivers: docs/HIERARCHY.md);
proposals are ranked by cost class (``cost_class``: within a factor ``CLASS_STEP``), then by a hash of the
position, and taken in that order unless they conflict with a collapse made before them or with a waiting proposal
of a cheaper class (those wait for the next round: the Luby-style maximal independent set within each cost class,
in one pass). Two collapses made in one round never touch each other's collapsed vertex's faces or either one-ring
their legality reads (``CollapseRounds.select``), so they commute (H-R): each was legal on the mesh the other
leaves, and any order of the round's collapses is a valid build order. The vertex arrays are compacted to the live
vertices whenever half of them have gone, so late rounds cost what the small mesh costs.
"""

from __future__ import annotations

import numpy as np

from lodprt.devices import warp
from lodprt.launches import DEVICE, KernelThreads, warp_view
from lodprt.model.hierarchy import distinct_corners

#: a moved face must keep its normal within this cosine of its old one (0 = 90 degrees)
FOLD_COS = 0.0
#: twice a moved face's area below SLIVER x its longest edge squared makes it a degenerate sliver
SLIVER = 1e-3
#: weight of |uv|^4 added to the QEM cost of v -> u: on flat regions (zero quadric error) the shortest edge wins
EDGE_WEIGHT = 1e-3
#: no collapse may leave the survivor with more neighbours (keeps fans and deep chains from forming)
MAX_VALENCE = 24
#: moves whose costs lie within one power of CLASS_STEP are ranked by position hash, not by cost (``cost_class``)
CLASS_STEP = 2.0


#: the removal level of a vertex the seeding decimation never removed (above every phase)
NEVER = np.iinfo(np.int32).max

# the 10 entries of a symmetric 4 x 4 quadric (row, column), upper triangle
QUADRIC_ENTRIES = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))


def position_hash(p: np.ndarray) -> np.ndarray:
    """(n,) uint64 a well-mixed hash of each position's float64 bits (splitmix64 finaliser): a tie-break that is
    deterministic, unbiased on regular grids, and the same whichever other meshes are built alongside."""
    b = np.ascontiguousarray(p, np.float64).view(np.uint64).reshape(-1, 3)
    with np.errstate(over="ignore"):
        h = b[:, 0] * np.uint64(0x9E3779B97F4A7C15) ^ b[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F) ^ b[:, 2]
        h ^= h >> np.uint64(30)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(27)
        h *= np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(31)
    return h


def cost_class(cost: np.ndarray) -> np.ndarray:
    """The priority class of each move's cost: ``floor(log_CLASS_STEP cost)`` (-inf for costs <= 0, which float
    rounding of a zero QEM error can give). Within a class the position hash orders the moves (a random-like order,
    so a round's local minima are dense, not a crawl along a smooth cost field); across classes the cheaper class
    goes first (rule H-R: selection; docs/HIERARCHY.md)."""
    with np.errstate(divide="ignore"):
        return np.floor(np.log(np.maximum(cost, 0.0)) / np.log(CLASS_STEP))


def class_key(cls: np.ndarray) -> np.ndarray:
    """(K,) uint16 the cost classes (``cost_class``) as sort keys, clipped to +-(2^15 - 1) (far beyond the classes
    float64 costs have; -inf, a cost <= 0, sorts first).

    The rank of a move is its class, then the top 48 bits of its position hash ``tie``, then its local id (equal
    keys, e.g. duplicated vertices, keep the order of their local ids, which is the same whichever other groups are
    built alongside): ``CollapseRounds.hash_order`` holds the vertices sorted by the last two once (positions never
    move, compaction keeps the order of local ids), so a round's ranking is one stable sort of the proposals, taken
    in that order, by these keys (a radix sort of 16-bit keys)."""
    return (np.clip(cls, -(2**15) + 1, 2**15 - 1) + 2**15).astype(np.uint16)


def one_rings(faces: np.ndarray, fcount: np.ndarray, threads: "KernelThreads") -> tuple:
    """The face corners and one-rings of ``faces`` (M, 3) int32 (``fcount`` (n,) the faces at each vertex):
    fstart (n + 1,) int64 and corner (3M,) int32, the flat corner indices around each vertex, ascending (a CSR);
    dst (6M,) int32 each vertex's distinct neighbours, ascending, and count (6M,) int32 the faces on each of those
    edges, in a padded CSR: vertex ``v``'s are at ``start[v]:end[v]``, start (n + 1,) int64 twice its corner start,
    end (n,) int64 (``lodprt.kernels.hierarchy``: ``fill_corners``, one thread; ``gather_rings``, sliced over
    ``threads``)."""
    wp = warp()
    from lodprt.kernels import hierarchy as kh

    n, flat = len(fcount), faces.ravel()
    fstart = np.zeros(n + 1, np.int64)
    np.cumsum(fcount, out=fstart[1:])
    corner = np.empty(len(flat), np.int32)
    wfstart, wcorner = warp_view(fstart, wp.int64), warp_view(corner, wp.int32)
    wp.launch(kh.fill_corners, dim=len(flat), device=DEVICE, inputs=[
        warp_view(flat, wp.int32), wfstart, warp_view(np.zeros(n, np.int32), wp.int32), wcorner])
    dst = np.empty(2 * len(flat), np.int32)
    count = np.empty(len(dst), np.int32)
    end = np.empty(n, np.int64)
    threads.launch(kh.gather_rings, n, [warp_view(faces, wp.int32), wfstart, wcorner, warp_view(dst, wp.int32),
                                        warp_view(count, wp.int32), warp_view(end, wp.int64)], work=fstart)
    return fstart, corner, dst, count, 2 * fstart, end


class CollapseRounds:
    """The mutable mesh of the build and its rounds of collapses (module docstring).

    Per live vertex (local ids ``0..n-1``, compacted now and then): ``gid`` original id, ``pos`` (n, 3) float64,
    ``quadric`` (n, 10) float64 (``QUADRIC_ENTRIES``), ``boundary``, ``frozen`` (never a target), ``movable`` (may
    collapse), ``group``, ``node`` the hierarchy node standing there. Faces ``faces`` (M, 3) int32 in local ids,
    never degenerate."""

    def __init__(self, gid, pos, quadric, boundary, frozen, movable, group, faces, split: bool,
                 threads: "KernelThreads | None" = None):
        self.split = split  # whether vertices of different groups may share an edge
        self.gid, self.pos, self.quadric = gid, pos, quadric
        self.boundary, self.frozen, self.movable, self.group = boundary, frozen, movable, group
        self.node = gid.copy()
        self.faces = faces
        self.tie = position_hash(pos)
        # the local ids sorted by the top 48 bits of their hash, equal ones by id: the rank's tie-break (class_key)
        self.hash_order = np.argsort(self.tie >> np.uint64(16), kind="stable").astype(np.int32)
        self.threads = threads if threads is not None else KernelThreads(None)
        self.level = None  # (n,) int32 removal level of a seeded build (``seed``), None for the plain rounds
        self.phase = None  # the level being replayed (None: every movable vertex may move anywhere)
        self.finished = None  # (G,) bool the groups ``finish_groups`` has settled
        self.corners = None  # the round's face corners around each vertex (CSR start, corners), set by ``adjacency``
        self.primed = None  # (faces, one_rings of them) made before the first round (``prime``)

    def seed(self, level: np.ndarray) -> None:
        """Seed the rounds with an external decimation order (``build_hierarchy(method="pymeshlab")``): ``level``
        (n,) int32, the level at which the decimation removed each vertex (``NEVER``: it never did). While
        ``phase`` is a level L, only vertices removed at a level <= L move, and only into vertices that survive
        level L (docs/HIERARCHY.md, "pymeshlab build")."""
        self.level = np.asarray(level, np.int32)

    def due(self) -> np.ndarray:
        """(n,) bool the vertices that may collapse now: movable, and removed by the seed's current phase."""
        if self.phase is None:
            return self.movable
        return self.movable & (self.level <= self.phase)

    @property
    def n(self) -> int:
        return len(self.gid)

    # -----------------------------------------------------------------------------------------------------------
    def compact(self, extra: dict[str, np.ndarray], used: np.ndarray) -> dict[str, np.ndarray]:
        """Keep only the vertices some face uses (``used`` (n,) bool: ``corner_counts() > 0``), renumbered in
        order; ``extra`` per-vertex arrays follow."""
        new = np.cumsum(used, dtype=np.int64).astype(np.int32) - 1
        self.faces = new[self.faces]
        for name in ("gid", "pos", "quadric", "tie", "boundary", "frozen", "movable", "group", "node"):
            setattr(self, name, getattr(self, name)[used])
        self.hash_order = new[self.hash_order[used[self.hash_order]]]  # the same order of the vertices kept
        if self.level is not None:
            self.level = self.level[used]
        return {k: a[used] for k, a in extra.items()}

    def adjacency(self, fcount: np.ndarray):
        """The one-rings of the current faces (``fcount`` (n,) the faces at each vertex, ``corner_counts``):
        ``one_rings``'s dst, count, start and end; its corners stay in ``corners`` for the round. The rings
        ``prime`` handed over are used when the faces are still the ones they were made of."""
        if self.primed is not None and self.primed[0] is self.faces:
            fstart, corner, dst, count, start, end = self.primed[1]
        else:
            fstart, corner, dst, count, start, end = one_rings(self.faces, fcount, self.threads)
        self.primed = None
        self.corners = (fstart, corner)
        return dst, count, start, end

    def prime(self, rings: tuple) -> None:
        """Hand over ``one_rings(self.faces, ...)``, made already (the topology's), for the first round."""
        self.primed = (self.faces, rings)

    def corner_counts(self) -> np.ndarray:
        """(n,) int64 the faces at each vertex (0: no face uses it any more)."""
        return np.bincount(self.faces.ravel(), minlength=self.n)

    # -----------------------------------------------------------------------------------------------------------
    def select(self, dst, count, start, end):
        """This round's collapses: (v, u) local ids (C,) of pairwise independent legal moves, in the order of
        their costs (rule H-R; module docstring), on the round's ``adjacency``.

        Every movable vertex proposes its cheapest legal move (``lodprt.kernels.hierarchy.best_moves``: it never
        holds its neighbours back with a cost it cannot realise). Two collapses ``v -> u`` and ``v' -> u'``
        conflict when ``v'`` is in the closed one-ring of ``v`` or of ``u``, or ``u'`` is in the closed one-ring
        of ``v`` (or the same with the roles swapped): otherwise neither changes the faces around the other's
        ``v``, nor the one-rings of its ``v`` and ``u``, so both stay legal in either order and commute. The
        proposals are taken in rank order (cost class, then position hash; ``greedy_select``): one is made unless
        it conflicts with a collapse made before it or with a waiting proposal of a cheaper class, and waits for
        the next round otherwise. This is the independent set the Luby-style rule "made when its rank is the
        lowest among the live proposals it conflicts with" reaches, so a round makes no collapse only when no
        movable vertex has a legal move."""
        n = self.n
        wp = warp()
        from lodprt.kernels import hierarchy as kh

        best = np.empty(n, np.int64)
        cost = np.empty(n)
        level = self.level if self.level is not None else np.zeros(n, np.int32)
        phase = -1 if self.phase is None else int(self.phase)
        self.threads.launch(kh.best_moves, n, [
            warp_view(self.pos, wp.float64), warp_view(self.quadric, wp.float64), warp_view(self.faces, wp.int32),
            warp_view(self.due(), wp.uint8), warp_view(self.frozen, wp.uint8), warp_view(self.boundary, wp.uint8),
            warp_view(self.group, wp.int32), warp_view(level, wp.int32), phase, int(self.split), warp_view(start, wp.int64),
            warp_view(end, wp.int64), warp_view(dst, wp.int32), warp_view(count, wp.int32), warp_view(self.corners[0], wp.int64),
            warp_view(self.corners[1], wp.int32), EDGE_WEIGHT, FOLD_COS, SLIVER, MAX_VALENCE,
            warp_view(np.empty(len(dst)), wp.float64), warp_view(best, wp.int64), warp_view(cost, wp.float64)],
            work=self.corners[0])
        lv = self.hash_order[best[self.hash_order] >= 0]  # the proposals, in position-hash order (``class_key``)
        if not len(lv):
            return np.zeros(0, np.int32), np.zeros(0, np.int32)
        target = np.full(n, -1, np.int32)
        target[lv] = dst[best[lv]]
        cls = np.full(n, np.inf)
        cls[lv] = cost_class(cost[lv])
        order = lv[np.argsort(class_key(cls[lv]), kind="stable")].astype(np.int32)
        made = np.zeros(len(order), np.uint8)
        wp.launch(kh.greedy_select, dim=1, device=DEVICE, inputs=[
            warp_view(order, wp.int32), warp_view(target, wp.int32), warp_view(cls, wp.float64), warp_view(start, wp.int64),
            warp_view(end, wp.int64), warp_view(dst, wp.int32), warp_view(np.zeros(n, np.uint8), wp.uint8),
            warp_view(np.zeros(n, np.uint8), wp.uint8), warp_view(np.full(n, np.inf), wp.float64),
            warp_view(np.full(n, np.inf), wp.float64), warp_view(made, wp.uint8)])
        v = order[made.view(bool)]
        o = np.lexsort((self.tie[v], cost[v]))
        return v[o], target[v[o]]

    def errors(self, v, u) -> np.ndarray:
        """Figure 10: (C, 3) float64 ``p_v - p'`` for this round's collapses ``v -> u`` (before ``apply``), ``p'``
        the closest point to ``v``'s position on the faces around ``u`` right after the collapse (zero when none)."""
        wp = warp()
        from lodprt.kernels import hierarchy as kh

        out = np.zeros((len(v), 3))
        self.threads.launch(kh.collapse_errors, len(v), [
            warp_view(self.pos, wp.float64), warp_view(self.faces, wp.int32), warp_view(self.corners[0], wp.int64),
            warp_view(self.corners[1], wp.int32), warp_view(v, wp.int32), warp_view(u, wp.int32), warp_view(out, wp.float64)])
        return out

    # -----------------------------------------------------------------------------------------------------------
    def apply(self, v, u) -> None:
        """Make the independent collapses ``v -> u`` (local ids): faces on ``uv`` vanish, the others around ``v``
        move to ``u``, quadrics add up."""
        to = np.arange(self.n, dtype=np.int32)
        to[v] = u
        f = to[self.faces]
        self.faces = f[distinct_corners(f)]
        wp = warp()
        from lodprt.kernels import hierarchy as kh

        # Q_u += Q_v (the u and v of one round are all distinct; ``merge_quadrics``)
        self.threads.launch(kh.merge_quadrics, len(v), [warp_view(v, wp.int32), warp_view(u, wp.int32),
                                                         warp_view(self.quadric, wp.float64)])
        self.movable[v] = False
        self.corners = None

    def finish_groups(self, target_base: int) -> None:
        """Groups with at most ``target_base`` faces left stop moving; their faces leave the working mesh once
        no moving vertex uses them."""
        if not len(self.faces):
            return
        G = int(self.group.max()) + 1
        nf = np.bincount(self.group[self.faces[:, 0]], minlength=G)
        done = nf <= target_base
        if self.finished is not None and len(self.finished) == G and not (done & ~self.finished).any():
            return  # no group newly done: the faces and vertices were settled already
        self.finished = done
        if done.any():
            self.movable &= ~done[self.group]
            gf = done[self.group[self.faces]]
            self.faces = self.faces[~gf.all(1)]
