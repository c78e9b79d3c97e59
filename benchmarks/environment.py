"""Distant-light transfer bake and environment projection: cost against accuracy, Warp against numpy + Embree.

    python benchmarks/environment.py [--quick] [--json PATH] [--device cpu|cuda] [--sh-order N]

Scene: the Stanford bunny on a 60 x 60 floor (quick: the bunny alone), thesis material (kd 0.88), lit by
the procedural sky. Three tables:

1. transfer bake time per vertex against rays per vertex and bounces (shadowed, interreflected with 1 and 2
   bounce passes), with the error of the relit radiance against a high-ray reference bake (1024 rays; quick 128);
2. the same bakes by a brute-force float64 numpy + Embree (embreex) baker on the same rays (vectorised: one
   Embree call per pass, one matrix product for the projection), the speed ratio and the agreement;
3. LOD: the transfer cut of the vertex hierarchy at several thresholds, vertices and bytes kept, and the error of
   the relit radiance after T-15 completion against the full transfer;
4. mip-level projection of a 6 x 256 x 256 cube map (quick 6 x 64 x 64) at order 3: time per projection and the
   error of the coefficients and of the 9-coefficient irradiance against level 0 (I-3.2).
"""

from __future__ import annotations

import time

import numpy as np

from common import environment, model, parser, plot_path, table, write


def scene_for(quick: bool):
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    pos, faces = load_mesh(model("stanford-bunny"))
    floor = None if quick else (60, 1.0, THESIS_MATERIAL)
    return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], floor, {}, "lights",
                          "stanford-bunny" + ("" if quick else " + 60x60 floor"))


class EmbreeBaker:
    """Baseline: the same quadrature in float64 numpy, rays by Embree (independent of Warp)."""

    def __init__(self, geom):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        self.g = geom
        self.scene = rtcs.EmbreeScene()
        TriangleMesh(self.scene, geom.positions[geom.faces].astype(np.float32))

    def _rays(self, dirs):
        g = self.g
        ids = np.flatnonzero(g.referenced)
        c = g.normals[ids] @ dirs.T  # (V, R)
        v, r = np.nonzero(c > 0)
        o = g.positions[ids][v] + g.offset * g.normals[ids][v]
        return ids, c, v, r, o.astype(np.float32), dirs[r].astype(np.float32)

    def transfer(self, order, rays, bounces):
        from lodprt.model import sh
        from lodprt.precompute.transfer import fibonacci_directions

        g = self.g
        dirs = fibonacci_directions(rays).astype(np.float32).astype(np.float64)
        y = sh.basis(dirs, order)
        w = 4 * np.pi / rays
        ids, c, v, r, o, d = self._rays(dirs)
        hit = self.scene.run(o, d, output=1)
        prim = np.asarray(hit["primID"])
        free = prim == -1
        k = np.zeros_like(c)
        k[v[free], r[free]] = w * c[v[free], r[free]]
        geo = k @ y  # (V, n^2): integral max(n.s,0) V(s) y(s) ds
        scale = g.albedo[ids] / np.pi
        cur = np.zeros((len(g.positions), 3, order * order))
        cur[ids] = scale[:, :, None] * geo[:, None, :]
        total = cur.copy()
        front = np.zeros(len(prim), bool)  # front-face hits pass light on; backs of surfaces do not
        front[~free] = (np.asarray(hit["Ng"])[~free] * d[~free]).sum(1) < 0  # Embree's Ng: (p1 - p0) x (p2 - p0)
        if bounces:
            sel = np.flatnonzero(front)
            f = g.faces[prim[sel]]
            u, vv = np.asarray(hit["u"])[sel], np.asarray(hit["v"])[sel]
            bw = np.stack([1 - u - vv, u, vv], 1)
            wc = w * c[v[sel], r[sel]]
        for _ in range(bounces):
            t = np.einsum("rk,rkcj->rcj", bw, cur[f]) * wc[:, None, None]
            acc = np.zeros((len(ids), 3, order * order))
            np.add.at(acc, v[sel], t)
            cur = np.zeros_like(cur)
            cur[ids] = scale[:, :, None] * acc
            total += cur
        return total


