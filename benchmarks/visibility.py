"""Shadow-ray throughput: Warp's BVH any-hit kernel against Embree (embreex) on the same rays, in one run.

    python benchmarks/visibility.py [--quick] [--json PATH] [--device cpu|cuda]

Scene: the Stanford bunny on a 380 x 380 floor, 3 x 1 x 3 light samples (quick: 100 x 100, 2 samples).
Rays: one per vertex facing each light (vertices facing away cast none, in both casters).
Reports rays/s of Warp (one launch per sample; on the CPU one thread, and the bake's two-threads-two-samples mode)
and of Embree, their ratio, and how often the two disagree.
"""

from __future__ import annotations

import concurrent.futures
import time

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write


def main():
    args = parser(__doc__.splitlines()[0]).parse_args()
    from lodprt.precompute import reference
    from lodprt.devices import load_kernels
    from lodprt.precompute.baker import Baker, bake_kernels, ray_offset
    from lodprt.devices import resolve_device, warp

    device = resolve_device(args.device)
    scene = thesis_scene(quick=args.quick)
    wp = warp()
    load_kernels(device, *bake_kernels())
    ids = np.flatnonzero(scene.referenced).astype(np.int32)
    t = time.perf_counter()
    baker = Baker(scene, 1, device, ids)
    bvh_seconds = time.perf_counter() - t
    t = time.perf_counter()
    caster = reference.EmbreeCaster(scene)
    embree_build = time.perf_counter() - t
    offset = ray_offset(scene)
    lights = scene.lights.positions
    repeats = 1 if args.quick else 3

    rows, total = [], {"warp": 0.0, "embree": 0.0, "rays": 0}
    for k, light in enumerate(lights):
        baker.visibility(light)  # warm
        wp.synchronize_device(device)
        tw = []
        for _ in range(repeats):
            t = time.perf_counter()
            vis = baker.visibility(light)
            wp.synchronize_device(device)
            tw.append(time.perf_counter() - t)
        vis = vis.numpy()
        facing, o, d, dist = reference.shadow_rays(scene, light, offset, ids)
        te = []
        for _ in range(repeats):
            t = time.perf_counter()
            hit = caster.occluded(o[facing], d[facing], dist[facing])
            te.append(time.perf_counter() - t)
        ref = np.full(len(ids), reference.BACK_FACING, np.uint8)
        ref[facing] = np.where(hit, reference.SHADOWED, reference.LIT)
        rays = int(facing.sum())
        row = {
            "sample": k,
            "rays": rays,
            "warp_s": min(tw),
            "embree_s": min(te),
            "warp_mrays": rays / min(tw) / 1e6,
            "embree_mrays": rays / min(te) / 1e6,
            "ratio": min(te) / min(tw),
            "disagree": float(np.mean(vis != ref)),
            "shadowed": float(np.mean(vis == reference.SHADOWED)),
        }
        rows.append(row)
        total["warp"] += row["warp_s"]
        total["embree"] += row["embree_s"]
        total["rays"] += rays

    # the bake's mode on the CPU: one sample per thread, both cores
    jobs = 2 if device == "cpu" else 1
    t = time.perf_counter()
    with concurrent.futures.ThreadPoolExecutor(jobs) as pool:
        list(pool.map(lambda li: baker.visibility(li).numpy(), lights))
    threaded = time.perf_counter() - t

    summary = {
        "rays": total["rays"],
        "warp_mrays_per_s": total["rays"] / total["warp"] / 1e6,
        "warp_threaded_mrays_per_s": total["rays"] / threaded / 1e6,
        "warp_threads": jobs,
        "embree_mrays_per_s": total["rays"] / total["embree"] / 1e6,
        "warp_over_embree_throughput": total["embree"] / total["warp"],
        "warp_bvh_build_s": bvh_seconds,
        "embree_build_s": embree_build,
        "max_disagreement": max(r["disagree"] for r in rows),
        "shadowed_fraction": float(np.mean([r["shadowed"] for r in rows])),
    }
    print(f"{scene.source}: {scene.num_vertices:,} vertices, {len(scene.faces):,} triangles, {len(lights)} samples, device {device}")
    print(table(rows, [("sample", "sample", "d"), ("rays", "rays", ","), ("warp_mrays", "warp Mray/s", ".2f"),
                       ("embree_mrays", "embree Mray/s", ".2f"), ("ratio", "warp/embree", ".2f"),
                       ("disagree", "disagree", ".2e"), ("shadowed", "shadowed", ".4f")]))
    print(f"total: Warp {summary['warp_mrays_per_s']:.2f} Mrays/s (1 launch at a time), "
          f"{summary['warp_threaded_mrays_per_s']:.2f} Mrays/s ({jobs} threads), Embree {summary['embree_mrays_per_s']:.2f} "
          f"Mrays/s; Warp/Embree throughput {summary['warp_over_embree_throughput']:.2f}x")
    results = {"benchmark": "visibility", "quick": args.quick, "scene": scene.source, "environment": environment(device),
               "summary": summary, "samples": rows}
    print("wrote", write("visibility" + ("-quick" if args.quick else ""), results, args.json))
    plot(rows, summary, "visibility" + ("-quick" if args.quick else ""))


def plot(rows, summary, name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["warp_mrays"] for r in rows], 0.4, label="Warp any-hit (1 launch)")
    ax.bar(x + 0.2, [r["embree_mrays"] for r in rows], 0.4, label="Embree OCCLUDED")
    ax.axhline(summary["warp_threaded_mrays_per_s"], color="k", ls="--", lw=1,
               label=f"Warp, {summary['warp_threads']} samples in parallel")
    ax.set_xlabel("light sample")
    ax.set_ylabel("million shadow rays / s")
    ax.set_title("Shadow-ray throughput, bunny + floor")
    ax.legend()
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
