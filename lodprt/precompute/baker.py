"""One light sample's work on a Warp device (SPEC 4; thesis 2.2; T-8..T-10): ``Baker`` holds the scene's BVH and
material tables, casts the shadow rays (visibility), shades Phong radiance and projects it on SH over the view
direction (T-6, closed-form specular lobe P-6), for every referenced vertex or only on a light cut
(:mod:`lodprt.precompute.light_cut`), or for a range of them (``lodprt.precompute.vertex_ranges``);
``bake_kernels`` names the kernels ``lodprt.devices.load_kernels`` compiles or loads once.
``lodprt.precompute.bake`` plans the bake and writes the store.
"""

from __future__ import annotations

import threading

import numpy as np

from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.kernels.visibility import BACK_FACING
from lodprt.model import sh
from lodprt.model.scene import Material, Scene, ray_offset  # noqa: F401  (ray_offset: the bake's, re-exported)

def layout(scene: Scene, sh_order: int) -> tuple[int, int]:
    """(coefficients per vertex, channels) the scene needs: 1 coefficient without specular, 1 channel when grey."""
    specular = any(m.ks > 0 for m in scene.materials)
    grey = all(m.grey for m in scene.materials)
    return (sh_order * sh_order if specular else 1), (1 if grey else 3)


def material_tables(materials: list[Material], sh_order: int, channels: int) -> dict[str, np.ndarray]:
    """Per-material kd (M, C), ks (M,), shininess (M,) and the scaled zonal table (M, order) of the Phong lobe
    (``materials``: a scene's or a store's ``Material`` list)."""
    kd = np.array([m.kd[:channels] for m in materials], np.float32)
    ks = np.array([m.ks for m in materials], np.float32)
    n = np.array([m.shininess for m in materials], np.float32)
    bands = np.arange(sh_order)
    # P-6 factor sqrt(4 pi/(2l+1)) folded in: lobe_lm = sqrt(4 pi/(2l+1)) z_l y_lm(R)
    zonal = np.array(
        [np.sqrt(4 * np.pi / (2 * bands + 1)) * sh.cosine_power_zonal(m.shininess, sh_order) for m in materials],
        np.float32,
    )
    return {"kd": kd, "ks": ks, "shininess": n, "zonal": zonal}


