"""Ten million vertices end to end on one machine: bake, ``lodprt frames`` and ``lodprt view``, peak memory each.

    python benchmarks/ten_million.py [--quick] [--floor N] [--frames N] [--keep DIR] [--json PATH]

Scene: the Stanford bunny on an N x N floor (default N = 3162: 10,034,191 vertices, 20.05M triangles; quick:
N = 100), 3 x 3 x 3 light samples, every setting at its default (SH order 4, light cut 5 degrees, the screen
criterion steered to its 36 dB frame target). Each step is the user's command in a child process (``python -m
lodprt ...``), timed by the wall clock around it; its peak resident memory is the child's ``ru_maxrss`` from
``os.wait4`` (what ``/usr/bin/time -v`` prints), the yardstick of issue 25 (the bake at most 12 GB, ``frames`` at
most 1 KB per vertex):

* ``bake``: ``lodprt bake SCENE.toml -o OUT.zarr``;
* ``frames``: ``lodprt frames OUT.zarr --frames F --json`` (the default orbit at 800 x 600: opening the store,
  completing the samples the moving light needs, the view cut each frame; its summary keeps the frame times and,
  apart, the samples setting the lights completed and their seconds);
* ``view``: ``lodprt view OUT.zarr --path orbit --frames F --screenshot PNG`` in a window under ``xvfb-run`` when
  it is installed, else ``--headless`` (the same loop, run-time frames and overlay on an EGL context, no window);
  the results say which (``view_mode``). The window plays the path ``frames`` times, its light moving the same
  way, completing the same samples with the window's notice up while it waits; the viewer's closing summary
  (``view_path``: median update and draw, the samples completed and their seconds, the longest wait) is kept,
  with the seconds its run time took to open (``open_seconds``, as in ``frames``' summary).

Writes benchmarks/results/ten_million[-quick].json, .png (bytes per vertex of each step against the 1 KB line) and
-view.png (the viewer's screenshot).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import environment, model, parser, plot_path, table, write

#: issue 25's lines: the bake's peak (bytes) and the run time's peak per vertex
BAKE_LIMIT = 12e9
RUN_LIMIT_PER_VERTEX = 1024


def measured(cmd: list[str], cwd: Path, stdout=None) -> dict:
    """Run ``cmd``; its wall seconds and peak resident bytes (``ru_maxrss`` of this child and the processes it
    waited for, from ``os.wait4``: what ``/usr/bin/time -v`` prints). A failure stops the benchmark, naming it."""
    with tempfile.TemporaryFile("w+") as err:
        t = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=stdout or subprocess.DEVNULL, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            raise SystemExit(f"ten_million: {' '.join(cmd)} failed (exit {proc.returncode}):\n{err.read()[-3000:]}")
    return {"seconds": wall, "peak_bytes": usage.ru_maxrss * 1024}


#: the line ``lodprt view --path`` prints when it closes (``lodprt.display.playback.summary_line``)
PATH_LINE = re.compile(r"path (?P<path>\w+): (?P<frames>\d+) frames, median update (?P<median_ms_update>[0-9.]+) ms "
                       r"and draw (?P<median_ms_draw>[0-9.]+) ms after the first \((?P<first_frame_ms>[0-9.]+) ms\); "
                       r"setting the lights completed (?P<samples_completed>\d+) light samples in "
                       r"(?P<lights_seconds>[0-9.]+) s \(longest frame's (?P<max_seconds_lights>[0-9.]+) s\)")


#: the line ``lodprt view`` prints once the store is open
OPEN_LINE = re.compile(r"lodprt view: .* opened in (?P<open_seconds>[0-9.]+) s - ")


def view_path(stdout: str) -> dict:
    """The numbers of the viewer's closing path summary in ``stdout``, and the seconds its opening took (a
    failure names what was printed)."""
    m, opened = PATH_LINE.search(stdout), OPEN_LINE.search(stdout)
    if m is None or opened is None:
        raise SystemExit(f"ten_million: no {'path summary' if m is None else 'opening time'} in lodprt view's "
                         f"output:\n{stdout[-2000:]}")
    return {**{k: (v if k == "path" else float(v)) for k, v in m.groupdict().items()},
            "open_seconds": float(opened["open_seconds"])}


def scene_file(folder: Path, floor: int) -> Path:
    path = folder / "scene.toml"
    mesh = model("stanford-bunny").as_posix()
    path.write_text(f'[[object]]\nmesh = "{mesh}"\n\n[floor]\nresolution = {floor}\n\n[lights]\ngrid = [3, 3, 3]\n')
    return path


def run(folder: Path, floor: int, frames: int, name: str) -> dict:
    lodprt = [sys.executable, "-m", "lodprt"]
    scene = scene_file(folder, floor)
    out = folder / "out.zarr"
    steps = {}
    steps["bake"] = measured(lodprt + ["bake", str(scene), "-o", str(out)], folder)
    from lodprt.store.bake_store import open_store

    store = open_store(out)
    V, F = store.num_vertices, int(store.root["scene/faces"].shape[0])
    del store
    store_bytes = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    with open(folder / "frames.json", "w") as fh:
        steps["frames"] = measured(lodprt + ["frames", str(out), "--frames", str(frames), "--json"], folder, fh)
    summary = json.loads((folder / "frames.json").read_text())["summary"]
    xvfb = shutil.which("xvfb-run")
    shot = folder / "view.png"
    view = lodprt + ["view", str(out), "--path", "orbit", "--frames", str(frames), "--screenshot", str(shot)]
    with open(folder / "view.txt", "w") as fh:
        if xvfb:
            steps["view"] = measured([xvfb, "-a", "-s", "-screen 0 1024x768x24"] + view, folder, fh)
        else:  # no X server: the same viewer loop on an EGL context
            steps["view"] = measured(view + ["--headless"], folder, fh)
    steps["view"]["path"] = view_path((folder / "view.txt").read_text())
    if shot.is_file():  # the viewer's last frame, kept beside the results
        shutil.copyfile(shot, plot_path(f"{name}-view"))
    steps["view"]["screenshot"] = shot.is_file()
    for s in steps.values():
        s["bytes_per_vertex"] = s["peak_bytes"] / V
    return {"vertices": V, "triangles": F, "store_bytes": store_bytes, "steps": steps,
            "view_mode": "window under xvfb-run" if xvfb else "headless (EGL)",
            "frames_summary": {k: summary[k] for k in ("median_ms", "p95_ms", "first_frame_ms", "median_triangles",
                                                      "full_triangles", "error_bound", "target_psnr", "samples_completed",
                                                      "samples_completed_at_open", "lights_seconds", "max_ms_lights",
                                                      "sample_cache_slots", "light_samples", "open_seconds")}}


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(res["steps"])
    vals = [res["steps"][k]["bytes_per_vertex"] for k in names]
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    ax.bar(names, vals, color=["#4c72b0", "#dd8452", "#55a868"][: len(names)])
    ax.axhline(RUN_LIMIT_PER_VERTEX, color="k", ls="--", lw=1, label="1 KB per vertex (run time)")
    ax.axhline(BAKE_LIMIT / res["vertices"], color="r", ls=":", lw=1, label="12 GB (bake)")
    ax.set_ylabel("peak resident bytes per vertex")
    ax.set_title(f"{res['vertices']:,} vertices, 27 samples, defaults")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    p = parser(__doc__.splitlines()[0])
    p.add_argument("--floor", type=int, default=None, help="floor resolution N (default 3162; quick 100)")
    p.add_argument("--frames", type=int, default=10, help="frames of the default orbit (default 10)")
    p.add_argument("--keep", metavar="DIR", default=None, help="bake into DIR and keep the store (default: a "
                   "temporary folder, removed)")
    args = p.parse_args()
    floor = args.floor or (100 if args.quick else 3162)
    name = "ten_million" + ("-quick" if args.quick else "")
    t0 = time.perf_counter()
    if args.keep:
        folder = Path(args.keep)
        folder.mkdir(parents=True, exist_ok=True)
        res = run(folder, floor, args.frames, name)
    else:
        with tempfile.TemporaryDirectory(prefix="lodprt-10m-") as tmp:
            res = run(Path(tmp), floor, args.frames, name)
    res.update({"benchmark": "ten_million", "quick": args.quick, "floor": floor, "frames": args.frames,
                "environment": environment("cpu"), "cores": len(os.sched_getaffinity(0)),
                "seconds": time.perf_counter() - t0})
    rows = [{"step": k, "s": v["seconds"], "peak GB": v["peak_bytes"] / 1e9, "B/vertex": v["bytes_per_vertex"]}
            for k, v in res["steps"].items()]
    print(f"{res['vertices']:,} vertices, {res['triangles']:,} triangles, store {res['store_bytes'] / 1e6:.0f} MB")
    print(table(rows, [("step", "step", "s"), ("s", "seconds", ".1f"), ("peak GB", "peak GB", ".2f"),
                       ("B/vertex", "bytes per vertex", ".0f")]))
    print(f"view: {res['view_mode']}")
    fs = res["frames_summary"]
    print(f"frames: median {fs['median_ms']:.0f} ms a frame after the first ({fs['first_frame_ms'] / 1e3:.1f} s); "
          f"setting the lights completed {fs['samples_completed']} light samples along the path in "
          f"{fs['lights_seconds']:.1f} s (longest frame's {fs['max_ms_lights'] / 1e3:.1f} s), "
          f"{fs['samples_completed_at_open']} at open; {fs['sample_cache_slots']} cache slots for "
          f"{fs['light_samples']} samples; opening the store took {fs['open_seconds']:.1f} s")
    vp = res["steps"]["view"]["path"]
    print(f"view: opened in {vp['open_seconds']:.1f} s; "
          f"{vp['frames']:.0f} frames of the orbit, median update {vp['median_ms_update']:.0f} ms and draw "
          f"{vp['median_ms_draw']:.0f} ms ({vp['first_frame_ms'] / 1e3:.1f} s the first); its light completed "
          f"{vp['samples_completed']:.0f} samples in {vp['lights_seconds']:.1f} s (longest frame's "
          f"{vp['max_seconds_lights']:.1f} s)")
    plot(res, plot_path(name))
    print(f"wrote {write(name, res, args.json)}")


if __name__ == "__main__":
    main()
