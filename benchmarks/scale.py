"""Scale: hierarchy build, bake and run-time time and peak memory from 75k to 2M vertices and from 9 to 729 samples.

    python benchmarks/scale.py [--quick] [--floors 200 380 ...] [--budget SECONDS] [--json PATH]

Scenes: the Stanford bunny on an N x N floor (N = 200 -> 1400: 75,947 -> 1,995,947 vertices). Every
measurement runs in a fresh child process; its peak resident memory is the kernel's high-water mark of that process
(``VmHWM``), its time the child's own clock around the measured call (the bake: the command's wall time):

* ``pymeshlab``: one QEM halving of the scene (``meshing_decimation_quadric_edge_collapse`` to half the faces,
  ``optimalplacement=False``), the baseline the issue sets for the hierarchy build (at most 2x);
* ``meshoptimizer``: meshoptimizer's ``simplify`` halving the scene (the best of three after a first call), the
  yardstick of issue 25 (the hierarchy build within 10x of it; ``x meshopt``);
* ``hierarchy``: ``build_hierarchy`` of the same scene (the default, sequential build; Warp and its kernels loaded
  first by a one-triangle build); bytes per vertex = (peak - resident size just before the build) / vertices;
* ``bake``: the whole ``lodprt bake SCENE.toml -o OUT.zarr`` command (scene loading, hierarchy, light cut at the
  default 5 degrees, SH order 4, store writing), 3 x 3 x 3 = 27 light samples for the vertex sweep and 3 x 1 x 3 ..
  9 x 9 x 9 (9 .. 729) samples on the 200 x 200 floor for the sample sweep;
* ``run time``: after each bake, ``Runtime(store)`` opened and its first frame drawn (800 x 600, default view): seconds
  and the peak above the child's start (Python, Warp, kernels), and how many light samples it completed (lazily:
  only those the first light uses, ``lodprt.runtime.samples``);
* ``workers``: the 27-sample bake of the sample-sweep floor in-process, with ``--workers 1`` and ``--workers 2``
  (a LocalCluster of worker processes; the command's wall time, cluster start included, and the client's peak).

Floors are measured in increasing size until ``--budget`` seconds have gone by (a row that starts before the
budget runs to its end). Writes benchmarks/results/scale[-quick].json and .png (log-log, fitted exponents).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import environment, meshopt_halving, model, parser, plot_path, table, write

BUNNY = model("stanford-bunny")


# ---------------------------------------------------------------------------------------------------------------
# children: one measurement each, printing one JSON line


def _status(key: str = "VmRSS") -> int:
    """VmRSS (resident now) or VmHWM (peak of this process image) in bytes. ``ru_maxrss`` of a child would also
    count the parent's pages at the fork, hence the children report their own peak."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return 0


def _scene(floor: int):
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    pos, faces = load_mesh(BUNNY)
    return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (floor, 1.0, THESIS_MATERIAL), {}, "lights",
                          f"bunny + {floor}x{floor} floor")


def child(kind: str, floor: int) -> dict:
    scene = _scene(floor)
    before = _status()
    if kind == "pymeshlab":
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=scene.positions, face_matrix=scene.faces))
        t = time.perf_counter()
        ms.meshing_decimation_quadric_edge_collapse(targetfacenum=len(scene.faces) // 2, optimalplacement=False,
                                                    preservetopology=True)
        return {"seconds": time.perf_counter() - t, "rss_before": before, "vertices": scene.num_vertices,
                "peak": _status("VmHWM")}
    if kind == "meshoptimizer":
        meshopt_halving(scene.positions, scene.faces)
        return {"seconds": min(meshopt_halving(scene.positions, scene.faces) for _ in range(3)),
                "rss_before": before, "vertices": scene.num_vertices, "peak": _status("VmHWM")}
    from lodprt.model.hierarchy_build import build_hierarchy

    build_hierarchy(scene.positions[:3], np.array([[0, 1, 2]]), scene.normals[:3])  # Warp and the build's kernels
    t = time.perf_counter()
    h = build_hierarchy(scene.positions, scene.faces, scene.normals)
    return {"seconds": time.perf_counter() - t, "rss_before": before, "vertices": scene.num_vertices,
            "nodes": h.num_nodes, "roots": len(h.roots), "depth": h.depth, "rounds": h.levels,
            "hierarchy_bytes": h.nbytes, "peak": _status("VmHWM")}


