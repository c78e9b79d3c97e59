"""Reading the stores of a lodprt format other than the point-light bake (``lodprt-transfer``, ``lodprt-volume``,
``lodprt-neighbourhood``; docs/FORMAT.md, docs/VOLUMES.md): ``FormatStore`` opens the zarr group, checks its
``format`` and ``format_version`` and reads its arrays, with errors that name the store and the field.

``read_array`` is how every store's arrays are read (``Store.read`` too): a garbled chunk, or a chunk file missing
from a store whose writer stored every chunk (root attribute ``all_chunks``), is a one-line ``StoreError`` naming
the store and the array, never a zarr traceback nor zeros in place of the lost data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lodprt.errors import StoreError
from lodprt.store.writer import ALL_CHUNKS


def read_array(root, path: Path, name: str, *, all_chunks: bool) -> np.ndarray:
    """Array ``name`` of the zarr group ``root`` of the store at ``path``, read whole; ``all_chunks``: the writer
    stored every chunk, so one missing is damage (older stores skipped all-zero chunks, which read as zeros)."""
    try:
        arr = root[name]
    except KeyError as exc:
        raise StoreError(f"{path}: field '{name}' is missing") from exc
    hint = f"; inspect the store with: lodprt info {path}"
    try:
        value = arr[...]
        missing = arr.nchunks - arr.nchunks_initialized if all_chunks and arr.size else 0
    except Exception as exc:  # noqa: BLE001 -- codecs raise RuntimeError, ValueError, ... for a garbled chunk
        detail = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise StoreError(f"{path}: array '{name}' is damaged, a chunk cannot be read ({detail}){hint}") from exc
    if missing:
        raise StoreError(f"{path}: array '{name}' is damaged, {missing} of its {arr.nchunks} chunk files are "
                         f"missing{hint}")
    return value


def array_names(group, prefix: str = "") -> list[str]:
    """The paths of every array under the zarr ``group``, sorted, sub-groups included."""
    names = []
    for name, member in sorted(group.members()):
        names.extend([prefix + name] if hasattr(member, "shape") else array_names(member, f"{prefix}{name}/"))
    return names


def damage(root, path: Path, *, all_chunks: bool, verify: bool = False) -> list[str]:
    """What is damaged in the store at ``path`` (zarr group ``root``), one line per array: a chunk file missing
    from a store whose writer stored every chunk; with ``verify``, every array read whole, so a garbled chunk is
    found too (``lodprt info --verify``). Empty when nothing is."""
    found = []
    for name in array_names(root):
        try:
            if verify:
                read_array(root, path, name, all_chunks=all_chunks)
            else:
                arr = root[name]
                missing = arr.nchunks - arr.nchunks_initialized if all_chunks and arr.size else 0
                if missing:
                    found.append(f"array '{name}': {missing} of its {arr.nchunks} chunk files are missing")
        except StoreError as exc:
            found.append(str(exc).removeprefix(f"{path}: ").split("; inspect the store")[0])
    return found


def folder_bytes(folder) -> int:
    """Bytes of the files under ``folder`` (0 when it does not exist): a store's size on disk."""
    folder = Path(folder)
    return int(sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())) if folder.exists() else 0


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
        return read_array(self.root, self.path, name, all_chunks=bool(self.attrs.get(ALL_CHUNKS)))

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

    def summary(self, *, verify: bool = False) -> dict:
        """What ``lodprt info`` prints of a store of this kind: its kind, format version, the command that bakes
        one, its root attributes (JSON values only; long lists shortened) and every array's shape and dtype, with
        the bytes on disk and what is damaged (``damage``; ``verify``: every array read whole)."""
        def plain(v):
            if isinstance(v, (list, tuple)) and len(v) > 12:
                return f"{len(v)} values"
            return v if isinstance(v, (str, int, float, bool, list, tuple, dict)) or v is None else str(v)

        arrays = {name: {"shape": list(self.root[name].shape), "dtype": str(self.root[name].dtype)}
                  for name in array_names(self.root)}
        return {"store": str(self.path), "kind": self.WHAT, "format": self.FORMAT,
                "format_version": self.attrs.get("format_version"), "baked_by": self.BAKE,
                "attrs": {k: plain(v) for k, v in sorted(self.attrs.items()) if k not in ("format", "format_version")},
                "arrays": arrays, "bytes_on_disk": folder_bytes(self.path),
                "damage": damage(self.root, self.path, all_chunks=bool(self.attrs.get(ALL_CHUNKS)), verify=verify)}
