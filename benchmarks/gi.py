"""Interreflection in the point-light bake: LOD GI bake against the full-resolution GI bake, and against Mitsuba 3.

    python benchmarks/gi.py [--quick] [--mitsuba] [--json PATH] [--device cpu|cuda]
    python benchmarks/gi.py --floors [--quick] [--repeats 5] [--tolerances 0.01 0.02 1]

Scene: the Stanford bunny on a floor, both diffuse white (kd 0.8, ks 0). For each bounce count 0..3 and
gathering ray count, in the same run: the full-resolution GI bake and the LOD GI bake (light cut --threshold-deg
plus the indirect cut --indirect-threshold-deg), their bake times (ratio), and the rel-RMSE of their completed
per-vertex radiance against a converged reference (full resolution, many rays, the same bounce count) and against
each other. ``--mitsuba`` also renders one light sample with lodprt's renderer and with Mitsuba 3's ``path``
integrator (same geometry, point light, camera; ``pip install 'lodprt[reference]'``) and reports PSNR and the mean
radiance inside the direct shadows. Writes benchmarks/results/gi[-quick].json, .png and gi-mitsuba[-quick].png.

``--floors`` instead: the bunny on floors of 60, 200 and 400 quads a side, 2 bounces, default rays (64), 2 x 1 x 2
lights; per floor, in the same run, the full-resolution GI bake, the LOD bake with the geometric indirect cut (G-5,
--indirect-threshold-deg) and with the error-driven one (G-9) at each of ``--tolerances``: bake time, its ratio to
the full bake's, gathering vertices per pass and the rel-RMSE of the completed radiance against the full bake (all
vertices, the bunny's, the floor's). The full bake and every cut run ``--repeats`` rounds, interleaved (this
machine's speed drifts by 10-20 % between minutes): times are medians, the ratio is the median of the rounds' ratios
with its least and largest beside it; the bakes are seeded, so every round's values must agree (checked). Then, per
floor, G-9's stated error against the error it leaves on one indirect pass (``estimate_check``: 1 bounce, the
tolerances and 0.003; per light sample, the RMS difference of the LOD and full completed radiance against
``tau L_rms``, and how much of it lies where the full pass gathers no light at all).
Writes benchmarks/results/gi-floors[-quick].json.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, model, parser, plot_path, table, write
from mitsuba_ref import mitsuba_image, psnr, require_mitsuba

KD = 0.8
#: the light of the Mitsuba comparison and the camera (scene units of the bunny, about 0.15 across)
MITSUBA_LIGHT = (0.09, 0.30, 0.12)
#: the least tolerance of the floor sweep's check of G-9's stated error (``estimate_check``), below the sweep's
CHECK_TOLERANCE = 0.003
EYE, TARGET, FOV = (-0.05, 0.16, 0.32), (-0.02, 0.07, 0.0), 40.0


def gi_scene(floor_res: int, grid, box=None):
    from lodprt.model.scene import Material, assemble_scene, load_mesh

    pos, faces = load_mesh(model("stanford-bunny"))
    white = Material((KD, KD, KD), 0.0, 1.0)
    lights = {"grid": list(grid)} if box is None else {"grid": list(grid), "box": list(box)}
    return assemble_scene([("bunny", pos, faces, white)], (floor_res, 1.0, white), lights, "lights",
                          f"stanford-bunny + {floor_res}x{floor_res} floor, diffuse kd {KD}")


def completed(path: Path, referenced: np.ndarray) -> np.ndarray:
    """(S, V') completed y_0 coefficient of every referenced vertex of every sample of the store at ``path``."""
    from lodprt.store.bake_store import open_store

    store = open_store(path)
    return np.stack([store.coefficients(k)[referenced, 0, 0] for k in range(store.num_samples)])


def rel_rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2)))


def reference(scene, rays: int, bounces: int, device: str) -> list[np.ndarray]:
    """Converged references: per bounce count 0..bounces, (S, V') y_0 of the full-resolution GI radiance."""
    from lodprt.devices import load_kernels
    from lodprt.precompute.baker import Baker, bake_kernels
    from lodprt.precompute.gi import GISettings, attach, constant_coefficient

    load_kernels(device, *bake_kernels())
    baker = Baker(scene, 2, device, np.flatnonzero(scene.referenced).astype(np.int32))
    gi = attach(baker, scene, GISettings(bounces=bounces, threshold=0.0, rays=rays, seed=12345))
    per_light = [np.cumsum(gi.pass_radiance(light), axis=0)[:, scene.referenced, 0] for light in scene.lights.positions]
    return [constant_coefficient() * np.stack([p[min(b, len(p) - 1)] for p in per_light]) for b in range(bounces + 1)]


