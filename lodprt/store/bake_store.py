"""Bake store: one zarr v3 group per bake, readable with zarr and numpy alone (layout in docs/FORMAT.md); ``Store``
reads it. It is written through ``lodprt.store.writer.StoreWriter`` (atomic: a partial folder renamed into place;
docs/FORMAT.md, "Interrupted bakes")."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from lodprt.errors import LodprtError, StoreError
from lodprt.store.codecs import CUT_STRUCTURE_ARRAYS, MODEL_ARRAYS, STRUCTURE_ARRAYS, parse_codec, sample_parts
from lodprt.store.reader import brief, damage, folder_bytes, missing_attributes, missing_parts, read_array
from lodprt.store.writer import (ALL_CHUNKS, FORMAT_NAME, NEIGHBOURHOOD_FORMAT, TRANSFER_FORMAT, VOLUME_FORMAT,
                                 store_format)

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
#: the attributes every sample group records that the readers need (``Store.sample_info`` checks them)
SAMPLE_ATTRS = ("vertices_kept", "bytes")
#: the root's, the lights' and the hierarchy's attributes every bake writes and the readers need
ROOT_ATTRS = ("sh_order", "coefficients_per_vertex", "channels", "ray_offset")
LIGHTS_ATTRS = ("grid", "box", "intensity", "falloff", "radius")
HIERARCHY_ATTRS = ("roots", "depth", "seconds")
#: versions ``Store`` reads: 1 (float32 samples) and 2 (samples encoded by a codec, ``lodprt.store.codecs``)
READ_VERSIONS = (1, 2)
#: the other stores lodprt writes, and what reads them (the point-light commands do not)
OTHER_STORES = {VOLUME_FORMAT: "a volume store (bake-volume): render it with render-volume",
                NEIGHBOURHOOD_FORMAT: "a neighbourhood store (bake-neighbourhood): render it with "
                                      "render-environment --receiver"}


def sample_group(k: int) -> str:
    return f"samples/{k:05d}"


def is_store(path: str | os.PathLike) -> bool:
    """True when ``path`` is a zarr v3 group written by lodprt (any version)."""
    return store_format(path) == FORMAT_NAME


class Store:
    """Read access to a bake store (arrays are loaded on demand and exactly as written)."""

    def __init__(self, path: str | os.PathLike):
        import zarr

        self.path = Path(path)
        if not self.path.exists():
            raise StoreError(f"{self.path}: no such store")
        fmt = store_format(self.path)
        if fmt == TRANSFER_FORMAT:
            raise StoreError(f"{self.path}: a transfer store (bake --environment): relight it with render-environment "
                             f"or render --environment, not with the point-light commands")
        if fmt in OTHER_STORES:
            raise StoreError(f"{self.path}: {OTHER_STORES[fmt]}, not with the point-light commands")
        if not is_store(self.path):
            raise StoreError(f"{self.path}: not a lodprt store (zarr.json missing or without attribute format='lodprt')")
        self.root = zarr.open_group(str(self.path), mode="r")
        self.attrs = dict(self.root.attrs)
        version = self.attrs.get("format_version")
        if version not in READ_VERSIONS:
            raise StoreError(f"{self.path}: format_version {version!r}; this lodprt reads versions "
                             f"{', '.join(map(str, READ_VERSIONS))}")
        #: the codec of the light samples ("none" in version 1; docs/FORMAT.md "Compressed bake store")
        self.codec = str(self.attrs.get("codec", "none")) if version == 2 else "none"
        self._cache: dict[str, np.ndarray] = {}

    def __repr__(self) -> str:
        mode = self.attrs.get("mode", "?")
        cut = f" {self.attrs['threshold_deg']:g} deg" if self.attrs.get("threshold_deg") is not None else ""
        return (f"Store({str(self.path)!r}: {self.num_vertices:,} vertices, {self.num_samples} light samples, "
                f"SH order {self.sh_order}, {mode}{cut}, codec {self.codec})")

    def read(self, name: str, *, cache: bool = True) -> np.ndarray:
        """Array ``name`` as written; kept on this Store unless ``cache`` is False (a light sample's rows: a store
        of many samples is read one sample at a time, its memory does not grow with the samples read)."""
        if name in self._cache:
            return self._cache[name]
        value = read_array(self.root, self.path, name, all_chunks=bool(self.attrs.get(ALL_CHUNKS)))
        if cache:
            self._cache[name] = value
        return value

    # -- scene -----------------------------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        return self.read("scene/positions")

    @property
    def normals(self) -> np.ndarray:
        return self.read("scene/normals")

    @property
    def faces(self) -> np.ndarray:
        return self.read("scene/faces")

    @property
    def num_vertices(self) -> int:
        return int(self.node("scene/positions").shape[0])

    @property
    def referenced(self) -> np.ndarray:
        """(V,) bool: the vertices some face uses (made once per Store; the others are never drawn)."""
        if "referenced" not in self._cache:
            referenced = np.zeros(self.num_vertices, bool)
            referenced[self.faces.ravel()] = True
            self._cache["referenced"] = referenced
        return self._cache["referenced"]

    @property
    def sh_order(self) -> int:
        return int(self.root_attr("sh_order"))

    @property
    def coefficients_per_vertex(self) -> int:
        """SH coefficients stored per vertex and channel, read off the arrays: 1 (diffuse-only) or sh_order^2."""
        if self.sample_codec() != "none":
            return int(self.root_attr("coefficients_per_vertex"))
        return int(self.node(f"{sample_group(self.check_sample(0))}/coefficients").shape[-1])

    def root_attr(self, key: str):
        """The root attribute ``key``; StoreError calling the store damaged when it is gone."""
        return self.required_attrs("root", self.attrs, (key,))[key]

    def sample_codec(self) -> str:
        """The codec of the light samples ("none" in version 1); StoreError calling the store damaged when a
        version-2 store's root attribute ``codec`` is gone or names no codec."""
        problem = self.codec_problem()
        if problem:
            raise self.damaged(problem)
        return self.codec

    def codec_problem(self) -> str | None:
        """What is wrong with a version-2 store's root attribute ``codec`` (gone, or no codec's name), or None."""
        if self.attrs.get("format_version") != 2:
            return None
        if "codec" not in self.attrs:
            return "root: attribute(s) codec missing"
        try:
            parse_codec(self.attrs["codec"], "codec")
        except LodprtError:
            return f"root: attribute codec {self.attrs['codec']!r} names no codec this lodprt reads"
        return None

    @property
    def light_positions(self) -> np.ndarray:
        return self.read("lights/positions")

    @property
    def num_samples(self) -> int:
        return int(self.node("lights/positions").shape[0])

    @property
    def light_box(self) -> np.ndarray:
        """(6,) float64 the sampled light region (xmin, ymin, zmin, xmax, ymax, zmax): lights between samples are
        interpolated inside it, clamped into it (or refused) outside."""
        return np.asarray(self.required_attrs("lights", self.node("lights").attrs, ("box",))["box"], np.float64)

    @property
    def intensity(self) -> np.ndarray:
        if "lights/intensity" not in self._cache:  # read once: the run time asks every frame
            attrs = self.required_attrs("lights", self.node("lights").attrs, ("intensity",))
            self._cache["lights/intensity"] = np.asarray(attrs["intensity"], dtype=np.float64)
        return self._cache["lights/intensity"].copy()

    def check_sample(self, k: int) -> int:
        if not 0 <= k < self.num_samples:
            raise StoreError(f"{self.path}: sample {k} out of range 0..{self.num_samples - 1}")
        return k

    def sample(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Vertex ids (K,) int32 and coefficients (K, C, ncoef) float32 of light sample ``k``."""
        g = sample_group(self.check_sample(k))
        if self.sample_codec() != "none":  # version 2: decoded afresh each call (lodprt.store.codecs, C-1..C-4)
            from lodprt.store.codecs import read_sample

            return read_sample(self, k)[:2]
        return self.read(f"{g}/vertex_ids", cache=False), self.read(f"{g}/coefficients", cache=False)

    def cut_arrays(self, k: int) -> dict:
        """{"cut_nodes", "dark"} of sample ``k`` of a light-cut store (decoded in version 2), {} in full mode."""
        g = sample_group(self.check_sample(k))
        if self.sample_codec() != "none":
            from lodprt.store.codecs import read_cut

            return read_cut(self, k)
        if f"{g}/cut_nodes" in self.root:
            return {"cut_nodes": self.read(f"{g}/cut_nodes", cache=False), "dark": self.read(f"{g}/dark", cache=False)}
        return {}

    def group(self, k: int):
        """Sample ``k``'s zarr group, or StoreError naming it when the store lost it."""
        return self.node(sample_group(self.check_sample(k)))

    def node(self, name: str):
        """The zarr array or group ``name`` of this store, StoreError calling the store damaged when it is gone or
        its metadata (``zarr.json``) cannot be read."""
        try:
            return self.root[name]
        except KeyError:
            raise self.damaged(f"'{name}' is missing") from None
        except Exception as exc:  # noqa: BLE001 -- a garbled zarr.json: JSONDecodeError, TypeError, ...
            raise self.damaged(f"the metadata of '{name}' cannot be read ({brief(exc)})") from exc

    def sample_info(self, k: int) -> dict:
        """Sample ``k``'s recorded statistics, StoreError naming any ``SAMPLE_ATTRS`` missing."""
        return self.required_attrs(sample_group(k), self.group(k).attrs, SAMPLE_ATTRS)

    def required_attrs(self, where: str, attrs, keys) -> dict:
        """``attrs`` (of ``where`` in this store) as a dict, StoreError naming any of ``keys`` it lacks."""
        a = dict(attrs)
        lost = [key for key in keys if key not in a]
        if lost:
            raise self.damaged(f"{where}: attribute(s) {', '.join(lost)} missing")
        return a

    def damaged(self, what: str) -> StoreError:
        """The error for a part of this store that its bake wrote and that is gone."""
        return StoreError(f"{self.path}: {what}: the store is damaged; bake it again")

    def completion_plan(self):
        """The geometry-only completion weights of this store's hierarchy (computed once, then cached)."""
        from lodprt.model.completion import CompletionPlan

        if "completion" not in self._cache:
            self._cache["completion"] = CompletionPlan(self.hierarchy(), self.positions, self.normals)
        return self._cache["completion"]

    def set_completion_plan(self, plan) -> None:
        """Reuse a ``CompletionPlan`` built for the same hierarchy and geometry (e.g. across several stores)."""
        self._cache["completion"] = plan

    def coefficients(self, sample: int) -> np.ndarray:
        """(V, C, ncoef) float64 coefficients of every vertex for ``sample``: stored where the light cut kept the
        vertex, completed from its pre-collapse neighbours elsewhere (T-15, ``lodprt.model.completion``); 0 for vertices
        no face uses. Completed samples are cached on this Store object."""
        key = f"completed/{sample}"
        if key not in self._cache:
            self._cache[key] = self.complete(sample)
        return self._cache[key]

    def complete(self, sample: int, dtype=np.float64) -> np.ndarray:
        """(V, C, ncoef) coefficients of ``sample`` completed afresh (T-15), not cached: ``coefficients`` caches
        them. In ``dtype`` (float64 by default; float32 completes in float32 throughout, no float64 copy)."""
        ids, coeffs = self.sample(sample)
        kept = np.zeros(self.num_vertices, bool)
        kept[ids] = True
        if (self.referenced & ~kept).any():
            cut = self.cut_arrays(sample)
            out = self.completion_plan().complete(ids, coeffs, self.num_vertices, dtype=dtype, **cut)
        else:
            out = np.zeros((self.num_vertices,) + coeffs.shape[1:], dtype)
            out[ids] = coeffs
        return out

    def radiance(self, sample: int, eye) -> np.ndarray:
        """Radiance toward ``eye`` of every vertex, (V, 3) float32, from the SH coefficients of ``sample`` (T-7),
        completed where the light cut did not keep a vertex.

        The light's RGB intensity scales the stored unit-intensity coefficients; vertices no face uses read 0.
        """
        return radiance_toward(self.positions, self.normals, self.coefficients(sample), eye, self.intensity)

    def scene(self):
        """The baked scene rebuilt from the store (positions, normals and faces exactly as baked)."""
        from lodprt.model.scene import Scene

        return Scene(
            positions=self.positions.astype(np.float64),
            faces=self.faces,
            normals=self.normals.astype(np.float64),
            material_id=self.read("scene/material_id"),
            object_id=self.read("scene/object_id"),
            referenced=self.referenced.copy(),
            materials=self.materials(),
            object_names=list(self.node("scene").attrs.get("object_names", [])),
            lights=self.lights(),
            source=str(self.attrs.get("source", self.path)),
        )

    def materials(self) -> list:
        """The baked scene's materials (``lodprt.model.scene.Material``), without its geometry."""
        from lodprt.model.scene import Material

        kd, ks, n = self.read("materials/kd"), self.read("materials/ks"), self.read("materials/shininess")
        return [Material(tuple(float(x) for x in kd[m]), float(ks[m]), float(n[m])) for m in range(len(ks))]

    def lights(self):
        """The baked scene's light grid (``lodprt.model.scene.Lights``)."""
        from lodprt.model.scene import Lights

        a = dict(self.node("lights").attrs)
        return Lights(tuple(a["grid"]), tuple(a["box"]), tuple(a["intensity"]), a["falloff"], float(a["radius"]))

    @property
    def has_hierarchy(self) -> bool:
        """The bake built a vertex hierarchy (root attribute ``with_hierarchy``; older stores: a hierarchy/ group).
        A store that says so and lost the group is damaged (``hierarchy`` raises), not a store without one."""
        if "with_hierarchy" in self.attrs:  # read first: a garbled hierarchy/zarr.json is damage, named on reading
            return bool(self.attrs["with_hierarchy"])
        return "hierarchy" in self.root

    def hierarchy(self):
        """The stored vertex hierarchy (``lodprt.model.hierarchy.Hierarchy``); StoreError when the bake made none."""
        from lodprt.model.hierarchy import Hierarchy

        if not self.has_hierarchy:
            raise StoreError(f"{self.path}: no hierarchy/ group (baked with --no-hierarchy)")
        g = self.node("hierarchy")
        arrays = {name: self.read(f"hierarchy/{name}") for name in Hierarchy.ARRAYS}
        try:
            return Hierarchy.from_arrays(arrays, levels=int(g.attrs.get("levels", 0)),
                                         build_seconds=float(g.attrs.get("seconds", 0.0)),
                                         method=str(g.attrs.get("method", "rounds")))
        except LodprtError as e:
            raise StoreError(f"{self.path}: hierarchy/: {e}") from None

    def info(self, *, verify: bool = False) -> dict:
        """The summary ``lodprt info --json`` prints; ``damage``: what is damaged (``reader.damage``: chunk files
        missing, and with ``verify`` every array read whole)."""
        samples = []
        for k, pos in enumerate(self.light_positions):
            a = self.sample_info(k)
            samples.append(
                {
                    "index": k,
                    "position": [float(x) for x in pos],
                    "vertices_kept": int(a["vertices_kept"]),
                    "bytes": int(a["bytes"]),
                    "seconds": float(a.get("seconds", 0.0)),
                    "lit": int(a.get("lit", 0)),
                    "shadowed": int(a.get("shadowed", 0)),
                    "back_facing": int(a.get("back_facing", 0)),
                }
            )
        keys = (
            "sh_order",
            "coefficients_per_vertex",
            "channels",
            "bake_seconds",
            "load_seconds",
            "device",
            "source",
            "mode",
            "threshold_deg",
            "lodprt_version",
            "format_version",
        )
        out = {k: self.attrs.get(k) for k in keys}
        out["vertices"] = self.num_vertices
        out["faces"] = int(self.node("scene/faces").shape[0])
        out["lights"] = dict(self.node("lights").attrs)
        out["light_box"] = [float(x) for x in self.light_box]
        out["samples"] = samples
        if self.has_hierarchy:
            g = self.required_attrs("hierarchy", self.node("hierarchy").attrs, HIERARCHY_ATTRS)
            out["hierarchy_nodes"] = int(self.node("hierarchy/parent").shape[0])
            out["hierarchy_roots"] = int(g["roots"])
            out["hierarchy_depth"] = int(g["depth"])
            out["hierarchy_seconds"] = float(g["seconds"])
            out["hierarchy_method"] = str(g.get("method", "rounds"))
        else:
            out["hierarchy_nodes"] = out["hierarchy_roots"] = out["hierarchy_depth"] = out["hierarchy_seconds"] = None
            out["hierarchy_method"] = None
        out["bytes_total"] = int(sum(s["bytes"] for s in samples))
        out["bytes_on_disk"] = folder_bytes(self.path)
        out["damage"] = self.damage(verify=verify)
        from lodprt.store.codecs import codec_summary  # version 2: codec, store-level bytes, version-1 payload

        return {**out, **codec_summary(self)}

    def damage(self, *, verify: bool = False) -> list[str]:
        """What is damaged in this store, one line each (``reader.damage``: metadata garbled or gone, chunk files
        missing, and with ``verify`` every array read whole), every part and attribute its bake wrote that is gone,
        and a version-2 store's ``codec`` attribute gone or of no known codec."""
        found = damage(self.root, self.path, all_chunks=bool(self.attrs.get(ALL_CHUNKS)), verify=verify)
        problem = self.codec_problem()
        found += [problem] if problem else []
        return (found + missing_parts(self.path, self.required_parts())
                + missing_attributes(self.root, self.required_attributes()))

    def samples_written(self) -> int:
        """Light samples the bake wrote (0 when the light positions are gone or garbled: named by ``damage``)."""
        try:
            return self.num_samples
        except StoreError:
            return 0

    def sample_layout(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(arrays, attributes) every light sample's group holds: its codec's (``codecs.sample_parts``; only the
        structure arrays when a version-2 store's codec is unknown) and ``SAMPLE_ATTRS``."""
        cut = self.attrs.get("mode") == "cut"
        if self.codec_problem():  # the codec is unknown: the arrays of every version-2 sample only
            return STRUCTURE_ARRAYS + (CUT_STRUCTURE_ARRAYS if cut else ()), SAMPLE_ATTRS
        arrays, attrs = sample_parts(self.codec, cut=cut)
        return arrays, SAMPLE_ATTRS + attrs

    def required_parts(self) -> list[str]:
        """The arrays and groups every bake of this store's kind writes: the scene, materials and lights, each
        light sample's group and the arrays its codec writes there (when the light positions can be read), a cpca
        store's model and the hierarchy when the bake built one."""
        from lodprt.model.hierarchy import Hierarchy

        parts = ["scene/positions", "scene/normals", "scene/faces", "scene/material_id", "scene/object_id",
                 "materials/kd", "materials/ks", "materials/shininess", "lights/positions"]
        arrays = self.sample_layout()[0]
        for k in range(self.samples_written()):
            parts += [sample_group(k)] + [f"{sample_group(k)}/{name}" for name in arrays]
        if not self.codec_problem() and self.codec.startswith("cpca"):
            parts += [f"codec/{name}" for name in MODEL_ARRAYS]
        if self.has_hierarchy:
            parts += [f"hierarchy/{name}" for name in Hierarchy.ARRAYS]
        return parts

    def required_attributes(self) -> list[tuple[str, tuple[str, ...]]]:
        """(group, "" for the root; the attributes of it every bake writes and the readers need): the root's, the
        lights', every sample group's, a cpca store's ``codec`` group's and the hierarchy's when there is one."""
        attrs = self.sample_layout()[1]
        wanted = [("", ROOT_ATTRS), ("lights", LIGHTS_ATTRS)]
        wanted += [(sample_group(k), attrs) for k in range(self.samples_written())]
        if not self.codec_problem() and self.codec.startswith("cpca"):
            wanted.append(("codec", ("weight_levels",)))
        if self.has_hierarchy:
            wanted.append(("hierarchy", HIERARCHY_ATTRS))
        return wanted


def radiance_toward(positions, normals, coeffs, eye, intensity) -> np.ndarray:
    """T-7 per vertex: sum_i c_i y_i((eye - p)/|eye - p|) times the RGB intensity; (V, 3) float32.

    coeffs (V, C, ncoef) with C = 1 (grey, used for R, G and B) or 3.
    """
    from lodprt.model import sh

    eye = np.asarray(eye, dtype=np.float64)
    if eye.shape != (3,) or not np.isfinite(eye).all():
        raise StoreError(f"eye: expected 3 finite numbers, got {eye.tolist()}")
    d = eye[None, :] - np.asarray(positions, np.float64)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where(n > 0, d / np.where(n > 0, n, 1.0), normals)  # an eye on the vertex looks along n
    order = int(round(np.sqrt(coeffs.shape[2])))
    rad = np.einsum("vci,vi->vc", np.asarray(coeffs, np.float64), sh.basis(d, order))
    if rad.shape[1] == 1:
        rad = np.repeat(rad, 3, axis=1)
    return (rad * np.asarray(intensity, np.float64)[None, :]).astype(np.float32)


def open_store(path: str | os.PathLike) -> Store:
    """Open a bake store for reading; raises StoreError naming the path when it is not one."""
    return Store(path)


def as_store(store) -> Store:
    """``store`` (a ``Store``, or anything read as one), a path opened (``open_store``); else a LodprtError."""
    if isinstance(store, (str, os.PathLike)):
        return Store(store)
    if not hasattr(store, "hierarchy"):
        raise StoreError(f"{store!r:.60}: not a bake store; pass lodprt.open_store(path) or the path")
    return store
