"""Full-resolution bake: Warp kernels against a brute-force numpy + Embree bake of the same radiance, in one run.

    python benchmarks/bake.py [--quick] [--json PATH] [--device cpu|cuda] [--sh-order N]

Scene: the Stanford bunny on a 380 x 380 floor (179,234 referenced vertices), 3 x 1 x 3 light samples,
SH order 4 (quick: 100 x 100 floor, 2 samples). Reports time per sample and per vertex, bytes per sample, the
speed ratio, and how far the two bakes' coefficients differ (float32 kernels vs float64 numpy, and the few rays the
two casters decide differently).
"""

from __future__ import annotations

import time

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write


def numpy_bake(scene, order, offset):
    """Baseline: Embree shadow rays + float64 numpy closed-form projection, one sample after another."""
    from lodprt.precompute import reference

    caster = reference.EmbreeCaster(scene)
    ids = np.flatnonzero(scene.referenced)
    out, times = [], []
    for light in scene.lights.positions:
        t = time.perf_counter()
        vis = reference.visibility(caster, scene, light, offset, ids)
        out.append(reference.phong_coefficients(scene, light, order, vis, ids).astype(np.float32))
        times.append(time.perf_counter() - t)
    return out, times


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--sh-order", type=int, default=4)
    args = p.parse_args()
    from lodprt.precompute.bake import bake
    from lodprt.precompute.baker import ray_offset
    from lodprt.devices import resolve_device

    device = resolve_device(args.device)
    scene = thesis_scene(quick=args.quick)
    order = args.sh_order
    n_samples = len(scene.lights.positions)
    n_vertices = int(scene.referenced.sum())

    rows = []
    runs = [("warp, 1 thread", 1), ("warp, 2 threads", 2)] if device == "cpu" else [("warp " + device, 1)]
    for label, jobs in runs:
        res = bake(scene, None, sh_order=order, device=device, jobs=jobs, full=True)  # every vertex: the Warp kernels' throughput
        rows.append({"bake": label, "seconds": res.bake_seconds, "load_s": res.load_seconds,
                     "bytes": int(np.mean([s["bytes"] for s in res.samples]))})
    # keep the coefficients of the last Warp bake to compare
    from lodprt.precompute.baker import Baker

    ids = np.flatnonzero(scene.referenced).astype(np.int32)
    baker = Baker(scene, order, device, ids)
    warp_coeffs = [baker.sample(light)[0][:, 0] for light in scene.lights.positions]

    t = time.perf_counter()
    ref, ref_times = numpy_bake(scene, order, ray_offset(scene))
    ref_seconds = time.perf_counter() - t
    rows.append({"bake": "numpy + embree", "seconds": ref_seconds, "load_s": 0.0,
                 "bytes": int(ids.nbytes + ref[0].nbytes)})
    for r in rows:
        r["per_sample_ms"] = 1e3 * r["seconds"] / n_samples
        r["per_vertex_ns"] = 1e9 * r["seconds"] / (n_samples * n_vertices)
        r["speedup_vs_numpy"] = ref_seconds / r["seconds"]
        r["kib_per_sample"] = r["bytes"] / 1024

    scale = max(np.abs(c).max() for c in ref)
    diff = [np.abs(w - r_) for w, r_ in zip(warp_coeffs, ref)]
    differing = float(np.mean([np.mean(d.max(axis=1) > 1e-4 * scale) for d in diff]))
    agree = [d[d.max(axis=1) <= 1e-4 * scale] for d in diff]
    summary = {
        "sh_order": order,
        "vertices": n_vertices,
        "samples": n_samples,
        "coefficients_per_vertex": order * order,
        "max_abs_diff_where_visibility_agrees_rel": float(max(a.max() for a in agree if a.size) / scale),
        "fraction_vertices_differing": differing,
    }
    print(f"{scene.source}: {n_vertices:,} baked vertices, {n_samples} samples, SH order {order}, device {device}")
    print(table(rows, [("bake", "bake", "s"), ("seconds", "seconds", ".3f"), ("per_sample_ms", "ms/sample", ".1f"),
                       ("per_vertex_ns", "ns/vertex/sample", ".1f"), ("kib_per_sample", "KiB/sample", ",.0f"),
                       ("speedup_vs_numpy", "x numpy", ".2f")]))
    print(f"coefficients: {differing:.3%} of vertices differ by more than 1e-4 of the largest coefficient "
          f"(rays the two casters decide differently); elsewhere max relative difference "
          f"{summary['max_abs_diff_where_visibility_agrees_rel']:.2e}")
    name = "bake" + ("-quick" if args.quick else "")
    results = {"benchmark": "bake", "quick": args.quick, "scene": scene.source, "environment": environment(device),
               "summary": summary, "rows": rows}
    print("wrote", write(name, results, args.json))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.barh([r["bake"] for r in rows], [r["per_sample_ms"] for r in rows], color=["C0"] * (len(rows) - 1) + ["C7"])
    for i, r in enumerate(rows):
        ax.text(r["per_sample_ms"], i, f"  {r['per_sample_ms']:.0f} ms ({r['speedup_vs_numpy']:.2f}x)", va="center")
    ax.set_xlabel(f"ms per light sample ({n_vertices:,} vertices, SH order {order})")
    ax.set_title("Full-resolution bake, bunny + floor")
    ax.set_xlim(0, max(r["per_sample_ms"] for r in rows) * 1.4)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
