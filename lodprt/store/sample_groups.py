"""Completion marks: which groups of a bake store (or of its partial folder) are finished (docs/FORMAT.md,
"Completion marks and resumed bakes").

A group of a store is complete when its ``zarr.json`` carries the attribute ``complete: true``. The mark is always
written last, after every array of the group, so a killed bake leaves either a complete group or one without the
mark, which a resumed bake deletes and writes again. zarr writes every file to a temporary name and renames it
into place, so a mark is never half written.

Light samples go further: :class:`SampleGroupWriter` writes a sample's group under ``.writing/`` of the partial
folder and renames the finished group (mark included) to ``samples/KKKKK`` in one step, so a sample group that
exists is complete, even when two processes bake the same sample at once (a dask task run twice, a worker killed
mid-task): the second rename finds the group there and drops its own copy.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import uuid
from pathlib import Path

from lodprt.errors import StoreError
from lodprt.store.bake_store import sample_group
from lodprt.store.writer import OWNER_FILE, StoreWriter

#: the attribute that marks a group complete (written after everything else of the group)
COMPLETE = "complete"
#: folder of a partial store where sample groups are assembled before they move to ``samples/``
WRITING = ".writing"
#: the groups of a bake store with a completion mark besides the samples: ``scene`` covers ``scene/*``,
#: ``materials/*`` and ``lights/*``; ``hierarchy`` covers ``hierarchy/*``
MARKED_GROUPS = ("scene", "hierarchy")
# zarr's temporary files (``<name>.<32 hex digits>.partial``), left behind when a write was killed
_ZARR_TEMP = re.compile(r"\.[0-9a-f]{32}\.partial$")


def group_attrs(folder: str | os.PathLike) -> dict | None:
    """The attributes of the zarr group at ``folder`` (None when it has no readable ``zarr.json``)."""
    try:
        doc = json.loads((Path(folder) / "zarr.json").read_text())
    except (OSError, ValueError):
        return None
    attrs = doc.get("attributes") if isinstance(doc, dict) else None
    return attrs if isinstance(attrs, dict) else None


def is_complete(folder: str | os.PathLike) -> bool:
    """True when the group at ``folder`` carries the completion mark."""
    attrs = group_attrs(folder)
    return bool(attrs and attrs.get(COMPLETE) is True)


def complete_samples(store: str | os.PathLike, count: int) -> list[int]:
    """Indices ``k < count`` whose ``samples/KKKKK`` group in ``store`` is complete."""
    root = Path(store)
    return [k for k in range(count) if is_complete(root / sample_group(k))]


def discard_incomplete(store: str | os.PathLike, names) -> list[str]:
    """Delete the groups ``names`` (paths inside ``store``) that exist without a completion mark; returns them."""
    gone = []
    for name in names:
        folder = Path(store) / name
        if folder.exists() and not is_complete(folder):
            shutil.rmtree(folder)
            gone.append(name)
    return gone


def tidy(store: str | os.PathLike) -> int:
    """Remove what killed writers leave inside a partial folder: the ``.writing`` area of unfinished sample groups,
    zarr's temporary files and half-claimed owner records. Returns the number of files and folders removed."""
    root = Path(store)
    removed = 0
    if (root / WRITING).exists():
        shutil.rmtree(root / WRITING)
        removed += 1
    for stray in root.glob(f"{OWNER_FILE}.*"):
        stray.unlink(missing_ok=True)
        removed += 1
    for folder, _dirs, files in os.walk(root):
        for name in files:
            if _ZARR_TEMP.search(name):
                (Path(folder) / name).unlink(missing_ok=True)
                removed += 1
    return removed


class SampleGroupWriter(StoreWriter):
    """Writes one light sample's group of the partial store at ``partial`` (any process may make one).

    ``array`` and ``attrs`` are :class:`StoreWriter`'s and take the same names (``samples/KKKKK/...``), so a sample
    is encoded exactly as the in-process writer encodes it; they go to a private folder under ``.writing/``.
    :meth:`finish` writes the completion mark and moves the group to ``samples/KKKKK``.
    """

    def __init__(self, partial: str | os.PathLike, k: int):  # noqa: D107 -- no StoreWriter.__init__: no destination
        import zarr

        self.partial = Path(partial)
        self.k = k
        self.group = sample_group(k)
        if not (self.partial / "samples").is_dir():
            raise StoreError(f"{self.partial}: no samples/ group; not a partial bake store being written")
        self.scratch = self.partial / WRITING / f"{k:05d}-{os.getpid()}-{uuid.uuid4().hex[:12]}"
        self.scratch.parent.mkdir(exist_ok=True)  # never parents=True: a partial folder renamed away stays away
        self.scratch.mkdir()
        self.root = zarr.open_group(str(self.scratch), mode="a", zarr_format=3)

    @property
    def destination(self) -> Path:
        """The partial store this sample group belongs to (what a disk-full error names)."""
        return self.partial

    def commit(self):  # a sample group is finished with finish(), never committed as a store
        raise StoreError("SampleGroupWriter: call finish(), not commit()")

    def finish(self) -> bool:
        """Mark the group complete and move it into place; False when another process finished it first."""
        self.attrs(self.group, **{COMPLETE: True})
        target = self.partial / self.group
        try:
            if target.exists() and not is_complete(target):
                shutil.rmtree(target)  # a writer killed before the rename-based scheme, or an interrupted delete
            os.rename(self.scratch / self.group, target)
            done = True
        except OSError:
            if not is_complete(target):
                raise
            done = False  # someone else's finished copy is there (identical: a sample depends on its light only)
        shutil.rmtree(self.scratch, ignore_errors=True)
        return done

    def abort(self) -> None:
        shutil.rmtree(self.scratch, ignore_errors=True)
