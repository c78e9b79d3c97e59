"""Hierarchy build, one round of parallel half-edge collapses (SPEC 3; thesis 3.2, figures 5 and 6; tag H-R):
``CollapseRounds``.

A round looks at the whole current mesh at once, vectorised (numpy, no per-vertex Python objects): every movable
vertex ``v`` proposes its cheapest move ``v -> u`` (Garland-Heckbert QEM cost of ``u``'s position under the summed
quadrics, plus ``EDGE_WEIGHT |uv|^4``); proposals are ranked by cost class (``cost_class``: within a factor
``CLASS_STEP``), then by a hash of the position; the proposals that are local minima of that rank among all live
proposals within two edges are checked for legality (link condition, valence, boundary rules, fold-over, slivers:
docs/HIERARCHY.md) and made together. A proposal found illegal checks all its vertex's other moves at once and
competes again with the cheapest legal one; proposals conflicting with a made collapse, or with a waiting proposal
of a cheaper class, wait for the next round; the selection repeats until no proposal is live (a Luby-style maximal
independent set within each cost class). Two collapses made in one round never touch each other's collapsed
vertex's faces or either one-ring their legality reads (``CollapseRounds.select``), so they commute (H-R): each was
legal on the mesh the other leaves, and any order of the round's collapses is a valid build order. The vertex
arrays are compacted to the live vertices whenever half of them have gone, so late rounds cost what the small mesh
costs.
"""

from __future__ import annotations

import numpy as np

from lodprt.model.hierarchy import concat_ranges, vertex_corners

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
#: moves costed at once (bounds the temporaries of a round to a few MB)
CHUNK = 1 << 16

#: the removal level of a vertex the seeding decimation never removed (above every phase)
NEVER = np.iinfo(np.int32).max

# the 10 entries of a symmetric 4 x 4 quadric (row, column), upper triangle
QUADRIC_ENTRIES = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))


