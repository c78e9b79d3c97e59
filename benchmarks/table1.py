"""Thesis Table 1: light-dependent cut thresholds against the original model -- vertices, bytes, bake time, error.

    python benchmarks/table1.py [--quick] [--json PATH] [--device cpu|cuda]

Scene: the Stanford bunny on a 380 x 380 floor, 3 x 1 x 3 uniform light samples, SH order 4, thresholds
5, 10, 20, 30, 50, 100 degrees and the full-resolution bake (quick: 100 x 100 floor, 2 samples, 3 thresholds).
Errors, for a fixed eye and averaged over the samples:
  * completed cut radiance against the full-resolution bake's radiance (relative RMSE and max, over all vertices
    and over the vertices the light reaches);
  * each bake against exact Phong with exact visibility (Embree) over the vertices facing the eye, excluding the
    vertices whose shadow state flips within one ring (shadow-boundary outliers, reported separately).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write

THESIS = {None: (177384.0, 15751), 5: (40985.7, 3640), 10: (38448.1, 3414), 20: (37164.6, 3300),
          30: (36943.5, 3280), 50: (36857.5, 3272), 100: (36856.7, 3272)}
EYE_OFFSET = np.array([0.0, 0.6, 1.6])  # in units of the objects' largest extent, from the objects' centre


def exact_phong(scene, light, eye, caster, offset):
    """Direct Phong radiance toward the eye with Embree visibility (unit intensity), float64."""
    from lodprt.precompute import reference

    vis = reference.visibility(caster, scene, light, offset)
    p, n = scene.positions, scene.normals
    to = light - p
    d = np.linalg.norm(to, axis=1)
    l = to / d[:, None]
    s = eye - p
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    ndl = (n * l).sum(1)
    r = 2 * ndl[:, None] * n - l
    m = scene.materials[0]
    e = 1 / np.maximum(d, scene.lights.radius) ** 2
    val = e * (m.kd[0] * np.clip(ndl, 0, None) + m.ks * np.clip((r * s).sum(1), 0, None) ** m.shininess)
    return np.where(vis == reference.LIT, val, 0.0), vis


def shadow_boundary(scene, vis):
    """Vertices with a neighbour of another shadow state (lit vs not)."""
    lit = vis == 1
    f = scene.faces
    mixed = lit[f].any(1) & ~lit[f].all(1)
    out = np.zeros(scene.num_vertices, bool)
    out[f[mixed].ravel()] = True
    return out


def rel_rmse(a, b, sel):
    return float(np.sqrt(np.mean((a[sel] - b[sel]) ** 2)) / max(np.sqrt(np.mean(b[sel] ** 2)), 1e-30))


def rel_max(a, b, sel):
    return float(np.abs(a[sel] - b[sel]).max() / max(np.abs(b[sel]).max(), 1e-30))


def main():
    args = parser(__doc__.splitlines()[0]).parse_args()
    from lodprt.precompute import reference
    from lodprt.precompute.bake import bake
    from lodprt.precompute.baker import ray_offset
    from lodprt.model.completion import CompletionPlan
    from lodprt.devices import resolve_device
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.store.bake_store import open_store

    device = resolve_device(args.device)
    scene = thesis_scene(quick=args.quick)
    thresholds = [5, 30, 100] if args.quick else [5, 10, 20, 30, 50, 100]
    t = time.perf_counter()
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    hierarchy_s = time.perf_counter() - t
    plan = CompletionPlan(tree, scene.positions, scene.normals)
    print(f"{scene.source}: {int(scene.referenced.sum()):,} referenced vertices; hierarchy {tree.num_nodes:,} nodes "
          f"in {hierarchy_s:.1f} s; completion rules {plan.rule_fractions()}", flush=True)
    obj = scene.object_id == 0
    ext = float((scene.positions[obj].max(0) - scene.positions[obj].min(0)).max())
    eye = scene.positions[obj].mean(0) + EYE_OFFSET * ext
    caster = reference.EmbreeCaster(scene)
    offset = ray_offset(scene)
    ref = scene.referenced
    tmp = Path(tempfile.mkdtemp(prefix="lodprt-table1-"))
    rows = []
    try:
        exact, exact_vis = [], []
        for light in scene.lights.positions:
            e, v = exact_phong(scene, light, eye, caster, offset)
            exact.append(e)
            exact_vis.append(v)
        facing = ((eye - scene.positions) * scene.normals).sum(1) > 0
        full_rad = None
        for th in [None] + thresholds:
            out = tmp / f"t{th}.zarr"
            res = bake(scene, out, sh_order=4, device=device, tree=tree, threshold_deg=th)
            store = open_store(out)
            store.set_completion_plan(plan)
            t = time.perf_counter()
            rad = [store.radiance(k, eye)[:, 0].astype(np.float64) for k in range(store.num_samples)]
            radiance_s = (time.perf_counter() - t) / store.num_samples
            if th is None:
                full_rad = rad
            row = {
                "threshold": "original" if th is None else th,
                "vertices": float(np.mean([s["vertices_kept"] for s in res.samples])),
                "kib": float(np.mean([s["bytes"] for s in res.samples]) / 1024),
                "bake_s": res.bake_seconds,
                "radiance_ms": 1e3 * radiance_s,
                "thesis_vertices": THESIS[th][0],
                "thesis_kib": THESIS[th][1],
            }
            errs = {"rmse_all": [], "max_all": [], "rmse_lit": [], "max_lit": [], "exact_rmse": [], "boundary": []}
            for k in range(len(rad)):
                lit = ref & (exact_vis[k] == reference.LIT)
                errs["rmse_all"].append(rel_rmse(rad[k], full_rad[k], ref))
                errs["max_all"].append(rel_max(rad[k], full_rad[k], ref))
                errs["rmse_lit"].append(rel_rmse(rad[k], full_rad[k], lit))
                errs["max_lit"].append(rel_max(rad[k], full_rad[k], lit))
                boundary = shadow_boundary(scene, exact_vis[k])
                sel = ref & facing & ~boundary
                errs["exact_rmse"].append(rel_rmse(rad[k], exact[k], sel))
                errs["boundary"].append(rel_rmse(rad[k], exact[k], ref & facing & boundary))
            for key, vals in errs.items():
                row[key] = float(np.mean(vals))
            row["reduction"] = rows[0]["vertices"] / row["vertices"] if rows else 1.0
            rows.append(row)
            print(f"threshold {row['threshold']}: {row['vertices']:,.0f} vertices, rmse vs full {row['rmse_all']:.4f}",
                  flush=True)
            shutil.rmtree(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print(table(rows, [("threshold", "threshold", ""), ("vertices", "mean vertices", ",.1f"),
                       ("reduction", "reduction", ".2f"), ("kib", "KiB/sample", ",.0f"),
                       ("thesis_vertices", "thesis vertices", ",.1f"), ("thesis_kib", "thesis KB", ",.0f"),
                       ("bake_s", "bake s", ".2f"), ("rmse_all", "rRMSE all", ".4f"), ("max_all", "rMax all", ".3f"),
                       ("rmse_lit", "rRMSE lit", ".4f"), ("exact_rmse", "rRMSE vs exact", ".4f"),
                       ("boundary", "rRMSE shadow edge", ".3f")]))
    name = "table1" + ("-quick" if args.quick else "")
    results = {"benchmark": "table1", "quick": args.quick, "scene": scene.source, "eye": eye.tolist(),
               "hierarchy_seconds": hierarchy_s, "completion_rules": plan.rule_fractions(),
               "environment": environment(device), "rows": rows}
    print("wrote", write(name, results, args.json))

    plot(rows, name)


def plot(rows, name):
    """Error against bake time (markers: the times are close and noisy) and against bytes (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key, label in ((axes[0], "bake_s", "bake time (s, all samples)"), (axes[1], "kib", "KiB per sample")):
        x = [r[key] for r in rows]
        style = ("o", "s") if key == "bake_s" else ("o-", "s--")
        ax.plot(x, [r["rmse_all"] for r in rows], style[0], label="vs full bake, all vertices")
        ax.plot(x, [r["exact_rmse"] for r in rows], style[1], label="vs exact Phong, facing eye, no shadow edges")
        for r in rows:
            ax.annotate(str(r["threshold"]), (r[key], r["rmse_all"]), fontsize=8, xytext=(3, 3), textcoords="offset points")
        ax.set_xlabel(label)
        ax.set_ylabel("relative RMSE of radiance")
        ax.grid(alpha=0.3)
    axes[1].set_xscale("log")
    axes[0].legend(fontsize=8)
    fig.suptitle("Light-dependent cut: error against bake time and bytes (labels: threshold, degrees)")
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
