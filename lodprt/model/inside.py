"""Whether points lie inside a closed triangle mesh: from a point inside, a ray in any direction leaves the mesh
through a back face (one whose winding normal points along the ray), so the first face it hits is a back face. A
point is inside when that holds in most of ``DIRECTIONS`` (all but ``MISSES``: a scanned mesh such as the Stanford
bunny has small holes a ray may leave through); outside a closed mesh, or anywhere near an open one (a plane), the
rays that miss or first hit a front face outnumber them. Pure numpy (Moller-Trumbore over all faces, one direction
at a time): for a few points (lights, the eye), not for vertices."""

from __future__ import annotations

import numpy as np

#: 14 fixed, slightly irrational directions (the six axes and eight diagonals, tilted so that they do not run along
#: a grid floor's edges or through the vertices of axis-aligned meshes)
_TILT = np.array([0.0123, 0.0371, 0.0217])
DIRECTIONS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                       [1, 1, 1], [1, 1, -1], [1, -1, 1], [1, -1, -1], [-1, 1, 1], [-1, 1, -1], [-1, -1, 1],
                       [-1, -1, -1]], np.float64) + _TILT
DIRECTIONS /= np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)
#: how many of the directions may miss or first hit a front face, for a point still to count as inside
MISSES = 2


def first_hits(origin, direction, v0, e1, e2) -> tuple[int, float]:
    """The first face a ray from ``origin`` along ``direction`` hits (index into the faces given as ``v0`` and
    edges ``e1``, ``e2``, each (F, 3)) and its distance; (-1, inf) when it hits none."""
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-18
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-12)
    if not hit.any():
        return -1, float("inf")
    k = int(np.flatnonzero(hit)[np.argmin(t[hit])])
    return k, float(t[k])


def back_face_hits(point, positions, faces) -> int:
    """In how many of ``DIRECTIONS`` the first face hit from ``point`` is a back face of the mesh, counted until
    more than ``MISSES`` directions were not (then the point is outside: the rays an outside point needs are few)."""
    tri = np.asarray(positions, np.float64)[np.asarray(faces)]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    normals = np.cross(e1, e2)
    count = 0
    for i, d in enumerate(DIRECTIONS):
        k, _ = first_hits(np.asarray(point, np.float64), d, v0, e1, e2)
        count += int(k >= 0 and normals[k] @ d > 0)
        if i + 1 - count > MISSES:  # too many rays left through a front face or missed: not inside, stop
            break
    return count


def inside_mesh(points, positions, faces) -> np.ndarray:
    """(P,) bool: each of ``points`` (P, 3) lies inside the closed mesh (``positions`` (V, 3), ``faces`` (F, 3),
    counter-clockwise seen from outside): its rays first hit a back face in all but ``MISSES`` of ``DIRECTIONS``.
    Points outside the mesh's bounding box are outside without a ray; a mesh of no volume (a plane) holds none."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    positions = np.asarray(positions, np.float64)
    faces = np.asarray(faces).reshape(-1, 3)
    out = np.zeros(len(pts), bool)
    if not len(faces):
        return out
    used = positions[np.unique(faces)]
    lo, hi = used.min(0), used.max(0)
    for i, p in enumerate(pts):
        if (p > lo).all() and (p < hi).all():
            out[i] = back_face_hits(p, positions, faces) >= len(DIRECTIONS) - MISSES
    return out
