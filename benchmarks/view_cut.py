"""View cut: image error against frame time for the two criteria ("screen", S-1/S-2, and the thesis' T-14), bound
sweeps, on each test model standing on a floor.

    python benchmarks/view_cut.py [--quick] [--json PATH] [--device cpu|cuda] [--floor N] [--frames N]
                                  [--scenes shared|procedural|all] [--only NAME ...]

Scenes: the bunny, spot and fandisk, each on an N x N floor (default 200; quick: 60, bunny only), 3 x 1 x 3
light samples in the default box, SH order 4, light cut at 5 degrees (the bake's defaults). Per criterion and bound:
an orbit of the camera (``lodprt.runtime.camera_path``, 400 x 300, light circling above) with the median frame time
of ``Runtime.update()`` (cut + triangulation + relighting, after the first frame) and triangles; every 8th frame
drawn by ``lodprt.render.Renderer`` against the full-mesh frame of the same camera and lights
(``lodprt.display.compare.error_against_full``: PSNR clipped at white, relative RMSE). Baseline in the same run: the full mesh
relit along the same orbit (LOD off). Writes ``benchmarks/results/view_cut.json`` and ``view_cut.png`` (error
against time, one panel per scene). Also, per scene, both criteria at their defaults and the screen criterion
steered to a target PSNR, from three fixed views, each the first frame of a fresh Runtime as ``lodprt render``
draws it, the light on the middle sample (``static_views``: triangles against the full mesh, PSNR, the frame's
time, and the target's estimated PSNR E-3 beside the measured one, on every pixel and on the grid); the default
also with the light halfway between two samples and at the centre of four (``between_lights``).

``--scenes procedural`` (or ``all``, the default of the full run) also measures the static views on the procedural
and decimated scenes of ``benchmarks/procedural.py`` (thin fins, fine relief, a crowd of sizes, terrain, a speck on
a wide floor, the decimated bunny, a rough scan; seed 0, each with its own floor), generated into the run's temporary folder;
the orbit sweeps stay on the shared models. Every static row names its scene and ``family`` (``shared`` or
``procedural``); ``static_summary`` gives, per criterion, the worst PSNR and the least "x fewer" over every scene
and view (the issue's bar: at least 35 dB with at least 4x fewer triangles). ``--quick`` is the bunny alone
unless ``--scenes`` says otherwise; ``--only NAME ...`` keeps only the named scenes (a smoke test of one).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

import procedural
from common import environment, model, parser, plot_path, table, write

SWEEPS = {"screen": (0.2, 0.35, 0.5, 0.7, 1.0, 1.4), "thesis": (0.1, 0.2, 0.25, 0.315, 0.4)}
MODELS_USED = ("stanford-bunny", "spot", "fandisk")
#: the static views' settings: the default (the screen criterion steered to its frame target, E-1..E-4; its rows
#: report the estimate E-3 beside the measured PSNR), the screen criterion at a fixed 0.8, T-14 at its default
STATIC_SETTINGS = {"default": {}, "screen": {"criterion": "screen", "error_bound": 0.8},
                   "thesis": {"criterion": "thesis"}}


def bake_scene(name: str, floor: int, folder: Path, device: str) -> Path:
    from lodprt.precompute.bake import bake
    from lodprt.model.scene import load_scene

    toml = folder / f"{name}.toml"
    toml.write_text(f'[[object]]\nmesh = "{model(name).as_posix()}"\n[floor]\nresolution = {floor}\n'
                    "[lights]\ngrid = [3, 1, 3]\n")
    path = folder / f"{name}.zarr"
    bake(load_scene(toml), path, sh_order=4, device=device, threshold_deg=5.0)
    return path


def bake_procedural(name: str, folder: Path, device: str) -> Path:
    """Generate procedural scene ``name`` (seed 0, its own floor) into ``folder`` and bake it as ``bake_scene``."""
    from lodprt.model.scene import load_scene
    from lodprt.precompute.bake import bake

    toml = procedural.write_scene(name, folder / name, seed=0)
    path = folder / f"{name}.zarr"
    bake(load_scene(toml), path, sh_order=4, device=device, threshold_deg=5.0)
    return path


def static_summary(static: list[dict]) -> list[dict]:
    """Per setting (STATIC_SETTINGS) and, for the default, per light between samples, the worst PSNR and the least
    "x fewer" over every static row, with the scene and view where each occurs."""
    out = []
    label = lambda r: r["setting"] + ("" if r.get("light", "sample") == "sample" else f", light {r['light']}")  # noqa: E731
    for criterion in dict.fromkeys(label(r) for r in static):
        mine = [r for r in static if label(r) == criterion]
        worst = min(mine, key=lambda r: r["psnr_db"])
        least = min(mine, key=lambda r: r["fewer"])
        out.append({"criterion": criterion, "rows": len(mine), "worst_psnr_db": worst["psnr_db"],
                    "worst_psnr_at": f"{worst['scene']}, {worst['view']}", "least_fewer": least["fewer"],
                    "least_fewer_at": f"{least['scene']}, {least['view']}"})
    return out


def run_orbit(store, rt, frames: int, every: int, renderer) -> dict:
    """Median ms and triangles along the orbit, and the image error of every ``every``-th frame."""
    from lodprt.display.compare import error_against_full
    from lodprt.runtime.camera import camera_path

    ms, tris, psnr, rmse = [], [], [], []
    for k, (cam, lights) in enumerate(camera_path(rt, "orbit", frames, size=(400, 300))):
        rt.set_camera(cam)
        rt.set_lights(lights)
        f = rt.update()
        if k:
            ms.append(f.stats["ms_total"])
            tris.append(f.stats["triangles"])
        if renderer is not None and k % every == 0:
            numbers = error_against_full(renderer, store, f, rt.white)
            psnr.append(min(numbers["psnr_db"], 100.0))
            rmse.append(numbers["relative_rmse"])
    out = {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
           "median_triangles": float(np.median(tris))}
    if psnr:
        out.update(median_psnr_db=float(np.median(psnr)), min_psnr_db=float(np.min(psnr)),
                   mean_relative_rmse=float(np.mean(rmse)))
    return out


def between_lights(store) -> dict:
    """The static views' lights: the middle sample, halfway to the next sample along x ("between 2") and the centre
    of the cell of four samples there ("between 4"; on a 3 x 1 x 3 grid, samples 4, 5, 7 and 8)."""
    p = store.light_positions
    mid = store.num_samples // 2
    out = {"sample": p[mid]}
    row = np.flatnonzero((np.abs(p[:, 1:] - p[mid, 1:]).max(1) < 1e-9) & (p[:, 0] > p[mid, 0] + 1e-9))
    col = np.flatnonzero((np.abs(p[:, :2] - p[mid, :2]).max(1) < 1e-9) & (p[:, 2] > p[mid, 2] + 1e-9))
    if len(row):
        x = row[np.argmin(p[row, 0])]
        out["between 2"] = 0.5 * (p[mid] + p[x])
        if len(col):
            z = col[np.argmin(p[col, 2])]
            out["between 4"] = 0.5 * (p[x] + p[z])
    return out


def static_views(store, name: str, renderer, device: str, family: str = "shared") -> list[dict]:
    """Each of STATIC_SETTINGS, light on the middle sample, 400 x 300, from the default eye of ``lodprt compare``
    (``default_eye``: a three-quarter view from the front and above), a front view of the object and a close one
    (the full frame made once per view and light), each the first frame of a fresh Runtime, as ``lodprt render``
    and ``compare`` draw it (the cut converged; under the default's target refined where its error is, E-5):
    triangles against the full mesh, PSNR, its time and, for the default's rows, the frame's estimated PSNR (E-3:
    how tight the estimate is, and whether it is ever optimistic) on every pixel, as a still frame is refined, and on
    the grid, as a moving one does. The default also with the light between samples (``between_lights``: the
    direct path, M-1..M-6)."""
    from lodprt.runtime.camera import Camera, default_eye, object_bounds, scene_centre

    b = object_bounds(store)
    c, size = 0.5 * (b[0] + b[1]), float(np.linalg.norm(b[1] - b[0]))
    at = lambda offset: dict(eye=tuple(c + size * np.array(offset)), target=tuple(c))  # noqa: E731
    views = {"default eye": Camera(eye=default_eye(store), target=scene_centre(store), width=400, height=300),
             "front": Camera(**at([0.25, 0.55, 1.1]), width=400, height=300),
             "close": Camera(**at([0.15, 0.3, 0.6]), width=400, height=300)}
    out = []
    for light_name, light in between_lights(store).items():
        settings = STATIC_SETTINGS if light_name == "sample" else {"default": STATIC_SETTINGS["default"]}
        out += light_views(store, name, renderer, device, family, views, light_name, light[None], settings)
    return out


def light_views(store, name, renderer, device, family, views, light_name, light, settings) -> list[dict]:
    """``static_views``' rows for one light: each of ``settings`` from each of ``views``."""
    from lodprt.display.compare import frame_error
    from lodprt.runtime.frames import full_frame
    from lodprt.runtime.session import Runtime

    fulls = {view: full_frame(store, cam, lights=light) for view, cam in views.items()}
    out = []
    for setting, kwargs in settings.items():
        for view, cam in views.items():
            rt = Runtime(store, device=device, **kwargs)  # a fresh run time and its first frame: ``lodprt render``
            rt.set_lights(light)
            rt.set_camera(cam)
            t = time.perf_counter()
            lod = rt.update()
            seconds = time.perf_counter() - t
            est = grid = float("nan")
            if rt.steering is not None:  # E-3 of the frame drawn: on every pixel (first and still frames) and on
                rt.estimate_frame_error(lod.vertex_ids, lod.triangles, lod.coefficients, steer=False,  # the grid
                                        every_pixel=True)  # of the frames in motion
                est = float(rt.estimated_psnr)
                rt.estimate_frame_error(lod.vertex_ids, lod.triangles, lod.coefficients, steer=False)
                grid = float(rt.estimated_psnr)
            full = fulls[view]
            numbers = frame_error(renderer, lod, full, rt.white)[0]
            label = rt.criterion.name + (f", target {rt.target_psnr:g} dB" if rt.target_psnr else "")
            out.append({"scene": name, "family": family, "view": view, "setting": setting, "light": light_name,
                        "criterion": f"{setting}: {label} (bound {rt.error_bound:.3g})",
                        "triangles": len(lod.triangles), "full": len(full.triangles),
                        "fewer": len(full.triangles) / max(len(lod.triangles), 1), "psnr_db": numbers["psnr_db"],
                        "estimated_psnr_db": est, "grid_psnr_db": grid, "first_frame_s": seconds})
            print(f"  {view}, light {light_name}, {out[-1]['criterion']}: {out[-1]['triangles']:,} / "
                  f"{out[-1]['full']:,} triangles, {out[-1]['psnr_db']:.1f} dB (estimated {est:.1f}, on the grid "
                  f"{grid:.1f}), first frame {seconds:.2f} s", flush=True)
    return out


def scene_names(args) -> tuple[list[str], list[str]]:
    """The shared models (orbits and static views) and the procedural scenes (static views) this run measures."""
    which = args.scenes or ("shared" if args.quick else "all")
    shared = list(MODELS_USED[:1] if args.quick else MODELS_USED) if which in ("shared", "all") else []
    made = list(procedural.SCENES) if which in ("procedural", "all") else []
    if args.only:
        unknown = set(args.only) - set(MODELS_USED) - set(procedural.SCENES)
        if unknown:
            raise SystemExit(f"--only: unknown scene(s) {', '.join(sorted(unknown))}")
        shared = [n for n in MODELS_USED if n in args.only]
        made = [n for n in procedural.SCENES if n in args.only]
    return shared, made


def procedural_static(names, folder: Path, renderer, device: str) -> list[dict]:
    """The static views on each procedural scene (no orbit sweeps: they are slow)."""
    from lodprt.store.bake_store import open_store

    static = []
    for name in names:
        t = time.perf_counter()
        store = open_store(bake_procedural(name, folder, device))
        print(f"{name} (procedural): {store.num_vertices:,} vertices, {len(store.faces):,} triangles "
              f"(baked in {time.perf_counter() - t:.0f} s)", flush=True)
        static += static_views(store, name, renderer, device, family="procedural")
    return static


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--floor", type=int, default=None, help="floor resolution of the shared models (default 200; "
                   "quick 60); the procedural scenes keep their own")
    p.add_argument("--frames", type=int, default=None, help="orbit frames (default 96; quick 16)")
    p.add_argument("--scenes", choices=("shared", "procedural", "all"), default=None,
                   help="the shared models (orbits and static views), the procedural scenes of "
                   "benchmarks/procedural.py (static views), or both (default: all; quick: the bunny alone)")
    p.add_argument("--only", nargs="+", metavar="NAME", default=None,
                   help="keep only these scenes (shared or procedural names; a smoke test)")
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.display.render import Renderer
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    device = resolve_device(args.device)
    floor = args.floor or (60 if args.quick else 200)
    frames = args.frames or (16 if args.quick else 96)
    names, made = scene_names(args)
    sweeps = {k: v[1:4:2] for k, v in SWEEPS.items()} if args.quick else SWEEPS
    sweeps = {"default": (None,), **sweeps}
    rows, static = [], []
    with tempfile.TemporaryDirectory(prefix="lodprt-view-cut-") as tmp, Renderer() as renderer:
        for name in names:
            t = time.perf_counter()
            store = open_store(bake_scene(name, floor, Path(tmp), device))
            print(f"{name} + {floor} floor: {store.num_vertices:,} vertices, {len(store.faces):,} triangles "
                  f"(baked in {time.perf_counter() - t:.0f} s)", flush=True)
            static += static_views(store, name, renderer, device)
            full = run_orbit(store, Runtime(store, lod=False, device=device), frames, frames, None)
            rows.append({"scene": name, "criterion": "full mesh", "error_bound": float("nan"), **full,
                         "median_psnr_db": float("inf"), "speedup": 1.0})
            for criterion, bounds in sweeps.items():
                for bound in bounds:
                    rt = Runtime(store, device=device) if bound is None else \
                        Runtime(store, criterion=criterion, error_bound=bound, device=device)  # None: the default
                    r = run_orbit(store, rt, frames, 8, renderer)
                    if bound is None:
                        criterion, bound = f"default (target {rt.target_psnr:g} dB)", float("nan")
                    rows.append({"scene": name, "criterion": criterion, "error_bound": bound, **r,
                                 "speedup": full["median_ms"] / r["median_ms"]})
                    print(f"  {criterion} {bound:g}: {r['median_triangles']:,.0f} tri, {r['median_ms']:.1f} ms "
                          f"(full {full['median_ms']:.1f}), PSNR {r['median_psnr_db']:.1f} dB", flush=True)
        static += procedural_static(made, Path(tmp), renderer, device)
    summary = static_summary(static)
    print_tables(rows, static, summary)
    name = "view_cut" + ("-quick" if args.quick else "")
    print("wrote", write(name, {"benchmark": "view_cut", "quick": args.quick, "environment": environment(device),
                                "floor": floor, "frames": frames, "rows": rows, "static_views": static,
                                "static_summary": summary}, args.json))
    if rows:
        plot(rows, names, name)


def print_tables(rows: list[dict], static: list[dict], summary: list[dict]) -> None:
    if rows:
        print()
        print(table(rows, [("scene", "scene", "s"), ("criterion", "criterion", "s"),
                           ("error_bound", "bound", ".3g"), ("median_triangles", "triangles", ",.0f"),
                           ("median_ms", "median ms", ".1f"), ("p95_ms", "p95 ms", ".1f"),
                           ("speedup", "vs full", ".2f"), ("median_psnr_db", "PSNR dB", ".1f"),
                           ("min_psnr_db", "worst dB", ".1f")]))
    print()
    print(table(static, [("scene", "scene", "s"), ("family", "family", "s"), ("view", "view", "s"),
                         ("light", "light", "s"), ("criterion", "criterion (default)", "s"), ("triangles", "triangles", ",.0f"),
                         ("full", "full", ",.0f"), ("fewer", "x fewer", ".1f"), ("psnr_db", "PSNR dB", ".1f"),
                         ("estimated_psnr_db", "estimated dB (E-3)", ".1f"), ("grid_psnr_db", "on the grid dB", ".1f"),
                         ("first_frame_s", "first frame s", ".2f")]))
    print()
    print("over every scene and view:")
    print(table(summary, [("criterion", "criterion", "s"), ("rows", "views", "d"),
                          ("worst_psnr_db", "worst PSNR dB", ".1f"), ("worst_psnr_at", "at", "s"),
                          ("least_fewer", "least x fewer", ".1f"), ("least_fewer_at", "at", "s")]))


def plot(rows: list[dict], names, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(names), figsize=(4.6 * len(names), 3.8), squeeze=False)
    for ax, scene in zip(axes[0], names):
        mine = [r for r in rows if r["scene"] == scene]
        for criterion, colour in (("screen", "C0"), ("thesis", "C1")):
            pts = sorted((r["median_ms"], 10 ** (-r["median_psnr_db"] / 20), r["error_bound"])
                         for r in mine if r["criterion"] == criterion)
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=colour, label=criterion)
            for x, y, b in pts:
                ax.annotate(f"{b:g}", (x, y), fontsize=7, xytext=(3, 2), textcoords="offset points")
        for r in mine:
            if r["criterion"].startswith("default"):
                ax.plot(r["median_ms"], 10 ** (-r["median_psnr_db"] / 20), "*", color="C2", ms=12,
                        label=r["criterion"])
        full = next(r for r in mine if r["criterion"] == "full mesh")
        ax.axvline(full["median_ms"], color="C3", ls="--", lw=0.8, label=f"full mesh {full['median_ms']:.0f} ms")
        ax.set_yscale("log")
        ax.set_xlabel("median ms per frame (cut + triangulation + relighting)")
        ax.set_ylabel("RMSE / white (clipped), median over frames")
        ax.set_title(scene, fontsize=10)
        ax.legend(fontsize=7)
    fig.suptitle("View cut: image error against frame time (lower left is better; labels: error bound)", fontsize=10)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
