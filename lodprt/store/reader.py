"""Reading the stores of a lodprt format other than the point-light bake (``lodprt-transfer``, ``lodprt-volume``,
``lodprt-neighbourhood``; docs/FORMAT.md, docs/VOLUMES.md): ``FormatStore`` opens the zarr group, checks its
``format`` and ``format_version`` and reads its arrays, with errors that name the store and the field.

``read_array`` is how every store's arrays are read (``Store.read`` too): a garbled chunk, or a chunk file missing
from a store whose writer stored every chunk (root attribute ``all_chunks``), is a one-line ``StoreError`` naming
the store and the array, never a zarr traceback nor zeros in place of the lost data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lodprt.errors import StoreError
from lodprt.store.writer import ALL_CHUNKS


def read_array(root, path: Path, name: str, *, all_chunks: bool) -> np.ndarray:
    """Array ``name`` of the zarr group ``root`` of the store at ``path``, read whole; ``all_chunks``: the writer
    stored every chunk, so one missing is damage (older stores skipped all-zero chunks, which read as zeros)."""
    value, problem = check_array(open_array(root, path, name), all_chunks=all_chunks, read=True)
    if problem:
        raise StoreError(f"{path}: array '{name}' is damaged, {problem}; inspect the store with: lodprt info {path}")
    return value


def open_array(root, path: Path, name: str):
    """The zarr array ``name`` of ``root`` (the store at ``path``), unread; StoreError when it is gone or its
    metadata (its ``zarr.json``, or a group's above it) cannot be read."""
    try:
        return root[name]
    except KeyError as exc:
        raise StoreError(f"{path}: field '{name}' is missing") from exc
    except Exception as exc:  # noqa: BLE001 -- a garbled zarr.json: JSONDecodeError, TypeError, ...
        raise StoreError(f"{path}: array '{name}' is damaged, its metadata cannot be read ({brief(exc)}); inspect "
                         f"the store with: lodprt info {path}") from exc


def check_array(arr, *, all_chunks: bool, read: bool) -> tuple[np.ndarray | None, str | None]:
    """(the zarr array ``arr``'s values when ``read``, else None; what is damaged in it, or None): a chunk that
    cannot be read (``read`` only), or chunk files missing where the writer stored every chunk (``all_chunks``)."""
    value = None
    if read:
        try:
            value = arr[...]
        except Exception as exc:  # noqa: BLE001 -- codecs raise RuntimeError, ValueError, ... for a garbled chunk
            return None, f"a chunk cannot be read ({brief(exc)})"
    missing = arr.nchunks - arr.nchunks_initialized if all_chunks and arr.size else 0
    return value, (f"{missing} of its {arr.nchunks} chunk files are missing" if missing else None)


def brief(exc: Exception) -> str:
    """An exception in one line of at most 200 characters (its type when it says nothing)."""
    return " ".join(str(exc).split())[:200] or type(exc).__name__


def walk(path: Path) -> tuple[list[str], list[str]]:
    """(the paths of every array in the zarr v3 store folder ``path``, sorted; what is damaged in its metadata):
    read from the folders' ``zarr.json`` files, so a garbled one, or a folder of files that lost its own (zarr no
    longer sees it), is named rather than raised or skipped."""
    arrays, problems = [], []

    def visit(folder: Path, prefix: str) -> None:
        for child in sorted(p for p in folder.iterdir() if p.is_dir()):
            name, meta = prefix + child.name, child / "zarr.json"
            if not meta.is_file():
                if any(f.is_file() for f in child.rglob("*")):
                    problems.append(f"'{name}': its zarr.json is missing, so its data cannot be found")
                continue
            try:
                kind = json.loads(meta.read_bytes())["node_type"]
            except (ValueError, KeyError, TypeError) as exc:  # garbled JSON, or JSON without node_type
                problems.append(f"'{name}/zarr.json' cannot be read ({brief(exc)})")
                continue
            if kind == "array":
                arrays.append(name)
            elif kind == "group":
                visit(child, name + "/")
            else:  # zarr opens neither: the folder's data cannot be found
                problems.append(f"'{name}/zarr.json' names no array or group (node_type {kind!r})")

    visit(path, "")
    return arrays, problems


def damage(root, path: Path, *, all_chunks: bool, verify: bool = False) -> list[str]:
    """What is damaged in the store at ``path`` (zarr group ``root``), one line per array or folder: metadata that
    is garbled or gone (``walk``); a chunk file missing from a store whose writer stored every chunk; with
    ``verify``, every array read whole, so a garbled chunk is found too (``lodprt info --verify``). Empty when
    nothing is."""
    arrays, found = walk(path)
    opened, problems = open_arrays(root, arrays)
    found += problems
    for name, arr in opened.items():
        problem = check_array(arr, all_chunks=all_chunks, read=verify)[1]
        if problem:
            found.append(f"array '{name}': {problem}")
    return found


def open_arrays(root, names) -> tuple[dict, list[str]]:
    """({name: zarr array} of the ``names`` (``walk``'s) of the zarr group ``root`` that open; one line for each
    whose metadata zarr rejects, a data type it does not know, say)."""
    opened, problems = {}, []
    for name in names:
        try:
            opened[name] = root[name]
        except Exception as exc:  # noqa: BLE001 -- JSON that zarr's metadata rejects: ValueError, TypeError, ...
            problems.append(f"array '{name}': its metadata cannot be read ({brief(exc)})")
    return opened, problems


def missing_parts(path: Path, names) -> list[str]:
    """One line per part of ``names`` (arrays or groups of the store at ``path``, a group before its arrays) whose
    folder is gone; the arrays of a group already named are not named again."""
    gone: list[str] = []
    for name in names:
        if not (path / name).is_dir() and not any(name.startswith(g + "/") for g in gone):
            gone.append(name)
    return [f"'{name}' is missing" for name in gone]


def missing_attributes(root, wanted) -> list[str]:
    """One line per group of ``wanted`` ((group path, "" for the root; attribute names)) of the zarr group ``root``
    that lacks some of its attributes; a group that is gone or garbled is left to ``walk`` and ``missing_parts``."""
    found = []
    for where, keys in wanted:
        try:
            attrs = root.attrs if not where else root[where].attrs
        except Exception:  # noqa: BLE001, S112 -- gone or its zarr.json garbled: named by the other checks
            continue
        lost = [key for key in keys if key not in attrs]
        if lost:
            found.append(f"{where or 'root'}: attribute(s) {', '.join(lost)} missing")
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

        opened = open_arrays(self.root, walk(self.path)[0])[0]  # metadata zarr rejects: ``damage`` names it
        arrays = {name: {"shape": list(arr.shape), "dtype": str(arr.dtype)} for name, arr in opened.items()}
        return {"store": str(self.path), "kind": self.WHAT, "format": self.FORMAT,
                "format_version": self.attrs.get("format_version"), "baked_by": self.BAKE,
                "attrs": {k: plain(v) for k, v in sorted(self.attrs.items()) if k not in ("format", "format_version")},
                "arrays": arrays, "bytes_on_disk": folder_bytes(self.path), "damage": self.damage(verify=verify)}

    def damage(self, *, verify: bool = False) -> list[str]:
        """What is damaged in this store, one line each: ``damage`` (metadata garbled or gone, chunk files missing,
        with ``verify`` every array read whole), every part and attribute its bake wrote that is gone."""
        found = damage(self.root, self.path, all_chunks=bool(self.attrs.get(ALL_CHUNKS)), verify=verify)
        return (found + missing_parts(self.path, self.required_parts())
                + missing_attributes(self.root, self.required_attributes()))

    def required_parts(self) -> list[str]:
        """The arrays every bake of this kind writes (subclasses add theirs to these): the lighting's coefficients
        when the bake stored one (its ``environment`` group is there)."""
        return ["environment/coefficients"] if (self.path / "environment").is_dir() else []

    def required_attributes(self) -> list[tuple[str, tuple[str, ...]]]:
        """(group, "" for the root; the attributes of it that every bake of this kind writes and readers need)."""
        return [("", ("sh_order",))]
