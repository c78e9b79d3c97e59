"""Light-dependent cut (SPEC 4; thesis 3.3, figure 8, eq. 11): per light sample, the front of the vertex hierarchy
that the bottom-up ``qreduce`` pass keeps. Only the cut's vertices get SH coefficients; the rest are completed at
read time (``lodprt.model.completion``).

The pass runs level-synchronously on the device: nodes are grouped by height (leaves 0, a parent one above its
higher child), and one launch of ``kernels.light_cut.qreduce_level`` per height decides every node of that height at
once. Children of a node always have smaller heights, so a single sweep from the leaves up is the fixed point.
"""

from __future__ import annotations

import math

import numpy as np

from lodprt.devices import warp
from lodprt.model.hierarchy import Hierarchy, node_heights


class LightCut:
    """Device-side state to compute light cuts of one hierarchy on one device (arrays shared by all samples;
    ``cut`` allocates the per-sample state, so samples on different threads do not interfere)."""

    def __init__(self, h: Hierarchy, points, device: str):
        wp = warp()
        self.h = h
        self.wp = wp
        self.device = device
        hk = node_heights(h)
        order = np.argsort(hk, kind="stable")
        counts = np.bincount(hk)
        self.levels = []  # device arrays of the internal nodes of each height >= 1
        start = counts[0]
        for c in counts[1:]:
            self.levels.append(wp.array(order[start : start + c].astype(np.int32), dtype=wp.int32, device=device))
            start += c
        self.children = wp.array(h.children.astype(np.int32), dtype=wp.int32, device=device)
        self.vertex = wp.array(h.vertex.astype(np.int32), dtype=wp.int32, device=device)
        self.axis = wp.array(h.cone_axis.astype(np.float32), dtype=wp.vec3, device=device)
        self.half = wp.array(h.cone_half_angle.astype(np.float32), dtype=wp.float32, device=device)
        self.points = points

    def cut(self, normals, visible, light: np.ndarray, threshold_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """The light cut for ``light``: (active (N,) bool, dark (N,) bool: every leaf below back-facing or in
        shadow, so its radiance is 0); ``visible`` (V,) device uint8 states."""
        from lodprt.kernels import light_cut as kcut

        wp, dev, N, V = self.wp, self.device, self.h.num_nodes, self.h.num_vertices
        state = {
            "active": wp.zeros(N, dtype=wp.uint8, device=dev),
            "dark": wp.zeros(N, dtype=wp.uint8, device=dev),
            "lit": wp.zeros(N, dtype=wp.uint8, device=dev),
            "amin": wp.zeros(N, dtype=wp.float32, device=dev),
            "amax": wp.zeros(N, dtype=wp.float32, device=dev),
        }
        lv = wp.vec3(*map(float, light))
        wp.launch(
            kcut.leaf_light_state,
            dim=V,
            inputs=[self.points, normals, visible, lv],
            outputs=[state["active"], state["dark"], state["lit"], state["amin"], state["amax"]],
            device=dev,
        )
        eps = math.radians(float(threshold_deg))
        for nodes in self.levels:
            wp.launch(
                kcut.qreduce_level,
                dim=nodes.shape[0],
                inputs=[nodes, self.children, self.vertex, self.points, self.axis, self.half, lv, eps],
                outputs=[state["active"], state["dark"], state["lit"], state["amin"], state["amax"]],
                device=dev,
            )
        return state["active"].numpy().astype(bool), state["dark"].numpy().astype(bool)
