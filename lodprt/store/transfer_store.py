"""Environment transfer store (``lodprt-transfer``, docs/FORMAT.md): writing a distant-light transfer bake and
reading it back, LOD stores completed on read (T-15). The bake itself is :mod:`lodprt.precompute.transfer`."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lodprt.errors import StoreError
from lodprt.store.bake_store import TRANSFER_FORMAT, StoreWriter, prepare_destination, store_format

# TRANSFER_FORMAT ("lodprt-transfer") is defined next to the point-light format in bake_store, which refuses it
TRANSFER_FORMAT_VERSION = 1
#: what messages call a transfer store
WHAT = "lodprt transfer store"


def is_transfer_store(path) -> bool:
    return store_format(path) == TRANSFER_FORMAT


def prepare_transfer_destination(path: str | os.PathLike, *, overwrite: bool) -> None:
    """Tidy leftovers of interrupted bakes of ``path`` and refuse to replace anything but a transfer store
    (StoreError); what a bake runs before any work."""
    prepare_destination(Path(path), overwrite=overwrite, format=TRANSFER_FORMAT, what=WHAT)


def write_transfer_store(path: str | os.PathLike, scene, *, overwrite: bool, diffuse: np.ndarray,
                         glossy_ids: np.ndarray, glossy: np.ndarray | None = None, cut_nodes: np.ndarray | None = None,
                         tree=None, hierarchy_seconds: float | None = None, environment: tuple | None = None,
                         attrs: dict) -> Path:
    """Write a ``lodprt-transfer`` store at ``path`` through :class:`StoreWriter` (a killed write never touches
    ``path``); returns the path.

    scene: the baked :class:`lodprt.model.scene.Scene` (geometry and materials are stored); diffuse (V, 3, n*n)
    transfer of every vertex; glossy_ids (G,) and glossy (G, g*g, n*n) or None; with ``cut_nodes`` (LOD) only the
    vertices of those nodes of ``tree`` keep their diffuse vectors, and the hierarchy is stored
    (``hierarchy_seconds`` its build time); environment: None or (coefficients (3, n*n), {"source", "kind",
    "resolution"}), the default lighting; attrs: the bake's root attributes after ``format``, ``format_version``
    and ``lodprt_version`` (docs/FORMAT.md).
    """
    from lodprt.version import __version__

    writer = StoreWriter(path, overwrite=overwrite, format=TRANSFER_FORMAT, what=WHAT)
    try:
        arr = writer.array
        arr("scene/positions", scene.positions.astype(np.float32))
        arr("scene/normals", scene.normals.astype(np.float32))
        arr("scene/faces", scene.faces.astype(np.int32))
        arr("scene/material_id", scene.material_id.astype(np.int32))
        arr("materials/kd", np.array([m.kd for m in scene.materials], np.float32))
        arr("materials/ks", np.array([m.ks for m in scene.materials], np.float32))
        arr("materials/shininess", np.array([m.shininess for m in scene.materials], np.float32))
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
        if glossy is not None:
            arr("transfer/glossy", glossy)
        if environment is not None:
            coefficients, env_attrs = environment
            arr("environment/coefficients", coefficients)
            writer.attrs("environment", **env_attrs)
        writer.attrs(format=TRANSFER_FORMAT, format_version=TRANSFER_FORMAT_VERSION, lodprt_version=__version__,
                     **attrs)
        return writer.commit()
    except BaseException:
        writer.abort()
        raise


def complete_transfer(h, positions, normals, cut_nodes, coefficients) -> np.ndarray:
    """Transfer vectors of every vertex from those of a cut's vertices (T-15 completion, ``lodprt.model.completion``):
    cut_nodes (K,), coefficients (K, ...) at ``h.vertex[cut_nodes]`` -> (V, ...) float64."""
    from lodprt.model.completion import CompletionPlan

    cut_nodes = np.asarray(cut_nodes)
    plan = CompletionPlan(h, positions, normals)
    return plan.complete(h.vertex[cut_nodes], np.asarray(coefficients), h.num_vertices, cut_nodes=cut_nodes,
                         dark=np.zeros(len(cut_nodes), bool))


class TransferStore:
    """Read access to a ``lodprt-transfer`` store (docs/FORMAT.md)."""

    def __init__(self, path):
        import zarr

        self.path = Path(path)
        if not self.path.exists():
            raise StoreError(f"{self.path}: no such store")
        if not is_transfer_store(self.path):
            raise StoreError(f"{self.path}: not a lodprt transfer store (zarr.json without attribute format='{TRANSFER_FORMAT}'; "
                             "bake one with lodprt bake-environment)")
        self.root = zarr.open_group(str(self.path), mode="r")
        self.attrs = dict(self.root.attrs)
        if self.attrs.get("format_version") != TRANSFER_FORMAT_VERSION:
            raise StoreError(f"{self.path}: format_version {self.attrs.get('format_version')!r}; this lodprt reads "
                             f"version {TRANSFER_FORMAT_VERSION}")

    def read(self, name: str) -> np.ndarray:
        try:
            return self.root[name][...]
        except KeyError as exc:
            raise StoreError(f"{self.path}: field '{name}' is missing") from exc

    def has(self, name: str) -> bool:
        try:
            self.root[name]
            return True
        except KeyError:
            return False

    @property
    def order(self) -> int:
        return int(self.attrs["sh_order"])

    def diffuse(self) -> np.ndarray:
        """(V, 3, n*n) diffuse transfer of every vertex; a LOD store's missing vertices are completed (T-15)."""
        if not hasattr(self, "_diffuse"):
            t = self.read("transfer/diffuse")
            if self.has("transfer/cut_nodes"):
                from lodprt.model.hierarchy import Hierarchy

                arrays = {name: self.read(f"hierarchy/{name}") for name in Hierarchy.ARRAYS if self.has(f"hierarchy/{name}")}
                tree = Hierarchy.from_arrays(arrays)
                t = complete_transfer(tree, self.read("scene/positions").astype(np.float64),
                                      self.read("scene/normals").astype(np.float64), self.read("transfer/cut_nodes"),
                                      t.astype(np.float64)).astype(np.float32)
            self._diffuse = t
        return self._diffuse