def sweep(scene, tree, args, tmp: Path) -> list[dict]:
    from lodprt.precompute.bake import bake

    ref_b = reference(scene, args.reference_rays, max(args.bounces), args.device)
    rows = []
    for b in args.bounces:
        for rays in (args.rays if b else args.rays[:1]):
            common = dict(sh_order=2, device=args.device, tree=tree, bounces=b, gi_rays=rays)
            full = bake(scene, tmp / "full.zarr", threshold_deg=None, overwrite=True, **common)
            lod = bake(scene, tmp / "lod.zarr", threshold_deg=args.threshold_deg, overwrite=True,
                       indirect_threshold_deg=args.indirect_threshold_deg, **common)
            cf, cl = completed(tmp / "full.zarr", scene.referenced), completed(tmp / "lod.zarr", scene.referenced)
            import zarr

            gathered = zarr.open_group(str(tmp / "lod.zarr"), mode="r").attrs.get("indirect_gather_vertices")
            rows.append({"bounces": b, "rays": rays, "full_s": full.bake_seconds, "lod_s": lod.bake_seconds,
                         "ratio": lod.bake_seconds / full.bake_seconds,
                         "kept": float(np.mean([s["vertices_kept"] for s in lod.samples])),
                         "gathered": gathered if b else 0,
                         "full_err": rel_rmse(cf, ref_b[b]), "lod_err": rel_rmse(cl, ref_b[b]),
                         "lod_vs_full": rel_rmse(cl, cf)})
            r = rows[-1]
            print(f"  bounces {b} rays {rays}: full {r['full_s']:.2f} s, LOD {r['lod_s']:.2f} s ({r['ratio']:.3f}), "
                  f"errors {r['full_err']:.4f} / {r['lod_err']:.4f}, LOD vs full {r['lod_vs_full']:.4f}", flush=True)
    return rows


def same_values(a: dict, b: dict) -> bool:
    """Whether two rounds of one cut gathered at the same vertices and agree in every error (to 1e-6)."""
    return a["gathered"] == b["gathered"] and all(abs(a[k] - b[k]) <= 1e-6 * abs(a[k]) for k in a if k != "gathered")


def floor_sweep(args) -> list[dict]:
    """Full vs LOD GI bakes (G-5 and G-9) on growing floors, 2 bounces, default rays (module docstring): per floor,
    ``args.repeats`` rounds of the full bake then every cut, interleaved so that a slow spell of the machine falls on
    both; times are medians, the ratio the median of each round's ratio (its range beside it)."""
    import zarr

    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.precompute.bake import bake

    rows, checks = [], []
    for floor in args.floors:
        scene = gi_scene(floor, (1, 1, 1) if args.quick else (2, 1, 2))
        tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
        bunny = scene.object_id[scene.referenced] == 0
        tmp = Path(tempfile.mkdtemp(prefix="lodprt-gi-floor-"))
        cuts = [("G-5", {"indirect_threshold_deg": args.indirect_threshold_deg}, args.indirect_threshold_deg)]
        cuts += [("G-9", {"indirect_tolerance": t}, t) for t in args.tolerances]
        full_s, lod_s, found = [], [[] for _ in cuts], [None] * len(cuts)
        try:
            common = dict(sh_order=2, device=args.device, tree=tree, bounces=2, overwrite=True)
            for rep in range(args.repeats):
                full_s.append(bake(scene, tmp / "full.zarr", threshold_deg=None, **common).bake_seconds)
                cf = completed(tmp / "full.zarr", scene.referenced)
                for i, (cut, kw, value) in enumerate(cuts):
                    lod = bake(scene, tmp / "lod.zarr", threshold_deg=args.threshold_deg, **common, **kw)
                    lod_s[i].append(lod.bake_seconds)
                    cl = completed(tmp / "lod.zarr", scene.referenced)
                    norm = float(np.mean(cf**2))
                    part = lambda m: float(np.sqrt(np.mean((cl[:, m] - cf[:, m]) ** 2) * m.mean() / norm))  # noqa: E731
                    errors = {"gathered": zarr.open_group(str(tmp / "lod.zarr"), mode="r").attrs.get(
                                  "indirect_gather_vertices"),
                              "lod_vs_full": rel_rmse(cl, cf), "bunny_part": part(bunny), "floor_part": part(~bunny)}
                    if found[i] is not None and not same_values(found[i], errors):  # seeded: every round the same
                        raise SystemExit(f"floor {floor} {cut} {value}: round {rep} baked other values: {errors} "
                                         f"against {found[i]}")
                    found[i] = errors
                    print(f"  floor {floor} round {rep} {cut} {value}: full {full_s[-1]:.2f} s, LOD "
                          f"{lod.bake_seconds:.2f} s ({lod.bake_seconds / full_s[-1]:.3f}), {errors['gathered']:,} "
                          f"gathered, LOD vs full {errors['lod_vs_full']:.4f} (bunny {errors['bunny_part']:.4f}, "
                          f"floor {errors['floor_part']:.4f})", flush=True)
            checks += estimate_check(scene, floor, sorted({CHECK_TOLERANCE, *args.tolerances}), common, tmp)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        for i, (cut, _kw, value) in enumerate(cuts):
            ratios = np.array(lod_s[i]) / np.array(full_s)
            rows.append({"floor": floor, "vertices": int(scene.referenced.sum()), "cut": cut, "setting": value,
                         "full_s": float(np.median(full_s)), "lod_s": float(np.median(lod_s[i])),
                         "ratio": float(np.median(ratios)), "ratio_min": float(ratios.min()),
                         "ratio_max": float(ratios.max()), "rounds": args.repeats, **found[i]})
    return rows, checks


