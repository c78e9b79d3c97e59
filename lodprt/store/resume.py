"""Resumed and extended bakes (``bake --resume``, ``bake --add-samples``; docs/DISTRIBUTED.md, docs/FORMAT.md
"Completion marks, resumed and extended bakes").

A bake records its settings and a fingerprint of its scene in the root attributes of the partial folder before any
other work, so a later run can tell whether it bakes the same thing. :class:`BakeTarget` is where one bake writes:

* a fresh partial folder (``StoreWriter``), as every bake did before;
* ``resume``: the partial folder of a killed bake of the same path, adopted when its writer is dead and its
  recorded settings equal this bake's (a mismatch is a ``LodprtError`` naming the setting); its complete groups
  (completion marks, ``lodprt.store.sample_groups``) are kept, the rest is deleted and baked again. A committed
  store with the same settings is already finished: nothing is baked.
* ``add_samples``: an extension of the committed store at the same path to a new light grid. The new store is laid
  out exactly as a fresh bake of the new grid; each new sample whose float32 light position equals an old
  sample's takes that sample's group (hard links, or copies where the file system has none) instead of being baked.

The settings are compared after a JSON round trip (what the attributes hold); timing attributes are never compared
(:data:`TIMINGS`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import uuid
from pathlib import Path

import numpy as np

from lodprt.errors import LodprtError, StoreError
from lodprt.store.bake_store import is_store, open_store, sample_group
from lodprt.store.writer import StoreWriter, dead_partials
from lodprt.store.sample_groups import (COMPLETE, WRITING, complete_samples, discard_incomplete, group_attrs,
                                        is_complete, tidy)
from lodprt.store.white import RECORD_KEYS, record_white

log = logging.getLogger(__name__)

#: attributes that record how long something took: the only ones in which a resumed, extended or distributed bake
#: may differ from an uninterrupted in-process bake of the same scene (group path: attribute names)
TIMINGS = {"/": ("bake_seconds", "load_seconds", "hierarchy_seconds"), "hierarchy": ("seconds",),
           "samples/KKKKK": ("seconds",)}
#: what a marked group covers: the ``scene`` mark vouches for ``scene/*``, ``materials/*`` and ``lights/*``
MARKED = {"scene": ("scene", "materials", "lights"), "hierarchy": ("hierarchy",)}
#: the light attributes that may change with ``--add-samples`` (the rest must stay as they were)
GRID_KEYS = ("grid", "box")
#: an old light sample this close to a new grid position (relative to the light box's diagonal) is the same
#: position up to the rounding of the grid arithmetic: it is baked again at the new position, not refused
SAME_POSITION = 1e-6


def fingerprint(scene) -> dict[str, str]:
    """SHA-256 (first 32 hex digits) of every array and table that decides a bake's coefficients, by name."""
    arrays = {"positions": scene.positions, "normals": scene.normals, "faces": scene.faces,
              "material_id": scene.material_id, "object_id": scene.object_id, "referenced": scene.referenced}
    out = {name: _digest(np.ascontiguousarray(a)) for name, a in arrays.items()}
    table = [[list(m.kd), m.ks, m.shininess] for m in scene.materials]
    out["materials"] = hashlib.sha256(json.dumps(table).encode()).hexdigest()[:32]
    return out


def _digest(a: np.ndarray) -> str:
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.view(np.uint8) if a.size else b"")
    return h.hexdigest()[:32]


def lights_attrs(lights) -> dict:
    """The ``lights`` group attributes of a bake of ``lights`` (``lodprt.model.scene.Lights``)."""
    return {"grid": list(lights.grid), "box": list(lights.box), "intensity": list(lights.intensity),
            "falloff": lights.falloff, "radius": lights.radius}


def _json(value):
    return json.loads(json.dumps(value))


def check_settings(where: str, recorded: dict | None, wanted: dict, *, prefix: str = "") -> None:
    """Refuse (``LodprtError`` naming the setting) when ``recorded`` differs from ``wanted`` in any key of it."""
    recorded = recorded or {}
    # the scene's fingerprint first: a different scene changes settings derived from it (ray_offset, ...) too,
    # and the user should hear about the scene, not about a setting they never gave
    for key, value in sorted(wanted.items(), key=lambda kv: kv[0] != "fingerprint"):
        have = recorded.get(key, "(not recorded)")
        if _json(have) == _json(value):
            continue
        if key == "fingerprint" and isinstance(have, dict):
            parts = [p for p in value if have.get(p) != value[p]]
            raise LodprtError(f"{where}: the scene differs from the one it baked (fingerprint of {', '.join(parts)}); "
                              "resume or extend only with the same scene")
        raise LodprtError(f"{where}: setting {prefix}{key} is {_json(have)!r} there but {_json(value)!r} now; "
                          "resume or extend only with the same scene and settings (or bake afresh with --overwrite)")