class Baker:
    """Device-side state of one bake of ``scene``: the BVH, the material tables and the per-sample work.

    ``ids`` (K,) are the vertices to bake (``bake`` passes every referenced vertex). The state is shared read-only
    between threads; each thread gets its own work arrays, so :meth:`sample` and :meth:`visibility` may run on
    several threads at once. Call ``lodprt.devices.load_kernels(device, *bake_kernels())`` first when threads will launch.
    ``ncoef`` and ``channels`` are the layout of the coefficients (:func:`layout`), ``offset`` the ray offset.
    """

    def __init__(self, scene: Scene, sh_order: int, device: str, ids: np.ndarray):
        from lodprt.kernels import sh as ksh

        wp = warp()
        if sh_order > ksh.MAX_KERNEL_ORDER:
            raise LodprtError(f"sh_order {sh_order}: the float32 kernels go up to order {ksh.MAX_KERNEL_ORDER}")
        if sh_order < 1:
            raise LodprtError(f"sh_order {sh_order}: must be >= 1")
        self.wp = wp
        self.device = device
        self.sh_order = sh_order
        self.ncoef, self.channels = layout(scene, sh_order)
        self.points = wp.array(scene.positions.astype(np.float32), dtype=wp.vec3, device=device)
        self.normals = wp.array(scene.normals.astype(np.float32), dtype=wp.vec3, device=device)
        self.indices = wp.array(scene.faces.astype(np.int32).ravel(), dtype=wp.int32, device=device)
        self.mesh = wp.Mesh(points=self.points, indices=self.indices)
        self.material_id = wp.array(scene.material_id.astype(np.int32), dtype=wp.int32, device=device)
        tables = material_tables(scene.materials, sh_order, self.channels)
        self.kd = wp.array(tables["kd"], dtype=wp.float32, device=device)
        self.ks = wp.array(tables["ks"], dtype=wp.float32, device=device)
        self.zonal = wp.array(tables["zonal"], dtype=wp.float32, device=device)
        self.ids_host = ids.astype(np.int32)
        self.ids = wp.array(self.ids_host, dtype=wp.int32, device=device)
        self.offset = ray_offset(scene)
        self.falloff = 1 if scene.lights.falloff == "inverse-square" else 0
        self.radius = float(scene.lights.radius)
        self.gi = None  # lodprt.precompute.gi.Interreflection when the bake has bounces (gi.attach)
        self._local = threading.local()

    def _scratch(self):
        # one set of work arrays per thread: samples never share mutable state
        s = getattr(self._local, "arrays", None)
        if s is None:
            wp, k = self.wp, len(self.ids_host)
            s = {
                "visible": wp.zeros(k, dtype=wp.uint8, device=self.device),
                "basis": wp.zeros((k, self.sh_order * self.sh_order), dtype=wp.float32, device=self.device),
                "coeffs": wp.zeros((k, self.channels, self.ncoef), dtype=wp.float32, device=self.device),
            }
            self._local.arrays = s
        return s

    def visibility(self, light: np.ndarray) -> np.ndarray:
        """Visibility state per baked vertex, (K,) uint8 (kernels.visibility states)."""
        from lodprt.kernels import visibility as kvis

        wp, s = self.wp, self._scratch()
        wp.launch(
            kvis.shadow_rays,
            dim=len(self.ids_host),
            inputs=[self.mesh.id, self.points, self.normals, self.ids, wp.vec3(*map(float, light)), float(self.offset)],
            outputs=[s["visible"]],
            device=self.device,
        )
        return s["visible"]

    def shade(self, light: np.ndarray, ids, visible, basis, coeffs) -> None:
        """Phong SH coefficients of vertices ``ids`` (device arrays, ``visible`` aligned with ``ids``)."""
        from lodprt.kernels import shading as kshade

        wp = self.wp
        wp.launch(
            kshade.phong_sh,
            dim=ids.shape[0],
            inputs=[
                self.points,
                self.normals,
                self.material_id,
                ids,
                visible,
                self.kd,
                self.ks,
                self.zonal,
                wp.vec3(*map(float, light)),
                self.falloff,
                self.radius,
                basis,
            ],
            outputs=[coeffs],
            device=self.device,
        )

    def sample(self, light: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bake one light sample at full resolution: (coefficients (K, C, ncoef) float32, visibility (K,) uint8)."""
        s = self._scratch()
        visible = self.visibility(light)
        self.shade(light, self.ids, visible, s["basis"], s["coeffs"])
        # .numpy() is a view of device memory on the CPU: copy, the next sample on this thread reuses it
        coeffs = s["coeffs"].numpy().copy()
        if self.gi is not None:
            coeffs += self.gi.full(light, visible)  # interreflection (docs/GI.md)
        return coeffs, visible.numpy().copy()

    def sample_cut(self, light: np.ndarray, lightcut, threshold_deg: float):
        """Bake one light sample on its light cut (thesis figure 8).

        Returns (vertex ids (K,) int32 of the cut, ascending; the cut node standing at each (K,) int32; whether that
        node is dark (K,) uint8; coefficients (K, C, ncoef); visibility of the referenced vertices).
        """
        if self.gi is not None:
            return self.gi.sample_cut(light, lightcut, threshold_deg)  # interreflection (docs/GI.md)
        vis = self.visibility(light).numpy().copy()
        ids, nodes, dark, states = self.light_cut(light, lightcut, threshold_deg, vis)
        return ids, nodes, dark, self.shade_rows(light, ids, states), vis

    def visibility_rows(self, light: np.ndarray, start: int, stop: int) -> np.ndarray:
        """Visibility states (stop - start,) uint8 of the baked vertices ``ids[start:stop]`` alone, one shadow ray
        each (T-8; the rows ``start:stop`` of :meth:`visibility`; a vertex-range task of a distributed bake)."""
        from lodprt.kernels import visibility as kvis

        wp = self.wp
        ids = self.ids_host[start:stop]
        visible = wp.zeros(len(ids), dtype=wp.uint8, device=self.device)
        wp.launch(
            kvis.shadow_rays,
            dim=len(ids),
            inputs=[self.mesh.id, self.points, self.normals, wp.array(ids, dtype=wp.int32, device=self.device),
                    wp.vec3(*map(float, light)), float(self.offset)],
            outputs=[visible],
            device=self.device,
        )
        return visible.numpy().copy()

    def sample_rows(self, light: np.ndarray, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``start:stop`` of :meth:`sample` (no interreflection), computed for those vertices alone:
        (coefficients (stop - start, C, ncoef) float32, visibility (stop - start,) uint8)."""
        if self.gi is not None:
            raise LodprtError("a vertex range of a sample has no interreflection passes (they gather over every "
                              "vertex)")
        visible = self.visibility_rows(light, start, stop)
        return self.shade_rows(light, self.ids_host[start:stop], visible), visible

    def light_cut(self, light: np.ndarray, lightcut, threshold_deg: float, vis: np.ndarray):
        """The light cut of one sample from the visibility ``vis`` (R,) of every baked vertex: (vertex ids (K,)
        int32 of the cut, ascending; the cut node of each (K,) int32; its dark flag (K,) uint8; the visibility
        state of each kept vertex (K,) uint8)."""
        wp = self.wp
        V = self.points.shape[0]
        full = np.full(V, BACK_FACING, np.uint8)  # vertices no face uses: dark, never kept
        full[self.ids_host] = vis
        active, dark = lightcut.cut(self.normals, wp.array(full, dtype=wp.uint8, device=self.device), light, threshold_deg)
        nodes = np.flatnonzero(active)
        verts = lightcut.h.vertex[nodes]
        keep = np.isin(verts, self.ids_host)  # isolated unreferenced vertices are roots but never baked
        order = np.argsort(verts[keep])
        nodes = nodes[keep][order].astype(np.int32)
        ids = verts[keep][order].astype(np.int32)
        return ids, nodes, dark[nodes].astype(np.uint8), full[ids]

    def shade_rows(self, light: np.ndarray, ids: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Phong SH coefficients (T-9, T-10) (K, C, ncoef) float32 of the vertices ``ids`` (K,) with visibility
        ``states`` (K,)."""
        wp = self.wp
        k = len(ids)
        basis = wp.zeros((k, self.sh_order * self.sh_order), dtype=wp.float32, device=self.device)
        coeffs = wp.zeros((k, self.channels, self.ncoef), dtype=wp.float32, device=self.device)
        self.shade(
            light,
            wp.array(np.ascontiguousarray(ids, np.int32), dtype=wp.int32, device=self.device),
            wp.array(np.ascontiguousarray(states, np.uint8), dtype=wp.uint8, device=self.device),
            basis,
            coeffs,
        )
        return coeffs.numpy().copy()


def bake_kernels() -> tuple:
    """The Warp modules a point-light bake launches: ``lodprt.devices.load_kernels(device, *bake_kernels())`` loads
    them before any thread does."""
    warp()
    from lodprt.kernels import gi as kgi
    from lodprt.kernels import light_cut as kcut
    from lodprt.kernels import shading as kshade
    from lodprt.kernels import visibility as kvis

    return kvis, kshade, kcut, kgi
