"""Re-encoding a bake store with a codec (``lodprt compress``, ``bake --compress``): version 1 or 2 in, version 2
out (version 1 for codec ``none``), written through :class:`StoreWriter` (atomic; docs/FORMAT.md "Compressed bake
store").

Everything but the light samples (scene, materials, lights, hierarchy, their attributes) is copied array for array;
each sample is decoded from the source, encoded (:mod:`lodprt.store.codecs`, C-1..C-4) and checked against the
source: its attributes record the largest and the RMS error of the decoded coefficients (``max_abs_error``,
``rms_error``), the encoded payload (``bytes``) and the version-1 payload it replaces (``bytes_raw``). The
default-white records and ``default_white`` are made afresh from the decoded rows (``lodprt.store.white``).
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import numpy as np

from lodprt.store import codecs
from lodprt.store.bake_store import FORMAT_VERSION, Store, open_store, sample_group
from lodprt.store.reader import folder_bytes
from lodprt.store.white import RECORD_KEYS, WHITE, record_white
from lodprt.store.writer import StoreWriter

log = logging.getLogger(__name__)

#: the format version of stores written with a lossy codec
COMPRESSED_VERSION = 2


def compress_store(source: str | os.PathLike | Store, out: str | os.PathLike, codec: str | codecs.Codec, *,
                   overwrite: bool = False, option: str = "--codec", progress=None) -> dict:
    """Write ``source`` re-encoded with ``codec`` at ``out`` (``out`` may be the source itself with ``overwrite``:
    the new store replaces it only once complete). Returns {"path", "codec", "seconds", "samples": per-sample
    attributes, "codec_bytes": bytes of the store-level codec arrays}. ``progress(done, total)`` per sample."""
    src = source if isinstance(source, Store) else open_store(source)
    if not isinstance(codec, codecs.Codec):
        codec = codecs.parse_codec(codec, option)
    channels, ncoef = int(src.attrs["channels"]), src.coefficients_per_vertex
    codecs.check_layout(codec, channels, ncoef, option)
    t0 = time.perf_counter()
    with StoreWriter(out, overwrite=overwrite) as writer:
        copy_static(src, writer)
        parent = src.read("hierarchy/parent").astype(np.int64) if src.has_hierarchy else None
        vertex = src.read("hierarchy/vertex").astype(np.int64) if src.has_hierarchy else None
        model, rows = None, None
        if codec.kind == "cpca":  # C-3 fits every row of the store at once; the other codecs one sample at a time
            model, rows = fit_cpca(codec, [src.sample(k)[1] for k in range(src.num_samples)])
        infos, codec_bytes = [], 0
        if model is not None:
            codec_bytes = write_model(writer, model)
        for k in range(src.num_samples):
            (ids, coeffs), cut = src.sample(k), src.cut_arrays(k)
            info = write_sample(writer, src, k, codec, ids, coeffs, cut, parent, vertex, model,
                                None if rows is None else rows[k])
            infos.append(info)
            if progress is not None:
                progress(k + 1, src.num_samples)
        attrs = dict(src.attrs)
        attrs.pop("codec", None)
        attrs.pop("codec_bytes", None)
        attrs.pop(WHITE, None)
        if codec.lossless:
            attrs["format_version"] = FORMAT_VERSION
        else:
            attrs.update(format_version=COMPRESSED_VERSION, codec=codec.name, codec_bytes=codec_bytes)
        writer.attrs(**attrs)
        record_white(writer, decoded=True)
        path = writer.commit()
    return {"path": str(path), "codec": codec.name, "seconds": time.perf_counter() - t0, "samples": infos,
            "codec_bytes": codec_bytes}


def copy_static(src: Store, writer: StoreWriter) -> None:
    """Every array and group attribute of ``src`` outside ``samples/`` and ``codec/``, as stored."""
    for name, obj in src.root.members(max_depth=None):
        if name.split("/")[0] in ("samples", "codec"):
            continue
        if hasattr(obj, "shape"):
            data = obj[...]
            chunks = obj.chunks[0] if obj.ndim and obj.chunks[0] < obj.shape[0] else None
            writer.array(name, data, chunk_rows=chunks)
        elif dict(obj.attrs):
            writer.attrs(name, **dict(obj.attrs))


def fit_cpca(codec: codecs.Codec, samples: list[np.ndarray]) -> tuple[dict, list[dict]]:
    """C-3 jointly over every (vertex, sample) row of the store: the model and each sample's rows."""
    X = np.concatenate([c.reshape(len(c), -1) for c in samples]) if samples else np.zeros((0, 1), np.float32)
    t = time.perf_counter()
    fit = codecs.cpca_fit(X, codec)
    log.info("cpca %s: %d rows of %d numbers fitted in %.1f s", codec.name, X.shape[0], X.shape[1],
             time.perf_counter() - t)
    bounds = np.cumsum([0] + [len(c) for c in samples])
    rows = [{"cluster": fit["cluster"][a:b], "weights": fit["weights"][a:b]} for a, b in zip(bounds[:-1], bounds[1:])]
    return fit, rows


