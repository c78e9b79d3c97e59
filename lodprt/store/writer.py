"""Atomic writing of every lodprt store format (docs/FORMAT.md, "Interrupted bakes"): ``StoreWriter`` creates a
store in a sibling ``<name>.partial-<pid>`` folder that is renamed into place only when the bake finished, so an
interrupted bake never leaves a half store and never destroys the previous one. An existing path is replaced only
with ``overwrite=True`` and only when it is itself a store of the same format. What a killed bake leaves behind (a
partial folder, or the previous store parked as ``<name>.replaced-<pid>``) is cleaned up or restored by the next
writer of the same path (``clean_leftovers``), or adopted by ``bake --resume`` (``dead_partials``).

Every chunk of every array is written, all-zero ones included (zarr would skip them and read them back as zeros),
so that a reader can tell a missing chunk file from an empty one (``lodprt.store.reader.read_array``). A full
disk while writing (OSError ENOSPC) becomes a one-line ``DiskFull`` naming the store, what was being written and
the bytes it needed (``no_space``).
"""

from __future__ import annotations

import contextlib
import errno
import glob
import json
import logging
import os
import shutil
import socket
from pathlib import Path

import numpy as np

from lodprt.errors import DiskFull, StoreError

log = logging.getLogger(__name__)

FORMAT_NAME = "lodprt"
#: the ``format`` of an environment transfer store (``lodprt.store.transfer_store``)
TRANSFER_FORMAT = "lodprt-transfer"
#: the ``format`` of a volume transfer store and of a neighbourhood transfer store (``lodprt.store.volume_store``,
#: ``lodprt.store.neighbourhood_store``; docs/VOLUMES.md)
VOLUME_FORMAT = "lodprt-volume"
NEIGHBOURHOOD_FORMAT = "lodprt-neighbourhood"
#: every store format lodprt writes through ``StoreWriter``
KNOWN_FORMATS = (FORMAT_NAME, TRANSFER_FORMAT, VOLUME_FORMAT, NEIGHBOURHOOD_FORMAT)
#: owner record inside a partial folder (and inside a parked ``.replaced-<pid>`` store while a commit runs):
#: host, pid, boot id and process start time of the writer, so a later bake can tell a dead writer from a live one
#: even when the pid has been reused. Removed before the folder becomes the store (zarr warns about unknown files).
OWNER_FILE = ".lodprt-owner.json"
#: root attribute of a store whose every array has every chunk on disk (written by this writer since it stores
#: all-zero chunks too): a reader treats a missing chunk file there as damage, not as zeros
ALL_CHUNKS = "all_chunks"


def no_space(exc: OSError, store: Path, what: str, needed: int | None = None) -> DiskFull:
    """The ``DiskFull`` error of ``exc`` (ENOSPC) while writing ``what`` of ``store``: names both, the bytes needed
    when known and what the file system has free."""
    try:
        free = f"{shutil.disk_usage(store.parent).free / 2**20:,.1f} MiB free"
    except OSError:
        free = "free space unknown"
    need = "" if needed is None else f"needed {needed / 2**20:,.1f} MiB uncompressed, "
    return DiskFull(f"{store}: no space left on the device writing {what} ({need}{free} in {store.parent}); "
                    "the unfinished store is removed and any earlier store at this path is unchanged")


@contextlib.contextmanager
def disk_space(store: Path, what: str, needed: int | None = None):
    """Turn an OSError ENOSPC inside the block into ``no_space``'s ``DiskFull``; other errors pass unchanged."""
    try:
        yield
    except OSError as exc:
        if exc.errno != errno.ENOSPC:
            raise
        raise no_space(exc, store, what, needed) from exc


def store_format(path: str | os.PathLike) -> str | None:
    """The ``format`` attribute of the zarr v3 group at ``path`` (None when it is not one)."""
    try:
        doc = json.loads((Path(path) / "zarr.json").read_text())
    except (OSError, ValueError):
        return None
    attrs = doc.get("attributes") if isinstance(doc, dict) else None  # JSON, but not a group's (null, a list)
    return attrs.get("format") if isinstance(attrs, dict) else None


