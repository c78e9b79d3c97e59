"""Bake memory against the number of light samples (issue 25: flat from 9 to 729 samples within 10%), and the
default white's cost when a Runtime opens a many-sample store (recorded at bake time, or the scan of every sample).

    python benchmarks/bake_memory.py [--quick] [--json PATH]

Scene: spot on a 20 x 20 floor (3,330 vertices), SH order 4, the default 5-degree light cut, CPU device, 2
threads; light grids 3 x 1 x 3, 9 x 1 x 9 and 9 x 9 x 9 (9, 81, 729 samples; quick: 1, 3 and 9). Every bake runs
in a fresh child process, which reports its own peak resident memory (``VmHWM``) and its resident size before the
bake (Python, numpy, Warp and the kernels loaded). After the biggest bake a child times ``default_white`` of its
store with the recorded ``default_white`` and with the scan of every sample's rows (the record hidden), and checks
that the two are equal. Writes benchmarks/results/bake_memory[-quick].json and .png.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

from common import environment, model, parser, plot_path, table, write

GRIDS = [[3, 1, 3], [9, 1, 9], [9, 9, 9]]
QUICK_GRIDS = [[1, 1, 1], [3, 1, 1], [3, 1, 3]]
FLOOR = 20

BAKE_CHILD = """
import json, sys, time
status = lambda key: int([ln for ln in open("/proc/self/status") if ln.startswith(key + ":")][0].split()[1]) * 1024
from lodprt.devices import load_kernels
from lodprt.model.scene import load_scene
from lodprt.precompute.bake import bake
from lodprt.precompute.baker import bake_kernels
scene = load_scene(sys.argv[1])
load_kernels("cpu", *bake_kernels())
before = status("VmRSS")
t = time.perf_counter()
res = bake(scene, sys.argv[2], device="cpu", jobs=2)
print(json.dumps({"seconds": time.perf_counter() - t, "rss_before": before, "peak": status("VmHWM"),
                  "vertices": scene.num_vertices, "samples": len(res.samples)}))
"""

WHITE_CHILD = """
import json, sys, time
from lodprt.runtime.samples import default_white
from lodprt.store.bake_store import open_store
from lodprt.store.white import WHITE
a, b = open_store(sys.argv[1]), open_store(sys.argv[1])
b.attrs.pop(WHITE)
t = time.perf_counter()
recorded = default_white(a)
t1 = time.perf_counter()
scanned = default_white(b)
t2 = time.perf_counter()
print(json.dumps({"recorded_s": t1 - t, "scan_s": t2 - t1, "recorded": recorded, "scanned": scanned}))
"""


def child(code: str, *args) -> dict:
    out = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{out.stderr[-4000:]}\nchild failed with status {out.returncode}")
    return json.loads([ln for ln in out.stdout.splitlines() if ln.startswith("{")][-1])


def scene_file(folder: Path, grid: list[int]) -> Path:
    path = folder / f"spot-{'x'.join(map(str, grid))}.toml"
    path.write_text(f'[[object]]\nmesh = "{model("spot").as_posix()}"\n[floor]\nresolution = {FLOOR}\n'
                    f"[lights]\ngrid = {grid}\n")
    return path


def main(argv=None) -> None:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    grids = QUICK_GRIDS if args.quick else GRIDS
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for grid in grids:
            store = Path(tmp) / f"{'x'.join(map(str, grid))}.zarr"
            r = child(BAKE_CHILD, scene_file(Path(tmp), grid), store)
            rows.append({"grid": "x".join(map(str, grid)), "samples": r["samples"], "vertices": r["vertices"],
                         "bake_s": r["seconds"], "peak_mib": r["peak"] / 2**20,
                         "before_mib": r["rss_before"] / 2**20, "above_mib": (r["peak"] - r["rss_before"]) / 2**20})
        white = child(WHITE_CHILD, store)
    base = rows[0]["peak_mib"]
    for row in rows:
        row["vs_first"] = row["peak_mib"] / base
    white["samples"] = rows[-1]["samples"]
    print(table(rows, [("grid", "grid", ""), ("samples", "samples", "d"), ("bake_s", "bake s", ".1f"),
                       ("peak_mib", "peak MiB", ".0f"), ("above_mib", "above start MiB", ".1f"),
                       ("vs_first", "x first", ".3f")]))
    print(f"default_white at {white['samples']} samples: recorded {white['recorded_s'] * 1e3:.1f} ms, scan "
          f"{white['scan_s']:.2f} s, equal: {white['recorded'] == white['scanned']}")
    if white["recorded"] != white["scanned"]:
        sys.exit("bake_memory: the recorded default white differs from the scan")
    name = "bake_memory-quick" if args.quick else "bake_memory"
    results = {"benchmark": "bake_memory", "quick": args.quick, "floor": FLOOR, "rows": rows, "white": white,
               "environment": environment("cpu")}
    print(write(name, results, args.json))
    plot(rows, name)


def plot(rows: list[dict], name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    s = [r["samples"] for r in rows]
    ax.plot(s, [r["peak_mib"] for r in rows], "o-", label="peak (VmHWM)")
    ax.plot(s, [r["before_mib"] for r in rows], "s--", label="before the bake")
    ax.set_xscale("log")
    ax.set_ylim(0, max(r["peak_mib"] for r in rows) * 1.2)
    ax.set_xlabel("light samples")
    ax.set_ylabel("MiB")
    ax.set_title(f"bake memory, spot + {FLOOR}x{FLOOR} floor ({rows[0]['vertices']:,} vertices)")
    ax.legend()
    fig.tight_layout()
    path = plot_path(name)
    fig.savefig(path, dpi=100)
    print(path)


if __name__ == "__main__":
    main()