def run_child(argv: list[str]) -> tuple[dict, int, float]:
    """Run a child process; returns what it printed last (JSON), its peak resident bytes (``ru_maxrss``: an upper
    bound, it includes the parent's pages at the fork), its wall seconds."""
    t = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:  # progress bars and logs: shown only when the child fails
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=err, text=True, cwd=Path(__file__).parent)
        out = proc.stdout.read()
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            sys.exit(f"{err.read()[-4000:]}\nchild {' '.join(argv[1:])} failed with status {proc.returncode}")
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    return (json.loads(lines[-1]) if lines else {}), usage.ru_maxrss * 1024, wall


def measure_build(kind: str, floor: int) -> dict:
    res, _, _ = run_child([sys.executable, __file__, "--child", kind, str(floor)])
    res["bytes_per_vertex"] = (res["peak"] - res["rss_before"]) / res["vertices"]
    return res


BAKE_CHILD = """
import json, sys
from lodprt.cli import main
rc = main(sys.argv[1:])
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")][0].split()[1]
print(json.dumps({"peak": int(hwm) * 1024}))
sys.exit(rc)
"""


RUNTIME_CHILD = """
import json, sys, time
from lodprt.devices import warp
from lodprt.runtime.camera import Camera, default_eye, scene_centre
from lodprt.runtime.session import Runtime
from lodprt.store.bake_store import open_store
warp()
status = lambda key: int([ln for ln in open("/proc/self/status") if ln.startswith(key + ":")][0].split()[1]) * 1024
before = status("VmRSS")
t = time.perf_counter()
store = open_store(sys.argv[1])
rt = Runtime(store, device=sys.argv[2])
t1 = time.perf_counter()
rt.set_camera(Camera(eye=default_eye(store), target=scene_centre(store), width=800, height=600))
frame = rt.update()
t2 = time.perf_counter()
print(json.dumps({"open_s": t1 - t, "first_frame_s": t2 - t1, "rss_before": before, "peak": status("VmHWM"),
                  "completed": rt.samples.completed, "samples": store.num_samples, "triangles": len(frame.triangles)}))
"""


def measure_runtime(store: Path, device: str) -> dict:
    """Open a store with the run time and draw its first frame (800 x 600, default view), in a child process: seconds
    and the peak resident bytes above the child's start (Python, Warp and the kernels loaded)."""
    res, _, _ = run_child([sys.executable, "-c", RUNTIME_CHILD, str(store), device])
    return {**res, "above_start": res["peak"] - res["rss_before"]}


def measure_bake(floor: int, grid: list[int], device: str, tmp: Path, options: tuple = ()) -> dict:
    scene = tmp / "scene.toml"
    scene.write_text(f'[[object]]\nmesh = "{BUNNY.resolve().as_posix()}"\n\n[floor]\nresolution = {floor}\n\n'
                     f"[lights]\ngrid = {list(grid)}\n")
    out = tmp / "out.zarr"
    cmd = [sys.executable, "-c", BAKE_CHILD, "bake", str(scene), "-o", str(out), "--overwrite", "--device", device,
           *options]
    res, _, wall = run_child(cmd)
    peak = res["peak"]
    from lodprt.store.bake_store import open_store

    info = open_store(out).info()
    return {"seconds": wall, "peak": peak, "hierarchy_seconds": info.get("hierarchy_seconds"),
            "samples": int(np.prod(grid)), "store_bytes": sum(f.stat().st_size for f in out.rglob("*") if f.is_file())}


# ---------------------------------------------------------------------------------------------------------------


