"""Reading the stores of a lodprt format other than the point-light bake (``lodprt-transfer``, ``lodprt-volume``,
``lodprt-neighbourhood``; docs/FORMAT.md, docs/VOLUMES.md): ``FormatStore`` opens the zarr group, checks its
``format`` and ``format_version`` and reads its arrays, with errors that name the store and the field."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lodprt.errors import StoreError


class FormatStore:
    """Read access to a store of ``FORMAT`` written by a lodprt that writes one of ``VERSIONS``; subclasses set
    ``FORMAT``, ``VERSIONS``, ``WHAT`` (what messages call it) and ``BAKE`` (the command that bakes one)."""

    FORMAT: str = ""
    VERSIONS: tuple[int, ...] = ()
    WHAT = ""
    BAKE = ""

    def __init__(self, path):
        import zarr

        from lodprt.store.writer import store_format

        self.path = Path(path)
        if not self.path.exists():
            raise StoreError(f"{self.path}: no such store")
        if store_format(self.path) != self.FORMAT:
            raise StoreError(f"{self.path}: not a {self.WHAT} (zarr.json without attribute format='{self.FORMAT}'; "
                             f"bake one with {self.BAKE})")
        self.root = zarr.open_group(str(self.path), mode="r")
        self.attrs = dict(self.root.attrs)
        if self.attrs.get("format_version") not in self.VERSIONS:
            read = (f"version {self.VERSIONS[0]}" if len(self.VERSIONS) == 1
                    else f"versions {', '.join(map(str, self.VERSIONS))}")
            raise StoreError(f"{self.path}: format_version {self.attrs.get('format_version')!r}; this lodprt reads "
                             f"{read}")

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
        """SH bands of the lighting the store's transfer takes."""
        return int(self.attrs["sh_order"])
