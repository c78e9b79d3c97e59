"""Neighbourhood transfer (patent 5): grid resolution against the error of an object's shadow on a receiver, and
the per-frame cost.

    python benchmarks/neighbourhood.py [--quick] [--json PATH] [--device cpu|cuda] [--rays R]

Object O: the Stanford bunny (quick: an icosphere) above a 61 x 61 ground plane (quick 31 x 31), kd 0.8,
lit by the procedural sky at order 3. The reference is the plane's own shadowed transfer bake of the O + plane
scene (``lodprt bake-environment --transfer shadowed``, same rays) against the plane alone: its darkening. For
each grid resolution G^3 (margin 1 extent, occlusion only, as that reference has no reflection): the bake time
(all, and of the matrices alone: the rest is O's own transfer, which the store keeps to draw O), the store size,
the RMS and worst error of the receiver's darkening relative to the deepest darkening, and the per-frame cost:
L'_p = M_p L on the grid (N-3) and the receiver's interpolation and exit radiance (N-4, N-5). One more row adds
O's reflected light (N-2) to show what it adds.
"""

from __future__ import annotations

import time

import numpy as np

from common import environment, model, parser, plot_path, table, write


def scene_for(quick: bool):
    """(scene with O and the plane, the plane alone, plane vertex positions, O's vertex count, a label)."""
    import trimesh

    from lodprt.model.scene import Material, assemble_scene, load_mesh, vertex_normals

    mat = Material((0.8, 0.8, 0.8), 0.0, 1.0)
    if quick:
        m = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
        op, of, name = np.asarray(m.vertices) + [0, 0.45, 0], np.asarray(m.faces), "icosphere"
    else:
        op, of = load_mesh(model("stanford-bunny"))
        name = "stanford-bunny"
    lo, hi = op.min(0), op.max(0)
    ext = float((hi - lo).max())
    n = 31 if quick else 61
    y0 = lo[1] - 0.02 * ext
    cx, cz = np.linspace(lo[0] - ext, hi[0] + ext, n), np.linspace(lo[2] - ext, hi[2] + ext, n)
    x, z = np.meshgrid(cx, cz, indexing="ij")
    pp = np.stack([x.ravel(), np.full(n * n, y0), z.ravel()], 1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + n, i.ravel() + 1, i.ravel() + n + 1
    pf = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    if vertex_normals(pp, pf)[0, 1] < 0:
        pf = pf[:, ::-1]
    both = assemble_scene([("object", op, of, mat), ("plane", pp, pf, mat)], None, {}, "lights", f"{name} + plane")
    bare = assemble_scene([("plane", pp, pf, mat)], None, {}, "lights", "plane")
    return both, bare, pp, len(op), f"{name} ({len(op):,} vertices) over a {n} x {n} plane"


class InMemory:
    def __init__(self, bake):
        self.bake, self.lo, self.hi = bake, bake.lo, bake.hi

    def matrices(self):
        return self.bake.matrices


def frame_cost(store, lighting, points, normals, repeats=5) -> tuple[float, float]:
    """Best-of-``repeats`` ms of N-3 on the grid, and of N-4 + N-5 on the receiver."""
    from lodprt.runtime import neighbourhood as N

    grid_t, recv_t = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        g = N.transferred_lighting(store.matrices(), lighting)
        grid_t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        lq, _ = N.receiver_lighting(g, store.lo, store.hi, lighting, points)
        N.diffuse_exit(lq, normals, np.full(3, 0.8))
        recv_t.append(time.perf_counter() - t0)
    return 1e3 * min(grid_t), 1e3 * min(recv_t)


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--rays", type=int, default=256)
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.model.environment import procedural
    from lodprt.precompute.neighbourhood import bake_neighbourhood
    from lodprt.precompute.transfer import Geometry, diffuse_transfer
    from lodprt.runtime import neighbourhood as N

    device = resolve_device(args.device)
    both, bare, pp, nobj, label = scene_for(args.quick)
    lighting = procedural("sky", resolution=64).project(3)
    t0 = time.perf_counter()
    t1 = diffuse_transfer(Geometry.from_scene(both, device=device), order=3, mode="shadowed", rays=args.rays).transfer[nobj:]
    ref_s = time.perf_counter() - t0
    t0_ = diffuse_transfer(Geometry.from_scene(bare, device=device), order=3, mode="shadowed", rays=args.rays).transfer
    r1, r0 = np.einsum("vci,ci->vc", t1, lighting), np.einsum("vci,ci->vc", t0_, lighting)
    dark_ref = r0 - r1
    deepest = float(dark_ref.max())
    nrm = np.tile([0.0, 1.0, 0.0], (len(pp), 1))
    plain = N.diffuse_exit(np.repeat(lighting[None], len(pp), 0), nrm, np.full(3, 0.8))
    sizes = [6, 10, 16] if args.quick else [8, 12, 16, 24, 32]
    rows, occluded = [], {}
    for g in sizes + [sizes[-2]]:
        refl = len(rows) == len(sizes)
        res = bake_neighbourhood(both, "object", None, grid=(g, g, g), margin=1.0, sh_order=3, rays=args.rays,
                                 reflection=refl, bounces=1 if refl else 0, device=device)
        store = InMemory(res)
        rad, inside = N.receiver_radiance(store, lighting, pp, nrm, np.full(3, 0.8))
        err = np.abs((plain - rad) - dark_ref)
        grid_ms, recv_ms = frame_cost(store, lighting, pp, nrm)
        rows.append({"grid": g, "points": g**3, "reflection": refl, "bake_s": res.seconds, "grid_s": res.grid_seconds,
                     "us_per_point": 1e6 * res.grid_seconds / g**3, "mib": res.matrices.nbytes / 2**20,
                     "rms_error": float(np.sqrt((err**2).mean()) / deepest), "max_error": float(err.max() / deepest),
                     "inside": float(inside.mean()), "grid_ms": grid_ms, "receiver_ms": recv_ms})
        if refl:  # what O's reflected light adds, mean and most, relative to the deepest darkening
            added = rad - occluded[g]
            rows[-1].update(reflection_mean=float(added.mean() / deepest), reflection_max=float(added.max() / deepest))
        else:
            occluded[g] = rad
    print(f"neighbourhood transfer, {label}; {args.rays} rays, SH order 3, device {device}; reference: the plane's "
          f"shadowed bake ({ref_s:.1f} s), deepest darkening {deepest:.4f} of {float(r0.max()):.4f}")
    print(table(rows, [("grid", "grid", "d"), ("reflection", "reflection", ""), ("bake_s", "bake s", ".2f"),
                       ("grid_s", "matrices s", ".2f"),
                       ("us_per_point", "us/point", ".0f"), ("mib", "MiB", ".1f"), ("rms_error", "RMS err", ".4f"),
                       ("max_error", "max err", ".4f"), ("inside", "in grid", ".2f"), ("grid_ms", "N-3 ms", ".2f"),
                       ("receiver_ms", "N-4,5 ms", ".2f")]))
    r = rows[-1]
    print(f"errors relative to the deepest darkening; the reflection row compares with the occlusion-only reference: "
          f"O's reflected light adds {r['reflection_mean']:.4f} on average, {r['reflection_max']:.4f} at most (same units)")
    results = {"benchmark": "neighbourhood", "quick": args.quick, "scene": label, "rays": args.rays,
               "receiver_vertices": len(pp), "reference_s": ref_s, "deepest_darkening": deepest, "rows": rows,
               "environment": environment(device)}
    name = "neighbourhood" + ("-quick" if args.quick else "")
    print(f"\nwrote {write(name, results, args.json)}")
    out = plot_path(name)
    plot(results, out)
    print(f"wrote {out}")


def plot(results: dict, out) -> None:
    """Error and per-frame cost against grid resolution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in results["rows"] if not r["reflection"]]
    g = [r["grid"] for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].semilogy(g, [r["rms_error"] for r in rows], "o-", label="RMS")
    ax[0].semilogy(g, [r["max_error"] for r in rows], "s-", label="worst")
    ax[0].set(xlabel="grid points per axis", ylabel="darkening error / deepest darkening",
              title=f"receiver error, {results['scene']}")
    ax[1].loglog([r["points"] for r in rows], [r["grid_ms"] for r in rows], "o-", label="L'_p = M_p L on the grid (N-3)")
    ax[1].loglog([r["points"] for r in rows], [r["receiver_ms"] for r in rows], "s-", label="receiver (N-4, N-5)")
    ax[1].loglog([r["points"] for r in rows], [r["grid_s"] * 1e3 for r in rows], "^:", label="bake of the matrices (ms)")
    ax[1].set(xlabel="grid points", ylabel="ms", title="per-frame cost and bake time")
    for a in ax:
        a.legend(fontsize=8)
    ax[0].title.set_fontsize(9)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
