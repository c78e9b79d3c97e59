"""One renderer per generated Markdown table: a results dict (``benchmarks/results/<name>.json``) -> a Markdown table.

``TABLES`` maps a marker name (``<!-- report:NAME -->`` in README.md or docs/*.md) to the results file it quotes and
its renderer. A renderer reads only its results dict: the table is what the JSON says, nothing typed by hand.
"""

from __future__ import annotations

import math


def md(headers: list[str], rows: list[list]) -> str:
    """A Markdown table (cells already formatted)."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def n(x) -> str:
    """An integer with thousands separators (rounded)."""
    return f"{round(x):,}"


def f(x, digits: int = 1) -> str:
    return f"{x:,.{digits}f}"


def g(x, sig: int = 3) -> str:
    """``sig`` significant digits, no exponent for ordinary sizes."""
    if x == 0:
        return "0"
    digits = max(0, sig - 1 - math.floor(math.log10(abs(x))))
    return f"{x:,.{digits}f}"


def pct(x, digits: int = 1) -> str:
    return f"{100 * x:.{digits}f}%"


def e4(x) -> str:
    """An error to 4 decimals; under 0.00005 it reads 0 (the rounding noise of an exact match)."""
    return "0" if abs(x) < 5e-5 else f"{x:.4f}"


def sci(x) -> str:
    """Two significant digits in exponent form: 1.7e-2."""
    mantissa, exponent = f"{x:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def ratio(x) -> str:
    return f"{x:.2f}x"


def render(r: dict) -> str:
    rows = [[row["size"].replace("x", " x "), row["mode"], row["shading"], n(row["triangles"]), f(row["update_ms"]),
             f(row["draw_ms"]), f(row["fps"])] for row in r["rows"]]
    return md(["size", "mode", "radiance per", "triangles", "update ms", "draw ms", "frames/s"], rows)


def _scene_label(scene: str, floor) -> str:
    return f"{'bunny' if scene == 'stanford-bunny' else scene} + {floor}"


def grid_db(row: dict) -> str:
    """A static row's E-3 on the grid, or "-" for results from before it was measured."""
    v = row.get("grid_psnr_db")
    return "-" if v is None or v != v else f"{v:.1f} dB"


def static_table(r: dict, family: str, label) -> str:
    """The static views of one scene family (rows without ``family`` are the shared models'), ``label(scene)``
    naming each scene: the default (at its target: x fewer, measured PSNR, estimated on every pixel as the frame
    was refined and on the grid of frames in motion), the screen
    criterion at a fixed 0.8 and T-14 (x fewer, PSNR)."""
    views = {}
    for v in r["static_views"]:
        if v.get("family", "shared") == family and v.get("light", "sample") == "sample":
            views.setdefault((v["scene"], v["view"]), {})[v.get("setting", v["criterion"].split()[0])] = v
    rows = []
    for (scene, view), by in views.items():
        d, s, t = by.get("default"), by["screen"], by["thesis"]
        rows.append([label(scene), view]
                    + ([] if d is None else [f"{n(d['triangles'])} / {n(d['full'])}", g(d["fewer"], 2),
                                             f"{d['psnr_db']:.1f} dB", f"{d['estimated_psnr_db']:.1f} dB",
                                             grid_db(d)])
                    + [g(s["fewer"], 2), f"{s['psnr_db']:.1f} dB", g(t["fewer"], 2), f"{t['psnr_db']:.1f} dB"])
    head = ["scene", "view"]
    if any("default" in by for by in views.values()):
        head += ["default: triangles / full", "x fewer", "PSNR", "estimated (E-3)", "on the grid"]
    head += ["screen 0.8 fixed: x fewer", "PSNR", "thesis 0.25: x fewer", "PSNR"]
    return md(head, rows)


def view_cut_static(r: dict) -> str:
    return static_table(r, "shared", lambda scene: _scene_label(scene, r["floor"]))


#: what a table of the procedural scenes reads before a run has measured them
NOT_MEASURED = "Not measured yet: run `python benchmarks/view_cut.py` (the full run measures the procedural scenes too)."


def view_cut_procedural(r: dict) -> str:
    """The static views on benchmarks/procedural.py's scenes (each on its own floor)."""
    if not any(v.get("family") == "procedural" for v in r["static_views"]):
        return NOT_MEASURED
    return static_table(r, "procedural", str)


