"""Hierarchy build, one round of parallel half-edge collapses (SPEC 3; thesis 3.2, figures 5 and 6; tag H-R):
``CollapseRounds``.

A round looks at the whole current mesh at once, vectorised (numpy, no per-vertex Python objects): every movable
vertex ``v`` proposes its cheapest move ``v -> u`` (Garland-Heckbert QEM cost of ``u``'s position under the summed
quadrics, plus ``EDGE_WEIGHT |uv|^4``); the proposals that are local minima of the cost among all proposals within
two edges are checked for legality (link condition, valence, boundary rules, fold-over, slivers: docs/HIERARCHY.md)
and made together; what failed tries its next-cheapest move, and the selection repeats on what the made collapses
left unblocked (a Luby-style maximal independent set). Two collapses made in one round never touch each other's
collapsed vertex's faces or either one-ring their legality reads (``CollapseRounds.select``), so they commute
(H-R): each was legal on the mesh the other leaves, and any order of the round's collapses is a valid build order. The vertex arrays are compacted to the live
vertices whenever half of them have gone, so late rounds cost what the small mesh costs.
"""

from __future__ import annotations

import numpy as np

from lodprt.model.hierarchy import concat_ranges

#: a moved face must keep its normal within this cosine of its old one (0 = 90 degrees)
FOLD_COS = 0.0
#: twice a moved face's area below SLIVER x its longest edge squared makes it a degenerate sliver
SLIVER = 1e-3
#: weight of |uv|^4 added to the QEM cost of v -> u: on flat regions (zero quadric error) the shortest edge wins
EDGE_WEIGHT = 1e-3
#: no collapse may leave the survivor with more neighbours (keeps fans and deep chains from forming)
MAX_VALENCE = 24
#: rounds of selection (local minima, legality, blocking) within one round of collapses
SELECTIONS = 4
#: moves costed at once (bounds the temporaries of a round to a few MB)
CHUNK = 1 << 16
#: moves a vertex tries in one round (cheapest first) before it waits for the next round
TRIES = 3

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


