"""The ``lodprt`` command line: bake, info, radiance, diff, render, compare, turntable, view.

Errors lodprt raises on purpose (bad scene, bad store, unavailable device) are printed as one line naming the file
and field, with exit code 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

import numpy as np

from lodprt.cli import environment as environment_cli
from lodprt.errors import LodprtError

EPILOG_BAKE = """\
examples:
  lodprt bake demo -o demo.zarr
  lodprt bake scene.toml -o bunny.zarr --sh-order 4 --overwrite
SCENE is 'demo' (the embedded default), a TOML scene file (docs/SCENE.md) or a mesh path."""


def _sample_output_args(p: argparse.ArgumentParser, output: str) -> None:
    """The arguments every per-sample command shares: store, sample, eye, output, overwrite."""
    p.add_argument("store", metavar="OUT.zarr")
    p.add_argument("--sample", type=int, required=True, metavar="K", help="light sample index (see lodprt info)")
    p.add_argument("--eye", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"), help="eye position")
    p.add_argument("-o", "--out", required=True, metavar=output, help=f"output {Path(output).suffix} (not replaced without --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")


def _view_cut_args(p: argparse.ArgumentParser) -> None:
    """The view cut's criterion and bounds (docs/RUNTIME.md)."""
    p.add_argument("--criterion", choices=("screen", "thesis"), default="screen",
                   help="view-cut criterion: 'screen' bounds the error on screen (luminance in units of white, "
                        "geometry in pixels; default), 'thesis' is T-14's blend alpha e_geo + (1 - alpha) e_lumi")
    p.add_argument("--error-bound", type=float, default=None, metavar="E",
                   help="view cut error bound (default 0.2 of white for 'screen', 0.25 for 'thesis')")
    p.add_argument("--alpha", type=float, default=0.6, metavar="A",
                   help="'thesis' only: weight of the geometric error against the luminance error (default 0.6)")