def view_cut_between(r: dict) -> str:
    """The default's static views with the light between samples (every scene, both families)."""
    rows = [[_scene_label(v["scene"], r["floor"]) if v.get("family", "shared") == "shared" else v["scene"],
             v["view"], v["light"], f"{n(v['triangles'])} / {n(v['full'])}", g(v["fewer"], 2),
             f"{v['psnr_db']:.1f} dB", f"{v['estimated_psnr_db']:.1f} dB",
             grid_db(v)]
            for v in r["static_views"] if v.get("light", "sample") != "sample"]
    if not rows:
        return NOT_MEASURED
    return md(["scene", "view", "light", "default: triangles / full", "x fewer", "PSNR", "estimated (E-3)",
               "on the grid"], rows)


def view_cut_summary(r: dict) -> str:
    """Per criterion, the worst PSNR and the least "x fewer" over every scene (both families) and view."""
    if "static_summary" not in r:
        return NOT_MEASURED
    rows = [[s["criterion"], s["rows"], f"{s['worst_psnr_db']:.1f} dB", s["worst_psnr_at"],
             g(s["least_fewer"], 2), s["least_fewer_at"]] for s in r["static_summary"]]
    return md(["criterion", "views", "worst PSNR", "at", "least x fewer", "at"], rows)


def view_cut(r: dict) -> str:
    full = {row["scene"]: row for row in r["rows"] if row["criterion"] == "full mesh"}
    rows, shown = [], set()
    for row in r["rows"]:
        if row["criterion"] == "full mesh":
            continue
        scene, first = row["scene"], row["scene"] not in shown
        shown.add(scene)
        tri = n(row["median_triangles"]) + (f" / {n(full[scene]['median_triangles'])}" if first else "")
        ms = f(row["median_ms"]) + (f" ({f(full[scene]['median_ms'])})" if first else "")
        what = row["criterion"] if row["error_bound"] != row["error_bound"] else \
            f"{row['criterion']} {row['error_bound']:g}"  # the default's bound is steered (NaN)
        rows.append([_scene_label(scene, r["floor"]), what, tri, ms,
                     ratio(row["speedup"]), f"{row['median_psnr_db']:.1f} dB"])
    return md(["scene", "criterion, bound", "triangles / full", "median ms (full mesh)", "vs full", "median PSNR"],
              rows)


def runtime(r: dict) -> str:
    rows = []
    for p in r["paths"]:
        full = p["mode"] == "full mesh"
        rows.append([p["path"], p["mode"], n(p["median_triangles"]), "0" if full else f(p["median_ms_cut"]),
                     f(p["median_ms_triangulate"]), f(p["median_ms_relight"]), f(p["median_ms_total"]),
                     f(p["p95_ms_total"]), "1" if full else f"{p['speedup']:.2f}x", f(p["mean_ms_total"]),
                     "1" if full else f"{p['mean_speedup']:.2f}x"])
    return md(["path", "mode", "triangles", "cut ms", "triangulation ms", "relight ms", "median ms", "p95 ms",
               "vs full (median)", "mean ms", "vs full (mean)"], rows)


def runtime_cli(r: dict) -> str:
    rows = [[c["store"], c["pair"] + 1, f"{n(c['triangles'])} / {n(c['full_triangles'])}", f(c["default_median_ms"]),
             f(c["full_median_ms"]), f"{c['ratio']:.2f}x", f(c["default_mean_ms"]), f(c["full_mean_ms"]),
             f"{c['mean_ratio']:.2f}x"] for c in r["cli"]]
    return md(["store", "pair", "triangles / full", "`frames` median ms", "`frames --full` median ms", "ratio",
               "`frames` mean ms", "`--full` mean ms", "ratio of means"], rows)


def runtime_sweep(r: dict) -> str:
    rows = [[f"{s['error_bound']:g}", n(s["median_triangles"]), n(s["thesis_triangles"]), f(s["median_ms"]),
             f"{s['rel_rmse']:.3f}"] for s in r["sweep"]]
    return md(["error bound", "triangles", "thesis figures 21-24", "median ms", "image rRMSE"], rows)