def relit_error(t, ref, lighting, referenced):
    from lodprt.runtime.environment_relight import diffuse_radiance

    a = diffuse_radiance(t[referenced], lighting)
    b = diffuse_radiance(ref[referenced], lighting)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--sh-order", type=int, default=3)
    args = p.parse_args()
    from lodprt.model import environment as E
    from lodprt.model import irradiance as I
    from lodprt.devices import resolve_device
    from lodprt.devices import load_kernels
    from lodprt.precompute.transfer import Geometry, diffuse_transfer, transfer_kernels

    device = resolve_device(args.device)
    order = args.sh_order
    scene = scene_for(args.quick)
    geom = Geometry.from_scene(scene, device=device)
    nv = int(geom.referenced.sum())
    load_s = load_kernels(device, *transfer_kernels())
    lighting = E.procedural("sky", resolution=64).project(order)
    ray_counts = [8, 16, 32] if args.quick else [32, 64, 128, 256]
    ref_rays = 128 if args.quick else 1024
    settings = [("shadowed", 0), ("interreflected", 1), ("interreflected", 2)]

    refs = {}
    for mode, b in settings:
        refs[(mode, b)] = diffuse_transfer(geom, order=order, mode=mode, rays=ref_rays, bounces=b, threshold=0).transfer

    embree = EmbreeBaker(geom)
    rows = []
    for mode, b in settings:
        for rays in ray_counts:
            t0 = time.perf_counter()
            res = diffuse_transfer(geom, order=order, mode=mode, rays=rays, bounces=b, threshold=0)
            warp_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            base = embree.transfer(order, rays, b)
            np_s = time.perf_counter() - t0
            rows.append({
                "mode": mode, "bounces": b, "rays": rays,
                "warp_s": warp_s, "warp_us_per_vertex": 1e6 * warp_s / nv,
                "error_vs_ref": relit_error(res.transfer, refs[(mode, b)], lighting, geom.referenced),
                "numpy_embree_s": np_s, "ratio": np_s / warp_s,
                "warp_vs_numpy": relit_error(res.transfer, base, lighting, geom.referenced),
                "energy": res.energy,
            })
    cols = [("mode", "mode", ""), ("bounces", "bounces", "d"), ("rays", "rays/vertex", "d"), ("warp_s", "warp s", ".2f"),
            ("warp_us_per_vertex", "warp us/vertex", ".1f"), ("error_vs_ref", f"err vs {ref_rays} rays", ".2e"),
            ("numpy_embree_s", "numpy+embree s", ".2f"), ("ratio", "numpy/warp", ".2f"),
            ("warp_vs_numpy", "warp vs numpy", ".1e")]
    print(f"transfer bake, {scene.source}: {nv:,} vertices, SH order {order}, device {device} (kernel load {load_s:.2f} s)")
    print(table(rows, cols))

    # LOD: keep vertices where transfer vectors differ (the reference 2-bounce transfer), complete the rest (T-15)
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.precompute.transfer import transfer_cut
    from lodprt.store.transfer_store import complete_transfer

    t0 = time.perf_counter()
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    tree_s = time.perf_counter() - t0
    full_t = refs[("interreflected", 2)]
    lods = []
    for eps in ([0.02, 0.05, 0.1] if args.quick else [0.01, 0.02, 0.05, 0.1, 0.2]):
        t0 = time.perf_counter()
        cut = transfer_cut(tree, full_t, eps)
        cut_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        done = complete_transfer(tree, scene.positions, scene.normals, cut, full_t[tree.vertex[cut]])
        comp_s = time.perf_counter() - t0
        lods.append({"threshold": eps, "vertices_kept": len(cut), "fraction": len(cut) / nv,
                     "kib": len(cut) * full_t[0].size * 4 / 1024, "cut_s": cut_s, "complete_s": comp_s,
                     "relit_error": relit_error(done, full_t, lighting, geom.referenced)})
    print(f"\nLOD (transfer cut + T-15 completion) of the {ref_rays}-ray 2-bounce transfer; hierarchy {tree_s:.1f} s, "
          f"full {nv:,} vertices = {nv * full_t[0].size * 4 / 1024:,.0f} KiB")
    print(table(lods, [("threshold", "threshold", ".2f"), ("vertices_kept", "kept", ",d"), ("fraction", "fraction", ".3f"),
                       ("kib", "KiB", ",.0f"), ("cut_s", "cut s", ".3f"), ("complete_s", "complete s", ".3f"),
                       ("relit_error", "relit RMS err", ".2e")]))

    res_cube = 64 if args.quick else 256
    env = E.procedural("sky", resolution=res_cube, kind="cube")
    n = np.random.default_rng(0).normal(size=(2000, 3))
    levels = E.mip_projections(env, 3, min_resolution=4, repeats=3)
    full_e = I.irradiance(n, levels[0]["coefficients"])
    mips = []
    for lv in levels:
        e = I.irradiance(n, lv["coefficients"])
        mips.append({"level": lv["level"], "face": f"{lv['shape'][1]}x{lv['shape'][2]}", "texels": lv["texels"],
                     "project_ms": 1e3 * lv["seconds"], "filter_ms": 1e3 * lv.get("filter_seconds", 0.0),
                     "coeff_rel_error": lv["relative_error"],
                     "irradiance_max_rel_error": float((np.abs(e - full_e) / full_e).max())})
    print(f"\nmip-level projection, procedural sky cube map 6 x {res_cube} x {res_cube}, order 3 (9 coefficients)")
    print(table(mips, [("level", "level", "d"), ("face", "face", ""), ("texels", "texels", ",d"),
                       ("project_ms", "project ms", ".3f"), ("filter_ms", "filter ms", ".2f"),
                       ("coeff_rel_error", "coeff rel err", ".2e"), ("irradiance_max_rel_error", "E max rel err", ".2e")]))

    results = {"benchmark": "environment", "quick": args.quick, "scene": scene.source, "vertices": nv,
               "sh_order": order, "reference_rays": ref_rays, "kernel_load_s": load_s, "transfer": rows, "mip": mips,
               "lod": lods, "hierarchy_s": tree_s,
               "environment": environment(device)}
    print(f"\nwrote {write('environment' + ('-quick' if args.quick else ''), results, args.json)}")

    out = plot_path("environment" + ("-quick" if args.quick else ""))
    plot(results, out)
    print(f"wrote {out}")


