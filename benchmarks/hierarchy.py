"""Vertex hierarchy builds compared on the same meshes in the same run: the sequential build (the default,
``build_hierarchy(method="sequential")``) against the rounds build (``method="rounds"``), the pymeshlab-seeded build
(``method="pymeshlab"``), pymeshlab's plain QEM decimation and meshoptimizer's halving.

    python benchmarks/hierarchy.py [--quick] [--json PATH] [--device cpu|cuda]

Meshes: the Stanford bunny (tests/data) on a 380 x 380 floor (180,347 vertices, the main case), spot and fandisk
(quick: the bunny on a 60 x 60 floor). Every build runs in a fresh child process (``python benchmarks/hierarchy.py --child
METHOD MESH``), which reports:

* ``build s``: the build's own time (the sequential and the rounds build: the best of ``REPEATS`` builds in the
  child, on every core; the others: one build); ``B/vertex``: the child's peak resident memory (``VmHWM``) above its
  resident size just before the first build, per vertex; ``worker MiB``: the largest peak of the pymeshlab worker
  processes (``RUSAGE_CHILDREN``; fresh interpreters, so Python, numpy and pymeshlab's own ~100 MiB included; at
  most ``workers`` of them run at once);
* ``roots``, ``depth``: the base mesh and the tree's height;
* ``light cut``: vertices the 5-degree light cut keeps, mean over the light samples (the bake's default; the
  bunny scene's 3 x 1 x 3 grid, quick 2 x 1 x 1), from a bake of the scene with that hierarchy (SH order 4);
* ``view tris`` and ``PSNR``: the run time's view cut at the fixed screen bound 0.8, converged, from one
  view (``default_eye``, 400 x 300, light on the middle sample), triangles drawn and PSNR against the full mesh
  (``lodprt.display.compare.frame_error``). Not triangles at equal PSNR: one bound, one view, both builds.

``pymeshlab 1p`` is the pymeshlab build on one process (build only); ``QEM only`` is pymeshlab decimating the
whole scene straight to the default build's base size in one call (time only); ``meshopt 1/2`` is meshoptimizer's
``simplify`` halving the same scene in the same run (time only; ``x meshopt``: each build's time over it, the
issue's yardstick: at most 10). Writes
benchmarks/results/hierarchy[-quick].json and .png.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, meshopt_halving, model, parser, plot_path, table, write

FULL = ("bunny380", "spot", "fandisk")
QUICK = ("bunny60",)
#: the sequential and rounds builds are timed this many times in their child, the best kept (``build s``); the others once
REPEATS = 3


def scene_of(name: str):
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    if name.startswith("bunny"):
        floor = int(name[5:])
        pos, faces = load_mesh(model("stanford-bunny"))
        grid = [3, 1, 3] if floor >= 380 else [2, 1, 1]
        return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (floor, 1.0, THESIS_MATERIAL),
                              {"grid": grid}, "lights", f"bunny + {floor}x{floor} floor")
    pos, faces = load_mesh(model(name))
    return assemble_scene([(name, pos, faces, THESIS_MATERIAL)], (60, 1.0, THESIS_MATERIAL), {"grid": [3, 1, 3]},
                          "lights", f"{name} + 60x60 floor")


def _status(key: str) -> int:
    """VmRSS (resident now) or VmHWM (peak of this process) in bytes."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return 0


def view_numbers(store, device: str) -> dict:
    """Triangles and PSNR of the converged view cut at the fixed screen bound 0.8 from the default eye (module
    docstring): one bound for every build, so the columns compare hierarchies, not the target's steering."""
    from lodprt.display.compare import frame_error
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import Camera, default_eye, scene_centre
    from lodprt.runtime.frames import full_frame
    from lodprt.runtime.session import Runtime

    cam = Camera(eye=default_eye(store), target=scene_centre(store), width=400, height=300)
    light = store.light_positions[store.num_samples // 2][None]
    rt = Runtime(store, device=device, criterion="screen", error_bound=0.8)  # a bound alone: fixed, no target
    rt.set_lights(light)
    rt.set_camera(cam)
    lod = rt.update(max_passes=10_000)
    full = full_frame(store, cam, lights=light)
    with Renderer() as renderer:
        psnr = frame_error(renderer, lod, full, rt.white)[0]["psnr_db"]
    return {"view_triangles": len(lod.triangles), "full_triangles": len(full.triangles), "psnr_db": float(psnr)}


def child(method: str, name: str, device: str) -> dict:
    """One build (and, but for ``pymeshlab-1p``, its bake and view) in this fresh process."""
    from lodprt.model.hierarchy_build import build_hierarchy

    scene = scene_of(name)
    build_hierarchy(scene.positions[:3], np.array([[0, 1, 2]]), scene.normals[:3])  # first-use imports
    from lodprt.devices import load_kernels
    from lodprt.kernels import hierarchy as kernels

    load_kernels("cpu", kernels)  # the round kernels' module (compiled once, then loaded from Warp's cache)
    if method.startswith("pymeshlab"):
        import pymeshlab  # noqa: F401  (its import, about 30 MiB, is not the build's memory)
    before = _status("VmRSS")
    workers = 1 if method == "pymeshlab-1p" else None

    def build():
        return build_hierarchy(scene.positions, scene.faces, scene.normals, method=method.split("-")[0],
                               workers=workers)

    h = build()
    peak = _status("VmHWM") - before
    seconds = [h.build_seconds]
    for _ in range(REPEATS - 1 if method in ("rounds", "sequential") else 0):  # the best of a few: the cores are shared
        seconds.append(build().build_seconds)
    out = {"method": method, "mesh": scene.source, "vertices": scene.num_vertices, "build_s": min(seconds),
           "bytes_per_vertex": peak / scene.num_vertices,
           "worker_mib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
           "roots": len(h.roots), "depth": h.depth, "rounds": h.levels, "nodes": h.num_nodes}
    if method == "pymeshlab-1p":
        return out
    from lodprt.precompute.bake import bake
    from lodprt.store.bake_store import open_store

    with tempfile.TemporaryDirectory(prefix="lodprt-hierarchy-") as tmp:
        path = Path(tmp) / "scene.zarr"
        t = time.perf_counter()
        res = bake(scene, path, sh_order=4, device=device, threshold_deg=5.0, tree=h)
        out["bake_s"] = time.perf_counter() - t
        out["light_cut_vertices"] = float(np.mean([s["vertices_kept"] for s in res.samples]))
        out.update(view_numbers(open_store(path), device))
    return out


def qem_only(name: str, target_vertices: int) -> float:
    """pymeshlab decimating the whole scene to ``target_vertices`` (about 2 faces each) in one call: seconds."""
    import pymeshlab

    scene = scene_of(name)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=scene.positions, face_matrix=scene.faces))
    t = time.perf_counter()
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=max(2 * target_vertices, 8), optimalplacement=False,
                                                preservetopology=True)
    return time.perf_counter() - t