def runtime_budgets(r: dict) -> str:
    rows = []
    for b in r["budgets"]:
        budget = "none" if b["frame_ms"] is None else f"{b['budget']}: {f(b['frame_ms'])} ms"
        met = "" if b["met"] is None else f"{100 * b['met']:.0f}%"
        est = "" if b["median_estimated_psnr_db"] is None else f"{b['median_estimated_psnr_db']:.1f}"
        rows.append([budget, f(b["median_ms"]), f"{b['ratio']:.2f}x", f(b["mean_ms"]), f"{b['mean_ratio']:.2f}x", met,
                     n(b["median_triangles"]), f"{b['median_bound']:.3g}", f"{b['median_psnr_db']:.1f}",
                     f"{b['min_psnr_db']:.1f}", est])
    return md(["frame-time budget (B-2)", "median ms", "vs full (median)", "mean ms", "vs full (mean)",
               "timed frames within it", "triangles", "median bound", "PSNR dB (median)", "PSNR dB (worst)",
               "E-3 dB (median)"], rows)


def light_spacing(r: dict) -> str:
    rows = [[row["grid"], n(row["samples"]), f"{row['spacing']:.3f}", f(row["bake_s"], 2), f(row["mib"]),
             pct(row["rmse_between"], 0), pct(row["rmse_between_t12"], 0), pct(row["rmse_on_samples"]),
             pct(row["rmse_edges"], 0)] for row in r["rows"]]
    return md(["grid", "samples", "spacing", "bake s", "MiB", "between samples", "between, T-12 as printed",
               "on samples", "shadow edges"], rows)


def hierarchy(r: dict) -> str:
    label = {"sequential": "`sequential` (default)", "rounds": "`rounds`",
             "meshopt 1/2": "meshoptimizer `simplify`, one halving",
             "pymeshlab": "`pymeshlab` (2 worker processes)",
             "pymeshlab-1p": "`pymeshlab` (`workers=1`, in process)", "QEM only": "pymeshlab alone, to the same base"}
    rows = []
    for row in r["rows"]:
        mem = ""
        if "bytes_per_vertex" in row:
            mem = n(row["bytes_per_vertex"]) + (f" (+ {n(row['worker_mib'])} MiB per worker)"
                                                 if row.get("worker_mib") else "")
        view = (f"{n(row['view_triangles'])} triangles, {row['psnr_db']:.1f} dB" if "view_triangles" in row else "")
        rows.append([row["mesh"].replace("x", " x "), label.get(row["method"], row["method"]), f(row["build_s"], 2),
                     f(row["x_meshopt"], 1) if "x_meshopt" in row else "", mem, n(row["roots"]) if "roots" in row else "", row.get("depth", ""),
                     n(row["light_cut_vertices"]) if "light_cut_vertices" in row else "", view])
    return md(["mesh", "build", "build s", "x meshopt 1/2", "peak B/vertex", "roots", "depth", "5-degree light cut (vertices)",
               "view cut at the screen bound 0.8, one view"], rows)


def scale_hierarchy(r: dict) -> str:
    rows = [[row["floor"], n(row["vertices"]), f(row["hierarchy_s"]), f(row["pymeshlab_s"]), f(row["ratio"], 2),
             f(row["meshopt_s"], 2), f(row["x_meshopt"], 1), n(row["hierarchy_b_per_v"]), n(row["pymeshlab_b_per_v"]), n(row["roots"]), row["depth"], row["rounds"]]
            for row in r["vertex_rows"]]
    return md(["floor", "vertices", "hierarchy s", "halving s", "x halving", "meshopt 1/2 s", "x meshopt 1/2",
               "build B/vertex", "halving B/vertex",
               "roots", "depth", "rounds"], rows)


def scale_bake(r: dict) -> str:
    rows = [[row["floor"], n(row["vertices"]), f(row["bake_s"]), f(row["bake_hierarchy_s"]), n(row["bake_peak_mib"]),
             n(row["bake_b_per_v"])] for row in r["vertex_rows"]]
    return md(["floor", "vertices", "bake s", "of which hierarchy s", "peak MiB", "bytes per vertex"], rows)


def scale_samples(r: dict) -> str:
    rows = [[row["grid"], row["samples"], f(row["bake_s"]), n(row["bake_peak_mib"]), f(row["store_mib"])]
            for row in r["sample_rows"]]
    return md(["grid", "samples", "bake s", "peak MiB", "store MiB"], rows)