def estimate_check(scene, floor: int, tolerances, common: dict, tmp: Path) -> list[dict]:
    """G-9's stated error against the error it leaves, on the first indirect pass (1 bounce): per tolerance and
    light sample, the RMS difference of the completed radiance of the LOD and the full bake (the direct term is
    the same in both, so it is the pass' error) over the referenced vertices, against what G-9 states for the
    pass, ``tau L_rms`` (L_rms the RMS of the sample's direct radiance), and the share of the squared error on the
    vertices the full pass gives no indirect light at all."""
    from lodprt.precompute.bake import bake

    one = {**common, "bounces": 1}
    bake(scene, tmp / "direct.zarr", threshold_deg=None, **{**common, "bounces": 0})
    direct = completed(tmp / "direct.zarr", scene.referenced)
    bake(scene, tmp / "full1.zarr", threshold_deg=None, **one)
    full = completed(tmp / "full1.zarr", scene.referenced)
    dark = full == direct  # (S, V'): no indirect light reaches the vertex in the full pass
    l_rms = np.sqrt(np.mean(direct**2, axis=1))
    out = []
    for tol in tolerances:
        bake(scene, tmp / "lod1.zarr", threshold_deg=0.0, indirect_tolerance=tol, **one)
        d2 = (completed(tmp / "lod1.zarr", scene.referenced) - full) ** 2
        actual = np.sqrt(d2.mean(axis=1))
        ratio = actual / (tol * l_rms)
        out.append({"floor": floor, "tolerance": tol, "stated_max": float((tol * l_rms).max()),
                    "actual_max": float(actual.max()), "over_min": float(ratio.min()), "over_max": float(ratio.max()),
                    "dark_share": float((d2 * dark).sum() / max(d2.sum(), 1e-300))})
        r = out[-1]
        print(f"  floor {floor} G-9 {tol}: first pass' RMS error {r['over_min']:.2f}-{r['over_max']:.2f} x the "
              f"stated tau L_rms, {r['dark_share']:.0%} of it where the full pass is dark", flush=True)
    return out


def floors_main(args) -> None:
    args.floors = [20, 40] if args.quick else [60, 200, 400]
    rows, checks = floor_sweep(args)
    print(table(rows, [("floor", "floor", "d"), ("vertices", "vertices", ",d"), ("cut", "cut", "s"),
                       ("setting", "setting", "g"), ("full_s", "full s", ".2f"), ("lod_s", "LOD s", ".2f"),
                       ("ratio", "LOD/full", ".3f"), ("ratio_min", "min", ".3f"), ("ratio_max", "max", ".3f"),
                       ("gathered", "gathered", ",d"),
                       ("lod_vs_full", "LOD vs full", ".4f"), ("bunny_part", "bunny", ".4f"),
                       ("floor_part", "floor", ".4f")]))
    name = "gi-floors" + ("-quick" if args.quick else "")
    results = {"benchmark": "gi", "quick": args.quick, "environment": environment(args.device),
               "settings": {"bounces": 2, "gi_rays": 64, "threshold_deg": args.threshold_deg,
                            "indirect_threshold_deg": args.indirect_threshold_deg, "tolerances": args.tolerances,
                            "lights": "1 x 1 x 1" if args.quick else "2 x 1 x 2", "kd": KD,
                            "rounds": args.repeats},
               "rows": rows, "estimate_check": checks}
    print(table(checks, [("floor", "floor", "d"), ("tolerance", "G-9", "g"), ("stated_max", "stated RMS (max)", ".4g"),
                         ("actual_max", "actual RMS (max)", ".4g"), ("over_min", "actual / stated min", ".2f"),
                         ("over_max", "max", ".2f"), ("dark_share", "share where the full pass is dark", ".2f")]))
    print("wrote", write(name, results, args.json))


