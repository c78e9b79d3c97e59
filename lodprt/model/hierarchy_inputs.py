"""What every vertex hierarchy build shares (SPEC 3; thesis 3.2): the checked inputs and two build constants.

``lodprt.model.hierarchy_build`` (the rounds, tag H-R) and ``lodprt.model.hierarchy_greedy`` (the sequential build,
tag H-G) read their inputs through ``checked_inputs``, so both refuse the same bad input with the same message.
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError

#: weight of the Garland-Heckbert boundary planes relative to the face quadrics
BOUNDARY_WEIGHT = 100.0
#: slack (radians) added to every stored cone half-angle to cover float32 rounding of axis and angle
CONE_SLACK = 1e-6


def checked_inputs(who: str, positions, faces, normals, component, target_base):
    """The inputs as float64 positions, int32 faces, unit float64 normals and the (V,) int components (None when
    ``component`` is None); raises LodprtError naming ``who`` (the build) and the bad input."""
    positions = np.ascontiguousarray(positions, np.float64)
    normals = np.asarray(normals, np.float64)
    faces = np.asarray(faces)
    if positions.ndim != 2 or positions.shape[1] != 3 or normals.shape != positions.shape:
        raise LodprtError(f"{who}: positions and normals must both be (V, 3), got {positions.shape} and "
                          f"{normals.shape}")
    V = len(positions)
    if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
        raise LodprtError(f"{who}: faces must be an (F, 3) integer array, got {faces.shape} {faces.dtype}")
    if len(faces) and (faces.min() < 0 or faces.max() >= V):
        raise LodprtError(f"{who}: faces index vertices {faces.min()}..{faces.max()} outside 0..{V - 1}")
    if 2 * V >= 2**31 - 1:
        raise LodprtError(f"{who}: {V} vertices do not fit int32 node ids")
    faces = faces.astype(np.int32)
    if not np.isfinite(positions).all():
        raise LodprtError(f"{who}: non-finite vertex positions")
    if not np.isfinite(normals).all():
        raise LodprtError(f"{who}: non-finite vertex normals")
    comp = None
    if component is not None:
        comp = np.asarray(component)
        if comp.shape != (V,) or not np.issubdtype(comp.dtype, np.integer):
            raise LodprtError(f"{who}: component must be a (V,) = ({V},) integer array, got "
                              f"{comp.shape} {comp.dtype}")
    if int(target_base) < 1:
        raise LodprtError(f"{who}: target_base must be >= 1 face, got {target_base}")
    nrm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(nrm > 0, normals / np.where(nrm > 0, nrm, 1), [0.0, 1.0, 0.0])
    return positions, faces, normals, comp