def scale_runtime(r: dict) -> str:
    both = [row for row in r["sample_rows"]] + [row for row in r["vertex_rows"] if row["floor"] != 200]
    rows = [[row["floor"], row["samples"], f(row["open_s"]), f(row["first_frame_s"]), n(row["runtime_mib"]),
             row["runtime_completed"]] for row in both if "open_s" in row]
    return md(["floor", "samples", "open s", "first frame s", "run-time MiB", "samples completed"], rows)


def bake_memory(r: dict) -> str:
    rows = [[row["grid"], row["samples"], f(row["bake_s"]), n(row["before_mib"]), n(row["peak_mib"]),
             f(row["vs_first"], 3)] for row in r["rows"]]
    return md(["grid", "samples", "bake s", "before MiB", "peak MiB", "peak / first"], rows)


def bake_memory_white(r: dict) -> str:
    w = r["white"]
    return md(["samples", "recorded attribute ms", "scan of every sample s", "equal"],
              [[w["samples"], f(w["recorded_s"] * 1e3, 2), f(w["scan_s"], 2), "yes" if w["recorded"] == w["scanned"]
                else "no"]])


def scale_workers(r: dict) -> str:
    rows = [[row["mode"] if row["mode"] == "in-process" else f"`{row['mode']}`", f(row["bake_s"]),
             n(row["client_peak_mib"])] for row in r["worker_rows"]]
    return md(["bake", "seconds (command, cluster start included)", "client peak MiB"], rows)


def ten_million(r: dict) -> str:
    what = {"bake": "`lodprt bake scene.toml -o out.zarr`",
            "frames": f"`lodprt frames out.zarr --frames {r['frames']} --json`",
            "view": f"`lodprt view out.zarr --path orbit --frames {r['frames']} --screenshot view.png` "
                    + ("(headless, EGL)" if r.get("view_mode", "").startswith("headless") else "(Xvfb)")}
    limit = {"bake": "12 GB", "frames": "1 KB per vertex", "view": "-"}
    rows = [[what[k], f(v["seconds"]), g(v["peak_bytes"] / 1e9), n(v["bytes_per_vertex"]), limit[k]]
            for k, v in r["steps"].items()]
    return md(["{:,} vertices, 27 samples, defaults".format(r["vertices"]), "seconds", "peak GB",
               "peak bytes per vertex", "issue 25's line"], rows)


def gi(r: dict) -> str:
    rows = [[row["bounces"], row["rays"] if row["bounces"] else "-", g(row["full_s"]), g(row["lod_s"]),
             g(row["ratio"]), n(row["gathered"]), e4(row["full_err"]), e4(row["lod_err"]), e4(row["lod_vs_full"])]
            for row in r["rows"]]
    return md(["bounces", "rays", "full s", "LOD s", "LOD / full", "gathered vertices", "full err", "LOD err",
               "LOD vs full"], rows)


def gi_floors(r: dict) -> str:
    rows = [[n(row["floor"]), n(row["vertices"]), row["cut"], g(row["setting"]), g(row["full_s"]), g(row["lod_s"]),
             g(row["ratio"]) + (f" ({g(row['ratio_min'])}-{g(row['ratio_max'])})" if "ratio_min" in row else ""),
             n(row["gathered"]), e4(row["lod_vs_full"]), e4(row["bunny_part"]), e4(row["floor_part"])]
            for row in r["rows"]]
    return md(["floor", "vertices", "cut", "setting", "full s", "LOD s", "LOD / full (range)", "gathered per pass",
               "LOD vs full", "bunny part", "floor part"], rows)


def gi_estimate(r: dict) -> str:
    rows = [[n(row["floor"]), g(row["tolerance"]), g(row["stated_max"]), g(row["actual_max"]),
             f"{row['over_min']:.2f}-{row['over_max']:.2f}", f"{100 * row['dark_share']:.0f} %"]
            for row in r.get("estimate_check", [])]
    return md(["floor", "G-9 tolerance", "stated RMS (largest sample)", "actual RMS (largest sample)",
               "actual / stated (samples)", "of the squared error where the full pass is dark"], rows)