def exponent(x, y) -> float:
    """Slope of log y against log x (least squares): y ~ x^slope."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0)
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0]) if ok.sum() >= 2 else float("nan")


def vertex_sweep(floors, device, budget, t0, tmp) -> list[dict]:
    rows = []
    for floor in floors:
        if rows and time.perf_counter() - t0 > budget:
            print(f"budget of {budget:.0f} s spent: stopping before floor {floor}", flush=True)
            break
        pm = measure_build("pymeshlab", floor)
        mo = measure_build("meshoptimizer", floor)
        h = measure_build("hierarchy", floor)
        b = measure_bake(floor, [3, 3, 3], device, tmp)
        rt = measure_runtime(tmp / "out.zarr", device)
        V = h["vertices"]
        rows.append({"floor": floor, "vertices": V, "hierarchy_s": h["seconds"], "pymeshlab_s": pm["seconds"],
                     "ratio": h["seconds"] / pm["seconds"], "meshopt_s": mo["seconds"],
                     "x_meshopt": h["seconds"] / mo["seconds"], "hierarchy_peak_mib": h["peak"] / 2**20,
                     "hierarchy_b_per_v": h["bytes_per_vertex"], "pymeshlab_b_per_v": pm["bytes_per_vertex"],
                     "roots": h["roots"], "depth": h["depth"], "rounds": h["rounds"],
                     "stored_b_per_v": h["hierarchy_bytes"] / V, "bake_s": b["seconds"],
                     "bake_hierarchy_s": b["hierarchy_seconds"], "bake_peak_mib": b["peak"] / 2**20,
                     "bake_b_per_v": b["peak"] / V, "samples": b["samples"], "open_s": rt["open_s"],
                     "first_frame_s": rt["first_frame_s"], "runtime_mib": rt["above_start"] / 2**20,
                     "runtime_completed": rt["completed"]})
        r = rows[-1]
        print(f"floor {floor}: {V:,} vertices, hierarchy {r['hierarchy_s']:.1f} s ({r['ratio']:.2f}x pymeshlab, "
              f"{r['x_meshopt']:.1f}x meshoptimizer), "
              f"{r['hierarchy_b_per_v']:.0f} B/vertex; bake {r['bake_s']:.1f} s, peak {r['bake_peak_mib']:.0f} MiB",
              flush=True)
    return rows


def sample_sweep(floor, grids, device, tmp) -> list[dict]:
    rows = []
    for grid in grids:
        b = measure_bake(floor, grid, device, tmp)
        rt = measure_runtime(tmp / "out.zarr", device)
        rows.append({"floor": floor, "grid": "x".join(map(str, grid)), "samples": b["samples"], "bake_s": b["seconds"],
                     "bake_hierarchy_s": b["hierarchy_seconds"], "bake_peak_mib": b["peak"] / 2**20,
                     "store_mib": b["store_bytes"] / 2**20, "open_s": rt["open_s"], "first_frame_s": rt["first_frame_s"],
                     "runtime_mib": rt["above_start"] / 2**20, "runtime_completed": rt["completed"]})
        print(f"{b['samples']} samples: bake {b['seconds']:.1f} s, peak {b['peak'] / 2**20:.0f} MiB; run time open "
              f"{rt['open_s']:.1f} s + first frame {rt['first_frame_s']:.1f} s, {rt['above_start'] / 2**20:.0f} MiB "
              f"({rt['completed']} samples completed)", flush=True)
    return rows


def worker_sweep(floor, grid, device, tmp) -> list[dict]:
    """The same bake in-process and on a LocalCluster of 1 and 2 worker processes (--workers; wall seconds of the
    whole command, cluster start included; peak of the client process)."""
    rows = []
    for label, options in (("in-process", ()), ("--workers 1", ("--workers", "1")), ("--workers 2", ("--workers", "2"))):
        b = measure_bake(floor, grid, device, tmp, options)
        rows.append({"floor": floor, "samples": b["samples"], "mode": label, "bake_s": b["seconds"],
                     "client_peak_mib": b["peak"] / 2**20})
        print(f"{label}: {b['samples']} samples, {b['seconds']:.1f} s, client peak {b['peak'] / 2**20:.0f} MiB",
              flush=True)
    return rows


def plot(name, vrows, srows, fits):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 4))
    V = [r["vertices"] for r in vrows]
    for key, label in (("hierarchy_s", "hierarchy"), ("pymeshlab_s", "one pymeshlab halving"), ("bake_s", "bake (27)"),
                       ("meshopt_s", "one meshoptimizer halving")):
        if all(key in r for r in vrows):
            ax[0].loglog(V, [r[key] for r in vrows], "o-", label=f"{label}  ~V^{fits[key]:.2f}")
    ax[0].set(xlabel="vertices", ylabel="seconds", title="time")
    for key, fit, label in (("hierarchy_b_per_v", "hierarchy_bytes", "hierarchy build, over start"),
                            ("bake_b_per_v", "bake_bytes", "whole bake, peak")):
        ax[1].loglog(V, [r[key] * r["vertices"] / 2**20 for r in vrows], "o-", label=f"{label}  ~V^{fits[fit]:.2f}")
    ax[1].axhline(2048, color="grey", ls=":", lw=1)
    ax[1].set(xlabel="vertices", ylabel="MiB", title="peak memory (2 GiB dotted)")
    S = [r["samples"] for r in srows]
    ax[2].loglog(S, [r["bake_s"] for r in srows], "o-", label=f"bake  ~S^{fits['samples_bake_s']:.2f}")
    ax[2].set(xlabel="light samples", ylabel="seconds", title=f"bake, floor {srows[0]['floor'] if srows else ''}")
    for a in ax:
        a.legend(fontsize=8)
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=110)


def main():
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--floors", type=int, nargs="+", default=None, metavar="N",
                   help="floor resolutions of the vertex sweep (default 200 380 700 1000 1400; quick: 40 100)")
    p.add_argument("--sample-floor", type=int, default=None, metavar="N",
                   help="floor resolution of the sample sweep (default 200; quick: 40)")
    p.add_argument("--budget", type=float, default=900.0, metavar="SECONDS",
                   help="start no new floor of the vertex sweep after this many seconds (default 900)")
    p.add_argument("--child", nargs=2, metavar=("KIND", "FLOOR"), help=argparse_hidden())
    args = p.parse_args()
    if args.child:
        print(json.dumps(child(args.child[0], int(args.child[1]))))
        return
    device = args.device or "cpu"
    floors = args.floors or ([40, 100] if args.quick else [200, 380, 700, 1000, 1400])
    sfloor = args.sample_floor or (40 if args.quick else 200)
    grids = [[1, 1, 1], [2, 1, 1]] if args.quick else [[3, 1, 3], [3, 3, 3], [9, 1, 9], [9, 3, 9], [9, 9, 9]]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        vrows = vertex_sweep(floors, device, args.budget, t0, Path(d))
        srows = sample_sweep(sfloor, grids, device, Path(d))
        wrows = worker_sweep(sfloor, [3, 3, 3] if not args.quick else [2, 1, 1], device, Path(d))
    V = [r["vertices"] for r in vrows]
    fits = {k: exponent(V, [r[k] for r in vrows]) for k in ("hierarchy_s", "pymeshlab_s", "bake_s", "meshopt_s")}
    fits["hierarchy_bytes"] = exponent(V, [r["hierarchy_b_per_v"] * r["vertices"] for r in vrows])  # above the start
    fits["bake_bytes"] = exponent(V, [r["bake_b_per_v"] * r["vertices"] for r in vrows])  # whole peak
    fits["samples_bake_s"] = exponent([r["samples"] for r in srows], [r["bake_s"] for r in srows])
    fits["runtime_bytes"] = exponent(V, [r["runtime_mib"] for r in vrows])
    fits["samples_runtime_bytes"] = exponent([r["samples"] for r in srows], [r["runtime_mib"] for r in srows])
    print(table(vrows, [("floor", "floor", "d"), ("vertices", "vertices", ","), ("hierarchy_s", "hierarchy s", ".1f"),
                        ("pymeshlab_s", "halving s", ".1f"), ("ratio", "x halving", ".2f"),
                        ("meshopt_s", "meshopt s", ".3f"), ("x_meshopt", "x meshopt", ".1f"),
                        ("hierarchy_b_per_v", "build B/v", ".0f"), ("pymeshlab_b_per_v", "halving B/v", ".0f"),
                        ("bake_s", "bake s", ".1f"), ("bake_peak_mib", "bake peak MiB", ".0f"),
                        ("bake_b_per_v", "bake B/v", ".0f"), ("open_s", "open s", ".1f"),
                        ("first_frame_s", "1st frame s", ".1f"), ("runtime_mib", "run time MiB", ".0f")]))
    print(table(srows, [("floor", "floor", "d"), ("grid", "grid", "s"), ("samples", "samples", "d"),
                        ("bake_s", "bake s", ".1f"), ("bake_peak_mib", "peak MiB", ".0f"),
                        ("store_mib", "store MiB", ".1f"), ("open_s", "open s", ".1f"),
                        ("first_frame_s", "1st frame s", ".1f"), ("runtime_mib", "run time MiB", ".0f"),
                        ("runtime_completed", "completed", "d")]))
    print(table(wrows, [("floor", "floor", "d"), ("samples", "samples", "d"), ("mode", "bake", "s"),
                        ("bake_s", "seconds", ".1f"), ("client_peak_mib", "client peak MiB", ".0f")]))
    print("fitted exponents (time or memory ~ size^e):", ", ".join(f"{k} {v:.2f}" for k, v in fits.items()))
    name = "scale" + ("-quick" if args.quick else "")
    print("wrote", write(name, {"benchmark": "scale", "quick": args.quick, "environment": environment(device),
                                "cores": os.cpu_count(), "vertex_rows": vrows, "sample_rows": srows,
                                "worker_rows": wrows,
                                "exponents": fits, "seconds": time.perf_counter() - t0}, args.json))
    plot(name, vrows, srows, fits)
    print("wrote", plot_path(name))


def argparse_hidden():
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    main()
