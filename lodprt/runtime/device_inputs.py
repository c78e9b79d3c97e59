"""A frame's small per-call kernel inputs (the nodes to evaluate, the vertices to relight, the lights, the sample
weights): on the CPU a Warp view of the numpy array, since at a few thousand rows a copy costs about what the
launch does (``benchmarks/runtime.py``'s orbit launches a handful of kernels a frame)."""

from __future__ import annotations

import numpy as np

from lodprt.devices import warp
from lodprt.launches import DEVICE, warp_view


def host_array(a, np_dtype, wp_dtype, device: str):
    """``a`` as a Warp array of ``wp_dtype`` on ``device``: on the CPU a view of the numpy array
    (``lodprt.launches.warp_view``: no copy; the Warp array keeps it alive, and the kernels only read it), elsewhere
    a copy."""
    if device == DEVICE:
        return warp_view(np.asarray(a, np_dtype), wp_dtype)
    return warp().array(np.ascontiguousarray(a, np_dtype), dtype=wp_dtype, device=device)