def gi_mitsuba(r: dict) -> str:
    m = r["mitsuba"]
    names = {"direct": "direct only", "gi_full": "2 bounces, 128 rays, full resolution",
             "gi_lod": "2 bounces, 128 rays, LOD"}
    rows = [[label, f"{m[k + '_psnr']:.2f} dB", f"{m[k + '_psnr_foreground']:.1f} dB",
             f"{100 * m[k + '_shadow_mean_rel']:.3g}%"] for k, label in names.items()]
    return md(["lodprt", "PSNR", "PSNR, object pixels",
               f"mean radiance in the direct shadows ({n(m['shadow_pixels'])} px) vs Mitsuba"], rows)


def volume(r: dict) -> str:
    names = {0: "shadowed: us/voxel, error", 1: "+ 1 scattering pass", 2: "+ 2 scattering passes"}
    rays = sorted({t["rays"] for t in r["transfer"]})
    cells = {(t["bounces"], t["rays"]): f"{n(t['us_per_voxel'])}, {sci(t['error_vs_ref'])}" for t in r["transfer"]}
    bounces = sorted({t["bounces"] for t in r["transfer"]})
    rows = [[names.get(b, f"+ {b} passes")] + [cells.get((b, k), "") for k in rays] for b in bounces]
    return md(["passes"] + [f"{k} rays" for k in rays], rows)


def neighbourhood(r: dict) -> str:
    rows = [[f"{row['grid']}^3" + (" + reflection" if row["reflection"] else ""), f(row["grid_s"], 2), f(row["mib"]),
             pct(row["rms_error"]), pct(row["max_error"], 0), g(row["grid_ms"]), g(row["receiver_ms"])]
            for row in r["rows"]]
    return md(["grid", "matrices s", "MiB", "RMS error", "worst error", "N-3 ms", "N-4, N-5 ms"], rows)


def environment_transfer(r: dict) -> str:
    rows = [[row["mode"], row["bounces"], row["rays"], f(row["warp_us_per_vertex"]), f"{row['error_vs_ref']:.4f}",
             f(row["numpy_embree_s"], 2), f(row["warp_s"], 2), f(row["ratio"], 2)] for row in r["transfer"]]
    return md(["mode", "bounces", "rays", "us/vertex", f"error vs {r['reference_rays']} rays", "numpy + Embree s",
               "Warp s", "numpy / Warp"], rows)


def environment_lod(r: dict) -> str:
    rows = [[f"{row['threshold']:g}", n(row["vertices_kept"]), pct(row["fraction"]), n(row["kib"]),
             f(row["cut_s"], 2), f(row["complete_s"], 2), pct(row["relit_error"], 2)] for row in r["lod"]]
    return md(["threshold", "vertices kept", "of all", "KiB", "cut s", "completion s", "relit error"], rows)


def table1(r: dict) -> str:
    rows = [[row["threshold"], n(row["vertices"]), f(row["reduction"]), n(row["kib"]), n(row["thesis_vertices"]),
             n(row["thesis_kib"]), f(row["bake_s"], 2), e4(row["rmse_all"]), f"{row['max_all']:.3f}",
             e4(row["exact_rmse"]), f"{row['boundary']:.3f}"] for row in r["rows"]]
    return md(["threshold (degrees)", "mean vertices", "reduction", "KiB/sample", "thesis vertices", "thesis KB",
               "bake s", "rRMSE vs full", "rMax vs full", "rRMSE vs exact", "rRMSE shadow edges"], rows)


def bake(r: dict) -> str:
    rows = [[row["bake"], f(row["seconds"], 2), f(row["per_sample_ms"]), n(row["per_vertex_ns"]),
             f(row["speedup_vs_numpy"], 2), n(row["kib_per_sample"])] for row in r["rows"]]
    return md(["bake", "seconds", "ms per sample", "ns per vertex and sample", "x numpy + Embree", "KiB per sample"],
              rows)


def visibility(r: dict) -> str:
    s = r["summary"]
    rows = [["Warp any-hit, 1 thread", n(s["rays"]), f(s["warp_mrays_per_s"], 2), f(s["warp_bvh_build_s"], 2)],
            [f"Warp any-hit, {s['warp_threads']} threads", n(s["rays"]), f(s["warp_threaded_mrays_per_s"], 2), ""],
            ["Embree", n(s["rays"]), f(s["embree_mrays_per_s"], 2), f(s["embree_build_s"], 2)]]
    table = md(["shadow rays", "rays", "Mrays/s", "build s"], rows)
    return table + f"\n\nLargest disagreement between the two per sample: {pct(s['max_disagreement'], 3)} of the rays."