def check_destination(path: str | os.PathLike, *, overwrite: bool, format: str = FORMAT_NAME,
                      what: str = "lodprt store") -> None:
    """Refuse to write over anything, unless ``overwrite`` and the thing there is a store of ``format``."""
    path = Path(path)
    if path.is_symlink():  # replacing it would empty the folder it points to, or write there
        raise StoreError(f"{path}: is a symbolic link (to {os.readlink(path)}); name the store's own folder, or "
                         "remove the link")
    if not path.exists():
        if not path.parent.is_dir():  # a parent that is a file raised NotADirectoryError making the partial folder
            what = "is a file, not a folder" if path.parent.exists() else "does not exist"
            raise StoreError(f"{path}: the folder {path.parent} {what}")
        return
    if not overwrite:
        raise StoreError(f"{path}: already exists; pass overwrite=True to replace it")
    if store_format(path) != format:
        raise StoreError(f"{path}: exists and is not a {what}; refusing to replace it even with overwrite=True")


# -- leftovers of interrupted bakes ------------------------------------------------------------------------------


def _proc_stat(pid: int) -> tuple[str, int] | None:
    """(state, start time in clock ticks since boot) of ``pid`` from /proc (Linux); None where unreadable."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()  # the command name in (...) may hold spaces
    try:
        return fields[0], int(fields[19])  # fields 3 (state) and 22 (starttime) of proc(5)
    except (IndexError, ValueError):
        return None


def _boot_id() -> str | None:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return None


def process_identity(pid: int | None = None) -> dict:
    """What identifies a running process across pid reuse: host, pid, boot id and start time (None where the
    platform does not say)."""
    pid = os.getpid() if pid is None else int(pid)
    stat = _proc_stat(pid)
    return {"host": socket.gethostname(), "pid": pid, "boot_id": _boot_id(), "start": None if stat is None else stat[1]}


def _pid_running(pid: int) -> bool:
    if os.name == "nt":  # os.kill(pid, 0) would terminate the process on Windows: assume it runs
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by another user
        return True
    except OSError:
        return True  # cannot tell: err on the side of leaving its folder alone
    stat = _proc_stat(pid)
    return stat is None or stat[0] != "Z"  # a zombie has finished writing for good


def writer_alive(owner: dict) -> bool | None:
    """True when the process of an owner record still runs, False when it is gone (or its pid now belongs to a
    process started later), None when this host cannot tell (written on another host)."""
    if owner.get("host") not in (None, socket.gethostname()):
        return None
    boot = _boot_id()
    if owner.get("boot_id") and boot and owner["boot_id"] != boot:
        return False  # the machine rebooted since
    pid = int(owner["pid"])
    if not _pid_running(pid):
        return False
    if owner.get("start") is not None:
        stat = _proc_stat(pid)
        if stat is not None and stat[1] != owner["start"]:
            return False  # pid reused by an unrelated process
    return True


def _read_owner(folder: Path) -> dict | None:
    try:
        owner = json.loads((folder / OWNER_FILE).read_text())
        int(owner["pid"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return owner if isinstance(owner, dict) else None


def _write_owner(folder: Path) -> None:
    (folder / OWNER_FILE).write_text(json.dumps(process_identity()))


def _remove_tree(folder: Path) -> None:
    """Delete a partial or parked store, its markers (``zarr.json``, the owner file) last: killed half way, the
    rest stays recognisable and the next bake finishes the job."""
    if folder.is_symlink():  # a link is removed, never what it points to
        folder.unlink()
        return
    markers = {"zarr.json", OWNER_FILE}
    for child in folder.iterdir():
        if child.name in markers:
            continue
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()
    for name in markers:
        (folder / name).unlink(missing_ok=True)
    folder.rmdir()


def _leftovers(path: Path) -> list[tuple[Path, str, int]]:
    """Siblings ``<name>.partial-<pid>`` / ``<name>.replaced-<pid>`` of ``path``: (folder, kind, pid), parked
    stores first, newest first."""
    found = []
    for kind in ("replaced", "partial"):
        for folder in path.parent.glob(f"{glob.escape(path.name)}.{kind}-*"):
            tail = folder.name[len(path.name) + len(kind) + 2:]
            try:
                if tail.isdigit() and folder.is_dir() and not folder.is_symlink():
                    found.append((folder, kind, int(tail), folder.stat().st_mtime))
            except OSError:  # gone meanwhile (another writer cleaned it)
                continue
    found.sort(key=lambda f: (f[1] == "partial", -f[3]))
    return [f[:3] for f in found]


def clean_leftovers(path: str | os.PathLike) -> list[str]:
    """Tidy what killed writers of ``path`` left behind; returns one line per action (each also logged).

    A folder counts only when it is recognisably lodprt's: it holds the owner file, or it is a zarr group with a
    lodprt ``format`` attribute, or it is empty (but for an unreadable owner file); anything else is left alone
    with a warning. Its writer must be dead (owner record: host, pid, boot id and start time, so a reused pid does
    not keep it; without a record: the pid in the name). Then a ``.replaced-<pid>`` store is moved back to
    ``path`` when ``path`` is missing (the kill came between parking the old store and moving the new one in) and
    deleted otherwise; a ``.partial-<pid>`` is deleted. Folders of live writers, and of writers on other hosts,
    are never touched.
    """
    path = Path(path)
    actions: list[str] = []
    if not path.parent.is_dir():
        return actions
    for folder, kind, pid in _leftovers(path):
        owner = _read_owner(folder)
        try:
            # killed between mkdir and the owner record (or while writing it): nothing there worth keeping
            trivial = {c.name for c in folder.iterdir()} <= {OWNER_FILE}
        except OSError:
            continue
        if owner is None and not trivial and store_format(folder) not in KNOWN_FORMATS:
            log.warning("%s: named like a leftover of an interrupted bake but holds neither %s nor a lodprt zarr "
                        "group; left alone (remove it by hand if it is not yours)", folder, OWNER_FILE)
            continue
        owner = owner or {"pid": pid}
        alive = writer_alive(owner)
        if alive is not False:
            log.info("%s: left alone, its writer (pid %s%s) %s", folder, owner["pid"],
                     "" if alive else f" on host {owner.get('host')}", "is still running" if alive else "may still run")
            continue
        try:
            if kind == "replaced" and not path.exists() and store_format(folder) in KNOWN_FORMATS:
                (folder / OWNER_FILE).unlink(missing_ok=True)
                folder.rename(path)
                actions.append(f"{path}: restored the previous store from {folder.name}, parked there by a bake "
                               f"(pid {owner['pid']}) that was killed while replacing it")
            else:
                _remove_tree(folder)
                actions.append(f"{folder}: removed, left by an interrupted bake (pid {owner['pid']}, "
                               "no longer running)")
        except OSError as exc:  # e.g. another writer of the same path cleaned it first
            log.warning("%s: could not tidy this leftover of an interrupted bake: %s", folder, exc)
            continue
        log.warning("%s", actions[-1])
    return actions


def prepare_destination(path: str | os.PathLike, *, overwrite: bool, format: str = FORMAT_NAME,
                        what: str = "lodprt store") -> None:
    """``clean_leftovers`` then ``check_destination``: what every writer runs before any work."""
    clean_leftovers(path)
    check_destination(path, overwrite=overwrite, format=format, what=what)


def dead_partials(path: str | os.PathLike, format: str = FORMAT_NAME) -> list[Path]:
    """Partial folders ``<name>.partial-<pid>`` of ``path`` left by a writer that is no longer running and holding
    a zarr group of ``format`` (its root attributes were written): what ``bake --resume`` may adopt, newest first."""
    path = Path(path)
    found = []
    if path.parent.is_dir():
        for folder, kind, pid in _leftovers(path):
            if kind == "partial" and store_format(folder) == format:
                if writer_alive(_read_owner(folder) or {"pid": pid}) is False:
                    found.append(folder)
    return found


def _claim(folder: Path) -> None:
    """Write this process' owner record into ``folder`` in one step (a torn record would read as no record)."""
    tmp = folder / f"{OWNER_FILE}.{os.getpid()}"
    tmp.write_text(json.dumps(process_identity()))
    os.replace(tmp, folder / OWNER_FILE)