def link_tree(src: Path, dst: Path) -> None:
    """Copy the folder ``src`` to ``dst`` (absent) as hard links, or as copies where links fail. Safe: lodprt and
    zarr replace files (write then rename), never write into one, so the two stores never change each other."""

    def link(a, b):
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)

    shutil.copytree(src, dst, copy_function=link)


def check_complete(store: Path, count: int) -> None:
    """StoreError naming the damaged groups unless the committed ``store`` holds ``count`` complete samples."""
    done = set(complete_samples(store, count))
    missing = [sample_group(k) for k in range(count) if k not in done]
    if missing:
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise StoreError(f"{store}: {', '.join(missing[:5])}{more} missing or incomplete: the store is damaged; bake "
                         "it again with --overwrite")


class BakeTarget:
    """Where one bake of ``settings`` (root attributes) and ``lights`` (``Lights``) writes (module docstring).

    ``finished`` is the committed store when it already holds this bake (``resume``, or ``add_samples`` with no new
    position): there is nothing to write. Otherwise ``writer`` is the ``StoreWriter`` of the partial folder.
    """

    def __init__(self, out, *, overwrite: bool, resume: bool, add_samples: bool, settings: dict, lights):
        self.path = Path(out)
        self.settings = _json(settings)
        self.lights = _json(lights_attrs(lights))
        self.positions = np.asarray(lights.positions, np.float32)
        self.reuse: dict[int, int] = {}  # add_samples: new sample index -> sample of the store being extended
        self.rebaked_near = 0
        self.finished: Path | None = None
        self.resumed_from: Path | None = None
        self.writer: StoreWriter | None = None
        if add_samples:
            self._plan_extension()
        adopt = None
        if resume:
            adopt = self._adoptable()
            if adopt is None and not add_samples and is_store(self.path):
                self._check(self.path, f"{self.path} (resuming a finished store)", grid=True)
                check_complete(self.path, len(self.positions))
                self.finished = self.path
        if self.finished is not None:
            return
        if adopt is not None and self.path.exists() and not (overwrite or add_samples):
            raise StoreError(f"{self.path}: exists, and the interrupted bake in {adopt.name} would replace it; pass "
                             "--add-samples too if it was extending the store, or --overwrite")
        self.writer = StoreWriter(self.path, overwrite=overwrite or add_samples, adopt=adopt)
        self.partial = self.writer.partial
        try:
            if adopt is None:
                self.writer.attrs(**self.settings)  # recorded first: a resumed bake checks against them
                self.writer.root.require_group("samples")
            else:
                self.resumed_from = adopt
                self._repair()
            if self.reuse:
                self._link_reused()
        except Exception:  # e.g. a damaged store to extend: no partial folder is left to block the next bake
            self.writer.abort()
            raise

    # -- checks --------------------------------------------------------------------------------------------------
    def _check(self, folder: Path, where: str, *, grid: bool) -> None:
        recorded = group_attrs(folder)
        wanted = self.settings
        if (recorded or {}).get("codec", "none") != "none":  # re-encoded by bake --compress or lodprt compress: its
            wanted = {k: v for k, v in wanted.items() if k != "format_version"}  # codec is the bake's to check
        check_settings(where, recorded, wanted)
        recorded = group_attrs(folder / "lights")
        if recorded is not None:  # absent in a partial killed before the scene was written: nothing depends on it
            wanted = {k: v for k, v in self.lights.items() if grid or k not in GRID_KEYS}
            check_settings(where, recorded, wanted, prefix="lights.")

    def _adoptable(self) -> Path | None:
        """The newest dead partial folder of this path baking the same thing (None: nothing to resume)."""
        first = None
        for folder in dead_partials(self.path):
            try:
                self._check(folder, f"{folder} (the interrupted bake --resume would continue)", grid=True)
            except LodprtError as exc:
                first = first or exc
                continue
            return folder
        if first is not None:
            raise first
        return None

    def _plan_extension(self) -> None:
        """Map the samples of the store being extended onto the new grid (``reuse``); refuse a grid that drops one."""
        if not is_store(self.path):
            raise StoreError(f"{self.path}: --add-samples extends an existing store, and there is none; bake it first")
        self._check(self.path, f"{self.path} (the store --add-samples extends)", grid=False)
        codec = (group_attrs(self.path) or {}).get("codec", "none")
        if codec != "none":
            raise StoreError(f"{self.path}: is encoded with codec {codec}; --add-samples extends a float32 store: "
                             "bake the new grid afresh, or decode this one first (lodprt compress IN -o OUT "
                             "--codec none) and extend that")
        old = open_store(self.path).light_positions.astype(np.float32)
        check_complete(self.path, len(old))
        box = np.asarray(self.lights["box"], np.float64)
        tol = SAME_POSITION * max(float(np.linalg.norm(box[3:] - box[:3])), float(np.abs(box).max()), 1e-30)
        exact = {p.tobytes(): k for k, p in enumerate(self.positions)}
        for j, p in enumerate(old):
            k = exact.get(p.tobytes())
            if k is not None:
                self.reuse[k] = j
                continue
            d = np.linalg.norm(self.positions.astype(np.float64) - p.astype(np.float64), axis=1)
            if d.min() <= tol:
                self.rebaked_near += 1  # the same position but for float rounding: baked again at the new one
                continue
            raise LodprtError(
                f"{self.path}: light sample {j} at {np.round(p, 6).tolist()} is not a position of the new grid "
                f"{self.lights['grid']} over {self.lights['box']}; --add-samples keeps every sample of the store, so "
                "the new grid must contain the old one (a finer grid over the same box multiplies each count by an "
                "odd number: 3 -> 9; a bigger box adds whole cells of the old size)")
        if len(self.reuse) == len(self.positions) and _json(group_attrs(self.path / "lights")) == self.lights:
            self.finished = self.path  # the same grid: nothing to add

    # -- the partial folder --------------------------------------------------------------------------------------
    def _repair(self) -> None:
        """An adopted partial folder: drop what its writer left unfinished (groups without a mark, scratch files)."""
        tidy(self.partial)
        for mark, groups in MARKED.items():
            if not is_complete(self.partial / mark):
                for name in groups:
                    shutil.rmtree(self.partial / name, ignore_errors=True)
        samples = self.partial / "samples"
        samples.mkdir(exist_ok=True)
        if not (samples / "zarr.json").is_file():
            self.writer.root.require_group("samples")
        discard_incomplete(self.partial, [f"samples/{p.name}" for p in samples.iterdir() if p.is_dir()])

    def _link_reused(self) -> None:
        """Give the partial folder the hierarchy and the reused samples of the store being extended."""
        pieces = [(self.path / "hierarchy", self.partial / "hierarchy")] if is_complete(self.path / "hierarchy") else []
        pieces += [(self.path / sample_group(j), self.partial / sample_group(k)) for k, j in sorted(self.reuse.items())]
        for src, dst in pieces:
            if is_complete(dst):
                continue  # an adopted extension had it already
            shutil.rmtree(dst, ignore_errors=True)
            scratch = self.partial / WRITING / f"link-{uuid.uuid4().hex[:12]}"
            scratch.parent.mkdir(exist_ok=True)
            link_tree(src, scratch)
            os.rename(scratch, dst)  # appears whole, completion mark included

    # -- what the bake asks ---------------------------------------------------------------------------------------
    def complete(self, group: str) -> bool:
        return is_complete((self.finished or self.partial) / group)

    def mark(self, group: str) -> None:
        """Write the completion mark of ``group`` (after everything else in it)."""
        self.writer.attrs(group, **{COMPLETE: True})

    def todo(self) -> list[int]:
        """The light samples still to bake."""
        done = set(complete_samples(self.finished or self.partial, len(self.positions)))
        return [k for k in range(len(self.positions)) if k not in done]

    def recorded(self, k: int) -> dict:
        """The statistics a complete sample group records (its attributes but the mark and the white record)."""
        attrs = group_attrs((self.finished or self.partial) / sample_group(k)) or {}
        return {key: v for key, v in attrs.items() if key != COMPLETE and key not in RECORD_KEYS}

    def hierarchy(self):
        """The hierarchy a complete ``hierarchy`` group holds (``Hierarchy``) and its recorded build seconds."""
        tree = open_store(self.finished or self.partial).hierarchy()
        return tree, float((group_attrs((self.finished or self.partial) / "hierarchy") or {}).get("seconds", 0.0))

    def summary(self, codec: str = "none") -> dict:
        """What ``BakeResult`` reports of the finished store (nothing baked now, every sample reused); ``codec``:
        the one it is encoded with, named in the warning."""
        attrs = group_attrs(self.finished) or {}
        encoded = "" if codec == "none" else f" (encoded with codec {codec}, left as it is)"
        log.warning("%s: already holds every light sample of this bake%s; nothing to do", self.finished, encoded)
        total = len(self.positions)
        return {"path": str(self.finished), "sh_order": attrs["sh_order"], "channels": attrs["channels"],
                "coefficients_per_vertex": attrs["coefficients_per_vertex"], "bake_seconds": 0.0,
                "load_seconds": 0.0, "device": attrs["device"], "samples": [self.recorded(k) for k in range(total)],
                "hierarchy_seconds": attrs.get("hierarchy_seconds"), "reused_samples": total}

    def finish(self, **timings) -> Path:
        """Record the timings, check that every sample is complete, record the default white from the samples'
        records (``lodprt.store.white``: the samples of a resumed, extended or distributed bake alike), tidy and
        commit."""
        if self.finished is not None:
            return self.finished
        if timings:
            self.writer.attrs(**timings)
        tidy(self.partial)
        missing = self.todo()
        if missing:
            raise StoreError(f"{self.partial}: samples {missing[:5]} are not complete; not committing")
        record_white(self.writer)
        return self.writer.commit()

    def abort(self) -> None:
        if self.writer is not None:
            self.writer.abort()