class CollapseRounds:
    """The mutable mesh of the build and its rounds of collapses (module docstring).

    Per live vertex (local ids ``0..n-1``, compacted now and then): ``gid`` original id, ``pos`` (n, 3) float64,
    ``quadric`` (n, 10) float64 (``QUADRIC_ENTRIES``), ``boundary``, ``frozen`` (never a target), ``movable`` (may collapse), ``group``,
    ``node`` the hierarchy node standing there. Faces ``faces`` (M, 3) int32 in local ids, never degenerate."""

    def __init__(self, gid, pos, quadric, boundary, frozen, movable, group, faces, split: bool):
        self.split = split  # whether vertices of different groups may share an edge
        self.gid, self.pos, self.quadric = gid, pos, quadric
        self.boundary, self.frozen, self.movable, self.group = boundary, frozen, movable, group
        self.node = gid.copy()
        self.faces = faces
        self.tie = position_hash(pos)

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
        ok = self.movable[v]
        ok &= ~self.frozen[u]
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
    def legal(self, v, u, e, dst, count, start, keys):
        """(K,) bool: which collapses ``v -> u`` (local ids; ``e`` their edge indices) are legal on the current
        mesh (docs/HIERARCHY.md): link condition, the survivor's valence, no fold-over (thesis figure 6), no
        sliver. The boundary and component rules hold already for every proposal."""
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
        slot = np.full(n, -1, np.int64)
        slot[v] = np.arange(K)
        flat = self.faces.ravel()
        ci = np.flatnonzero(slot[flat] >= 0)
        f, j = ci // 3, ci % 3
        r = slot[flat[ci]]
        b = self.faces[f, (j + 1) % 3]
        c = self.faces[f, (j + 2) % 3]
        uu = u[r]
        moved = (b != uu) & (c != uu)
        r, b, c, uu, vv = r[moved], b[moved], c[moved], uu[moved], v[r[moved]]
        P = self.pos
        pb, pc = P[b], P[c]
        old = np.cross(pb - P[vv], pc - P[vv])
        e1, e2 = pb - P[uu], pc - P[uu]
        new = np.cross(e1, e2)
        n2 = (new * new).sum(1)
        o2 = (old * old).sum(1)
        fold = (old * new).sum(1) <= FOLD_COS * np.sqrt(n2 * o2)
        lmax = np.maximum(np.maximum((e1 * e1).sum(1), (e2 * e2).sum(1)), ((pc - pb) ** 2).sum(1))
        sliver = n2 <= (SLIVER * lmax) ** 2
        bad = np.bincount(r, weights=fold | sliver, minlength=K) > 0
        return ok & ~bad

    def select(self, src, dst, count, start, keys):
        """This round's collapses: (v, u) local ids (C,) of pairwise independent legal moves, in the order of
        their costs (module docstring: local minima, legality, blocking, repeated ``SELECTIONS`` times).

        Two collapses ``v -> u`` and ``v' -> u'`` conflict when ``v'`` is in the closed one-ring of ``v`` or of
        ``u``, or ``u'`` is in the closed one-ring of ``v`` (or the same with the roles swapped): otherwise
        neither changes the faces around the other's ``v``, nor the one-rings of its ``v`` and ``u``, so both
        stay legal in either order and commute (H-R). A proposal is taken when its rank is the lowest among all
        live proposals it conflicts with."""
        n = self.n
        moves, cost, seg_start, seg_v = self.proposals(src, dst, count, start)
        S = len(seg_v)
        if not S:
            return np.zeros(0, np.int32), np.zeros(0, np.int32)
        best, own = self.cheapest(cost, seg_start, np.arange(S))
        tries = np.zeros(S, np.int32)
        big = np.iinfo(np.int32).max
        # priority: own cost, then a hash of the position (exact ties, common on flat regions, broken without
        # the bias of vertex order, which would make the selection crawl across a grid): a rank per vertex
        rank = np.full(n, big, np.int32)
        rank[seg_v[np.lexsort((self.tie[seg_v], own))]] = np.arange(S, dtype=np.int32)
        target = np.full(n, -1, np.int64)  # move index of each vertex's current proposal
        target[seg_v] = best
        seg_of_v = np.full(n, -1, np.int64)
        seg_of_v[seg_v] = np.arange(S)
        live = target >= 0

        def ring_min(x, at):  # min of x over the closed one-ring of each vertex in ``at`` (all have neighbours)
            lo, hi = start[at], start[at + 1]
            m = np.minimum.reduceat(x[dst[concat_ranges(lo, hi)]], np.cumsum(hi - lo) - (hi - lo))
            return np.minimum(m, x[at])

        made_v, made_u = [], []
        for _ in range(SELECTIONS):
            lv = np.flatnonzero(live)
            if not len(lv):
                break
            lu = dst[moves[target[lv]]]
            r = np.full(n, big, np.int32)
            r[lv] = rank[lv]
            mu = np.full(n, big, np.int32)
            np.minimum.at(mu, lu, rank[lv])
            rv = rank[lv]
            pick = (ring_min(r, lv) == rv) & (ring_min(r, lu) == rv) & (ring_min(mu, lv) == rv)
            sel, su = lv[pick], lu[pick]
            mv = moves[target[sel]]
            ok = self.legal(sel.astype(np.int32), su.astype(np.int32), mv, dst, count, start, keys)
            v_ok, u_ok = sel[ok], su[ok]
            made_v.append(v_ok)
            made_u.append(u_ok)
            # block every proposal that conflicts with a made collapse
            ring_v = np.zeros(n, bool)
            ring_v[v_ok] = True
            ring_v[dst[concat_ranges(start[v_ok], start[v_ok + 1])]] = True
            ring_vu = ring_v.copy()
            ring_vu[u_ok] = True
            ring_vu[dst[concat_ranges(start[u_ok], start[u_ok + 1])]] = True
            live[lv] &= ~ring_vu[lv] & ~ring_v[lu]
            # failed proposals: the next-cheapest move, up to TRIES per round
            bad = sel[~ok]
            sb = seg_of_v[bad]
            cost[target[bad]] = np.inf
            tries[sb] += 1
            retry = tries[sb] < TRIES
            nb, _ = self.cheapest(cost, seg_start, sb[retry])
            target[bad] = -1
            target[bad[retry]] = nb
            live[bad] = target[bad] >= 0
        v_all = np.concatenate(made_v)
        u_all = np.concatenate(made_u)
        o = np.argsort(rank[v_all], kind="stable")
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