# -- Mitsuba 3 --------------------------------------------------------------------------------------------------


def lodprt_image(store_path: Path, size, supersample: int = 4) -> np.ndarray:
    """Linear RGB (H, W, 3) of sample 0 by lodprt's renderer, ``supersample``^2 pixels averaged per pixel (as the
    path tracer's box filter averages over the pixel)."""
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.frames import full_frame
    from lodprt.store.bake_store import open_store

    w, h = size
    cam = Camera(eye=EYE, target=TARGET, fov=FOV, width=w * supersample, height=h * supersample)
    store = open_store(store_path)
    with Renderer() as r:
        img = r.image(full_frame(store, cam, sample=0), camera=cam, linear=True, light_markers=False).astype(np.float64)
    return img.reshape(h, supersample, w, supersample, 3).mean((1, 3))


def mitsuba_check(args, tmp: Path) -> dict:
    """The done-when comparison: bunny + floor, 2 bounces, one light, against Mitsuba's path tracer."""
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.precompute.bake import bake

    require_mitsuba()
    eps = 1e-4
    box = [c - eps for c in MITSUBA_LIGHT] + [c + eps for c in MITSUBA_LIGHT]
    scene = gi_scene(args.mitsuba_floor, (1, 1, 1), box)
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    size, B = tuple(args.mitsuba_size), 2
    out = {"scene": scene.source, "vertices": int(scene.referenced.sum()), "size": list(size), "spp": args.spp,
           "eye": EYE, "target": TARGET, "fov": FOV, "light": MITSUBA_LIGHT}
    images = {}
    for label, b, thr in [("direct", 0, None), ("gi_full", B, None), ("gi_lod", B, args.threshold_deg)]:
        t = time.perf_counter()
        res = bake(scene, tmp / f"{label}.zarr", sh_order=2, device=args.device, tree=tree, bounces=b,
                   gi_rays=args.mitsuba_rays, threshold_deg=thr, indirect_threshold_deg=args.indirect_threshold_deg,
                   overwrite=True)
        out[f"{label}_bake_s"] = res.bake_seconds
        images[label] = lodprt_image(tmp / f"{label}.zarr", size)
        print(f"  lodprt {label}: bake {res.bake_seconds:.1f} s, rendered in {time.perf_counter() - t:.1f} s", flush=True)
    t = time.perf_counter()
    ref = mitsuba_image(scene, MITSUBA_LIGHT, scene.lights.intensity, B, size, args.spp, tmp, camera=(EYE, TARGET, FOV))
    out["mitsuba_s"] = time.perf_counter() - t
    # direct light from a point light is noise-free but for the pixel filter: few samples find the shadows
    direct_ref = mitsuba_image(scene, MITSUBA_LIGHT, scene.lights.intensity, 0, size, 16, tmp, camera=(EYE, TARGET, FOV))
    white = float(np.percentile(ref[ref.max(2) > 0], 99.5))
    fg = ref.max(2) > 0
    shadow = fg & (images["direct"].max(2) <= 0) & (direct_ref.max(2) <= 1e-3 * white)  # both say: direct shadow
    out.update(white=white, shadow_pixels=int(shadow.sum()), foreground_pixels=int(fg.sum()))
    for label, img in images.items():
        out[f"{label}_psnr"] = psnr(img, ref, white)
        out[f"{label}_psnr_foreground"] = psnr(img, ref, white, fg)
        m, r = img[shadow].mean(), ref[shadow].mean()
        out[f"{label}_shadow_mean_rel"] = float(m / r - 1) if r > 0 else float("nan")
    out["mitsuba_direct_vs_lodprt_direct_psnr"] = psnr(images["direct"], direct_ref, white)
    _mitsuba_figure(images, ref, white, shadow, out, "gi-mitsuba" + ("-quick" if args.quick else ""))
    return out


