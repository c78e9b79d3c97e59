"""Hierarchy build, per-node geometry (SPEC 3; thesis 3.2, figures 7 and 10): normal cones, bounding radii and
error vectors of the nodes ``lodprt.model.hierarchy_build`` creates, vectorised over one round of collapses.

A parent's cone is the minimal cone holding its two children's cones (figure 7); its radius bounds every leaf
below; the error vector of a collapse ``v -> u`` is ``p - p'``, ``p'`` the closest point to ``v``'s position on the
faces around ``u`` right after the collapse (figure 10).
"""

from __future__ import annotations

import math

import numpy as np


def merge_cones(a1, t1, a2, t2):
    """Minimal cones (M, 3) axes, (M,) half-angles holding cones (a1, t1) and (a2, t2) (unit axes, radians).

    If one cone holds the other, it is the answer; otherwise the half-angle is (g + t1 + t2) / 2 (g the angle
    between the axes) and the axis is a1 turned toward a2 by that minus t1; at pi the cone is the whole sphere.
    """
    c = (a1 * a2).sum(1)
    g = np.arctan2(np.linalg.norm(np.cross(a1, a2), axis=1), c)  # well conditioned near 0 and pi
    t = 0.5 * (g + t1 + t2)
    perp = a2 - c[:, None] * a1
    pn = np.linalg.norm(perp, axis=1)
    tiny = pn < 1e-12
    if tiny.any():  # (anti)parallel axes: any direction perpendicular to a1 will do
        e = np.where((np.abs(a1[tiny, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        alt = np.cross(a1[tiny], e)
        perp[tiny] = alt
        pn[tiny] = np.linalg.norm(alt, axis=1)
    perp /= pn[:, None]
    ang = (t - t1)[:, None]
    axis = np.cos(ang) * a1 + np.sin(ang) * perp
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    in1 = g + t2 <= t1
    in2 = ~in1 & (g + t1 <= t2)
    axis = np.where(in1[:, None], a1, np.where(in2[:, None], a2, axis))
    half = np.where(in1, t1, np.where(in2, t2, t))
    full = half >= math.pi
    axis[full] = a1[full]
    return axis, np.minimum(half, math.pi)


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest points (M, 3) on triangles (a, b, c) to points p, all (M, 3) (Ericson, Real-Time Collision
    Detection 5.1.5); degenerate triangles fall back to their closest edge or corner."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    safe = np.where(np.abs(denom) > 0, denom, 1.0)
    out = a + ab * (vb / safe)[:, None] + ac * (vc / safe)[:, None]  # interior
    with np.errstate(divide="ignore", invalid="ignore"):
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        out = np.where(m[:, None], a + ab * np.where(m, d1 / np.where(d1 - d3 != 0, d1 - d3, 1), 0)[:, None], out)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        out = np.where(m[:, None], a + ac * np.where(m, d2 / np.where(d2 - d6 != 0, d2 - d6, 1), 0)[:, None], out)
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        den = (d4 - d3) + (d5 - d6)
        out = np.where(m[:, None], b + (c - b) * np.where(m, (d4 - d3) / np.where(den != 0, den, 1), 0)[:, None], out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)  # corner regions take precedence
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)
    # a zero-area triangle: the closest of its three edges' closest points
    flat = ~(np.abs(denom) > 0)
    if flat.any():
        best = None
        for s, e in ((a, b), (b, c), (c, a)):
            d = e[flat] - s[flat]
            dd = (d * d).sum(1)
            tt = np.clip(((p[flat] - s[flat]) * d).sum(1) / np.where(dd > 0, dd, 1), 0, 1)
            q = s[flat] + d * tt[:, None]
            dist = ((p[flat] - q) ** 2).sum(1)
            if best is None:
                best, bq = dist, q
            else:
                take = dist < best
                best, bq = np.where(take, dist, best), np.where(take[:, None], q, bq)
        out[flat] = bq
    return out


def error_vectors(positions, pv, counts, tris) -> np.ndarray:
    """Figure 10: ``p - p'`` for each collapse, p the collapsed vertex ``pv`` (C,), p' its closest point on the
    ``counts`` (C,) faces ``tris`` (sum counts, 3) around the survivor right after the collapse."""
    out = np.zeros((len(pv), 3))
    has = counts > 0
    if not len(tris):
        return out
    p = positions[np.repeat(pv, counts)]
    q = _closest_on_triangles(p, positions[tris[:, 0]], positions[tris[:, 1]], positions[tris[:, 2]])
    d2 = ((p - q) ** 2).sum(1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    idx = np.flatnonzero(has)
    best = np.minimum.reduceat(d2, starts[idx])
    seg = np.repeat(np.arange(len(idx)), counts[idx])
    hits = np.flatnonzero(d2 == best[seg])
    first = np.full(len(idx), -1)
    first[seg[hits][::-1]] = hits[::-1]  # the first closest face of each collapse
    out[idx] = p[first] - q[first]
    return out