def plot(results: dict, out) -> None:
    """The three panels from a results dict (also: python -c 'plot(json.load(...), path)' to redraw)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, mips, nv, ref_rays = results["transfer"], results["mip"], results["vertices"], results["reference_rays"]
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    settings = sorted({(r["mode"], r["bounces"]) for r in rows}, key=lambda x: x[1])
    for k, (mode, b) in enumerate(settings):
        rs = [r for r in rows if r["mode"] == mode and r["bounces"] == b]
        label = mode if mode == "shadowed" else f"{b} bounce(s)"
        col = f"C{k}"
        ax[0].plot([r["rays"] for r in rs], [r["warp_us_per_vertex"] for r in rs], "o-", color=col, label=f"warp, {label}")
        ax[0].plot([r["rays"] for r in rs], [1e6 * r["numpy_embree_s"] / nv for r in rs], "x--", color=col,
                   label=f"numpy+embree, {label}")
        ax[1].loglog([r["warp_us_per_vertex"] for r in rs], [r["error_vs_ref"] for r in rs], "o-", color=col, label=label)
        for r in rs:
            ax[1].annotate(str(r["rays"]), (r["warp_us_per_vertex"], r["error_vs_ref"]), fontsize=7)
    ax[0].set(xlabel="rays per vertex", ylabel="bake time per vertex (us)", title="transfer bake cost", xscale="log", yscale="log")
    ax[0].legend(fontsize=7)
    ax[1].set(xlabel="warp time per vertex (us)", ylabel=f"relit radiance error vs {ref_rays} rays",
              title="error against run time (labels: rays)")
    ax[1].legend(fontsize=7)
    lv = [m for m in mips if m["level"] > 0]
    ax[2].semilogy([m["level"] for m in lv], [m["coeff_rel_error"] for m in lv], "o-", label="coefficient rel. error")
    ax[2].semilogy([m["level"] for m in lv], [m["irradiance_max_rel_error"] for m in lv], "s-", label="irradiance max rel. error")
    ax2 = ax[2].twinx()
    ax2.semilogy([m["level"] for m in mips], [m["project_ms"] for m in mips], "k^:", label="projection ms")
    ax2.set_ylabel("projection time (ms)")
    ax[2].set(xlabel=f"mip level (0 = {mips[0]['face']} faces)", ylabel="error against level 0",
              title="mip-level projection (I-3.2)")
    ax[2].legend(fontsize=7, loc="upper left")
    ax2.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
