"""Volume transfer store (``lodprt-volume``, docs/VOLUMES.md "Store"): writing a volumetric self-transfer bake and
reading it back. The bake itself is :mod:`lodprt.precompute.volume`.

Layout: root attributes ``format = "lodprt-volume"``, ``format_version``, ``lodprt_version``, the bake's settings;
``volume/density`` (X, Y, Z) float32 sigma_t, ``volume`` attributes ``lo``, ``hi``, ``albedo``;
``transfer/vectors`` (X, Y, Z, 3, n*n) float32; optionally ``environment/coefficients`` (3, n*n).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lodprt.errors import StoreError
from lodprt.store.reader import FormatStore
from lodprt.store.writer import VOLUME_FORMAT, StoreWriter, prepare_destination, store_format

VOLUME_FORMAT_VERSION = 1
WHAT = "lodprt volume store"


def is_volume_store(path) -> bool:
    return store_format(path) == VOLUME_FORMAT


def prepare_volume_destination(path: str | os.PathLike, *, overwrite: bool) -> None:
    """Tidy leftovers of interrupted bakes of ``path`` and refuse to replace anything but a volume store."""
    prepare_destination(Path(path), overwrite=overwrite, format=VOLUME_FORMAT, what=WHAT)


def write_volume_store(path: str | os.PathLike, volume, *, overwrite: bool, transfer: np.ndarray,
                       environment: tuple | None = None, attrs: dict) -> Path:
    """Write a ``lodprt-volume`` store at ``path`` (atomic: a killed write never touches ``path``); returns it.

    volume: the baked :class:`lodprt.model.volume.Volume`; transfer (X, Y, Z, 3, n*n); environment: None or
    (coefficients (3, n*n), {"source", "kind", "resolution"}); attrs: the bake's root attributes.
    """
    from lodprt.version import __version__

    t = np.asarray(transfer, np.float32)
    if t.shape[:4] != volume.shape + (3,):
        raise StoreError(f"{path}: transfer {t.shape} does not fit the volume grid {volume.shape}")
    with StoreWriter(path, overwrite=overwrite, format=VOLUME_FORMAT, what=WHAT) as writer:
        writer.array("volume/density", volume.density.astype(np.float32))
        writer.attrs("volume", lo=volume.lo.tolist(), hi=volume.hi.tolist(), albedo=volume.albedo.tolist())
        writer.array("transfer/vectors", t)
        writer.environment(environment)
        writer.attrs(format=VOLUME_FORMAT, format_version=VOLUME_FORMAT_VERSION, lodprt_version=__version__,
                     shape=list(volume.shape), **attrs)
        return writer.commit()


class VolumeStore(FormatStore):
    """Read access to a ``lodprt-volume`` store."""

    FORMAT, VERSIONS, WHAT, BAKE = VOLUME_FORMAT, (VOLUME_FORMAT_VERSION,), WHAT, "lodprt bake-volume"

    def required_parts(self) -> list[str]:
        """The arrays ``write_volume_store`` writes: the density and the transfer vectors."""
        return super().required_parts() + ["volume/density", "transfer/vectors"]

    def required_attributes(self) -> list[tuple[str, tuple[str, ...]]]:
        """The root's and the ``volume`` group's attributes (its box and albedo)."""
        return super().required_attributes() + [("volume", ("lo", "hi", "albedo"))]

    def volume(self):
        """The baked :class:`lodprt.model.volume.Volume` (density, box, albedo)."""
        from lodprt.model.volume import Volume

        a = dict(self.root["volume"].attrs)
        try:
            # named by the store that holds the values (the bake's source file, where they were read, is not)
            return Volume(self.read("volume/density"), np.array(a["lo"]), np.array(a["hi"]), np.array(a["albedo"]),
                          f"{self.path}: volume")
        except KeyError as exc:
            raise StoreError(f"{self.path}: volume attribute {exc} is missing") from exc

    def transfer(self) -> np.ndarray:
        """(X, Y, Z, 3, n*n) float32 transfer vectors."""
        t = self.read("transfer/vectors")
        d = self.root["volume/density"].shape
        if t.ndim != 5 or t.shape[:4] != tuple(d) + (3,):
            raise StoreError(f"{self.path}: transfer/vectors {t.shape} does not fit volume/density {tuple(d)}")
        return t