def write_model(writer: StoreWriter, model: dict) -> int:
    """The store-level cpca arrays under ``codec/``; returns their bytes."""
    for name in ("mean", "basis", "weight_scale"):
        writer.array(f"codec/{name}", model[name])
    writer.attrs("codec", weight_levels=int(model["weight_levels"]))
    return int(sum(model[n].nbytes for n in ("mean", "basis", "weight_scale")))


def write_sample(writer: StoreWriter, src: Store, k: int, codec: codecs.Codec, ids, coeffs, cut: dict, parent,
                 vertex, model, rows) -> dict:
    """Encode and write light sample ``k``; returns its attributes (the source's, with bytes and errors)."""
    g = sample_group(k)
    info = dict(src.sample_info(k))
    for key in ("bytes", "bytes_raw", "max_abs_error", "rms_error", "scale_exponent", "band_bits", *RECORD_KEYS):
        info.pop(key, None)
    raw = int(ids.nbytes + coeffs.astype(np.float32).nbytes + sum(np.asarray(a).nbytes for a in cut.values()))
    if codec.lossless:
        arrays = {"vertex_ids": np.asarray(ids, np.int32), "coefficients": np.asarray(coeffs, np.float32),
                  **{name: np.asarray(a) for name, a in cut.items()}}
        extra, got = {}, coeffs
    else:
        arrays = codecs.encode_structure(ids, cut.get("cut_nodes"), cut.get("dark"), parent, vertex)
        if rows is None:
            coded, extra = codecs.encode_sample(codec, np.asarray(coeffs, np.float32))
        else:
            coded, extra = rows, {}
        arrays.update(coded)
        got = codecs.decode_sample(codec.name, coded, extra, model, coeffs.shape[1:])
    for name, a in arrays.items():
        writer.array(f"{g}/{name}", a, chunk_rows=1 << 18)
    err = np.abs(got.astype(np.float64) - coeffs)
    info.update(extra, bytes=int(sum(a.nbytes for a in arrays.values())), bytes_raw=raw,
                max_abs_error=float(err.max()) if err.size else 0.0,
                rms_error=float(np.sqrt(np.mean(err * err))) if err.size else 0.0)
    writer.attrs(g, **info)
    return info


def on_disk_bytes(path: str | os.PathLike) -> dict:
    """Bytes on disk of a store: {"total", "samples": per sample folder, "codec": the codec/ folder}."""
    root = Path(path)
    samples = sorted((root / "samples").glob("[0-9]*")) if (root / "samples").exists() else []
    return {"total": folder_bytes(root), "samples": [folder_bytes(f) for f in samples],
            "codec": folder_bytes(root / "codec")}
