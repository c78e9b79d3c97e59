"""Coefficient compression: bytes per light sample against radiance error for every codec, and CPCA relighting time.

    python benchmarks/compression.py [--quick] [--json PATH] [--device cpu|cuda] [--threshold-deg E]

Scene: the Stanford bunny on a 380 x 380 floor, 3 x 1 x 3 light samples, SH order 4, light cut at 5 degrees
(quick: 100 x 100 floor, 2 x 1 x 1 samples, fewer codecs). The cut store (format version 1, float32) is re-encoded
with every codec (``lodprt.store.compress``, format version 2). Per codec: bytes per sample, payload (the arrays'
bytes, store-level codec arrays shared out over the samples) and on disk (zarr's default zstd included); the
relative RMSE of the completed radiance toward a fixed eye over every referenced vertex and sample, against the
uncompressed cut store and against exact Phong (a full-resolution bake of the same scene: every vertex baked);
the largest coefficient error; the seconds the encoding took. Then a frame's relighting of a cpca store in the
compressed domain (``lodprt.runtime.cpca_relight``, C-5) against decoding the same rows first.

Done when (issue 16): a codec stores a sample in at most 1/10 of the bytes of the uncompressed cut store with
completed radiance within 1% relative RMSE of it.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write

EYE = (-0.0268, 0.1886, 0.2581)  # table1's eye: the bunny and the floor around it
CODECS = ["f16", "q12", "q10", "q8", "cpca:1024:3", "cpca:256:4", "cpca:256:3", "cpca:128:3", "cpca:64:2"]
QUICK_CODECS = ["f16", "q8", "cpca:64:3"]


def completed_radiance(store, referenced) -> np.ndarray:
    """(S, R, 3) radiance toward EYE of every referenced vertex, each sample completed (T-15)."""
    return np.stack([store.radiance(k, EYE)[referenced] for k in range(store.num_samples)]).astype(np.float64)


def rel_rmse(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(((a - ref) ** 2).sum() / (ref**2).sum()))


def measure(store, S: int) -> tuple[float, float]:
    """(payload, on-disk) bytes per sample of a store: the sample groups plus 1/S of the store-level codec arrays."""
    from lodprt.store.compress import on_disk_bytes

    info = store.info()
    disk = on_disk_bytes(store.path)
    return (info["bytes_total"] + info["codec_bytes"]) / S, (sum(disk["samples"]) + disk["codec"]) / S


def relight_timing(path, repeats: int) -> dict:
    """Milliseconds per frame: C-5 on the compressed rows, the same rows decoded first, and the run time's
    relighting of cached completed coefficients (every vertex), for a light at the centre of the region."""
    from lodprt.model import sh
    from lodprt.runtime.cpca_relight import CompressedSamples
    from lodprt.store.bake_store import open_store, radiance_toward

    store = open_store(path)
    cs = CompressedSamples(store)
    W = cs.light_weights([store.light_positions.mean(0)])
    active = np.flatnonzero(np.abs(W).sum(1) > 0)

    def compressed():
        return cs.radiance(W, EYE)

    def decoded():
        c = np.zeros((store.num_vertices, 3, store.coefficients_per_vertex), np.float32)
        for j in active:
            ids, cj = store.sample(int(j))
            c[ids] += cj * W[j].astype(np.float32)[None, :, None]
        return radiance_toward(store.positions, store.normals, c, EYE, np.ones(3))

    completed = {int(j): store.coefficients(int(j)).astype(np.float32) for j in active}
    d = np.asarray(EYE)[None, :] - store.positions
    y = sh.basis(d / np.linalg.norm(d, axis=1, keepdims=True), store.sh_order).astype(np.float32)

    def runtime_style():
        c = sum(completed[j] * W[j].astype(np.float32)[None, :, None] for j in completed)
        return np.einsum("vcn,vn->vc", c, y)

    out = {"active_samples": int(len(active))}
    for name, fn in (("compressed_ms", compressed), ("decoded_ms", decoded), ("completed_ms", runtime_style)):
        fn()
        t = time.perf_counter()
        for _ in range(repeats):
            fn()
        out[name] = 1e3 * (time.perf_counter() - t) / repeats
    rad, covered = compressed()
    ref = decoded()
    out["covered_vertices"] = int(covered.sum())
    out["max_abs_diff_vs_decoded"] = float(np.abs(rad[covered] - ref[covered]).max())
    return out


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--threshold-deg", type=float, default=5.0)
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.precompute.bake import bake
    from lodprt.store.bake_store import open_store
    from lodprt.store.compress import compress_store

    device = resolve_device(args.device)
    scene = thesis_scene(quick=args.quick)
    codecs = QUICK_CODECS if args.quick else CODECS
    referenced = scene.referenced
    folder = Path(tempfile.mkdtemp(prefix="lodprt-compression-"))
    try:
        cut, full = folder / "cut.zarr", folder / "full.zarr"
        bake(scene, full, sh_order=4, device=device, hierarchy=False)
        bake(scene, cut, sh_order=4, device=device, threshold_deg=args.threshold_deg)
        S = len(scene.lights.positions)
        exact = completed_radiance(open_store(full), referenced)
        base = open_store(cut)
        plain = completed_radiance(base, referenced)
        full_payload, full_disk = measure(open_store(full), S)
        cut_payload, cut_disk = measure(base, S)
        rows = [{"codec": "full float32", "payload_kib": full_payload / 1024, "disk_kib": full_disk / 1024,
                 "ratio_payload": cut_payload / full_payload, "ratio_disk": cut_disk / full_disk,
                 "rel_rmse_store": float("nan"), "rel_rmse_exact": 0.0, "max_coef_error": 0.0, "seconds": 0.0},
                {"codec": "none (cut)", "payload_kib": cut_payload / 1024, "disk_kib": cut_disk / 1024,
                 "ratio_payload": 1.0, "ratio_disk": 1.0, "rel_rmse_store": 0.0,
                 "rel_rmse_exact": rel_rmse(plain, exact), "max_coef_error": 0.0, "seconds": 0.0}]
        for codec in codecs:
            out = folder / f"{codec.replace(':', '_')}.zarr"
            res = compress_store(base, out, codec)
            store = open_store(out)
            payload, disk = measure(store, S)
            rad = completed_radiance(store, referenced)
            rows.append({"codec": codec, "payload_kib": payload / 1024, "disk_kib": disk / 1024,
                         "ratio_payload": cut_payload / payload, "ratio_disk": cut_disk / disk,
                         "rel_rmse_store": rel_rmse(rad, plain), "rel_rmse_exact": rel_rmse(rad, exact),
                         "max_coef_error": max(s["max_abs_error"] for s in res["samples"]),
                         "seconds": res["seconds"]})
            print(f"  {codec}: {payload / 1024:,.1f} KiB/sample, rel-RMSE {rows[-1]['rel_rmse_store']:.3%}",
                  flush=True)
        best = [r for r in rows[2:]
                if r["ratio_payload"] >= 10 and r["ratio_disk"] >= 10 and r["rel_rmse_store"] <= 0.01]
        cpca = [c for c in codecs if c.startswith("cpca")]
        pick = next((r["codec"] for r in best if r["codec"].startswith("cpca")), cpca[-1])
        timing = relight_timing(folder / f"{pick.replace(':', '_')}.zarr", 3 if args.quick else 10)
        timing["codec"] = pick
    finally:
        shutil.rmtree(folder, ignore_errors=True)

    vertices = int(referenced.sum())
    print(f"{scene.source}: {vertices:,} referenced vertices, {S} samples, SH order 4, cut at "
          f"{args.threshold_deg} degrees; eye {EYE}; device {device}")
    print(table(rows, [("codec", "codec", "s"), ("payload_kib", "KiB/sample", ",.1f"),
                       ("disk_kib", "disk KiB/sample", ",.1f"), ("ratio_payload", "x smaller", ".1f"),
                       ("ratio_disk", "x smaller disk", ".1f"), ("rel_rmse_store", "rel-RMSE vs cut", ".3%"),
                       ("rel_rmse_exact", "rel-RMSE vs exact", ".3%"), ("max_coef_error", "max coef err", ".3g"),
                       ("seconds", "encode s", ".1f")]))
    print(f"relighting one frame ({timing['codec']}, {timing['active_samples']} active samples, "
          f"{timing['covered_vertices']:,} vertices kept by all of them): compressed domain "
          f"{timing['compressed_ms']:.1f} ms, decoded rows {timing['decoded_ms']:.1f} ms, cached completed "
          f"coefficients (every vertex) {timing['completed_ms']:.1f} ms; max |difference| vs decoded "
          f"{timing['max_abs_diff_vs_decoded']:.2e}")
    met = [r["codec"] for r in best]
    print("done-when (<= 1/10 of the cut store's bytes per sample, payload and on disk, and <= 1% rel-RMSE vs it): "
          + (f"met by {', '.join(met)}" if met else "not met"))
    name = "compression" + ("-quick" if args.quick else "")
    results = {"benchmark": "compression", "quick": args.quick, "scene": scene.source, "vertices": vertices,
               "samples": S, "threshold_deg": args.threshold_deg, "eye": EYE, "environment": environment(device),
               "rows": rows, "relight": timing, "done_when_met_by": met}
    print("wrote", write(name, results, args.json))
    plot(rows, cut_payload, name)


def plot(rows: list[dict], cut_payload: float, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for r in rows[2:]:
        colour = "C1" if r["codec"].startswith("cpca") else "C0"
        for key, marker in (("payload_kib", "o"), ("disk_kib", "s")):
            ax.scatter(r[key], max(r["rel_rmse_store"], 1e-7), color=colour, marker=marker)
        ax.annotate(r["codec"], (r["payload_kib"], max(r["rel_rmse_store"], 1e-7)), textcoords="offset points",
                    xytext=(4, 4), fontsize=8)
    ax.axvline(cut_payload / 1024 / 10, color="C3", ls="--", lw=1, label="1/10 of the cut store's payload")
    ax.axhline(0.01, color="C3", ls=":", lw=1, label="1% rel-RMSE")
    ax.scatter([], [], color="k", marker="o", label="payload")
    ax.scatter([], [], color="k", marker="s", label="on disk")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("KiB per light sample")
    ax.set_ylabel("rel-RMSE of completed radiance vs the float32 cut store")
    ax.set_title("Coefficient codecs, bunny + floor, 5-degree cut")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
