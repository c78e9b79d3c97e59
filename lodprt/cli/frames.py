"""``lodprt frames``: the view-dependent cut along a camera path, per-frame times and triangles (optionally the image
error against the full mesh), and what setting each frame's lights cost: the light samples completed on the way
(``ms_lights``, ``samples_completed``; not part of ``ms_total``, the frame's ``Runtime.update``)."""

from __future__ import annotations

import json
import math
import time

from lodprt.cli import args as cli_args
from lodprt.display.playback import light_costs
from lodprt.runtime.camera import PATH_FRAMES, PATHS

FRAME_KEYS = ("triangles", "active_nodes", "nodes_touched", "refined", "coarsened", "ms_cut", "ms_triangulate",
              "ms_relight", "ms_total", "shadow_rays",
              "estimated_psnr_db", "error_bound", "bound_floor")


def register(sub) -> None:
    """Add ``frames`` to ``sub`` (the subparsers object of the lodprt parser)."""
    fr = sub.add_parser(
        "frames",
        help="run the view-dependent cut along a camera path and report per-frame times and triangles",
        description="Move the camera along a path around the scene (orbit, or dolly toward the target) while the "
        "lights circle above it, update the run-time cut every frame (no drawing) and print per-frame "
        "milliseconds (cut update, triangulation, relighting; apart: setting the lights, which completes the light "
        "samples they reach that the sample cache does not hold) and triangle counts.",
    )
    cli_args.add_store(fr)
    fr.add_argument("--path", choices=PATHS, default=PATHS[0], help=f"camera path (default {PATHS[0]})")
    fr.add_argument("--frames", type=int, default=PATH_FRAMES, metavar="N",
                    help=f"number of frames (default {PATH_FRAMES})")
    cli_args.add_view_cut(fr)
    fr.add_argument("--triangle-budget", type=int, default=None, metavar="T", action=cli_args.Given,
                    help="steer the bound toward this many triangles")
    cli_args.add_frame_ms(fr)
    cli_args.add_light(fr, help="fixed light position(s) instead of the moving light")
    cli_args.add_screen(fr, size_what="screen size for e_geo")
    cli_args.add_device(fr, " of the per-frame kernels")
    fr.add_argument("--full", action="store_true", help="LOD off: relight the full mesh along the same path (the baseline)")
    fr.add_argument("--error-every", type=int, default=0, metavar="K",
                    help="every K frames, draw the frame and the full-mesh frame offscreen (--size) and report the "
                         "image error (PSNR clipped at white, relative RMSE); 0: never (default)")
    cli_args.add_json(fr, "one JSON object (frames and a summary) instead of the table; strict JSON: a PSNR of inf "
                          "(no difference) and any other non-finite number read null")
    fr.set_defaults(handler=cmd_frames)


def cmd_frames(args) -> int:
    from lodprt.cli.progress import set_lights_with_progress
    from lodprt.runtime.camera import camera_path
    from lodprt.runtime.settings import check_frame_ms, check_triangle_budget
    from lodprt.store.bake_store import open_store

    cli_args.at_least("--frames", args.frames, 1)
    cli_args.at_least("--error-every", args.error_every, 0, " (0: no image error)")
    cli_args.refuse_with_full(args)
    # the view cut's values before the store is opened (the names are the options': lodprt.cli.main.as_flags)
    criterion = cli_args.criterion(args)
    check_triangle_budget(args.triangle_budget)
    check_frame_ms(args.frame_ms)
    t_open = time.perf_counter()
    store = open_store(args.store)
    rt = _runtime(store, criterion=criterion, triangle_budget=args.triangle_budget,
                  frame_ms=args.frame_ms,
                  device=args.device, lod=not args.full, interpolation=args.interpolation, outside=args.outside)
    open_seconds = time.perf_counter() - t_open  # the store and its run time, the samples completed at open included
    errors = _FrameErrors(store, rt) if args.error_every else None
    rows = []
    at_open = rt.samples.completed  # completed while the Runtime opened (its default light)
    try:
        for k, (camera, lights) in enumerate(camera_path(rt, args.path, args.frames, size=tuple(args.size),
                                                         fov=args.fov)):
            rt.set_camera(camera)
            done, t0 = rt.samples.completed, time.perf_counter()
            set_lights_with_progress(rt, args.light if args.light else lights,  # completes the samples not held
                                     desc=f"frame {k}: completing light samples")
            lit = {"ms_lights": 1e3 * (time.perf_counter() - t0), "samples_completed": rt.samples.completed - done}
            frame = rt.update()
            s = frame.stats
            rows.append({"frame": k, **{key: s[key] for key in FRAME_KEYS}, **lit})
            if errors is not None and k % args.error_every == 0:
                rows[-1].update(errors.measure(frame))
    finally:
        if errors is not None:
            errors.close()
    summary = _frames_summary(args, rt, store, rows, at_open, open_seconds)
    if args.json:
        # strict JSON: an infinite PSNR (no difference) or any other non-finite number is written as null
        print(json.dumps(finite_or_null({"summary": summary, "frames": rows}), indent=2, allow_nan=False))
        return 0
    _print_frames(rows, summary, rt)
    return 0