def _mitsuba_figure(images, ref, white, shadow, out, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("Mitsuba 3 path, max_depth 4", ref), ("lodprt direct only", images["direct"]),
              ("lodprt 2 bounces, full", images["gi_full"]), ("lodprt 2 bounces, LOD", images["gi_lod"])]
    fig, axes = plt.subplots(1, 5, figsize=(17, 3.4))
    for ax, (title, img) in zip(axes, panels):
        ax.imshow(np.clip(img / white, 0, 1) ** (1 / 2.2))
        key = {"lodprt direct only": "direct", "lodprt 2 bounces, full": "gi_full", "lodprt 2 bounces, LOD": "gi_lod"}
        sub = f"\n{out[key[title] + '_psnr']:.1f} dB" if title in key else ""
        ax.set_title(title + sub, fontsize=9)
        ax.axis("off")
    axes[4].imshow(shadow, cmap="gray")
    axes[4].set_title("direct-shadow pixels", fontsize=9)
    axes[4].axis("off")
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=110)
    print("wrote", plot_path(name))


def plot(rows, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for b in sorted({r["bounces"] for r in rows}):
        sel = [r for r in rows if r["bounces"] == b]
        ax.plot([r["full_s"] for r in sel], [r["full_err"] for r in sel], "o-", color=f"C{b}", label=f"{b} bounces, full")
        ax.plot([r["lod_s"] for r in sel], [r["lod_err"] for r in sel], "s--", color=f"C{b}", label=f"{b} bounces, LOD")
        for r in sel:
            ax.annotate(f"{r['rays']}", (r["lod_s"], r["lod_err"]), fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("bake seconds (light samples; labels: rays per vertex)")
    ax.set_ylabel("rel-RMSE of completed radiance vs converged reference")
    ax.set_title("GI bake: error against time")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--mitsuba", action="store_true", help="also compare one light sample with Mitsuba 3's path tracer")
    p.add_argument("--threshold-deg", type=float, default=0.0, help="light cut of the LOD bakes (default 0: the direct "
                   "term costs one shadow ray per vertex; the LOD saves on the indirect passes)")
    p.add_argument("--indirect-threshold-deg", type=float, default=20.0, help="indirect cut (default 20)")
    p.add_argument("--floors", action="store_true", help="only the floor sweep: full vs LOD (G-5 and G-9) on floors "
                   "of 60, 200 and 400, 2 bounces, default rays (gi-floors.json)")
    p.add_argument("--repeats", type=int, default=5, help="floor sweep: rounds of the full bake and every cut, "
                   "interleaved; medians reported (default 5)")
    p.add_argument("--tolerances", type=float, nargs="+", default=[0.01, 0.0125, 0.014, 0.015, 0.02, 1.0],
                   help="G-9 tolerances of the floor sweep (default 0.01 0.0125 0.014 0.015 0.02 1; 1 is the coarsest "
                   "cut: the cost of everything but the gathering)")
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.model.hierarchy_build import build_hierarchy

    args.device = resolve_device(args.device)
    if args.floors:
        floors_main(args)
        return
    q = args.quick
    args.bounces = [0, 1, 2, 3]
    args.rays = [16] if q else [32, 128]
    args.reference_rays = 64 if q else 256
    args.mitsuba_floor, args.mitsuba_rays = (40, 32) if q else (120, 128)
    args.mitsuba_size, args.spp = ((160, 120), 16) if q else ((320, 240), 512)
    scene = gi_scene(20 if q else 60, (1, 1, 1) if q else (2, 1, 2))
    t = time.perf_counter()
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    print(f"{scene.source}: {int(scene.referenced.sum()):,} vertices, {len(scene.lights.positions)} light samples, "
          f"hierarchy {time.perf_counter() - t:.1f} s, device {args.device}", flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="lodprt-gi-"))
    try:
        rows = sweep(scene, tree, args, tmp)
        mitsuba = mitsuba_check(args, tmp) if args.mitsuba else None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(table(rows, [("bounces", "bounces", "d"), ("rays", "rays", "d"), ("full_s", "full s", ".2f"),
                       ("lod_s", "LOD s", ".2f"), ("ratio", "LOD/full", ".3f"), ("kept", "kept/sample", ",.0f"),
                       ("gathered", "gathered", ",d"), ("full_err", "full err", ".4f"), ("lod_err", "LOD err", ".4f"),
                       ("lod_vs_full", "LOD vs full", ".4f")]))
    if mitsuba:
        for k, v in mitsuba.items():
            print(f"  mitsuba {k}: {v}")
    name = "gi" + ("-quick" if q else "")
    results = {"benchmark": "gi", "quick": q, "scene": scene.source, "environment": environment(args.device),
               "settings": {"threshold_deg": args.threshold_deg, "indirect_threshold_deg": args.indirect_threshold_deg,
                            "reference_rays": args.reference_rays, "kd": KD},
               "rows": rows, "mitsuba": mitsuba}
    print("wrote", write(name, results, args.json))
    plot(rows, name)


if __name__ == "__main__":
    main()
