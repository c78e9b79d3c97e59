"""Thesis 4.3: light-sample spacing against bake time, bytes and the error of lights placed between samples.

    python benchmarks/light_spacing.py [--quick] [--json PATH] [--device cpu|cuda]

Scene: the Stanford bunny on a 380 x 380 floor (quick: 100 x 100), SH order 4, light cut at 5 degrees,
one vertex hierarchy shared by every bake. The light box is the scene's default slab above the bunny; it is
sampled by grids of n x 1 x n lights (n = 2, 3, 5, 8; quick: 2, 3). Test lights: 8 fixed random positions in
the box (the same for every grid), so they fall between samples. For each, the run time's interpolated and
completed radiance (``Runtime.radiance``, full resolution: the default interpolation "direct", M-1, and the thesis
blend of the samples, T-12 + T-15, with the default "exact" weights and T-12 as printed) toward a fixed eye is
compared with exact
Phong with exact visibility at that light (Embree, float64) over the vertices facing the eye, shadow-boundary
vertices (a neighbour with another shadow state) reported separately. Baseline in the same run: each grid's own
error at its sample positions (lights on samples: no interpolation error), so the ratio isolates spacing.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write
from lodprt.runtime import Runtime
from table1 import EYE_OFFSET, exact_phong, rel_rmse, shadow_boundary


def main():
    args = parser(__doc__.splitlines()[0]).parse_args()
    from lodprt.precompute import reference
    from lodprt.precompute.bake import bake
    from lodprt.precompute.baker import ray_offset
    from lodprt.devices import resolve_device
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.runtime.lights import LightInterpolator
    from lodprt.store.bake_store import open_store

    device = resolve_device(args.device)
    scene = thesis_scene(quick=args.quick)
    grids = [2, 3] if args.quick else [2, 3, 5, 8]
    t = time.perf_counter()
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    print(f"{scene.source}: hierarchy in {time.perf_counter() - t:.1f} s", flush=True)
    obj = scene.object_id == 0
    ext = float((scene.positions[obj].max(0) - scene.positions[obj].min(0)).max())
    eye = scene.positions[obj].mean(0) + EYE_OFFSET * ext
    box = np.asarray(scene.lights.box, np.float64)
    rng = np.random.default_rng(2006)
    tests = box[:3] + rng.random((3 if args.quick else 8, 3)) * (box[3:] - box[:3])
    caster = reference.EmbreeCaster(scene)
    offset = ray_offset(scene)
    facing = ((eye - scene.positions) * scene.normals).sum(1) > 0
    exact = [exact_phong(scene, light, eye, caster, offset) for light in tests]
    tmp = Path(tempfile.mkdtemp(prefix="lodprt-spacing-"))
    rows = []
    try:
        for n in grids:
            sc = dataclasses.replace(scene, lights=dataclasses.replace(scene.lights, grid=(n, 1, n)))
            out = tmp / f"g{n}.zarr"
            res = bake(sc, out, sh_order=4, device=device, tree=tree, threshold_deg=5.0)
            store = open_store(out)
            rt = Runtime(store, lod=False, device=device)  # the default interpolation, "direct" (M-1)
            old = Runtime(store, lod=False, device=device, interpolation="thesis")  # T-12: the samples blended
            errs, edge, t12, blend = [], [], [], []
            printed = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"], weighting="t12")
            exact_weights = old.lighting.interp
            for light, (ex, vis) in zip(tests, exact):
                boundary = shadow_boundary(sc, vis)
                # the default last: its edges are reported
                for r, interp, acc in ((old, printed, t12), (old, exact_weights, blend), (rt, None, errs)):
                    if interp is not None:
                        r.lighting.interp = interp
                    r.set_lights([light], colors=[(1.0, 1.0, 1.0)])
                    rad = r.radiance(eye)[:, 0].astype(np.float64)
                    acc.append(rel_rmse(rad, ex, sc.referenced & facing & ~boundary))
                edge.append(rel_rmse(rad, ex, sc.referenced & facing & boundary))
            on = []
            for k in range(min(store.num_samples, 4)):
                light = store.light_positions[k].astype(np.float64)
                ex, vis = exact_phong(sc, light, eye, caster, offset)
                rt.set_lights([light], colors=[(1.0, 1.0, 1.0)])
                rad = rt.radiance(eye)[:, 0].astype(np.float64)
                on.append(rel_rmse(rad, ex, sc.referenced & facing & ~shadow_boundary(sc, vis)))
            spacing = float(np.max((box[3:] - box[:3])[[0, 2]] / n))
            rows.append({"grid": f"{n}x1x{n}", "samples": n * n, "spacing": spacing,
                         "spacing_rel": spacing / ext, "bake_s": res.bake_seconds,
                         "mib": sum(s["bytes"] for s in res.samples) / 2**20,
                         "rmse_between": float(np.mean(errs)), "rmse_between_max": float(np.max(errs)),
                         "rmse_between_t12": float(np.mean(t12)), "rmse_between_thesis": float(np.mean(blend)),
                         "rmse_edges": float(np.mean(edge)), "rmse_on_samples": float(np.mean(on)),
                         "ratio": float(np.mean(errs)) / max(float(np.mean(on)), 1e-12)})
            print(f"grid {n}x1x{n}: bake {res.bake_seconds:.1f} s, {rows[-1]['mib']:.1f} MiB, error between samples "
                  f"{rows[-1]['rmse_between']:.4f} (on samples {rows[-1]['rmse_on_samples']:.4f})", flush=True)
            del rt, old, store
            shutil.rmtree(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print(table(rows, [("grid", "grid", "s"), ("samples", "samples", "d"), ("spacing_rel", "spacing/bunny", ".3f"),
                       ("bake_s", "bake s", ".2f"), ("mib", "MiB", ".1f"), ("rmse_between", "rRMSE between", ".4f"),
                       ("rmse_between_max", "worst light", ".4f"), ("rmse_between_thesis", "thesis blend", ".4f"),
                       ("rmse_between_t12", "T-12 as printed", ".4f"), ("rmse_on_samples", "rRMSE on samples", ".4f"),
                       ("ratio", "between/on", ".1f"), ("rmse_edges", "rRMSE shadow edges", ".3f")]))
    name = "light_spacing" + ("-quick" if args.quick else "")
    print("wrote", write(name, {"benchmark": "light_spacing", "quick": args.quick, "scene": scene.source,
                                "eye": eye.tolist(), "test_lights": tests.tolist(), "environment": environment(device),
                                "rows": rows}, args.json))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key, label in ((axes[0], "spacing_rel", "sample spacing / bunny size"), (axes[1], "mib", "MiB per bake")):
        x = [r[key] for r in rows]
        ax.plot(x, [r["rmse_between"] for r in rows], "o-", label="lights between samples (mean of 8), direct (M-1)")
        ax.plot(x, [r["rmse_between_thesis"] for r in rows], "v-.", label="same, thesis blend, exact weights")
        ax.plot(x, [r["rmse_between_t12"] for r in rows], "^:", label="same, thesis blend, T-12 as printed")
        ax.plot(x, [r["rmse_on_samples"] for r in rows], "s--", label="lights on samples")
        for r in rows:
            ax.annotate(r["grid"], (r[key], r["rmse_between"]), fontsize=8, xytext=(3, 3), textcoords="offset points")
        ax.set_xlabel(label)
        ax.set_ylabel("rRMSE vs exact Phong")
        ax.grid(alpha=0.3)
    axes[1].set_xscale("log")
    axes[1].xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    axes[1].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes[0].legend(fontsize=8)
    fig.suptitle("Light-sample spacing (thesis 4.3): error of lights between samples against exact Phong\n"
                 "(vertices facing the eye, shadow-boundary vertices excluded)", fontsize=10)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
