"""Environment transfer store (``lodprt-transfer``, docs/FORMAT.md): writing a distant-light transfer bake and
reading it back, LOD stores completed on read (T-15). The bake itself is :mod:`lodprt.precompute.transfer`."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lodprt.errors import StoreError
from lodprt.store.reader import FormatStore
from lodprt.store.writer import TRANSFER_FORMAT, StoreWriter, prepare_destination, store_format

# TRANSFER_FORMAT ("lodprt-transfer") is defined next to the point-light format in bake_store, which refuses it
#: 2: LOD stores keep glossy matrices of the cut only (``transfer/glossy_kept_ids``), ``materials/mirror``
TRANSFER_FORMAT_VERSION = 2
#: versions this reader reads (a version-1 store has neither of version 2's fields and reads as before)
READABLE_VERSIONS = (1, 2)
#: what messages call a transfer store
WHAT = "lodprt transfer store"


def is_transfer_store(path) -> bool:
    return store_format(path) == TRANSFER_FORMAT


def prepare_transfer_destination(path: str | os.PathLike, *, overwrite: bool) -> None:
    """Tidy leftovers of interrupted bakes of ``path`` and refuse to replace anything but a transfer store
    (StoreError); what a bake runs before any work."""
    prepare_destination(Path(path), overwrite=overwrite, format=TRANSFER_FORMAT, what=WHAT)


def write_transfer_store(path: str | os.PathLike, scene, *, overwrite: bool, diffuse: np.ndarray,
                         glossy_ids: np.ndarray, glossy: np.ndarray | None = None,
                         glossy_kept_ids: np.ndarray | None = None, cut_nodes: np.ndarray | None = None,
                         tree=None, hierarchy_seconds: float | None = None, environment: tuple | None = None,
                         attrs: dict) -> Path:
    """Write a ``lodprt-transfer`` store at ``path`` through :class:`StoreWriter` (a killed write never touches
    ``path``); returns the path.

    scene: the baked :class:`lodprt.model.scene.Scene` (geometry and materials are stored); diffuse (V, 3, n*n)
    transfer of every vertex; glossy_ids (G,) and glossy (G, g*g, n*n) or None; with ``cut_nodes`` (LOD) only the
    vertices of those nodes of ``tree`` keep their diffuse vectors, ``glossy`` then holds the matrices of
    ``glossy_kept_ids`` (the glossy vertices among them, sorted), and the hierarchy is stored
    (``hierarchy_seconds`` its build time); environment: None or (coefficients (3, n*n), {"source", "kind",
    "resolution"}), the default lighting; attrs: the bake's root attributes after ``format``, ``format_version``
    and ``lodprt_version`` (docs/FORMAT.md).
    """
    from lodprt.version import __version__

    with StoreWriter(path, overwrite=overwrite, format=TRANSFER_FORMAT, what=WHAT) as writer:
        arr = writer.array
        arr("scene/positions", scene.positions.astype(np.float32))
        arr("scene/normals", scene.normals.astype(np.float32))
        arr("scene/faces", scene.faces.astype(np.int32))
        arr("scene/material_id", scene.material_id.astype(np.int32))
        arr("materials/kd", np.array([m.kd for m in scene.materials], np.float32))
        arr("materials/ks", np.array([m.ks for m in scene.materials], np.float32))
        arr("materials/shininess", np.array([m.shininess for m in scene.materials], np.float32))
        arr("materials/mirror", np.array([getattr(m, "mirror", False) for m in scene.materials], bool))
        if cut_nodes is None:
            arr("transfer/diffuse", diffuse)
        else:
            kept = tree.vertex[cut_nodes].astype(np.int32)
            arr("transfer/vertex_ids", kept)
            arr("transfer/cut_nodes", cut_nodes)
            arr("transfer/diffuse", diffuse[kept])
            for name, a in tree.to_arrays().items():
                arr(f"hierarchy/{name}", a)
            writer.attrs("hierarchy", levels=tree.levels, seconds=hierarchy_seconds)
        arr("transfer/glossy_vertex_ids", glossy_ids)
        if cut_nodes is not None and glossy_kept_ids is not None:
            arr("transfer/glossy_kept_ids", np.asarray(glossy_kept_ids, np.int32))
        if glossy is not None:
            arr("transfer/glossy", glossy)
        writer.environment(environment)
        writer.attrs(format=TRANSFER_FORMAT, format_version=TRANSFER_FORMAT_VERSION, lodprt_version=__version__,
                     **attrs)
        return writer.commit()


def complete_glossy(h, positions, normals, cut_nodes, kept_ids, matrices, glossy_ids) -> np.ndarray:
    """Glossy matrices of every glossy vertex ``glossy_ids`` (G,) from those of ``kept_ids`` (K_g,), the glossy
    vertices of the cut (T-15, as :func:`complete_transfer`): (G, g*g, n*n) float64, exact at ``kept_ids``.

    The cut's other vertices (materials without ks) enter as zeros; a collapse never joins two objects, so glossy
    vertices complete from glossy neighbours alone."""
    cut_nodes = np.asarray(cut_nodes)
    cut_vertices = h.vertex[cut_nodes]
    m = np.asarray(matrices)
    full = np.zeros((len(cut_nodes),) + m.shape[1:], np.float64)
    by_vertex = np.argsort(cut_vertices)
    at = by_vertex[np.minimum(np.searchsorted(cut_vertices, kept_ids, sorter=by_vertex), len(by_vertex) - 1)]
    if len(kept_ids) != len(m) or not np.array_equal(cut_vertices[at], kept_ids):
        raise StoreError("glossy completion: every kept glossy vertex must be a vertex of the cut, one matrix each")
    full[at] = m
    return complete_transfer(h, positions, normals, cut_nodes, full)[np.asarray(glossy_ids)]


def complete_transfer(h, positions, normals, cut_nodes, coefficients) -> np.ndarray:
    """Transfer vectors of every vertex from those of a cut's vertices (T-15 completion, ``lodprt.model.completion``):
    cut_nodes (K,), coefficients (K, ...) at ``h.vertex[cut_nodes]`` -> (V, ...) float64."""
    from lodprt.model.completion import CompletionPlan

    cut_nodes = np.asarray(cut_nodes)
    plan = CompletionPlan(h, positions, normals)
    return plan.complete(h.vertex[cut_nodes], np.asarray(coefficients), h.num_vertices, cut_nodes=cut_nodes,
                         dark=np.zeros(len(cut_nodes), bool))


class TransferStore(FormatStore):
    """Read access to a ``lodprt-transfer`` store (docs/FORMAT.md)."""

    FORMAT, VERSIONS, WHAT, BAKE = TRANSFER_FORMAT, READABLE_VERSIONS, WHAT, "lodprt bake-environment"

    def required_parts(self) -> list[str]:
        """The arrays ``write_transfer_store`` writes for this store's settings: the geometry, materials and diffuse
        transfer always; ``materials/mirror`` from version 2; the glossy matrices when ``glossy_order`` says the bake
        made some; with ``lod_threshold`` the cut, the hierarchy and (version 2) ``glossy_kept_ids``."""
        from lodprt.model.hierarchy import Hierarchy

        v2 = (self.attrs.get("format_version") or 1) >= 2
        parts = super().required_parts() + [
            "scene/positions", "scene/normals", "scene/faces", "scene/material_id", "materials/kd", "materials/ks",
            "materials/shininess", "transfer/diffuse", "transfer/glossy_vertex_ids"]
        parts += ["materials/mirror"] if v2 else []
        parts += ["transfer/glossy"] if self.attrs.get("glossy_order") is not None else []
        if self.attrs.get("lod_threshold") is not None:
            parts += ["transfer/vertex_ids", "transfer/cut_nodes"] + (["transfer/glossy_kept_ids"] if v2 else [])
            parts += [f"hierarchy/{name}" for name in Hierarchy.ARRAYS]
        return parts

    def diffuse(self) -> np.ndarray:
        """(V, 3, n*n) diffuse transfer of every vertex; a LOD store's missing vertices are completed (T-15)."""
        if not hasattr(self, "_diffuse"):
            t = self.read("transfer/diffuse")
            if self.has("transfer/cut_nodes"):
                t = complete_transfer(self._hierarchy(), self.read("scene/positions").astype(np.float64),
                                      self.read("scene/normals").astype(np.float64), self.read("transfer/cut_nodes"),
                                      t.astype(np.float64)).astype(np.float32)
            self._diffuse = t
        return self._diffuse

    def _hierarchy(self):
        from lodprt.model.hierarchy import Hierarchy

        arrays = {name: self.read(f"hierarchy/{name}") for name in Hierarchy.ARRAYS if self.has(f"hierarchy/{name}")}
        return Hierarchy.from_arrays(arrays)

    def glossy(self) -> tuple[np.ndarray, np.ndarray | None]:
        """(ids (G,), matrices (G, g*g, n*n) float32 or None): the glossy matrix of every glossy vertex; a LOD
        store's matrices at vertices it did not keep are completed (T-15)."""
        if not hasattr(self, "_glossy"):
            ids = self.read("transfer/glossy_vertex_ids")
            m = self.read("transfer/glossy") if self.has("transfer/glossy") else None
            if self.has("transfer/glossy_kept_ids") and len(ids):
                kept = self.read("transfer/glossy_kept_ids")
                if m is None or len(kept) == 0:
                    raise StoreError(f"{self.path}: field 'transfer/glossy': a LOD store with glossy vertices keeps "
                                     "none of their matrices")
                if len(kept) != len(m):
                    raise StoreError(f"{self.path}: field 'transfer/glossy' has {len(m)} rows for {len(kept)} "
                                     "'transfer/glossy_kept_ids'")
                m = complete_glossy(self._hierarchy(), self.read("scene/positions").astype(np.float64),
                                    self.read("scene/normals").astype(np.float64), self.read("transfer/cut_nodes"),
                                    kept, m.astype(np.float64), ids).astype(np.float32)
            self._glossy = (ids, m)
        return self._glossy
