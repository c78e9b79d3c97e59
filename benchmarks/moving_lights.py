"""Lights between samples: error against frame time and bytes of each run-time interpolation (M-1..M-4, T-12).

    python benchmarks/moving_lights.py [--quick] [--mitsuba | --only-mitsuba] [--json PATH] [--device cpu|cuda]

Scenes: the Stanford bunny, spot and fandisk (tests/data), each on a 200 x 200 floor (quick: the bunny on 60 x 60), the
thesis material, SH order 4, light cut at 5 degrees (the bake's defaults), one vertex hierarchy per scene shared by
its bakes; light grids 2 x 1 x 2, 3 x 1 x 3 (the default) and 5 x 1 x 5 (quick: 3 x 1 x 3). Test lights: 6 (quick:
3) fixed random positions in the light box, each at least a quarter of the sample spacing from every sample. For
each interpolation (``Runtime(interpolation=...)``: "direct", the default; "direct-agree"; "direct-blend";
"thesis") and grid:

* ``rrmse``: per-vertex RMSE of the full-resolution radiance toward the eye (``Runtime.radiance``) against exact
  Phong with Embree visibility at the test light (float64, ``table1.exact_phong``), over the maximum of the exact
  radiance, on the referenced vertices facing the eye; ``off5``: the share of those vertices more than 5% of the
  maximum off. Baseline in the same run: the same numbers with the light on the grid's samples.
* ``psnr``: the full-mesh frame (per-vertex radiance, 400 x 300) against the exact per-vertex frame, display
  values (clipped at the white point).
* ``ms``, ``p95``: the default ``frames`` orbit (view cut, 800 x 600, 48 frames; quick 12) on the 3 x 1 x 3 store,
  every interpolation stepped in lockstep (``runtime.run_paths``), and the ratio to "thesis".
* ``bytes`` and ``bake_s``: the store's payload and bake time (one store serves every interpolation: the direct
  path reads nothing more from it).

``--mitsuba`` (``--only-mitsuba``: nothing else): the bunny on the thesis' 380 x 380 floor, diffuse (ks = 0), a
full-resolution store and light-cut stores at 5 and 30 degrees (one hierarchy), the light halfway between four
samples and on sample 4: the full-mesh frame of each interpolation (cut stores: "direct" and "thesis") against
Mitsuba 3's direct light (PSNR), moving_lights-mitsuba[-quick].json and a figure (moving_lights-mitsuba.png).
Writes benchmarks/results/moving_lights[-quick].json and .png (error against frame time and against bytes).
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, model, parser, plot_path, table, write
from runtime import run_paths, summary
from table1 import EYE_OFFSET, exact_phong

METHODS = ("direct", "direct-agree", "direct-blend", "thesis")
MODEL_FILES = {"bunny": "stanford-bunny", "spot": "spot", "fandisk": "fandisk"}


def model_scene(name: str, floor: int, grid, *, ks: float | None = None):
    """``name`` (MODEL_FILES) on a floor of ``floor`` x ``floor`` vertices under a ``grid`` of light samples."""
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    mat = THESIS_MATERIAL if ks is None else dataclasses.replace(THESIS_MATERIAL, ks=ks)
    pos, faces = load_mesh(model(MODEL_FILES[name]))
    return assemble_scene([(name, pos, faces, mat)], (floor, 1.0, mat), {"grid": list(grid)}, "lights",
                          f"{name} + {floor}x{floor} floor")


def eye_of(scene) -> np.ndarray:
    obj = scene.object_id == 0
    ext = float((scene.positions[obj].max(0) - scene.positions[obj].min(0)).max())
    return scene.positions[obj].mean(0) + EYE_OFFSET * ext


def test_lights(scene, count: int, seed: int = 2026) -> np.ndarray:
    """``count`` random lights in the box, each at least a quarter of the sample spacing from every sample."""
    box = np.asarray(scene.lights.box, np.float64)
    grid = np.asarray(scene.lights.grid)
    spacing = float(np.min(((box[3:] - box[:3]) / grid)[grid > 1])) if (grid > 1).any() else 1.0
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        p = box[:3] + rng.random(3) * (box[3:] - box[:3])
        if np.linalg.norm(scene.lights.positions - p, axis=1).min() >= 0.25 * spacing:
            out.append(p)
    return np.array(out)


def vertex_errors(rad, exact, sel) -> tuple[float, float]:
    """(RMSE over the maximum, share of vertices more than 5% of the maximum off) on ``sel``."""
    peak = max(float(exact[sel].max()), 1e-30)
    e = np.abs(rad[sel] - exact[sel]) / peak
    return float(np.sqrt(np.mean(e**2))), float(np.mean(e > 0.05))


def exact_frame(store, frame, exact):
    """``frame`` with the exact per-vertex radiance (as a view-independent y_0 term)."""
    y0 = 0.28209479177387814
    rad = np.repeat(exact[frame.vertex_ids, None], 3, axis=1).astype(np.float32)
    return dataclasses.replace(frame, coefficients=(rad / y0)[:, :, None].astype(np.float32), radiance=rad)


def measure_grid(scene, store, renderer, cameras, device: str, lights) -> list[dict]:
    """Per interpolation: vertex errors and frame PSNR over the test lights, and on the samples (baseline)."""
    from lodprt.precompute import reference
    from lodprt.runtime.session import Runtime
    from lodprt.display.compare import frame_error

    caster = reference.EmbreeCaster(scene)
    offset = float(store.attrs["ray_offset"])
    eye, cam = cameras
    sel = scene.referenced & (((eye - scene.positions) * scene.normals).sum(1) > 0)
    exact = [exact_phong(scene, p, eye, caster, offset)[0] for p in lights]
    on = store.light_positions.astype(np.float64)[: min(store.num_samples, 4)]
    exact_on = [exact_phong(scene, p, eye, caster, offset)[0] for p in on]
    rows = []
    for method in METHODS:
        rt = Runtime(store, device=device, lod=False, interpolation=method)
        rt.set_camera(cam)
        errs, offs, psnrs, on_errs = [], [], [], []
        for p, ex in zip(lights, exact):
            rt.set_lights(p[None], colors=np.ones(3))
            rad = rt.radiance(eye)[:, 0].astype(np.float64)
            e, o = vertex_errors(rad, ex, sel)
            errs.append(e)
            offs.append(o)
            fr = rt.update()
            white = float(np.percentile(ex[sel], 99))
            psnrs.append(frame_error(renderer, fr, exact_frame(store, fr, ex), white, per_vertex=True)[0]["psnr_db"])
        for p, ex in zip(on, exact_on):
            rt.set_lights(p[None], colors=np.ones(3))
            on_errs.append(vertex_errors(rt.radiance(eye)[:, 0].astype(np.float64), ex, sel)[0])
        rows.append({"method": method, "rrmse": float(np.median(errs)), "rrmse_worst": float(np.max(errs)),
                     "off5": float(np.median(offs)), "off5_worst": float(np.max(offs)),
                     "psnr_db": float(np.median(psnrs)), "psnr_worst_db": float(np.min(psnrs)),
                     "rrmse_on_samples": float(np.median(on_errs)), "rrmse_all": errs, "off5_all": offs})
    return rows


def frame_times(store, device: str, frames: int) -> dict:
    """The default orbit with the view cut, every interpolation in lockstep: per-method summaries."""
    from lodprt.runtime.session import Runtime

    rts = {m: Runtime(store, device=device, interpolation=m) for m in METHODS}
    out = run_paths(rts, "orbit", frames)
    rays = {m: float(np.median([rt.lighting.rays for rt in [rts[m]]])) for m in METHODS}
    return {m: {**summary(rows), "shadow_rays_last": rays[m]} for m, rows in out.items()}


def run_scene(name: str, floor: int, grids, count: int, frames: int, device: str, tmp: Path, renderer) -> list[dict]:
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.precompute.bake import bake
    from lodprt.runtime.camera import Camera
    from lodprt.store.bake_store import open_store

    base = model_scene(name, floor, (3, 1, 3))
    t = time.perf_counter()
    tree = build_hierarchy(base.positions, base.faces, base.normals)
    print(f"{base.source}: {base.num_vertices:,} vertices, hierarchy in {time.perf_counter() - t:.1f} s", flush=True)
    eye = eye_of(base)
    c = base.positions[base.object_id == 0].mean(0)
    cam = Camera(eye=tuple(eye), target=tuple(c), fov=40.0, width=400, height=300)
    lights = test_lights(base, count)
    rows = []
    for n in grids:
        scene = model_scene(name, floor, (n, 1, n))
        out = tmp / f"{name}-{n}.zarr"
        res = bake(scene, out, sh_order=4, device=device, tree=tree, threshold_deg=5.0)
        store = open_store(out)
        size = sum(s["bytes"] for s in res.samples)
        times = frame_times(store, device, frames) if n == 3 else None
        for r in measure_grid(scene, store, renderer, (eye, cam), device, lights):
            r.update({"scene": name, "grid": f"{n}x1x{n}", "samples": n * n, "bytes": size,
                      "bake_s": res.bake_seconds})
            if times:
                t = times[r["method"]]
                r.update({"ms": t["median_ms_total"], "p95_ms": t["p95_ms_total"],
                          "ms_relight": t["median_ms_relight"],
                          "ms_ratio": t["median_ms_total"] / times["thesis"]["median_ms_total"]})
            rows.append(r)
            print(f"  {name} {r['grid']} {r['method']:>12}: rRMSE {r['rrmse']:.4f} (on samples "
                  f"{r['rrmse_on_samples']:.4f}), >5% {r['off5']:.3f}, PSNR {r['psnr_db']:.1f} dB"
                  + (f", {r['ms']:.1f} ms/frame ({r['ms_ratio']:.2f}x thesis)" if times else ""), flush=True)
        del store
        shutil.rmtree(out)
    return rows


#: the light cuts (degrees) whose stores the Mitsuba check renders besides the full-resolution store, and the
#: interpolations it draws them with (the default, and T-12 which reads the cut's samples)
MITSUBA_CUTS, CUT_METHODS = (5.0, 30.0), ("direct", "thesis")


def mitsuba_check(device: str, tmp: Path, quick: bool) -> dict:
    """The full-mesh frame of each interpolation against Mitsuba 3's direct light, light between samples and on
    one, the bunny on the thesis' floor (diffuse): from the full-resolution store (keys ``case/method``) and from
    light-cut stores at MITSUBA_CUTS degrees (``case/method@deg``) sharing its hierarchy."""
    from mitsuba_ref import mitsuba_image, psnr
    from lodprt.display.render import Renderer
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.precompute.bake import bake
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    floor = 100 if quick else 380
    scene = model_scene("bunny", floor, (3, 1, 3), ks=0.0)
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    stores = {}
    for thr in (None,) + MITSUBA_CUTS:
        path = tmp / f"mitsuba-{thr}.zarr"
        bake(scene, path, sh_order=4, device=device, threshold_deg=thr, tree=tree)
        stores[thr] = open_store(path)
    eye, target, fov, size, ss = eye_of(scene), scene.positions[scene.object_id == 0].mean(0), 40.0, (320, 240), 3
    samples = stores[None].light_positions.astype(np.float64)
    cases = {"between": samples[[0, 1, 3, 4]].mean(0), "on sample 4": samples[4]}
    out, images = {"floor": floor, "eye": eye.tolist(), "lights": {k: v.tolist() for k, v in cases.items()},
                   "cuts": list(MITSUBA_CUTS)}, {}
    cam = Camera(eye=tuple(eye), target=tuple(target), fov=fov, width=size[0] * ss, height=size[1] * ss)
    with Renderer() as r:
        for case, light in cases.items():
            ref = mitsuba_image(scene, light, scene.lights.intensity, 0, size, 64, tmp, camera=(eye, target, fov))
            white = float(np.percentile(ref[ref.max(2) > 0].max(1), 99))
            images[(case, "Mitsuba 3")] = ref
            for thr, store in stores.items():
                for method in METHODS if thr is None else CUT_METHODS:
                    rt = Runtime(store, device=device, lod=False, interpolation=method)
                    rt.set_lights(light[None])
                    rt.set_camera(cam)
                    img = r.image(rt.update(), camera=cam, linear=True, light_markers=False).astype(np.float64)
                    img = img.reshape(size[1], ss, size[0], ss, 3).mean((1, 3))
                    key = f"{case}/{method}" + ("" if thr is None else f"@{thr:g}")
                    out[key] = psnr(img, ref, white)
                    if thr is None:
                        images[(case, method)] = img
                    print(f"  Mitsuba 3, light {case}: {key.split('/')[1]} {out[key]:.1f} dB", flush=True)
    mitsuba_figure(images, out, cases, white, "moving_lights-mitsuba" + ("-quick" if quick else ""))
    return out


def mitsuba_figure(images, out, cases, white, name) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = ("Mitsuba 3",) + METHODS
    fig, axes = plt.subplots(len(cases), len(cols), figsize=(3.2 * len(cols), 3.0 * len(cases)))
    for i, case in enumerate(cases):
        for j, col in enumerate(cols):
            ax = axes[i, j]
            ax.imshow(np.clip(images[(case, col)] / white, 0, 1) ** (1 / 2.2))
            sub = "" if col == "Mitsuba 3" else f" {out[f'{case}/{col}']:.1f} dB"
            ax.set_title(f"{col}, light {case}{sub}", fontsize=8)
            ax.axis("off")
    fig.suptitle("Full-mesh frame against Mitsuba 3's direct light (bunny, diffuse, full-resolution store)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=100)
    print("wrote", plot_path(name))


def plot(rows, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    timed = [r for r in rows if "ms" in r]
    scenes = sorted({r["scene"] for r in rows})
    for k, (m, mark) in enumerate(zip(METHODS, "os^v")):
        colour = f"C{k}"
        t = [r for r in timed if r["method"] == m]
        axes[0].plot([r["ms"] for r in t], [r["rrmse"] for r in t], mark, color=colour, label=m)
        for r in t:
            axes[0].annotate(r["scene"], (r["ms"], r["rrmse"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
        for scene, style in zip(scenes, ("-", "--", ":")):
            s = sorted((r for r in rows if r["method"] == m and r["scene"] == scene), key=lambda r: r["bytes"])
            axes[1].plot([r["bytes"] / 2**20 for r in s], [r["rrmse"] for r in s], mark + style, color=colour,
                         alpha=0.8, label=f"{m}, {scene}" if m == METHODS[0] or scene == scenes[0] else None)
    axes[0].set_xlabel("frame time, default orbit (ms, median)")
    axes[1].set_xlabel("store payload (MiB; grids 2x1x2, 3x1x3, 5x1x5)")
    axes[1].set_xscale("log")
    for ax in axes:
        ax.set_ylabel("rRMSE of the maximum, lights between samples")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Lights between samples against exact Phong (Embree visibility): error, frame time and bytes",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=110)
    print("wrote", plot_path(name))


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--mitsuba", action="store_true", help="also compare full-mesh frames with Mitsuba 3")
    p.add_argument("--only-mitsuba", action="store_true", help="only the Mitsuba 3 comparison")
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.display.render import Renderer

    device = resolve_device(args.device)
    scenes = ["bunny"] if args.quick else ["bunny", "spot", "fandisk"]
    floor, grids = (60, [3]) if args.quick else (200, [2, 3, 5])
    count, frames = (3, 12) if args.quick else (6, 48)
    tmp = Path(tempfile.mkdtemp(prefix="lodprt-moving-"))
    rows, mitsuba = [], None
    suffix = "-quick" if args.quick else ""
    try:
        if not args.only_mitsuba:
            with Renderer() as renderer:
                for name in scenes:
                    rows += run_scene(name, floor, grids, count, frames, device, tmp, renderer)
        if args.mitsuba or args.only_mitsuba:
            mitsuba = mitsuba_check(device, tmp, args.quick)
            print("wrote", write("moving_lights-mitsuba" + suffix, {"benchmark": "moving_lights", "quick": args.quick,
                                                                   "environment": environment(device),
                                                                   "mitsuba": mitsuba}, None))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.only_mitsuba:
        return
    print(table(rows, [("scene", "scene", "s"), ("grid", "grid", "s"), ("method", "interpolation", "s"),
                       ("rrmse", "rRMSE", ".4f"), ("rrmse_worst", "worst light", ".4f"),
                       ("rrmse_on_samples", "on samples", ".4f"), ("off5", ">5% off", ".3f"),
                       ("psnr_db", "PSNR dB", ".1f"), ("ms", "ms/frame", ".1f"), ("p95_ms", "p95 ms", ".1f"),
                       ("ms_ratio", "x thesis", ".2f"), ("bytes", "bytes", ",d"), ("bake_s", "bake s", ".1f")]))
    name = "moving_lights" + suffix
    print("wrote", write(name, {"benchmark": "moving_lights", "quick": args.quick, "floor": floor,
                                "environment": environment(device), "rows": rows}, args.json))
    plot(rows, name)


if __name__ == "__main__":
    main()