def run_child(method: str, name: str, device: str) -> dict:
    cmd = [sys.executable, __file__, "--child", method, name, "--device", device]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr[-4000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def plot(rows: list[dict], name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    methods = ("sequential", "rounds", "pymeshlab")
    panels = (("build_s", "build seconds"), ("bytes_per_vertex", "peak bytes / vertex (main process)"),
              ("light_cut_vertices", "5-degree light cut: vertices kept"), ("view_triangles", "view cut triangles"))
    fig, axes = plt.subplots(1, len(panels), figsize=(14, 3.2))
    y = np.arange(len(meshes))
    for ax, (key, title) in zip(axes, panels):
        for j, m in enumerate(methods):
            vals = [next((r.get(key, 0) for r in rows if r["mesh"] == me and r["method"] == m), 0) for me in meshes]
            ax.barh(y + 0.27 * (1 - j), vals, 0.27, label=m)
        if key == "build_s":  # meshoptimizer's halving and 10x it, the yardstick
            half = [next((r["meshopt_s"] for r in rows if r["mesh"] == me and "meshopt_s" in r), 0) for me in meshes]
            ax.plot(half, y, "k|", ms=14, label="meshopt 1/2")
            ax.plot([10 * h for h in half], y, "r|", ms=14, label="10x meshopt 1/2")
        ax.set_yticks(y, meshes if ax is axes[0] else [""] * len(meshes), fontsize=7)
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=110)
    print("wrote", plot_path(name))


def main():
    if "--child" in sys.argv:
        i = sys.argv.index("--child")
        device = sys.argv[sys.argv.index("--device") + 1] if "--device" in sys.argv else "cpu"
        print(json.dumps(child(sys.argv[i + 1], sys.argv[i + 2], device)))
        return
    args = parser(__doc__.splitlines()[0]).parse_args()
    from lodprt.devices import resolve_device

    device = resolve_device(args.device)
    rows = []
    for name in QUICK if args.quick else FULL:
        methods = ("sequential", "rounds", "pymeshlab") + (("pymeshlab-1p",) if name == "bunny380" else ())
        for method in methods:
            rows.append(run_child(method, name, device))
            r = rows[-1]
            print(f"{r['mesh']} {method}: {r['build_s']:.1f} s, {r['roots']:,} roots", flush=True)
        seq = next(r for r in rows if r["mesh"] == rows[-1]["mesh"] and r["method"] == "sequential")
        rounds = next(r for r in rows if r["mesh"] == seq["mesh"] and r["method"] == "rounds")
        rows.append({"method": "QEM only", "mesh": seq["mesh"], "vertices": seq["vertices"],
                     "build_s": qem_only(name, seq["roots"])})
        scene = scene_of(name)
        meshopt_halving(scene.positions, scene.faces)  # its first call pays for the module's start-up
        half = min(meshopt_halving(scene.positions, scene.faces) for _ in range(3))
        for r in rows:
            if r["mesh"] == seq["mesh"]:
                r["meshopt_s"], r["x_meshopt"] = half, r["build_s"] / half
        rows.append({"method": "meshopt 1/2", "mesh": seq["mesh"], "vertices": seq["vertices"],
                     "build_s": half, "meshopt_s": half, "x_meshopt": 1.0})
        print(f"{seq['mesh']}: meshoptimizer halving {half:.3f} s, sequential build (default) {seq['x_meshopt']:.1f}x "
              f"it, rounds build {rounds['x_meshopt']:.1f}x", flush=True)
    print(table(rows, [("mesh", "mesh", "s"), ("method", "build", "s"), ("vertices", "vertices", ","),
                       ("build_s", "build s", ".2f"), ("x_meshopt", "x meshopt", ".1f"), ("bytes_per_vertex", "B/vertex", ".0f"),
                       ("worker_mib", "worker MiB", ".0f"), ("roots", "roots", ","), ("depth", "depth", "d"),
                       ("light_cut_vertices", "light cut", ",.0f"), ("view_triangles", "view tris", ","),
                       ("full_triangles", "full tris", ","), ("psnr_db", "PSNR dB", ".1f")]))
    name = "hierarchy" + ("-quick" if args.quick else "")
    print("wrote", write(name, {"benchmark": "hierarchy", "quick": args.quick, "environment": environment(device),
                                "rows": rows}, args.json))
    plot(rows, name)


if __name__ == "__main__":
    main()
