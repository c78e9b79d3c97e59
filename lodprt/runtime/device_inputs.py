"""A frame's small per-call kernel inputs (the nodes to evaluate, the vertices to relight, the lights, the sample
weights): on the CPU a Warp view of the numpy array, since at a few thousand rows a copy costs about what the
launch does (``benchmarks/runtime.py``'s orbit launches a handful of kernels a frame); and its zeroed outputs
(``zeros``)."""

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


def zeros(shape, np_dtype, wp_dtype, device: str):
    """A zeroed Warp array ``shape`` of the scalar ``wp_dtype`` (``np_dtype`` on the host) on ``device``: on the
    CPU a view of ``np.zeros`` (fresh pages come zeroed from the system, so only the pages a kernel writes are
    touched, by the kernel's threads; ``wp.zeros`` fills them on one thread first, about 10 ms for a full frame's
    19 MB of coefficients on the benchmark machine), elsewhere ``wp.zeros``."""
    if device == DEVICE:
        return warp_view(np.zeros(shape, np_dtype), wp_dtype)
    return warp().zeros(shape, dtype=wp_dtype, device=device)