def _runtime(store, **options):
    """``Runtime(store, **options)`` with a progress bar on stderr while the light samples are completed."""
    from lodprt.cli.progress import with_progress
    from lodprt.runtime.session import Runtime

    rt = with_progress(store.num_samples, "completing light samples", "sample",
                       lambda progress: Runtime(store, progress=progress, **options))
    rt.samples.progress = None  # that bar is closed: a later frame's completions show their own
    return rt


def finite_or_null(value):
    """``value`` (dicts, lists, numbers) with every non-finite float as None, for strict JSON."""
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


class _FrameErrors:
    """The image error of run-time frames against the full mesh under the same camera and lights."""

    def __init__(self, store, rt):
        from lodprt.display.render import Renderer

        self.store, self.rt = store, rt
        self.renderer = Renderer()

    def measure(self, frame) -> dict:
        from lodprt.display.compare import error_against_full

        numbers = error_against_full(self.renderer, self.store, frame, self.rt.white, self.rt.interpolation)
        return {"psnr_db": numbers["psnr_db"], "relative_rmse": numbers["relative_rmse"]}

    def close(self) -> None:
        self.renderer.release()


def _frames_summary(args, rt, store, rows, at_open: int, open_seconds: float) -> dict:
    import numpy as np

    ms = np.array([r["ms_total"] for r in rows[1:]])  # the frames after the first: None when there is none
    tris = np.array([r["triangles"] for r in rows])
    summary = {"frames": len(rows), "path": args.path, "lod": not args.full, "criterion": rt.criterion.name,
               "interpolation": rt.interpolation, **rt.criterion.settings(),  # the active criterion's knobs only
               "first_frame_ms": rows[0]["ms_total"],
               "median_ms": float(np.median(ms)) if ms.size else None, "mean_ms": float(ms.mean()) if ms.size else None,
               "p95_ms": float(np.percentile(ms, 95)) if ms.size else None,
               "median_triangles": float(np.median(tris)), "full_triangles": int(len(store.faces)),
               "device": rt.device, "frame_ms_budget": rt.budgets.frame_ms,
               # setting the lights, apart from the frame times: the samples completed along the path and their time
               **light_costs(rows),
               "samples_completed_at_open": int(at_open), "open_seconds": float(open_seconds),
               "sample_cache_slots": int(rt.samples.slots), "light_samples": int(store.num_samples)}
    psnr = [r["psnr_db"] for r in rows if "psnr_db" in r]
    if psnr:
        summary["median_psnr_db"] = float(np.median(psnr))
        summary["min_psnr_db"] = float(np.min(psnr))
        summary["median_relative_rmse"] = float(np.median([r["relative_rmse"] for r in rows if "psnr_db" in r]))
    return summary


def _print_frames(rows, summary, rt) -> None:
    has_err = "median_psnr_db" in summary
    print(f"{'frame':>5} {'triangles':>9} {'touched':>8} {'cut ms':>7} {'tri ms':>7} {'relight ms':>10} {'total ms':>8}"
          f" {'completed':>9} {'set lights ms':>13}" + (f" {'PSNR dB':>8}" if has_err else ""))
    for r in rows:
        err = f" {r['psnr_db']:>8.1f}" if "psnr_db" in r else (" " * 9 if has_err else "")
        print(f"{r['frame']:>5} {r['triangles']:>9,} {r['nodes_touched']:>8,} {r['ms_cut']:>7.2f} "
              f"{r['ms_triangulate']:>7.2f} {r['ms_relight']:>10.2f} {r['ms_total']:>8.2f} "
              f"{r['samples_completed']:>9} {r['ms_lights']:>13.1f}{err}")
    what = "full mesh" if not summary["lod"] else f"{rt.criterion.name} criterion, bound {rt.error_bound:.3g}"
    if summary["lod"] and rt.target_psnr is not None:
        what += f" (steered toward an estimated {rt.target_psnr:g} dB)"
    if summary["lod"] and rt.budgets.frame_ms is not None:
        what += f", frame-time budget {rt.budgets.frame_ms:g} ms (B-2: the bound's floor {rt.budgets.floor:.3g})"
    if summary["median_ms"] is None:
        times = f"first frame {summary['first_frame_ms']:.0f} ms, no frame after it to time"
    else:
        times = (f"median {summary['median_ms']:.2f} ms per frame after the first "
                 f"({summary['first_frame_ms']:.0f} ms), mean {summary['mean_ms']:.2f} ms (frames with an estimate of "
                 f"the error included), p95 {summary['p95_ms']:.2f} ms")
    print(f"{what}: {times}; median {summary['median_triangles']:,.0f} triangles of {summary['full_triangles']:,} "
          f"on {rt.device}")
    print(f"setting the lights (not in the frame times): {summary['samples_completed']} light samples completed along "
          f"the path in {summary['lights_seconds']:.2f} s (longest {summary['max_ms_lights']:.0f} ms), "
          f"{summary['samples_completed_at_open']} at open (opening the store took {summary['open_seconds']:.1f} s); "
          f"the sample cache ended with "
          f"{summary['sample_cache_slots']} slots for the store's {summary['light_samples']} samples")
    if has_err:
        print(f"image error against the full mesh: median PSNR {summary['median_psnr_db']:.1f} dB (worst "
              f"{summary['min_psnr_db']:.1f}), median relative RMSE {summary['median_relative_rmse']:.4f}")