def _view_args(p: argparse.ArgumentParser, output: str | None, *, required: bool = True) -> None:
    """The arguments of the display commands: store, lights, camera, view cut, drawing, output."""
    p.add_argument("store", metavar="OUT.zarr")
    p.add_argument("--light", type=float, nargs=3, action="append", required=required, metavar=("X", "Y", "Z"),
                   help="a point light's position (repeat for several lights)")
    p.add_argument("--color", type=float, nargs=3, action="append", default=None, metavar=("R", "G", "B"),
                   help="RGB intensity of each --light, in order (default: the bake's intensity)")
    p.add_argument("--eye", type=float, nargs=3, required=required, default=None, metavar=("X", "Y", "Z"),
                   help="eye position" + ("" if required else " (default: a three-quarter view of the scene)"))
    p.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"), help="look-at point (default: scene centre)")
    p.add_argument("--up", type=float, nargs=3, default=(0.0, 1.0, 0.0), metavar=("X", "Y", "Z"), help="up direction (default +y)")
    p.add_argument("--fov", type=float, default=40.0, metavar="DEG", help="vertical field of view in degrees (default 40)")
    p.add_argument("--size", type=int, nargs=2, default=(800, 600), metavar=("W", "H"), help="image size in pixels (default 800 600)")
    _view_cut_args(p)
    p.add_argument("--full", action="store_true", help="LOD off: draw the full-resolution mesh")
    p.add_argument("--wireframe", action="store_true", help="overlay the triangles of the cut")
    p.add_argument("--per-vertex", action="store_true", help="radiance per vertex, interpolated (default: per fragment from interpolated SH)")
    p.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="exposure in stops (tone mapping, default 0)")
    p.add_argument("--white", type=float, default=None, metavar="L", help="linear radiance shown as white (default: the run time's white point)")
    p.add_argument("--no-markers", action="store_true", help="do not draw the lights as markers")
    if output is not None:
        p.add_argument("-o", "--out", required=True, metavar=output, help="output (not replaced without --overwrite)")
        p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _view_setup(args, store):
    """(lights, colors, Camera) from the display arguments."""
    from lodprt.display.render import default_eye, scene_centre
    from lodprt.runtime.session import Camera

    lights = args.light if args.light else [store.light_positions[store.num_samples // 2].tolist()]
    colors = args.color
    if colors is not None and len(colors) != len(lights):
        raise LodprtError(f"--color: {len(colors)} given for {len(lights)} --light; give one per light or none")
    eye = args.eye if args.eye is not None else default_eye(store)
    target = args.target if args.target is not None else scene_centre(store)
    camera = Camera(eye=tuple(eye), target=tuple(target), up=tuple(args.up), fov=args.fov, width=args.size[0],
                    height=args.size[1])
    return lights, colors, camera


def _draw_options(args) -> dict:
    return {"wireframe": args.wireframe, "per_vertex": args.per_vertex, "exposure": args.exposure,
            "white": args.white, "light_markers": not args.no_markers}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="lodprt",
        description="Level-of-detail based precomputed local radiance transfer (bake, inspect, reconstruct).",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details to stderr")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    b = sub.add_parser(
        "bake",
        help="bake SH radiance transfer for every light sample of a scene",
        description="Bake, for every point-light sample of SCENE, each vertex's outgoing radiance as SH "
        "coefficients over the view direction, and write a zarr store.",
        epilog=EPILOG_BAKE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    b.add_argument("scene", metavar="SCENE", help="'demo', a .toml scene file, or a mesh (obj, ply, stl, off, glb)")
    b.add_argument("-o", "--out", required=True, metavar="OUT.zarr", help="store to write (never replaced without --overwrite)")
    b.add_argument("--sh-order", type=int, default=None, metavar="N",
                   help="SH bands (N*N coefficients), default 4 (3 with --environment)")
    b.add_argument("--environment", default=None, metavar="ENV",
                   help="bake distant-light transfer instead (as bake-environment with its defaults, which lists the "
                   "transfer options): ENV is stored as the default lighting; 'none' stores none")
    b.add_argument("--device", default=None, metavar="DEV", help="Warp device: cpu, cuda, cuda:N (default: cuda if present, else cpu)")
    b.add_argument("--threshold-deg", type=float, default=5.0, metavar="E",
                   help="light cut: collapse lit siblings whose incident angles differ by less than E degrees (default 5)")
    b.add_argument("--full", action="store_true", help="keep every vertex (no light cut)")
    b.add_argument("--jobs", type=int, default=None, metavar="J", help="CPU threads, one light sample each (default: all cores)")
    b.add_argument("--overwrite", action="store_true", help="replace OUT if it is an existing lodprt store")
    b.add_argument("--no-hierarchy", action="store_true", help="skip the vertex hierarchy (implies --full: no light cut, no LOD later)")

    i = sub.add_parser("info", help="summarise a store", description="Print what a bake store holds.")
    i.add_argument("store", metavar="OUT.zarr")
    i.add_argument("--json", action="store_true", help="print a JSON object (vertices, sh_order, bake_seconds, samples, ...)")

    r = sub.add_parser(
        "radiance",
        help="radiance toward an eye for every vertex, from a light sample or arbitrary point lights",
        description="Reconstruct the radiance toward the eye of every scene vertex (store order) and save it as "
        "a (V, 3) float32 .npy (linear RGB): either of light sample K (--sample) or of point lights anywhere in "
        "the sampled region (--light, repeatable; interpolated from the 8 nearest samples, T-12, and summed). "
        "Vertices the light cut did not keep are completed from their pre-collapse neighbours (T-15).",
    )
    r.add_argument("store", metavar="OUT.zarr")
    which = r.add_mutually_exclusive_group(required=True)
    which.add_argument("--sample", type=int, metavar="K", help="light sample index (see lodprt info)")
    which.add_argument("--light", type=float, nargs=3, action="append", metavar=("X", "Y", "Z"),
                       help="a point light's position (repeat for several lights)")
    r.add_argument("--color", type=float, nargs=3, action="append", default=None, metavar=("R", "G", "B"),
                   help="RGB intensity of each --light, in order (default: the bake's intensity)")
    r.add_argument("--outside", choices=("clamp", "error"), default="clamp",
                   help="a light outside the sampled region: clamp it into the region with a warning (default) or refuse")
    r.add_argument("--eye", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"), help="eye position")
    r.add_argument("-o", "--out", required=True, metavar="rad.npy", help="output .npy (not replaced without --overwrite)")
    r.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    fr = sub.add_parser(
        "frames",
        help="run the view-dependent cut along a camera path and report per-frame times and triangles",
        description="Move the camera along a path around the scene (orbit, or dolly toward the target) while the "
        "lights circle above it, update the run-time cut every frame (no drawing) and print per-frame "
        "milliseconds (cut update, triangulation, relighting) and triangle counts.",
    )
    fr.add_argument("store", metavar="OUT.zarr")
    fr.add_argument("--path", choices=("orbit", "dolly"), default="orbit", help="camera path (default orbit)")
    fr.add_argument("--frames", type=int, default=120, metavar="N", help="number of frames (default 120)")
    _view_cut_args(fr)
    fr.add_argument("--triangle-budget", type=int, default=None, metavar="T", help="steer the bound toward this many triangles")
    fr.add_argument("--light", type=float, nargs=3, action="append", default=None, metavar=("X", "Y", "Z"),
                    help="fixed light position(s) instead of the moving light")
    fr.add_argument("--size", type=int, nargs=2, default=(800, 600), metavar=("W", "H"), help="screen size for e_geo (default 800 600)")
    fr.add_argument("--fov", type=float, default=40.0, metavar="DEG", help="vertical field of view (default 40)")
    fr.add_argument("--device", default=None, metavar="DEV", help="Warp device of the per-frame kernels")
    fr.add_argument("--full", action="store_true", help="LOD off: relight the full mesh along the same path (the baseline)")
    fr.add_argument("--error-every", type=int, default=0, metavar="K",
                    help="every K frames, draw the frame and the full-mesh frame offscreen (--size) and report the "
                         "image error (PSNR clipped at white, relative RMSE); 0: never (default)")
    fr.add_argument("--json", action="store_true", help="print one JSON object (frames and a summary) instead of the table")
    d = sub.add_parser(
        "diff",
        help="picture of the light cut's error against the full-resolution radiance (figures 14-17)",
        description="Render offscreen (EGL) the completed radiance of light sample K from a cut bake, the "
        "full-resolution radiance of the same sample (re-baked from the stored scene), and their difference in "
        "false colour with its scale, side by side, into a PNG.",
    )
    _sample_output_args(d, "diff.png")
    d.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"), help="look-at point (default: scene centre)")
    d.add_argument("--fov", type=float, default=40.0, metavar="DEG", help="vertical field of view (default 40)")
    d.add_argument("--size", type=int, nargs=2, default=(640, 480), metavar=("W", "H"), help="each panel's size in pixels")
    d.add_argument("--scale", type=float, default=None, metavar="S", help="error that maps to the top of the colour scale (default: the largest)")
    d.add_argument("--device", default=None, metavar="DEV", help="Warp device for the full-resolution re-bake")

    rn = sub.add_parser(
        "render",
        help="render one frame offscreen (moving lights, view cut) to a PNG or a linear .npy",
        description="Relight the store with the given point lights, choose the view cut for the camera and draw "
        "it offscreen (EGL). A .png is tone-mapped sRGB; a .npy is the linear radiance image (H, W, 3) float32, "
        "background 0, no overlays. Camera: perspective, vertical field of view, right-handed, y up (docs/DISPLAY.md).",
    )
    _view_args(rn, "frame.png|frame.npy", required=False)
    rn.add_argument("--environment", default=None, metavar="ENV",
                    help="OUT is a transfer store (bake --environment): relight it by this environment instead of point "
                    "lights (as render-environment; 'stored' uses the bake's own)")
    rn.add_argument("--rotate", type=float, default=0.0, metavar="DEG", help="with --environment: turn it about +y by DEG degrees")
    cp = sub.add_parser(
        "compare",
        help="figure: LOD frame, full-resolution frame and their difference side by side (figures 14-17)",
        description="Render the view-cut frame and the full-resolution frame for the same lights and camera, and "
        "their per-pixel difference in false colour with its scale, side by side in one PNG.",
    )
    _view_args(cp, "fig.png")
    cp.add_argument("--scale", type=float, default=None, metavar="S",
                    help="difference (relative to white) at the top of the colour scale (default: its 99.5th percentile)")
    tt = sub.add_parser(
        "turntable",
        help="an orbit of the camera with moving lights: PNG sequence (a folder) or an animated GIF",
        description="Orbit the camera around the target (and the lights around the vertical axis through it) "
        "and write every frame: OUT a folder gets frame_0000.png ..., OUT ending in .gif an animated GIF.",
    )
    _view_args(tt, "DIR|video.gif", required=False)
    tt.add_argument("--frames", type=int, default=36, metavar="N", help="frames per orbit (default 36)")
    tt.add_argument("--light-turns", type=float, default=1.0, metavar="T",
                    help="turns the lights make about the vertical axis per orbit (default 1; 0 keeps them still)")
    tt.add_argument("--fps", type=float, default=12.0, metavar="F", help="GIF frame rate (default 12)")
    vw = sub.add_parser(
        "view",
        help="interactive viewer (orbit, drag lights, error bound and alpha, wireframe, LOD toggle)",
        description="Open a window on the store: drag to orbit, right-drag to pan, wheel to zoom, shift-drag to "
        "move the selected light; keys in docs/DISPLAY.md (H prints them). Needs a display (X11 or Xvfb).",
    )
    _view_args(vw, None, required=False)
    vw.add_argument("--frames", type=int, default=None, metavar="N", help="close after N frames (smoke tests)")
    vw.add_argument("--screenshot", default=None, metavar="PNG", help="save the last frame drawn as a PNG")
    environment_cli.add_parsers(sub)  # irradiance, bake-environment, render-environment
    return p


def _delegate(command: str, argv: list[str]) -> int:
    """Run another subcommand with these arguments (the short forms bake/render --environment)."""
    args = _parser().parse_args([command, *argv])
    return {**environment_cli.COMMANDS}[command](args)


def _cmd_render(args) -> int:
    from lodprt.display.render import render_to_file
    from lodprt.store.bake_store import open_store

    if args.environment is not None:  # a transfer store relit by an environment: render-environment
        if args.light:
            raise LodprtError("--light and --environment exclude each other (point lights or an environment)")
        argv = [args.store, "--rotate", str(args.rotate), "--fov", str(args.fov), "--size", *map(str, args.size),
                "-o", str(args.out)]
        argv += [] if args.environment == "stored" else ["--environment", args.environment]
        if args.eye is None:
            raise LodprtError("--environment needs --eye X Y Z")
        argv += ["--eye", *map(str, args.eye)]
        argv += ["--target", *map(str, args.target)] if args.target is not None else []
        argv += ["--white", str(args.white)] if args.white is not None else []
        argv += ["--overwrite"] if args.overwrite else []
        return _delegate("render-environment", argv)
    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    stats = render_to_file(store, args.out, lights=lights, colors=colors, camera=camera, error_bound=args.error_bound,
                           alpha=args.alpha, criterion=args.criterion, lod=not args.full, overwrite=args.overwrite, **_draw_options(args))
    print(f"wrote {args.out}: {stats['triangles']:,} triangles ({'view cut' if stats['lod'] else 'full resolution'}), "
          f"frame {stats.get('ms_total', 0.0):.0f} ms, draw {stats['ms_draw']:.0f} ms")
    return 0


def _cmd_compare(args) -> int:
    from lodprt.display.compare import compare_figure
    from lodprt.store.bake_store import open_store

    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    opts = _draw_options(args)
    opts.pop("light_markers")
    numbers = compare_figure(store, args.out, lights=lights, colors=colors, camera=camera,
                             error_bound=args.error_bound, alpha=args.alpha, criterion=args.criterion,
                             overwrite=args.overwrite,
                             scale=args.scale, markers=not args.no_markers, **opts)
    print(f"wrote {args.out}: {numbers['triangles_lod']:,} of {numbers['triangles_full']:,} triangles, PSNR "
          f"{numbers['psnr_db']:.1f} dB, relative RMSE {numbers['relative_rmse']:.4f}")
    return 0


def _cmd_turntable(args) -> int:
    from lodprt.display.render import turntable
    from lodprt.store.bake_store import open_store

    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    written = turntable(store, args.out, lights=lights, colors=colors, camera=camera, frames=args.frames,
                        light_turns=args.light_turns, fps=args.fps, error_bound=args.error_bound, alpha=args.alpha,
                        criterion=args.criterion,
                        lod=not args.full, overwrite=args.overwrite, **_draw_options(args))
    print(f"wrote {written}")
    return 0


def _cmd_view(args) -> int:
    from lodprt.store.bake_store import open_store
    from lodprt.display.viewer import run_viewer

    if args.screenshot is not None:
        from lodprt.display.render import check_output

        check_output(args.screenshot, (".png",), overwrite=True)
    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    return run_viewer(store, lights=lights, colors=colors, camera=camera, error_bound=args.error_bound,
                      criterion=args.criterion,
                      alpha=args.alpha, lod=not args.full, frames=args.frames, screenshot=args.screenshot,
                      **_draw_options(args))


def _cmd_diff(args) -> int:
    from lodprt.devices import resolve_device
    from lodprt.display.diff import diff_figure
    from lodprt.store.bake_store import open_store

    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise LodprtError(f"{out}: the output must be a .png file")
    if out.exists() and not args.overwrite:
        raise LodprtError(f"{out}: already exists; pass --overwrite to replace it")
    store = open_store(args.store)
    store.check_sample(args.sample)
    numbers = diff_figure(store, args.sample, args.eye, out, target=args.target, size=tuple(args.size), fov=args.fov,
                          device=resolve_device(args.device), scale=args.scale)
    print(f"wrote {out}: relative RMSE {numbers['relative_rmse']:.4f}, max {numbers['relative_max']:.4f}, "
          f"{numbers['vertices_kept']:,} vertices kept")
    return 0


def _cmd_bake(args) -> int:
    if args.environment is not None:  # distant-light transfer: bake-environment with its defaults
        if args.full or args.no_hierarchy:
            raise LodprtError("--full and --no-hierarchy are point-light options; an environment bake has no light "
                              "cut (see bake-environment --lod-threshold)")
        argv = [args.scene, "-o", str(args.out)]
        argv += ["--jobs", str(args.jobs)] if args.jobs is not None else []
        argv += [] if args.environment == "none" else ["--environment", args.environment]
        argv += ["--sh-order", str(args.sh_order)] if args.sh_order is not None else []
        argv += ["--device", args.device] if args.device else []
        argv += ["--overwrite"] if args.overwrite else []
        return _delegate("bake-environment", argv)
    from tqdm import tqdm

    from lodprt.precompute.bake import bake
    from lodprt.model.scene import load_scene

    if args.jobs is not None and args.jobs < 1:
        raise LodprtError(f"--jobs {args.jobs}: must be >= 1")
    from lodprt.devices import resolve_device

    device = resolve_device(args.device)  # refuse an unavailable device before loading anything
    scene = load_scene(args.scene)
    n = scene.lights.positions.shape[0]
    print(
        f"scene {scene.source}: {scene.num_vertices:,} vertices ({int(scene.referenced.sum()):,} referenced), "
        f"{len(scene.faces):,} triangles, {n} light samples",
        file=sys.stderr,
    )
    bars = {}

    def bar_for(name, unit):
        def update(done, total):
            if name not in bars:
                bars[name] = tqdm(total=total, unit=unit, desc=name, file=sys.stderr)
            bars[name].update(done - bars[name].n)

        return update

    try:
        res = bake(
            scene,
            args.out,
            sh_order=4 if args.sh_order is None else args.sh_order,
            device=device,
            overwrite=args.overwrite,
            jobs=args.jobs,
            hierarchy=not args.no_hierarchy,
            threshold_deg=None if args.full or args.no_hierarchy else args.threshold_deg,
            progress=bar_for("bake", "sample"),
            hierarchy_progress=bar_for("hierarchy", "collapse"),
        )
    finally:
        for b in bars.values():
            b.close()
    kb = np.mean([s["bytes"] for s in res.samples]) / 1024
    kept = np.mean([s["vertices_kept"] for s in res.samples])
    print(f"kept {kept:,.0f} of {int(scene.referenced.sum()):,} vertices per sample on average", file=sys.stderr)
    print(
        f"wrote {res.path}: {res.coefficients_per_vertex} coefficient(s) x {res.channels} channel(s) per vertex, "
        f"{kb:,.0f} KiB per sample, bake {res.bake_seconds:.2f} s on {res.device} (+{res.load_seconds:.2f} s kernel load"
        + (f", +{res.hierarchy_seconds:.1f} s hierarchy)" if res.hierarchy_seconds is not None else ")")
    )
    return 0


def _cmd_info(args) -> int:
    from lodprt.store.bake_store import open_store

    info = open_store(args.store).info()
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    mode = info["mode"] + (f", threshold {info['threshold_deg']} deg" if info.get("threshold_deg") is not None else "")
    print(f"{args.store}: lodprt store v{info['format_version']} ({mode}) from {info['source']}")
    print(f"  vertices {info['vertices']:,}, triangles {info['faces']:,}")
    print(
        f"  SH order {info['sh_order']}: {info['coefficients_per_vertex']} coefficient(s) x {info['channels']} channel(s)"
    )
    if info["hierarchy_nodes"] is not None:
        print(f"  hierarchy {info['hierarchy_nodes']:,} nodes, {info['hierarchy_roots']:,} roots, depth "
              f"{info['hierarchy_depth']}, built in {info['hierarchy_seconds']:.1f} s")
    print(f"  bake {info['bake_seconds']:.2f} s on {info['device']}; {info['bytes_total'] / 1024:,.0f} KiB payload, "
          f"{info['bytes_on_disk'] / 1024:,.0f} KiB on disk")
    print(f"  {'sample':>6} {'position':>30} {'kept':>9} {'lit':>9} {'shadowed':>9} {'KiB':>9}")
    for s in info["samples"]:
        pos = "(" + ", ".join(f"{x:.3g}" for x in s["position"]) + ")"
        print(f"  {s['index']:>6} {pos:>30} {s['vertices_kept']:>9,} {s['lit']:>9,} {s['shadowed']:>9,} {s['bytes'] / 1024:>9,.0f}")
    return 0


def _cmd_radiance(args) -> int:
    from lodprt.store.bake_store import open_store

    out = Path(args.out)
    if out.suffix != ".npy":
        raise LodprtError(f"{out}: the output must be a .npy file")
    if out.exists() and not args.overwrite:
        raise LodprtError(f"{out}: already exists; pass --overwrite to replace it")
    store = open_store(args.store)
    if args.sample is not None:
        if args.color:
            raise LodprtError("--color goes with --light, not with --sample")
        rad = store.radiance(args.sample, args.eye)
    else:
        if args.color is not None and len(args.color) != len(args.light):
            raise LodprtError(f"--color: {len(args.color)} given for {len(args.light)} --light; give one per light or none")
        from lodprt.runtime.session import light_radiance

        rad = light_radiance(store, args.light, args.eye, colors=args.color, outside=args.outside)
    np.save(out, rad)
    print(f"wrote {out}: {rad.shape} float32, mean {rad.mean():.4g}, max {rad.max():.4g}")
    return 0


def _runtime(store, **options):
    """``Runtime(store, **options)`` with a progress bar on stderr while the light samples are completed."""
    from tqdm import tqdm

    from lodprt.runtime.session import Runtime

    bar = tqdm(total=store.num_samples, unit="sample", desc="completing light samples", file=sys.stderr, leave=False)
    try:
        return Runtime(store, progress=lambda done, total: bar.update(done - bar.n), **options)
    finally:
        bar.close()


def _cmd_frames(args) -> int:
    from lodprt.runtime.session import camera_path
    from lodprt.store.bake_store import open_store

    if args.frames < 1:
        raise LodprtError(f"--frames {args.frames}: must be >= 1")
    if args.error_every < 0:
        raise LodprtError(f"--error-every {args.error_every}: must be >= 0 (0: no image error)")
    store = open_store(args.store)
    rt = _runtime(store, error_bound=args.error_bound, alpha=args.alpha, criterion=args.criterion,
                  triangle_budget=args.triangle_budget, device=args.device, lod=not args.full)
    errors = _FrameErrors(store, rt) if args.error_every else None
    rows = []
    try:
        for k, (camera, lights) in enumerate(camera_path(rt, args.path, args.frames, size=tuple(args.size),
                                                         fov=args.fov)):
            rt.set_camera(camera)
            rt.set_lights(args.light if args.light else lights)
            frame = rt.update()
            s = frame.stats
            rows.append({"frame": k, **{key: s[key] for key in FRAME_KEYS}})
            if errors is not None and k % args.error_every == 0:
                rows[-1].update(errors.measure(frame))
    finally:
        if errors is not None:
            errors.close()
    summary = _frames_summary(args, rt, store, rows)
    if args.json:
        print(json.dumps({"summary": summary, "frames": rows}, indent=2))
        return 0
    _print_frames(rows, summary, rt)
    return 0


FRAME_KEYS = ("triangles", "active_nodes", "nodes_touched", "refined", "coarsened", "ms_cut", "ms_triangulate",
              "ms_relight", "ms_total")


class _FrameErrors:
    """The image error of run-time frames against the full mesh under the same camera and lights."""

    def __init__(self, store, rt):
        from lodprt.display.render import Renderer

        self.store, self.rt = store, rt
        self.renderer = Renderer()

    def measure(self, frame) -> dict:
        from lodprt.display.compare import frame_error
        from lodprt.display.render import full_frame

        full = full_frame(self.store, frame.camera, lights=frame.lights, colors=frame.light_colors)
        numbers, _, _ = frame_error(self.renderer, frame, full, self.rt.white)
        return {"psnr_db": numbers["psnr_db"], "relative_rmse": numbers["relative_rmse"]}

    def close(self) -> None:
        self.renderer.release()


def _frames_summary(args, rt, store, rows) -> dict:
    ms = np.array([r["ms_total"] for r in rows[1:]] or [rows[0]["ms_total"]])
    tris = np.array([r["triangles"] for r in rows])
    summary = {"frames": len(rows), "path": args.path, "lod": not args.full, "criterion": rt.criterion,
               "error_bound": rt.error_bound, "alpha": args.alpha, "first_frame_ms": rows[0]["ms_total"],
               "median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
               "median_triangles": float(np.median(tris)), "full_triangles": int(len(store.faces)),
               "device": rt.device}
    psnr = [r["psnr_db"] for r in rows if "psnr_db" in r]
    if psnr:
        summary["median_psnr_db"] = float(np.median(psnr))
        summary["min_psnr_db"] = float(np.min(psnr))
        summary["median_relative_rmse"] = float(np.median([r["relative_rmse"] for r in rows if "psnr_db" in r]))
    return summary


def _print_frames(rows, summary, rt) -> None:
    has_err = "median_psnr_db" in summary
    print(f"{'frame':>5} {'triangles':>9} {'touched':>8} {'cut ms':>7} {'tri ms':>7} {'light ms':>8} {'total ms':>8}"
          + (f" {'PSNR dB':>8}" if has_err else ""))
    for r in rows:
        err = f" {r['psnr_db']:>8.1f}" if "psnr_db" in r else (" " * 9 if has_err else "")
        print(f"{r['frame']:>5} {r['triangles']:>9,} {r['nodes_touched']:>8,} {r['ms_cut']:>7.2f} "
              f"{r['ms_triangulate']:>7.2f} {r['ms_relight']:>8.2f} {r['ms_total']:>8.2f}{err}")
    what = "full mesh" if not summary["lod"] else f"{rt.criterion} criterion, bound {rt.error_bound:g}"
    print(f"{what}: median {summary['median_ms']:.2f} ms per frame after the first "
          f"({summary['first_frame_ms']:.0f} ms), p95 {summary['p95_ms']:.2f} ms; median "
          f"{summary['median_triangles']:,.0f} triangles of {summary['full_triangles']:,} on {rt.device}")
    if has_err:
        print(f"image error against the full mesh: median PSNR {summary['median_psnr_db']:.1f} dB (worst "
              f"{summary['min_psnr_db']:.1f}), median relative RMSE {summary['median_relative_rmse']:.4f}")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(name)s: %(message)s")
    commands = {"bake": _cmd_bake, "info": _cmd_info, "radiance": _cmd_radiance, "diff": _cmd_diff, "frames": _cmd_frames,
                "render": _cmd_render, "compare": _cmd_compare, "turntable": _cmd_turntable, "view": _cmd_view,
                **environment_cli.COMMANDS}
    try:
        return commands[args.command](args)
    except LodprtError as exc:
        print(f"lodprt {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