def monomials(p: np.ndarray) -> np.ndarray:
    """(K, 10) the terms of ``x^T Q x``, ``x = (p, 1)``, matching ``QUADRIC_ENTRIES`` (off-diagonal ones twice)."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    out = np.empty((len(p), 10))
    out[:, 0], out[:, 1], out[:, 2], out[:, 3] = x * x, 2 * x * y, 2 * x * z, 2 * x
    out[:, 4], out[:, 5], out[:, 6] = y * y, 2 * y * z, 2 * y
    out[:, 7], out[:, 8], out[:, 9] = z * z, 2 * z, 1.0
    return out


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


def rank_key(cls: np.ndarray, tie: np.ndarray) -> np.ndarray:
    """(K,) uint64 sort keys ordering moves by cost class (``cost_class``), then by the position hash ``tie``:
    the class in the top 16 bits (clipped to +-2^15, far beyond the classes float64 costs have), the hash's top 48
    bits below it (one stable sort instead of a two-key lexsort; equal keys, e.g. duplicated vertices, keep the
    order of their local ids, which is the same whichever other groups are built alongside)."""
    c = (np.clip(cls, -(2**15) + 1, 2**15 - 1) + 2**15).astype(np.uint64)
    return (c << np.uint64(48)) | (tie >> np.uint64(16))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (K, 3) arrays (``np.cross`` without its generic set-up)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


class CollapseRounds:
    """The mutable mesh of the build and its rounds of collapses (module docstring).

    Per live vertex (local ids ``0..n-1``, compacted now and then): ``gid`` original id, ``pos`` (n, 3) float64,
    ``quadric`` (n, 10) float64 (``QUADRIC_ENTRIES``), ``boundary``, ``frozen`` (never a target), ``movable`` (may
    collapse), ``group``, ``node`` the hierarchy node standing there. Faces ``faces`` (M, 3) int32 in local ids,
    never degenerate."""

    def __init__(self, gid, pos, quadric, boundary, frozen, movable, group, faces, split: bool):
        self.split = split  # whether vertices of different groups may share an edge
        self.gid, self.pos, self.quadric = gid, pos, quadric
        self.boundary, self.frozen, self.movable, self.group = boundary, frozen, movable, group
        self.node = gid.copy()
        self.faces = faces
        self.tie = position_hash(pos)
        self.level = None  # (n,) int32 removal level of a seeded build (``seed``), None for the plain rounds
        self.phase = None  # the level being replayed (None: every movable vertex may move anywhere)

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
    def compact(self, extra: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Keep only the vertices some face uses (renumbered in order); ``extra`` per-vertex arrays follow."""
        used = np.zeros(self.n, bool)
        used[self.faces.ravel()] = True
        new = np.cumsum(used, dtype=np.int64).astype(np.int32) - 1
        self.faces = new[self.faces]
        for name in ("gid", "pos", "quadric", "tie", "boundary", "frozen", "movable", "group", "node"):
            setattr(self, name, getattr(self, name)[used])
        if self.level is not None:
            self.level = self.level[used]
        return {k: a[used] for k, a in extra.items()}

    def adjacency(self):
        """Directed edges of the current faces, sorted by (source, target): source, target (K,) int32, the number
        of faces on each edge (K,) int32, the CSR start of every vertex (n + 1,) int64 and the sorted keys
        ``source * n + target`` (K,) int64 (for edge look-ups)."""
        f, n = self.faces, self.n
        a = f.ravel().astype(np.int64)
        b = f[:, [1, 2, 0]].ravel().astype(np.int64)
        k = np.concatenate([a * n + b, b * n + a])  # each face counts once in both directions of its edges
        del a, b
        k.sort()
        first = np.empty(len(k), bool)
        first[:1] = True
        np.not_equal(k[1:], k[:-1], out=first[1:])
        at = np.flatnonzero(first)
        count = np.diff(np.append(at, len(k))).astype(np.int32)
        keys = k[at]
        del k, first, at
        src = (keys // n).astype(np.int32)
        dst = (keys - src.astype(np.int64) * n).astype(np.int32)
        start = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(src, minlength=n), out=start[1:])
        return src, dst, count, start, keys

    # -----------------------------------------------------------------------------------------------------------
    def proposals(self, src, dst, count, start):
        """Every movable vertex's possible moves ``v -> u`` with their costs (QEM error of u's position under
        ``Q_v + Q_u``, plus ``EDGE_WEIGHT |uv|^4``). Returns moves (K,) int64 edge indices into the adjacency, in
        vertex order (one segment per vertex, any order within), cost (K,) float64, seg_start (S + 1,) int64 and
        seg_vertex (S,) int32, the vertex of each segment."""
        v, u = src, dst
        ok = self.due()[v]
        ok &= ~self.frozen[u]
        if self.phase is not None:  # a seeded phase L: targets survive level L
            ok &= self.level[u] > self.phase
        if self.split:  # groups split by ``component`` may touch; connected components never do
            ok &= self.group[v] == self.group[u]
        ok &= count == 2 - self.boundary[v]  # boundary vertices move along boundary edges only (one face)
        moves = np.flatnonzero(ok)
        del ok
        mv = v[moves]
        mono = monomials(self.pos)  # per vertex: a move is costed at its target's position
        own = np.einsum("ij,ij->i", self.quadric, mono)  # x_u^T Q_u x_u
        cost = np.empty(len(moves))
        for lo in range(0, len(moves), CHUNK):  # bounded temporaries
            cv, cu = mv[lo : lo + CHUNK], u[moves[lo : lo + CHUNK]]
            c = np.einsum("ij,ij->i", self.quadric[cv], mono[cu])  # x_u^T Q_v x_u
            c += own[cu]
            d2 = ((self.pos[cu] - self.pos[cv]) ** 2).sum(1)
            c += EDGE_WEIGHT * d2 * d2
            cost[lo : lo + CHUNK] = c
        if not len(moves):
            return moves, cost, np.zeros(1, np.int64), np.zeros(0, np.int32)
        brk = np.flatnonzero(mv[1:] != mv[:-1]) + 1
        seg_start = np.concatenate([[0], brk, [len(moves)]]).astype(np.int64)
        return moves, cost, seg_start, mv[seg_start[:-1]]

    @staticmethod
    def cheapest(cost, seg_start, segs):
        """Index (into the moves) of the cheapest remaining move of each segment in ``segs``, -1 when none is
        left (cost inf), and its cost."""
        lo, hi = seg_start[segs], seg_start[segs + 1]
        idx = concat_ranges(lo, hi)
        c = cost[idx]
        m = np.minimum.reduceat(c, np.cumsum(np.r_[0, hi - lo][:-1])) if len(idx) else np.zeros(0)
        seg_of = np.repeat(np.arange(len(segs)), hi - lo)
        hit = np.flatnonzero(c == m[seg_of])
        best = np.full(len(segs), -1, np.int64)
        best[seg_of[hit][::-1]] = idx[hit][::-1]  # the first cheapest move of each segment
        best[~np.isfinite(m)] = -1
        return best, m

    # -----------------------------------------------------------------------------------------------------------
    def legal(self, v, u, e, dst, count, start, keys, around):
        """(K,) bool: which collapses ``v -> u`` (local ids; ``e`` their edge indices; ``around`` the face
        corners of ``hierarchy.vertex_corners``) are legal on the current mesh (docs/HIERARCHY.md): link condition, the
        survivor's valence, no fold-over (thesis figure 6), no sliver. The boundary and component rules hold
        already for every proposal. A vertex may appear in several rows (one per move checked)."""
        n = self.n
        K = len(v)
        deg_v = start[v + 1] - start[v]
        deg_u = start[u + 1] - start[u]
        # link condition: the common neighbours of u and v are exactly the third corners of the faces on uv
        idx = concat_ranges(start[v], start[v + 1])
        row = np.repeat(np.arange(K), deg_v)
        w = dst[idx].astype(np.int64)
        ku = u.astype(np.int64)[row] * n + w
        at = np.minimum(np.searchsorted(keys, ku), len(keys) - 1)
        common = np.bincount(row, weights=(keys[at] == ku) & (w != u[row]), minlength=K).astype(np.int64)
        after = deg_u + deg_v - common - 2
        ok = (common == count[e]) & (after <= MAX_VALENCE) & (after >= np.where(self.boundary[u], 2, 3))
        # fold-over and slivers on every face that moves (the faces around v without u)
        fstart, corner = around
        lo, hi = fstart[v], fstart[v + 1]
        ci = corner[concat_ranges(lo, hi)]
        r = np.repeat(np.arange(K), hi - lo)
        f, j = ci // 3, ci % 3
        b = self.faces[f, (j + 1) % 3]
        c = self.faces[f, (j + 2) % 3]
        uu = u[r]
        moved = (b != uu) & (c != uu)
        r, b, c, uu, vv = r[moved], b[moved], c[moved], uu[moved], v[r[moved]]
        P = self.pos
        pb, pc = P[b], P[c]
        old = cross(pb - P[vv], pc - P[vv])
        e1, e2 = pb - P[uu], pc - P[uu]
        new = cross(e1, e2)
        n2 = (new * new).sum(1)
        o2 = (old * old).sum(1)
        fold = (old * new).sum(1) <= FOLD_COS * np.sqrt(n2 * o2)
        lmax = np.maximum(np.maximum((e1 * e1).sum(1), (e2 * e2).sum(1)), ((pc - pb) ** 2).sum(1))
        sliver = n2 <= (SLIVER * lmax) ** 2
        bad = np.bincount(r, weights=fold | sliver, minlength=K) > 0
        return ok & ~bad

    def next_legal(self, bad, cost, seg_start, seg_of_v, moves, src, dst, count, start, keys, around):
        """For the vertices ``bad`` whose proposal was illegal (its cost already set to inf): every other move
        of theirs is checked at once (``legal``, on the round's mesh), illegal ones get cost inf, and the cheapest
        legal one is returned (move index, -1 when none is left) with its cost. A vertex thus reaches a legal
        move in the round its cheaper moves fail, however many they are (rule H-R: selection)."""
        sb = seg_of_v[bad]
        idx = concat_ranges(seg_start[sb], seg_start[sb + 1])
        idx = idx[np.isfinite(cost[idx])]
        if len(idx):
            e = moves[idx]
            ok = self.legal(src[e], dst[e], e, dst, count, start, keys, around)
            cost[idx[~ok]] = np.inf
        return self.cheapest(cost, seg_start, sb)

    def select(self, src, dst, count, start, keys):
        """This round's collapses: (v, u) local ids (C,) of pairwise independent legal moves, in the order of
        their costs (rule H-R; module docstring).

        Two collapses ``v -> u`` and ``v' -> u'`` conflict when ``v'`` is in the closed one-ring of ``v`` or of
        ``u``, or ``u'`` is in the closed one-ring of ``v`` (or the same with the roles swapped): otherwise
        neither changes the faces around the other's ``v``, nor the one-rings of its ``v`` and ``u``, so both
        stay legal in either order and commute. In each selection, a live proposal is taken when its rank (cost
        class, then position hash) is the lowest among the live proposals it conflicts with and no waiting
        proposal it conflicts with has a cheaper class. A taken proposal that is illegal moves to its vertex's
        cheapest legal move (``next_legal``) and competes again at that cost: it never holds its neighbours back
        with a cost it cannot realise, and needs no second round to reach a legal move. Every live proposal
        conflicting with any collapse made so far in the round leaves it (whatever its current target): the
        round's collapses are pairwise non-conflicting. Selections repeat until no proposal is live, so a round
        makes no collapse only when no movable vertex has a legal move."""
        n = self.n
        moves, cost, seg_start, seg_v = self.proposals(src, dst, count, start)
        S = len(seg_v)
        if not S:
            return np.zeros(0, np.int32), np.zeros(0, np.int32)
        best, own = self.cheapest(cost, seg_start, np.arange(S))
        around = vertex_corners(self.faces, self.n)
        target = np.full(n, -1, np.int32)  # move index of each vertex's current proposal
        target[seg_v] = best
        prio = np.full(n, np.inf)  # its cost
        prio[seg_v] = own
        seg_of_v = np.full(n, -1, np.int32)
        seg_of_v[seg_v] = np.arange(S)
        live = target >= 0
        big = np.iinfo(np.int32).max
        rank = np.full(n, big, np.int32)  # per selection, over the live proposals (reset after use)
        mu = np.full(n, big, np.int32)  # lowest rank of the live proposals into each vertex
        wait_v = np.full(n, np.inf, np.float32)  # cost class of the waiting proposal of each vertex
        wait_u = np.full(n, np.inf, np.float32)  # lowest cost class of the waiting proposals into each vertex
        ring_v = np.zeros(n, bool)  # closed one-rings of the v of the collapses made this round
        ring_vu = np.zeros(n, bool)  # ... and of their u

        def ring(at):  # the one-rings of the vertices ``at`` (all have neighbours): neighbours, segment starts
            lo, hi = start[at], start[at + 1]
            return at, dst[concat_ranges(lo, hi)], np.cumsum(hi - lo) - (hi - lo)

        def ring_min(x, r):  # min of x over each closed one-ring of ``ring``
            return np.minimum(np.minimum.reduceat(x[r[1]], r[2]), x[r[0]])

        def mark(mask, at):
            mask[at] = True
            mask[dst[concat_ranges(start[at], start[at + 1])]] = True

        made_v, made_u, made_c = [], [], []
        waiting = False
        lv = np.flatnonzero(live)
        while len(lv):
            lu = dst[moves[target[lv]]]
            cl = cost_class(prio[lv])
            rv = np.empty(len(lv), np.int32)
            rv[np.argsort(rank_key(cl, self.tie[lv]), kind="stable")] = np.arange(len(lv), dtype=np.int32)
            rank[lv] = rv
            np.minimum.at(mu, lu, rv)
            rlv, rlu = ring(lv), ring(lu)
            pick = (ring_min(rank, rlv) == rv) & (ring_min(rank, rlu) == rv) & (ring_min(mu, rlv) == rv)
            rank[lv] = big
            mu[lu] = big
            # a proposal conflicting with a waiting one of a cheaper class waits too (the sequential order)
            held = np.zeros(len(lv), bool)
            if waiting:
                wait = np.minimum(np.minimum(ring_min(wait_v, rlv), ring_min(wait_v, rlu)), ring_min(wait_u, rlv))
                held = wait < cl
                pick &= ~held
            del rlv, rlu
            sel, su = lv[pick], lu[pick]
            ok = self.legal(sel.astype(np.int32), su.astype(np.int32), moves[target[sel]], dst, count, start, keys,
                            around)
            v_ok, u_ok = sel[ok], su[ok]
            made_v.append(v_ok)
            made_u.append(u_ok)
            made_c.append(prio[v_ok])
            live[v_ok] = False
            mark(ring_v, v_ok)
            mark(ring_vu, v_ok)
            mark(ring_vu, u_ok)
            bad = sel[~ok]
            cost[target[bad]] = np.inf
            target[bad], prio[bad] = self.next_legal(bad, cost, seg_start, seg_of_v, moves, src, dst, count, start,
                                                     keys, around)
            live[bad] = target[bad] >= 0
            # every live proposal conflicting with a collapse made this round leaves it (H-R), at its current
            # target; it waits for the next round with the held ones, holding back costlier conflicting proposals
            keep = live[lv]
            lv, held = lv[keep], held[keep]
            lu = dst[moves[target[lv]]]
            stop = held | ring_vu[lv] | ring_v[lu]
            wv, wu = lv[stop], lu[stop]
            wait_v[wv] = cost_class(prio[wv])
            np.minimum.at(wait_u, wu, wait_v[wv])
            live[wv] = False
            waiting = waiting or len(wv) > 0
            lv = lv[~stop]
        v_all = np.concatenate(made_v)
        u_all = np.concatenate(made_u)
        o = np.lexsort((self.tie[v_all], np.concatenate(made_c)))
        return v_all[o].astype(np.int32), u_all[o].astype(np.int32)

    # -----------------------------------------------------------------------------------------------------------
    def apply(self, v, u):
        """Make the independent collapses ``v -> u`` (local ids): faces on ``uv`` vanish, the others around ``v``
        move to ``u``, quadrics add up. Returns (faces (T, 3) local ids around each ``u`` after the collapse,
        grouped in collapse order, and their counts (C,))."""
        to = np.arange(self.n, dtype=np.int32)
        to[v] = u
        f = to[self.faces]
        keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
        self.faces = f[keep]
        self.quadric[u] += self.quadric[v]  # the u of one round are distinct
        self.movable[v] = False
        slot = np.full(self.n, -1, np.int64)
        slot[u] = np.arange(len(u))
        flat = self.faces.ravel()
        ci = np.flatnonzero(slot[flat] >= 0)
        s = slot[flat[ci]]
        o = np.argsort(s, kind="stable")
        return self.faces[ci[o] // 3], np.bincount(s, minlength=len(u))

    def finish_groups(self, target_base: int) -> None:
        """Groups with at most ``target_base`` faces left stop moving; their faces leave the working mesh once
        no moving vertex uses them."""
        if not len(self.faces):
            return
        G = int(self.group.max()) + 1
        nf = np.bincount(self.group[self.faces[:, 0]], minlength=G)
        done = nf <= target_base
        if done.any():
            self.movable &= ~done[self.group]
            gf = done[self.group[self.faces]]
            self.faces = self.faces[~gf.all(1)]
