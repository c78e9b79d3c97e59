"""Run time: per-frame cost of the view-dependent cut with moving lights, against relighting the full mesh.

    python benchmarks/runtime.py [--quick] [--json PATH] [--store OUT.zarr] [--device cpu|cuda]

Scene: the Stanford bunny on a 380 x 380 floor, 3 x 1 x 3 light samples, SH order 4, light cut at 30
degrees (the thesis' setting for its run-time figures 21-24), baked here into a temporary store unless --store
names one (quick: 100 x 100 floor, 2 x 1 x 1 samples, short paths).

1. Camera paths (``lodprt.runtime.camera_path``): an orbit and a dolly, each with a light circling inside the
   sampled region, 800 x 600 screen, three view cuts: the thesis criterion (T-14, error bound 0.25, alpha 0.6),
   the default (the "screen" criterion steered toward its frame target, E-1..E-4) and the "screen" criterion at a
   fixed 0.8. Per frame: ``Runtime.update()`` split into cut update,
   triangulation and relighting (ms), and triangles; summed up as the median frame and the mean frame (the mean
   counts the frames that estimate the frame's error, E-1, every few frames, which the median leaves out). Baseline in the same run: the same paths with LOD off (the
   full mesh relit every frame by the same kernel). The four are stepped in lockstep, frame by frame, so that
   the machine's slow spells fall on all of them (``run_paths``).
2. The issue's yardstick as a user meets it: ``lodprt frames STORE --json`` (the default orbit, 120 frames at 800 x
   600) against ``lodprt frames STORE --full --json``, each command in a fresh process, ``CLI_PAIRS`` pairs taking
   turns at going first (``cli_pairs``), on this store and on the README's demo store (``lodprt bake demo``, every
   setting at its default); per pair the median and mean ms per frame after the first, as each command's summary
   reports them, and their ratios. A process that relights only the full mesh keeps its own memory state (the
   lockstep of 1. interleaves four), so its frame time can differ from 1.'s.
3. Error-bound sweep of the thesis criterion, 0.2, 0.25, 0.315, 0.4 at alpha 0.6, over the orbit (120 frames; quick: 40): median
   triangles beside the thesis' figures 21-24, median frame time (``stats["ms_total"]`` of ``Runtime.update()``,
   as in 1.: the rendering below is not timed), and the error of the frame against the full-resolution frame:
   both drawn by ``lodprt.render.Renderer`` as linear radiance images (every 10th frame, 400 x 300) and compared
   over the pixels either covers (relative RMSE and the 99th percentile of the per-pixel relative error).
4. Frame-time budgets (B-2, ``Runtime(frame_ms=...)``, ``--frame-ms``): the default over the orbit (120 frames;
   quick: 40) without a budget and under budgets of the full mesh's median frame (from 1.) / 4 and / 5, stepped in
   lockstep with the full mesh; per run the median and mean ms, their ratios to the full mesh's in the same
   lockstep, the share of frames in motion without an estimate that met the budget, median triangles, and the
   image error against the full-mesh frame of the same camera and lights (both drawn at 800 x 600, PSNR clipped
   at white, every 10th frame), beside E-3's estimate.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write
from lodprt.runtime import Runtime

THESIS_TRIANGLES = {0.2: 13335, 0.25: 9115, 0.315: 5742, 0.4: 2799}
KEYS = ("ms_cut", "ms_triangulate", "ms_relight", "ms_total", "triangles", "nodes_touched")
#: 2.: pairs of ``lodprt frames`` and ``lodprt frames --full`` per store, each command in a fresh process
CLI_PAIRS = 2


def build_store(quick: bool, folder: Path, device: str) -> Path:
    from lodprt.precompute.bake import bake

    path = folder / "runtime-bench.zarr"
    bake(thesis_scene(quick=quick), path, sh_order=4, device=device, threshold_deg=30.0)
    return path


def run_paths(rts: dict, path: str, frames: int) -> dict:
    """Per-frame stats of each Runtime of ``rts`` (name -> Runtime) along one camera path, stepped in lockstep: at
    every frame each Runtime updates for the same camera and lights in turn, so that a slow spell of the machine
    falls on all of them alike and the ratios compare like with like (the first frame, which converges from the
    base, is kept apart by ``summary``)."""
    from lodprt.runtime.camera import camera_path

    out = {name: [] for name in rts}
    for cam, lights in camera_path(next(iter(rts.values())), path, frames):
        for name, rt in rts.items():
            rt.set_camera(cam)
            rt.set_lights(lights)
            s = rt.update().stats
            out[name].append({k: s[k] for k in KEYS})
    return out


def command(cmd: list[str]) -> str:
    """Run ``cmd``; what it printed. A failure stops the benchmark, naming the command, with the end of its stderr."""
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"runtime: {' '.join(cmd)} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    return proc.stdout


def cli_frames(store: Path, full: bool, device: str, frames: int | None) -> dict:
    """One ``lodprt frames STORE --json [--full]`` in a fresh process (``frames`` None: the command's default): the
    summary it prints."""
    cmd = [sys.executable, "-m", "lodprt", "frames", str(store), "--json", "--device", device]
    cmd += (["--frames", str(frames)] if frames else []) + (["--full"] if full else [])
    return json.loads(command(cmd))["summary"]


def cli_pairs(stores: dict, device: str, pairs: int, frames: int | None) -> list[dict]:
    """2.: for each store (name -> path), ``pairs`` pairs of the default and the ``--full`` command, the first pair
    default first, the next full first, and so on; one row per pair."""
    rows = []
    for name, path in stores.items():
        for k in range(pairs):
            order = (True, False) if k % 2 else (False, True)  # which goes first: --full on odd pairs
            got = {full: cli_frames(path, full, device, frames) for full in order}
            lod, base = got[False], got[True]
            rows.append({"store": name, "pair": k, "triangles": lod["median_triangles"],
                         "full_triangles": base["full_triangles"], "default_median_ms": lod["median_ms"],
                         "full_median_ms": base["median_ms"], "ratio": base["median_ms"] / lod["median_ms"],
                         "default_mean_ms": lod["mean_ms"], "full_mean_ms": base["mean_ms"],
                         "mean_ratio": base["mean_ms"] / lod["mean_ms"]})
            print(f"lodprt frames on {name}, pair {k}: default {lod['median_ms']:.2f} ms, --full "
                  f"{base['median_ms']:.2f} ms ({rows[-1]['ratio']:.2f}x)", flush=True)
    return rows


def demo_store(folder: Path) -> Path:
    """The README's demo store: ``lodprt bake demo -o demo.zarr``, every setting at its default."""
    path = folder / "demo.zarr"
    command([sys.executable, "-m", "lodprt", "bake", "demo", "-o", str(path)])
    return path


def summary(rows: list[dict]) -> dict:
    later = rows[1:] or rows
    out = {"first_ms": rows[0]["ms_total"],  # the mean: every frame's cost, those that estimate the error included
           "mean_ms_total": float(np.mean([r["ms_total"] for r in later]))}
    for k in KEYS:
        a = np.array([r[k] for r in later], np.float64)
        out[f"median_{k}"] = float(np.median(a))
        out[f"p95_{k}"] = float(np.percentile(a, 95))
    return out


def image_error(lod_img: np.ndarray, full_img: np.ndarray) -> tuple[float, float]:
    """Relative RMSE and 99th-percentile per-pixel relative error over the pixels either image covers."""
    cover = (np.abs(lod_img).sum(2) > 0) | (np.abs(full_img).sum(2) > 0)
    a, b = lod_img[cover].astype(np.float64), full_img[cover].astype(np.float64)
    rmse = float(np.sqrt(np.mean((a - b) ** 2)) / max(np.sqrt(np.mean(b**2)), 1e-30))
    peak = float(np.percentile(np.abs(b).max(1), 99)) or 1.0
    return rmse, float(np.percentile(np.abs(a - b).max(1) / peak, 99))


def sweep(store, device: str, frames: int, every: int) -> list[dict]:
    """Error-bound sweep over the orbit: triangles, frame time and image error against the full mesh."""
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import Camera, camera_path

    full = Runtime(store, lod=False, device=device)
    rows = []
    with Renderer() as renderer:
        for bound in (0.2, 0.25, 0.315, 0.4):
            rt = Runtime(store, error_bound=bound, alpha=0.6, criterion="thesis", device=device)
            tris, ms, errs, p99 = [], [], [], []
            for k, (cam, lights) in enumerate(camera_path(rt, "orbit", frames)):
                rt.set_camera(cam)
                rt.set_lights(lights)
                f = rt.update()
                if k:
                    tris.append(f.stats["triangles"])
                    ms.append(f.stats["ms_total"])  # timed inside update(): the rendering below is not included
                if k % every == 0:
                    small = Camera(eye=cam.eye, target=cam.target, fov=cam.fov, width=400, height=300)
                    full.set_camera(small)
                    full.set_lights(lights)
                    ref = renderer.image(full.update(), linear=True)
                    img = renderer.image(f, linear=True, camera=small)
                    e, q = image_error(img, ref)
                    errs.append(e)
                    p99.append(q)
            rows.append({"error_bound": bound, "alpha": 0.6, "median_triangles": float(np.median(tris)),
                         "thesis_triangles": THESIS_TRIANGLES[bound], "median_ms": float(np.median(ms)),
                         "rel_rmse": float(np.mean(errs)), "p99_rel_error": float(np.mean(p99))})
            print(f"bound {bound}: {rows[-1]['median_triangles']:,.0f} triangles, {rows[-1]['median_ms']:.1f} ms, "
                  f"image rRMSE {rows[-1]['rel_rmse']:.4f}", flush=True)
    return rows


def budget_runs(store, device: str, frames: int, every: int, full_ms: float) -> list[dict]:
    """4.: the default without a budget and under ``full_ms`` / 4 and / 5 (B-2), in lockstep with the full mesh."""
    from lodprt.display.compare import frame_error
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import camera_path

    budgets = {"none": None, "full / 4": full_ms / 4, "full / 5": full_ms / 5}
    rts = {name: Runtime(store, device=device, frame_ms=ms) for name, ms in budgets.items()}
    full = Runtime(store, lod=False, device=device)
    stats = {name: [] for name in [*rts, "full"]}
    psnr = {name: [] for name in rts}
    with Renderer() as renderer:
        for k, (cam, lights) in enumerate(camera_path(full, "orbit", frames)):
            made = {}
            for name, rt in [*rts.items(), ("full", full)]:
                rt.set_camera(cam)
                rt.set_lights(lights)
                made[name] = rt.update()
                stats[name].append(made[name].stats)
            if k % every == 0:
                for name, rt in rts.items():
                    psnr[name].append(frame_error(renderer, made[name], made["full"], rt.white)[0]["psnr_db"])
    full_ms_all = [s["ms_total"] for s in stats["full"][1:]]
    base = {"median": float(np.median(full_ms_all)), "mean": float(np.mean(full_ms_all))}
    rows = []
    for name, ms_budget in budgets.items():
        later = stats[name][1:]
        ms = np.array([s["ms_total"] for s in later])
        timed = np.array([s["ms_total"] for s in later if s["budget_timed"]])  # the frames B-2 reads
        est = [s["estimated_psnr_db"] for s in later if s["estimated_psnr_db"] is not None]
        rows.append({"budget": name, "frame_ms": ms_budget, "median_ms": float(np.median(ms)),
                     "mean_ms": float(ms.mean()), "full_median_ms": base["median"], "full_mean_ms": base["mean"],
                     "ratio": base["median"] / float(np.median(ms)), "mean_ratio": base["mean"] / float(ms.mean()),
                     "met": None if ms_budget is None else float(np.mean(timed <= ms_budget)),
                     "median_triangles": float(np.median([s["triangles"] for s in later])),
                     "median_bound": float(np.median([s["error_bound"] for s in later])),
                     "median_psnr_db": float(np.median(psnr[name])), "min_psnr_db": float(np.min(psnr[name])),
                     "median_estimated_psnr_db": float(np.median(est)) if est else None})
        print(f"budget {name}: {rows[-1]['median_ms']:.2f} ms ({rows[-1]['ratio']:.2f}x the full mesh's "
              f"{base['median']:.1f}), {rows[-1]['median_triangles']:,.0f} triangles, PSNR "
              f"{rows[-1]['median_psnr_db']:.1f} dB (worst {rows[-1]['min_psnr_db']:.1f})", flush=True)
    return rows


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--store", default=None, help="use this bake store instead of baking the thesis scene")
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.store.bake_store import open_store

    device = resolve_device(args.device)
    frames = 40 if args.quick else 240
    tmp = Path(tempfile.mkdtemp(prefix="lodprt-runtime-bench-"))
    try:
        t = time.perf_counter()
        path = Path(args.store) if args.store else build_store(args.quick, tmp, device)
        store = open_store(path)
        samples = store.num_samples
        print(f"store {path.name}: {store.num_vertices:,} vertices, {len(store.faces):,} triangles "
              f"({time.perf_counter() - t:.0f} s)", flush=True)
        t = time.perf_counter()
        lod = Runtime(store, error_bound=0.25, alpha=0.6, criterion="thesis", device=device)
        init_s = time.perf_counter() - t
        screen = Runtime(store, device=device)  # the default: the screen criterion steered to its frame target
        fixed = Runtime(store, error_bound=0.8, device=device)  # the screen criterion at a fixed 0.8
        full = Runtime(store, lod=False, device=device)
        modes = {"lod": "thesis 0.25", "screen": f"default (target {screen.target_psnr:g} dB)",
                 "fixed": "screen 0.8 fixed", "full": "full mesh"}
        runtimes = {"lod": lod, "screen": screen, "fixed": fixed, "full": full}
        paths = {}
        for kind in ("orbit", "dolly"):
            paths[kind] = run_paths(runtimes, kind, frames)
            for rt in (lod, screen, fixed):
                rt.set_lod(True)  # the dolly starts again from the base mesh, like a fresh view
            print(f"{kind}: " + ", ".join(f"{label} {summary(paths[kind][m])['median_ms_total']:.1f} ms "
                                          f"({summary(paths[kind][m])['median_triangles']:,.0f} tri)"
                                          for m, label in modes.items()), flush=True)
        rows = []
        for kind, runs in paths.items():
            for mode, label in modes.items():
                rows.append({"path": kind, "mode": label, **summary(runs[mode])})
        for r in rows:
            base = next(x for x in rows if x["path"] == r["path"] and x["mode"] == "full mesh")
            r["speedup"] = base["median_ms_total"] / r["median_ms_total"]
            r["mean_speedup"] = base["mean_ms_total"] / r["mean_ms_total"]
        cli_rows = cli_pairs({path.stem: path, "demo": demo_store(tmp)}, device, 1 if args.quick else CLI_PAIRS,
                             20 if args.quick else None)
        sweep_rows = sweep(store, device, 40 if args.quick else 120, 10)
        full_orbit = next(x for x in rows if x["path"] == "orbit" and x["mode"] == "full mesh")["median_ms_total"]
        budget_rows = budget_runs(store, device, 40 if args.quick else 120, 10, full_orbit)
        nv, nf = store.num_vertices, int(len(store.faces))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print(f"\nRuntime init (hierarchy, upload, the first light's samples completed with their per-node bounds; "
          f"the store has {samples}): {init_s:.1f} s; a later frame completes a sample when its light first reaches it")
    print(table(rows, [("path", "path", "s"), ("mode", "mode", "s"), ("median_triangles", "triangles", ",.0f"),
                       ("median_ms_cut", "cut ms", ".2f"), ("median_ms_triangulate", "tri ms", ".2f"),
                       ("median_ms_relight", "relight ms", ".2f"), ("median_ms_total", "median ms", ".2f"),
                       ("p95_ms_total", "p95 ms", ".2f"), ("mean_ms_total", "mean ms", ".2f"),
                       ("first_ms", "first ms", ".0f"), ("speedup", "vs full", ".2f"),
                       ("mean_speedup", "vs full (mean)", ".2f")]))
    print()
    print(table(cli_rows, [("store", "store", "s"), ("pair", "pair", "d"), ("triangles", "triangles", ",.0f"),
                           ("default_median_ms", "frames ms", ".2f"), ("full_median_ms", "--full ms", ".2f"),
                           ("ratio", "ratio", ".2f"), ("default_mean_ms", "mean ms", ".2f"),
                           ("full_mean_ms", "--full mean ms", ".2f"), ("mean_ratio", "mean ratio", ".2f")]))
    print()
    print(table(sweep_rows, [("error_bound", "error bound", ".3f"), ("median_triangles", "triangles", ",.0f"),
                             ("thesis_triangles", "thesis tri", ","), ("median_ms", "median ms", ".2f"),
                             ("rel_rmse", "image rRMSE", ".4f"), ("p99_rel_error", "p99 rel err", ".3f")]))
    print()
    shown = [{k: "" if v is None else v for k, v in r.items()} for r in budget_rows]
    print(table(shown, [("budget", "frame budget", "s"), ("frame_ms", "ms", ".2f"),
                              ("median_ms", "median ms", ".2f"), ("ratio", "vs full", ".2f"),
                              ("mean_ms", "mean ms", ".2f"), ("mean_ratio", "vs full (mean)", ".2f"),
                              ("met", "met", ".2f"), ("median_triangles", "triangles", ",.0f"),
                              ("median_bound", "bound", ".3g"), ("median_psnr_db", "PSNR dB", ".1f"),
                              ("min_psnr_db", "worst dB", ".1f"), ("median_estimated_psnr_db", "E-3 dB", ".1f")]))
    name = "runtime" + ("-quick" if args.quick else "")
    print("wrote", write(name, {"benchmark": "runtime", "quick": args.quick, "environment": environment(device),
                                "vertices": nv, "faces": nf, "frames": frames,
                                "init_seconds": init_s, "paths": rows, "cli": cli_rows, "sweep": sweep_rows,
                                "budgets": budget_rows,
                                "per_frame": paths}, args.json))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    labels = {"lod": "thesis 0.25", "screen": "screen", "full": "full mesh"}
    for kind, ls in (("orbit", "-"), ("dolly", ":")):
        for mode, col in (("lod", "C0"), ("screen", "C2"), ("full", "C3")):
            ms = [r["ms_total"] for r in paths[kind][mode][1:]]
            axes[0].plot(ms, ls, color=col, lw=0.8, label=f"{kind}, {labels[mode]}")
        axes[1].plot([r["triangles"] for r in paths[kind]["lod"][1:]], ls, color="C0", lw=0.8, label=f"{kind}, view cut")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("frame")
    axes[0].set_ylabel("ms per frame (cut + triangulation + relighting)")
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel("frame")
    axes[1].set_ylabel("triangles")
    axes[1].legend(fontsize=7)
    for r in sweep_rows:
        axes[2].scatter(r["median_ms"], r["rel_rmse"], color="C0")
        axes[2].annotate(f"{r['error_bound']} ({r['median_triangles']:,.0f} tri)", (r["median_ms"], r["rel_rmse"]),
                         fontsize=7, xytext=(4, 2), textcoords="offset points")
    full_ms = next(x for x in rows if x["path"] == "orbit" and x["mode"] == "full mesh")["median_ms_total"]
    axes[2].axvline(full_ms, color="C3", ls="--", lw=0.8, label=f"full mesh {full_ms:.0f} ms (error 0)")
    axes[2].set_xlabel("median ms per frame")
    axes[2].set_ylabel("image relative RMSE vs full mesh")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"Run time on {nv:,} vertices ({environment(device)['device']}): view cut vs full mesh",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
