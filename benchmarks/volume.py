"""Volumetric self-transfer (patent 4.3): bake time per voxel against rays and bounces, error against a many-ray
reference, and the per-frame cost of relighting and ray marching.

    python benchmarks/volume.py [--quick] [--json PATH] [--device cpu|cuda] [--sh-order N]

Medium: the procedural cloud (``cloud:16``, 16 x 8 x 16 voxels; quick ``cloud:10``), albedo 0.9, lit by the
procedural sky. For the shadowed pass alone and with 1 and 2 scattering passes, at several rays per voxel: the
bake time per voxel and the relative RMS error of the relit source radiance J = M . L (V-6, weighted by density)
against a reference bake with many rays (512; quick 96) and the same passes. Then the run-time cost of a frame:
the relighting (one dot product per voxel and channel) and the GL ray march of a 320 x 240 image (V-7).
"""

from __future__ import annotations

import time

import numpy as np

from common import environment, parser, plot_path, table, write


def relit_error(t, ref, lighting, density) -> float:
    from lodprt.runtime.volume_relight import source_radiance

    a, b = source_radiance(t, lighting), source_radiance(ref, lighting)
    w = density[..., None]
    return float(np.sqrt((w * (a - b) ** 2).sum() / (w * b**2).sum()))


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--sh-order", type=int, default=3)
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.model.environment import procedural
    from lodprt.model.volume import procedural_volume
    from lodprt.devices import load_kernels
    from lodprt.precompute.volume import VolumeGrid, volume_kernels, volume_transfer

    device = resolve_device(args.device)
    order = args.sh_order
    spec = "cloud:10" if args.quick else "cloud:16"
    vol = procedural_volume(spec, albedo=0.9)
    nvox = int(np.prod(vol.shape))
    load_s = load_kernels(device, *volume_kernels())
    grid = VolumeGrid(vol, device=device)
    lighting = procedural("sky", resolution=64).project(order)
    ray_counts = [8, 16, 32] if args.quick else [16, 32, 64, 128]
    ref_rays = 96 if args.quick else 512
    settings = [0, 1, 2]
    refs = {b: volume_transfer(grid, order=order, rays=ref_rays, bounces=b, threshold=0, seed=1000) for b in settings}
    rows = []
    for b in settings:
        for rays in ray_counts:
            t0 = time.perf_counter()
            res = volume_transfer(grid, order=order, rays=rays, bounces=b, threshold=0)
            s = time.perf_counter() - t0
            rows.append({"bounces": b, "rays": rays, "seconds": s, "us_per_voxel": 1e6 * s / nvox,
                         "error_vs_ref": relit_error(res.transfer, refs[b].transfer, lighting, vol.density),
                         "energy": res.energy})
    print(f"volume transfer bake, {vol.source}: {' x '.join(map(str, vol.shape))} = {nvox:,} voxels, SH order {order}, "
          f"step {grid.step:.4g}, device {device} (kernel load {load_s:.2f} s); reference {ref_rays} rays")
    print(table(rows, [("bounces", "bounces", "d"), ("rays", "rays/voxel", "d"), ("seconds", "bake s", ".2f"),
                       ("us_per_voxel", "us/voxel", ".1f"), ("error_vs_ref", f"err vs {ref_rays} rays", ".2e")]))
    ref_energy = refs[2].energy
    print("pass energies (density-weighted radiance under a unit white sky, V-5) of the reference: "
          + ", ".join(f"{e:.4f}" for e in ref_energy) + "; ratios "
          + ", ".join(f"{b / a:.3f}" for a, b in zip(ref_energy, ref_energy[1:])) + f" (albedo {vol.albedo[0]:g})")

    frame = frame_cost(vol, refs[2].transfer, lighting)
    print(f"\nper frame: relight {frame['relight_ms']:.2f} ms, GL ray march {frame['size'][0]} x {frame['size'][1]} "
          f"{frame['march_ms']:.1f} ms ({frame['renderer']})")
    results = {"benchmark": "volume", "quick": args.quick, "volume": vol.source, "shape": list(vol.shape),
               "voxels": nvox, "sh_order": order, "step": grid.step, "reference_rays": ref_rays,
               "kernel_load_s": load_s, "transfer": rows, "reference_energy": ref_energy, "frame": frame,
               "environment": environment(device)}
    name = "volume" + ("-quick" if args.quick else "")
    print(f"\nwrote {write(name, results, args.json)}")
    out = plot_path(name)
    plot(results, out)
    print(f"wrote {out}")


def frame_cost(vol, transfer, lighting, size=(320, 240), repeats=3) -> dict:
    """Per-frame relighting (V-6) and GL ray march (V-7) times, best of ``repeats``; the march includes the
    context, texture upload and read-back, as render-volume does it."""
    from lodprt.display.render import create_context
    from lodprt.display.volume_render import march
    from lodprt.runtime.volume_relight import source_radiance

    relight, marching = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        src = source_radiance(transfer, lighting)
        relight.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        march(vol.density, src, vol.lo, vol.hi, eye=(0.0, 0.8, 2.6), size=size)
        marching.append(time.perf_counter() - t0)
    ctx = create_context()
    renderer = ctx.info.get("GL_RENDERER", "?")
    ctx.release()
    return {"relight_ms": 1e3 * min(relight), "march_ms": 1e3 * min(marching), "size": list(size), "renderer": renderer}


def plot(results: dict, out) -> None:
    """Time per voxel against rays, and error against time (labels: rays), per number of scattering passes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = results["transfer"]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for b in sorted({r["bounces"] for r in rows}):
        rs = [r for r in rows if r["bounces"] == b]
        label = "shadowed" if b == 0 else f"+{b} scattering pass(es)"
        ax[0].loglog([r["rays"] for r in rs], [r["us_per_voxel"] for r in rs], "o-", label=label)
        ax[1].loglog([r["us_per_voxel"] for r in rs], [r["error_vs_ref"] for r in rs], "o-", label=label)
        for r in rs:
            ax[1].annotate(str(r["rays"]), (r["us_per_voxel"], r["error_vs_ref"]), fontsize=7)
    ax[0].set(xlabel="rays per voxel", ylabel="bake time per voxel (us)",
              title=f"volume bake, {results['volume']} ({results['voxels']:,} voxels)")
    ax[1].set(xlabel="bake time per voxel (us)", ylabel=f"relit J error vs {results['reference_rays']} rays",
              title="error against bake time (labels: rays)")
    for a in ax:
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