class StoreWriter:
    """Creates the store in a partial folder; ``commit()`` moves it into place.

    The partial folder holds an owner record (``OWNER_FILE``) until the commit, so that a bake killed with
    SIGKILL leaves something the next writer of the same path recognises and removes (``clean_leftovers``).
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool, format: str = FORMAT_NAME,
                 what: str = "lodprt store", adopt: str | os.PathLike | None = None):
        import zarr

        self.path = Path(path)
        if self.path.name in ("", ".", ".."):  # '.', '..', '/': the store needs a name of its own beside them
            raise StoreError(f"{path}: name the store's folder (e.g. out.zarr), not {str(path)!r}")
        self.format, self.what = format, what
        self.partial = self.path.with_name(f"{self.path.name}.partial-{os.getpid()}")
        if adopt is not None:  # resume a dead writer's partial folder (one of dead_partials): it becomes ours
            check_destination(self.path, overwrite=overwrite, format=format, what=what)
            adopt = Path(adopt)
            try:
                _claim(adopt)  # first our record (a live owner: nobody tidies it away), then our name
                if adopt != self.partial:
                    adopt.rename(self.partial)
                _claim(self.partial)
            except OSError as exc:
                raise StoreError(f"{adopt}: could not take over this interrupted bake ({exc}); another "
                                 "bake may be resuming it") from exc
        prepare_destination(self.path, overwrite=overwrite, format=format, what=what)
        self.overwrite = overwrite
        if adopt is not None:
            self.root = zarr.open_group(str(self.partial), mode="a", zarr_format=3)
            return
        if self.partial.exists():  # this process' own, from an earlier writer of the same path
            if _read_owner(self.partial) is None and store_format(self.partial) not in KNOWN_FORMATS:
                raise StoreError(f"{self.partial}: exists and is not a lodprt partial store; refusing to replace it")
            _remove_tree(self.partial)
        with disk_space(self.path, "the partial store"):
            self.partial.mkdir()
            _write_owner(self.partial)  # before any zarr file: recognisable from its first moment
            self.root = zarr.open_group(str(self.partial), mode="a", zarr_format=3)
        self.attrs(**{ALL_CHUNKS: True})

    def __enter__(self) -> "StoreWriter":
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        """An exception (Ctrl-C included) inside ``with StoreWriter(...)`` removes the partial folder; after
        ``commit()`` there is none left to remove."""
        if kind is not None:
            self.abort()
        return False

    def environment(self, environment: tuple | None) -> None:
        """The lighting a store was baked with, when given: ``(coefficients (3, n*n), {"source", "kind",
        "resolution"})`` (``Environment.stored``) as ``environment/coefficients`` float64 and its attributes."""
        if environment is not None:
            coefficients, attrs = environment
            self.array("environment/coefficients", np.asarray(coefficients, np.float64))
            self.attrs("environment", **attrs)

    def array(self, name: str, data: np.ndarray, *, chunk_rows: int | None = None) -> None:
        data = np.ascontiguousarray(data)
        chunks = None
        if chunk_rows and data.ndim and len(data) > chunk_rows:
            chunks = (chunk_rows,) + data.shape[1:]
        with disk_space(self.destination, f"array '{name}'", data.nbytes):
            arr = self.root.create_array(name, shape=data.shape, dtype=data.dtype, chunks=chunks or "auto",
                                         config={"write_empty_chunks": True})  # every chunk on disk (module doc)
            if data.size:
                arr[...] = data

    def attrs(self, name: str | None = None, **values) -> None:
        with disk_space(self.destination, f"the attributes of '{name or '/'}'"):
            target = self.root if name is None else self.root.require_group(name)
            target.update_attributes(values)  # one write of the group's metadata, not one per key

    @property
    def destination(self) -> Path:
        """The store this writer makes (what a disk-full error names)."""
        return self.path

    def commit(self) -> Path:
        """Move the finished store into place. Each step leaves a state ``clean_leftovers`` recovers from: the
        old store is parked as ``.replaced-<pid>`` (with an owner record) before the new one moves in."""
        if store_format(self.partial) != self.format:
            # the format attribute is what keeps the folder recognisable once the owner record is gone
            raise StoreError(f"{self.partial}: commit before the root attribute format={self.format!r} was written")
        if self.path.exists():
            check_destination(self.path, overwrite=self.overwrite, format=self.format, what=self.what)
            backup = self.path.with_name(f"{self.path.name}.replaced-{os.getpid()}")
            if backup.exists():
                raise StoreError(f"{backup}: exists; move it away to replace {self.path}")
            self.path.rename(backup)
            try:
                with disk_space(self.path, "the owner record of the store it replaces"):
                    _write_owner(backup)
            except BaseException:  # the old store goes back where it was, as it was
                (backup / OWNER_FILE).unlink(missing_ok=True)
                backup.rename(self.path)
                raise
            (self.partial / OWNER_FILE).unlink()
            self.partial.rename(self.path)
            _remove_tree(backup)
        else:
            (self.partial / OWNER_FILE).unlink()
            self.partial.rename(self.path)
        return self.path

    def abort(self) -> None:
        if self.partial.exists():
            try:
                _remove_tree(self.partial)
            except OSError as exc:
                log.warning("%s: could not remove the partial store: %s", self.partial, exc)