def compression(r: dict) -> str:
    def err(x):
        return "-" if x != x else f"{x:.4f}"

    rows = [[f"`{row['codec']}`", n(row["payload_kib"]), n(row["disk_kib"]), f(row["ratio_disk"], 2),
             err(row["rel_rmse_store"]), err(row["rel_rmse_exact"]), f(row["seconds"], 1)] for row in r["rows"]]
    return md(["codec", "payload KiB/sample", "on disk KiB/sample", "x smaller on disk (vs cut)",
               "rRMSE vs cut store", "rRMSE vs exact", "encode s"], rows)


def moving_lights(r: dict) -> str:
    rows = [[f"{row['scene']} + {r['floor']} floor", f"`{row['method']}`",
             f"{pct(row['rrmse'], 2)} ({pct(row['rrmse_worst'], 2)})", pct(row["rrmse_on_samples"], 2),
             pct(row["off5"]), f(row["psnr_db"]), f"{f(row['ms'])} ({f(row['p95_ms'])})", f(row["ms_ratio"], 2)]
            for row in r["rows"] if row["grid"] == "3x1x3"]
    return md(["scene", "interpolation", "rRMSE between (median, worst light)", "on samples", "> 5% off", "PSNR dB",
               "ms/frame (p95)", "x thesis"], rows)


def moving_lights_mitsuba(r: dict) -> str:
    m = r["mitsuba"]
    order = ("direct", "direct-agree", "direct-blend", "thesis")
    methods = sorted({k.split("/")[1] for k in m if "/" in k and "@" not in k}, key=order.index)
    stores = [("full", "")] + [(f"light cut {c:g} deg", f"@{c:g}") for c in m.get("cuts", [])]
    rows = [[f"{label}, light {case}"] + [f(m[f"{case}/{meth}{at}"]) if f"{case}/{meth}{at}" in m else "-"
                                           for meth in methods]
            for label, at in stores for case in m["lights"]]
    return md(["bunny + {} floor, diffuse: store, light".format(m["floor"])] + [f"`{x}` dB" for x in methods], rows)


#: marker name -> (results file stem in benchmarks/results, renderer)
TABLES = {
    "render": ("render", render),
    "view_cut_static": ("view_cut", view_cut_static),
    "view_cut_procedural": ("view_cut", view_cut_procedural),
    "view_cut_summary": ("view_cut", view_cut_summary),
    "view_cut_between": ("view_cut", view_cut_between),
    "view_cut": ("view_cut", view_cut),
    "runtime": ("runtime", runtime),
    "runtime_cli": ("runtime", runtime_cli),
    "runtime_sweep": ("runtime", runtime_sweep),
    "runtime_budgets": ("runtime", runtime_budgets),
    "light_spacing": ("light_spacing", light_spacing),
    "hierarchy": ("hierarchy", hierarchy),
    "scale_hierarchy": ("scale", scale_hierarchy),
    "scale_bake": ("scale", scale_bake),
    "scale_samples": ("scale", scale_samples),
    "scale_runtime": ("scale", scale_runtime),
    "scale_workers": ("scale", scale_workers),
    "ten_million": ("ten_million", ten_million),
    "bake_memory": ("bake_memory", bake_memory),
    "bake_memory_white": ("bake_memory", bake_memory_white),
    "gi": ("gi", gi),
    "gi_mitsuba": ("gi", gi_mitsuba),
    "gi_floors": ("gi-floors", gi_floors),
    "gi_estimate": ("gi-floors", gi_estimate),
    "volume": ("volume", volume),
    "neighbourhood": ("neighbourhood", neighbourhood),
    "environment_transfer": ("environment", environment_transfer),
    "environment_lod": ("environment", environment_lod),
    "table1": ("table1", table1),
    "bake": ("bake", bake),
    "visibility": ("visibility", visibility),
    "compression": ("compression", compression),
    "moving_lights": ("moving_lights", moving_lights),
    "moving_lights_mitsuba": ("moving_lights-mitsuba", moving_lights_mitsuba),
}
