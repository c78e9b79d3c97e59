"""A warning when a light or the eye lies inside a closed mesh of the store's scene (``lodprt.model.inside``): a
light there lights only the mesh's inside (and, clamped into the sampled region, renders as if from elsewhere), an
eye there sees the inside's back faces, which are culled (a black frame). Logged like the clamp warning of
``lodprt.runtime.lights``: once per run time for the lights and once for the eye, naming the position and the
object; later positions are still checked only until the first warning of their kind."""

from __future__ import annotations

import logging

import numpy as np

from lodprt.model.inside import inside_mesh

log = logging.getLogger(__name__)

WHY = {"light": "it lights that mesh's inside only", "eye": "the frame shows the back of that mesh's faces, shaded with the outside's radiance, "
                                                "not a view of its inside"}


def object_box(positions: np.ndarray, faces: np.ndarray):
    """(min, max) corners of the vertices ``faces`` use, or None for no faces (a mask, not a sort: O(V + F))."""
    if not len(faces):
        return None
    used = np.zeros(len(positions), bool)
    used[faces.ravel()] = True
    p = positions[used]
    return p.min(0), p.max(0)


class InsideCheck:
    """Checks lights and eyes against each object of ``store``'s scene (its faces grouped by the object of their
    first vertex; names from the store's ``object_names``, the floor last)."""

    def __init__(self, store):
        self.store = store
        self.parts = None
        self.boxes = None
        self.warned: set[str] = set()
        self.checked: dict[str, tuple] = {}

    def objects(self) -> list[tuple[str, np.ndarray]]:
        """(name, faces (F_k, 3)) per object of the scene, built on first use."""
        if self.parts is None:
            faces = np.asarray(self.store.faces)
            object_id = np.asarray(self.store.read("scene/object_id"))
            names = list(self.store.root["scene"].attrs.get("object_names", []))
            of_face = object_id[faces[:, 0]] if len(faces) else np.zeros(0, int)
            ks = np.unique(of_face)
            if len(of_face) < 2 or (of_face[1:] >= of_face[:-1]).all():  # objects in order (as baked): views
                cut = np.searchsorted(of_face, np.r_[ks, ks[-1] + 1] if len(ks) else [0])
                rows = [slice(cut[i], cut[i + 1]) for i in range(len(ks))]
            else:
                rows = [of_face == k for k in ks]
            self.parts = [(names[k] if k < len(names) else f"object {k}", faces[r]) for k, r in zip(ks, rows)]
        return self.parts

    def check(self, points, what: str) -> list[tuple[tuple, str]]:
        """Warn (once per ``what``, "light" or "eye") when one of ``points`` (P, 3) lies inside a closed object;
        returns the (position, object) pairs found (empty once ``what`` was warned about, or for the same points as
        the last call)."""
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        with np.errstate(over="ignore"):  # |x| past ~1e296 (clamped below): no numpy warning on the user's screen
            key = tuple(np.round(pts, 12).ravel())
        if what in self.warned or self.checked.get(what) == key:
            return []
        self.checked[what] = key
        positions = self.store.positions
        if self.boxes is None:  # each object's bounding box: a point outside it is outside without a ray
            self.boxes = [object_box(positions, f) for _, f in self.objects()]
        found = []
        for (name, faces), box in zip(self.objects(), self.boxes):
            near = np.zeros(len(pts), bool) if box is None else ((pts > box[0]) & (pts < box[1])).all(1)
            if near.any():
                hits = inside_mesh(pts[near], positions, faces)
                found += [(tuple(float(x) for x in p), name) for p in pts[near][hits]]
        if found:
            self.warned.add(what)
            (p, name), more = found[0], len(found) - 1
            log.warning("%s (%.4g, %.4g, %.4g) lies inside the closed mesh %r: %s%s (further %ss inside a mesh are "
                        "not warned about)", what, *p, name, WHY[what], f"; {more} more inside" if more else "", what)
        return found
