"""Neighbourhood transfer store (``lodprt-neighbourhood``, docs/VOLUMES.md "Stores"): the transfer matrices on a
grid around an object O, O's own geometry and diffuse self-transfer (to draw O and for its reflected light), and
optionally the default lighting. The bake is :mod:`lodprt.precompute.neighbourhood`.

Layout: root attributes ``format = "lodprt-neighbourhood"``, ``format_version``, ``lodprt_version``, ``object``,
``grid`` [NX, NY, NZ], ``lo``, ``hi``, ``sh_order`` (lighting), ``transferred_order`` and the bake's settings;
``grid/matrices`` (NX, NY, NZ, 3, no*no, ni*ni) float32; ``object/positions``, ``object/normals`` (V, 3) float32,
``object/faces`` (F, 3) int32, ``object/albedo`` (V, 3) float32, ``object/transfer`` (V, 3, ni*ni) float32;
``environment/coefficients`` (3, ni*ni) when the bake stored a lighting.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lodprt.errors import StoreError
from lodprt.store.reader import FormatStore
from lodprt.store.writer import NEIGHBOURHOOD_FORMAT, StoreWriter, prepare_destination, store_format

NEIGHBOURHOOD_FORMAT_VERSION = 1
WHAT = "lodprt neighbourhood store"


def is_neighbourhood_store(path) -> bool:
    return store_format(path) == NEIGHBOURHOOD_FORMAT


def prepare_neighbourhood_destination(path: str | os.PathLike, *, overwrite: bool) -> None:
    """Tidy leftovers of interrupted bakes of ``path`` and refuse to replace anything but a neighbourhood store."""
    prepare_destination(Path(path), overwrite=overwrite, format=NEIGHBOURHOOD_FORMAT, what=WHAT)


def write_neighbourhood_store(path: str | os.PathLike, *, overwrite: bool, matrices: np.ndarray, arrays: dict,
                              environment: tuple | None = None, attrs: dict) -> Path:
    """Write a ``lodprt-neighbourhood`` store at ``path`` (atomic); returns it.

    matrices (NX, NY, NZ, 3, no^2, ni^2); arrays: ``object/...`` name -> array (the layout above); environment:
    None or (coefficients (3, ni^2), {"source", "kind", "resolution"}); attrs: the bake's root attributes.
    """
    from lodprt.version import __version__

    with StoreWriter(path, overwrite=overwrite, format=NEIGHBOURHOOD_FORMAT, what=WHAT) as writer:
        writer.array("grid/matrices", np.asarray(matrices, np.float32))
        for name, a in arrays.items():
            writer.array(name, a)
        writer.environment(environment)
        writer.attrs(format=NEIGHBOURHOOD_FORMAT, format_version=NEIGHBOURHOOD_FORMAT_VERSION,
                     lodprt_version=__version__, **attrs)
        return writer.commit()


class NeighbourhoodStore(FormatStore):
    """Read access to a ``lodprt-neighbourhood`` store."""

    FORMAT, VERSIONS, WHAT = NEIGHBOURHOOD_FORMAT, (NEIGHBOURHOOD_FORMAT_VERSION,), WHAT
    BAKE = "lodprt bake-neighbourhood"

    def __init__(self, path):
        super().__init__(path)
        for key in ("lo", "hi", "grid", "sh_order"):
            if key not in self.attrs:
                raise StoreError(f"{self.path}: root attribute '{key}' is missing")

    def required_parts(self) -> list[str]:
        """The arrays ``write_neighbourhood_store`` writes: the grid's matrices and O's geometry and transfer."""
        return super().required_parts() + ["grid/matrices"] + [
            f"object/{name}" for name in ("positions", "normals", "faces", "albedo", "transfer")]

    @property
    def lo(self) -> np.ndarray:
        return np.asarray(self.attrs["lo"], np.float64)

    @property
    def hi(self) -> np.ndarray:
        return np.asarray(self.attrs["hi"], np.float64)

    def matrices(self) -> np.ndarray:
        """(NX, NY, NZ, 3, no^2, ni^2) float32 transfer matrices M_p (N-2)."""
        if not hasattr(self, "_matrices"):
            m = self.read("grid/matrices")
            if m.ndim != 6 or list(m.shape[:3]) != list(self.attrs["grid"]) or m.shape[3] != 3:
                raise StoreError(f"{self.path}: grid/matrices {m.shape} does not fit grid {self.attrs['grid']}")
            self._matrices = m
        return self._matrices
