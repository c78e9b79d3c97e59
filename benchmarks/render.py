"""Offscreen frames per second with and without the view-dependent cut, at 512x512 and 1024x1024.

    python benchmarks/render.py [--quick] [--json PATH] [--store OUT.zarr] [--device cpu|cuda]

Scene: the Stanford bunny on a 380 x 380 floor, 3 x 1 x 3 light samples, SH order 4, light cut at 5
degrees, baked here into a temporary store (quick: 100 x 100 floor, 2 x 1 x 1 samples) unless --store names one.
Each frame the camera orbits 1 degree about the bunny and a light moves, so the run time moves its cut and
relights every frame; "update" is ``set_camera`` + ``set_lights`` + ``Runtime.update()`` (cut, triangulation,
relighting), "draw" is ``Renderer.draw`` of the new frame into the offscreen EGL framebuffer (coefficient upload,
SH radiance per fragment from interpolated coefficients, or per vertex, tone mapping) until ``glFinish``. Baseline
in the same run: the full mesh (LOD off, every vertex, same lights and camera path). Recorded: the GL renderer
(llvmpipe on CPU machines) and the Warp device the bake and the run time's kernels used (``--device``; default:
CUDA when present, else the CPU, as ``lodprt.devices.resolve_device`` decides).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, parser, plot_path, table, thesis_scene, write
from lodprt.runtime import Runtime


def build_store(quick: bool, folder: Path, device: str) -> Path:
    from lodprt.precompute.bake import bake

    path = folder / "render-bench.zarr"
    bake(thesis_scene(quick=quick), path, sh_order=4, device=device, threshold_deg=5.0)
    return path


def measure(rt, renderer, camera, lights, frames: int, per_vertex: bool) -> dict:
    """Mean update and draw milliseconds over ``frames`` frames of a 1-degree orbit with a moving light."""
    from lodprt.runtime.camera import orbit

    rt.set_lights(lights)
    rt.set_camera(camera)
    frame = rt.update()  # converge the cut once (first frame from the base mesh), warm the shader
    renderer.draw(frame, per_vertex=per_vertex, white=rt.white)
    renderer.ctx.finish()
    upd, drw, tris = [], [], []
    for k in range(frames):
        t0 = time.perf_counter()
        rt.set_camera(orbit(camera, np.radians(k + 1)))
        rt.set_lights(lights + 0.002 * (k + 1) * np.array([1.0, 0.0, 0.0]))
        frame = rt.update()
        t1 = time.perf_counter()
        renderer.draw(frame, per_vertex=per_vertex, white=rt.white)
        renderer.ctx.finish()
        t2 = time.perf_counter()
        upd.append(t1 - t0)
        drw.append(t2 - t1)
        tris.append(len(frame.triangles))
    u, d = 1e3 * float(np.mean(upd)), 1e3 * float(np.mean(drw))
    return {"triangles": int(np.mean(tris)), "update_ms": u, "draw_ms": d, "draw_fps": 1e3 / d, "fps": 1e3 / (u + d)}


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--store", default=None, help="use this bake store instead of baking the thesis scene")
    args = p.parse_args()
    from lodprt.devices import resolve_device
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import scene_centre
    from lodprt.runtime.camera import Camera
    from lodprt.store.bake_store import open_store

    device = resolve_device(args.device)  # refuse an unavailable device before baking
    tmp = Path(tempfile.mkdtemp(prefix="lodprt-render-bench-"))
    try:
        t = time.perf_counter()
        path = Path(args.store) if args.store else build_store(args.quick, tmp, device)
        store = open_store(path)
        nv = store.num_vertices
        print(f"store {path.name}: {store.num_vertices:,} vertices ({time.perf_counter() - t:.0f} s)", flush=True)
        centre = np.array(scene_centre(store))
        extent = float(np.ptp(store.positions[store.faces.ravel()][:, 0]))
        lights = store.light_positions[store.num_samples // 2][None, :].astype(np.float64)
        frames = 3 if args.quick else 10
        sizes = [(512, 512), (1024, 1024)]
        rows = []
        rt = Runtime(store, device=device)
        with Renderer() as renderer:
            gl = renderer.ctx.info["GL_RENDERER"]
            for size in sizes:
                cam = Camera(eye=tuple(centre + extent * np.array([0.0, 0.25, 0.45])), target=tuple(centre),
                             fov=40.0, width=size[0], height=size[1])
                for mode in ("view cut", "full mesh"):
                    rt.set_lod(mode == "view cut")
                    for shading in ("fragment", "vertex"):
                        r = measure(rt, renderer, cam, lights, frames, per_vertex=shading == "vertex")
                        rows.append({"size": f"{size[0]}x{size[1]}", "mode": mode, "shading": shading, **r})
                        print(f"{size} {mode} {shading}: {r['fps']:.1f} fps", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"GL renderer: {gl}; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (other work slows llvmpipe)")
    print(table(rows, [("size", "size", "s"), ("mode", "mode", "s"), ("shading", "radiance per", "s"),
                       ("triangles", "triangles", ","), ("update_ms", "update ms", ".1f"), ("draw_ms", "draw ms", ".1f"),
                       ("draw_fps", "draw fps", ".1f"), ("fps", "frame fps", ".1f")]))
    name = "render" + ("-quick" if args.quick else "")
    # the device the Runtime's kernels actually ran on (the bake used the same one unless --store was given)
    env = dict(environment(rt.device), gl_renderer=gl, cpu_count=os.cpu_count(), load_average_after=os.getloadavg())
    print("wrote", write(name, {"benchmark": "render", "quick": args.quick, "environment": env,
                                "vertices": nv, "frames": frames, "rows": rows}, args.json))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharey=True)
    for ax, shading in zip(axes, ("fragment", "vertex")):
        x = np.arange(len(sizes))
        for off, mode in ((-0.2, "view cut"), (0.2, "full mesh")):
            sel = [r for r in rows if r["mode"] == mode and r["shading"] == shading]
            ax.bar(x + off, [r["fps"] for r in sel], 0.38, label=f"{mode} ({sel[0]['triangles']:,} tri)")
            ax.scatter(x + off, [r["draw_fps"] for r in sel], color="k", marker="_", s=200, zorder=3)
        ax.set_xticks(x, [f"{s[0]}x{s[1]}" for s in sizes])
        ax.set_title(f"radiance per {shading} ({gl.split(' (')[0]})", fontsize=9)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("frames per second")
    fig.suptitle(f"Offscreen rendering, {nv:,}-vertex bake (bars: run-time update + draw; ticks: draw only)", fontsize=10)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
