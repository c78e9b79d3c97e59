"""The display commands of ``lodprt``, each drawn with OpenGL (docs/DISPLAY.md): diff (the light cut's error against
the full-resolution radiance), render, compare, turntable and view (moving point lights, view cut)."""

from __future__ import annotations

import os

from lodprt.cli import args as cli_args
from lodprt.cli import environment as environment_cli
from lodprt.runtime.camera import PATH_FRAMES, PATHS
from lodprt.errors import LodprtError


def register(sub) -> None:
    """Add diff, render, compare, turntable and view to ``sub`` (the subparsers object of the lodprt parser)."""
    _add_diff(sub)
    _add_render(sub)
    _add_compare(sub)
    _add_turntable(sub)
    _add_view(sub)


def _add_view_args(p, output: str | None, *, required: bool = True, full: bool = True) -> None:
    """The arguments of the display commands: store, lights, camera, view cut, drawing (``full``: with --full,
    LOD off), output."""
    cli_args.add_store(p)
    cli_args.add_light(p, required=required)
    cli_args.add_colors(p)
    cli_args.add_camera(p, eye_required=required, up=True)
    cli_args.add_view_cut(p)
    if full:
        p.add_argument("--full", action="store_true", help="LOD off: draw the full-resolution mesh")
    p.add_argument("--wireframe", action="store_true", help="overlay the triangles of the cut")
    p.add_argument("--per-vertex", action="store_true", help="radiance per vertex, interpolated (default: per fragment from interpolated SH)")
    p.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="exposure in stops (tone mapping, default 0)")
    p.add_argument("--white", type=float, default=None, metavar="L", help="linear radiance shown as white (default: the run time's white point)")
    p.add_argument("--no-markers", action="store_true", help="do not draw the lights as markers")
    if output is not None:
        cli_args.add_output(p, output)


def _add_diff(sub) -> None:
    d = sub.add_parser(
        "diff",
        help="picture of the light cut's error against the full-resolution radiance (figures 14-17)",
        description="Render offscreen (EGL) the completed radiance of light sample K from a cut bake, the "
        "full-resolution radiance of the same sample (re-baked from the stored scene), and their difference in "
        "false colour with its scale, side by side, into a PNG.",
    )
    cli_args.add_store(d)
    cli_args.add_sample(d, required=True)
    cli_args.add_camera(d, size=(640, 480), size_what="each panel's size in pixels")
    cli_args.add_output(d, "diff.png", "output .png")
    d.add_argument("--scale", type=float, default=None, metavar="S", help="|difference| / white at the top of the colour scale (default: its 99th percentile)")
    cli_args.add_device(d, " for the full-resolution re-bake")
    d.set_defaults(handler=cmd_diff)


def _add_render(sub) -> None:
    rn = sub.add_parser(
        "render",
        help="render one frame offscreen (moving lights, view cut) to a PNG, a linear .npy or an OpenEXR .exr",
        description="Relight the store with the given point lights, choose the view cut for the camera and draw "
        "it offscreen (EGL). A .png is tone-mapped sRGB; a .npy is the linear radiance image (H, W, 3) float32, "
        "background 0, no overlays; an .exr the same radiance as OpenEXR float32 RGB (pip install 'lodprt[exr]'). Camera: perspective, vertical field of view, right-handed, y up (docs/DISPLAY.md).",
    )
    _add_view_args(rn, "frame.png|frame.npy|frame.exr", required=False)
    rn.add_argument("--sample", type=int, default=None, metavar="K",
                    help="light the scene with stored light sample K (one light there, the bake's intensity, the "
                    "thesis interpolation: exactly that sample's coefficients), instead of --light")
    rn.add_argument("--environment", default=None, metavar="ENV",
                    help="OUT is a transfer store (bake --environment): relight it by this environment instead of point "
                    "lights (as render-environment; 'stored' uses the bake's own); needs --eye, writes a .png, and "
                    "takes of the drawing options only --target, --fov, --size and --white")
    rn.add_argument("--rotate", type=float, default=0.0, metavar="DEG", help="with --environment: turn it about +y by DEG degrees")
    rn.set_defaults(handler=cmd_render)


def _add_compare(sub) -> None:
    cp = sub.add_parser(
        "compare",
        help="figure: LOD frame, full-resolution frame and their difference side by side (figures 14-17)",
        description="Render the view-cut frame and the full-resolution frame for the same lights and camera, and "
        "their per-pixel difference in false colour with its scale, side by side in one PNG (fig.exr: the "
        "linear radiance of the two frames and their absolute difference side by side, OpenEXR float32 RGB).",
    )
    _add_view_args(cp, "fig.png|fig.exr", full=False)  # it draws the full-resolution frame beside the cut anyway
    cp.add_argument("--scale", type=float, default=None, metavar="S",
                    help="|difference| / white at the top of the colour scale (default: its 99th percentile)")
    cp.set_defaults(handler=cmd_compare)


def _add_turntable(sub) -> None:
    tt = sub.add_parser(
        "turntable",
        help="an orbit of the camera with moving lights: PNG sequence (a folder), an animated GIF, an H.264 MP4 or "
        "an EXR sequence",
        description="Orbit the camera around the target (and the lights around the vertical axis through it) "
        "and write every frame: OUT a folder gets frame_0000.png ..., OUT ending in .gif an animated GIF, OUT "
        "ending in .mp4 an H.264 video (needs the optional imageio-ffmpeg: pip install 'lodprt[video]'; odd sizes "
        "are padded to even), OUT NAME.exr the linear radiance of each frame as OpenEXR float32 RGB, NAME_0000.exr "
        "... (pip install 'lodprt[exr]').",
    )
    _add_view_args(tt, "DIR|video.gif|video.mp4|NAME.exr", required=False)
    tt.add_argument("--frames", type=int, default=36, metavar="N", help="frames per orbit (default 36)")
    tt.add_argument("--light-turns", type=float, default=1.0, metavar="T",
                    help="turns the lights make about the vertical axis per orbit (default 1; 0 keeps them still)")
    tt.add_argument("--fps", type=float, default=12.0, metavar="F", help="GIF or MP4 frame rate (default 12)")
    tt.set_defaults(handler=cmd_turntable)


def _add_view(sub) -> None:
    vw = sub.add_parser(
        "view",
        help="interactive viewer (orbit, drag lights, the criterion's knobs, wireframe, LOD toggle)",
        description="Open a window on the store: drag to orbit, right-drag to pan, wheel to zoom, shift-drag to "
        "move the selected light; keys in docs/DISPLAY.md (H prints them). Needs a display (X11 or Xvfb), or "
        "--headless: the same loop and overlay on an EGL context, no window (with --frames and --screenshot).",
    )
    _add_view_args(vw, None, required=False)
    cli_args.add_frame_ms(vw)
    vw.add_argument("--path", choices=PATHS, default=None,
                    help="play the camera path of 'lodprt frames' (the light circling with it unless --light is "
                         "given), looped; P pauses and plays it, a drag pauses it; on closing, print what its "
                         "frames cost (update, draw, light samples completed)")
    vw.add_argument("--frames", type=int, default=None, metavar="N",
                    help=f"close after N frames (smoke tests); with --path, a lap of the path is N frames "
                         f"(default {PATH_FRAMES})")
    vw.add_argument("--headless", action="store_true",
                    help="no window: draw --frames N frames with the overlay on an EGL context (no DISPLAY needed)")
    vw.add_argument("--screenshot", default=None, metavar="PNG", help="save the last frame drawn as a PNG")
    vw.set_defaults(handler=cmd_view)


def _view_setup(args, store):
    """(lights, colors, Camera) from the display arguments."""
    from lodprt.runtime.camera import Camera, default_eye, scene_centre

    lights = args.light if args.light else [store.light_positions[store.num_samples // 2].tolist()]
    colors = args.color
    cli_args.check_colors(colors, lights)
    eye = args.eye if args.eye is not None else default_eye(store)
    target = args.target if args.target is not None else scene_centre(store)
    camera = Camera(eye=tuple(eye), target=tuple(target), up=tuple(args.up), fov=args.fov, width=args.size[0],
                    height=args.size[1])
    return lights, colors, camera


def _view_cut(args) -> dict:
    return {"criterion": cli_args.criterion(args), "interpolation": args.interpolation, "outside": args.outside}


def _draw_options(args) -> dict:
    cli_args.check_tone(args.white, args.exposure)
    return {"wireframe": args.wireframe, "per_vertex": args.per_vertex, "exposure": args.exposure,
            "white": args.white, "light_markers": not args.no_markers}


def cmd_diff(args) -> int:
    from lodprt.devices import resolve_device
    from lodprt.display.diff import diff_figure
    from lodprt.store.bake_store import open_store

    out = cli_args.new_output(args.out, ".png", args.overwrite)
    store = open_store(args.store)
    store.check_sample(args.sample)
    numbers = diff_figure(store, args.sample, args.eye, out, target=args.target, size=tuple(args.size), fov=args.fov,
                          device=resolve_device(args.device), scale=args.scale)
    print(f"wrote {out}: PSNR {numbers['psnr_db']:.1f} dB, relative RMSE {numbers['relative_rmse']:.4f}, max "
          f"|cut - full| / white {numbers['max_difference']:.4f}, {numbers['vertices_kept']:,} vertices kept")
    return 0


def cmd_render(args) -> int:
    if args.environment is not None:
        return _render_environment(args)
    from lodprt.display.pictures import render_to_file
    from lodprt.store.bake_store import open_store

    cli_args.refuse_with_full(args)
    cli_args.criterion(args)  # its values checked before the store is opened
    store = open_store(args.store)
    if args.sample is not None:
        _sample_as_light(args, store)
    lights, colors, camera = _view_setup(args, store)
    stats = render_to_file(store, args.out, lights=lights, colors=colors, camera=camera, lod=not args.full,
                           overwrite=args.overwrite, **_view_cut(args), **_draw_options(args))
    print(f"wrote {args.out}: {stats['triangles']:,} triangles ({'view cut' if stats['lod'] else 'full resolution'}), "
          f"frame {stats.get('ms_total', 0.0):.0f} ms, draw {stats['ms_draw']:.0f} ms")
    return 0


def _sample_as_light(args, store) -> None:
    """``--sample K``: one light at stored sample K, lit by the thesis interpolation (its T-12 weights select sample
    K alone, so the frame shows the stored coefficients), as ``export --sample`` and ``radiance --sample`` do."""
    if args.light:
        raise LodprtError("--sample and --light exclude each other")
    if args.color:
        raise LodprtError("--color goes with --light, not with --sample")
    store.check_sample(args.sample)
    args.light = [store.light_positions[args.sample].tolist()]
    args.interpolation = "thesis"


def _render_environment(args) -> int:
    """``render OUT --environment ENV``: a transfer store relit by an environment, as render-environment."""
    if args.light or args.sample is not None:
        raise LodprtError("--light/--sample and --environment exclude each other (point lights or an environment)")
    if args.eye is None:  # a transfer store keeps no mesh bounds to frame a default view from
        raise LodprtError("--environment needs --eye X Y Z (the default view is a point-light store's)")
    # the point lights' drawing options have no meaning for a transfer store: refused, not silently dropped
    unused = [flag for flag, on in (("--full", args.full), ("--wireframe", args.wireframe),
                                    ("--per-vertex", args.per_vertex), ("--no-markers", args.no_markers),
                                    ("--exposure", args.exposure != 0.0), ("--color", bool(args.color)),
                                    ("--up", tuple(args.up) != (0.0, 1.0, 0.0))) if on]
    if unused:
        raise LodprtError(f"{', '.join(unused)}: not with --environment (a transfer store is drawn as "
                          "render-environment draws it)")
    if str(args.out).lower().endswith((".npy", ".exr")):
        raise LodprtError(f"{args.out}: --environment writes a .png (the .npy and .exr outputs are point-light "
                          "frames')")
    return environment_cli.render_environment(
        args.store, args.out, eye=args.eye, environment=None if args.environment == "stored" else args.environment,
        rotate=args.rotate, target=args.target, fov=args.fov, size=args.size, white=args.white,
        overwrite=args.overwrite)


def cmd_compare(args) -> int:
    from lodprt.display.compare import compare_figure
    from lodprt.store.bake_store import open_store

    view_cut = _view_cut(args)  # its values checked before the store is opened
    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    opts = _draw_options(args)
    opts.pop("light_markers")
    numbers = compare_figure(store, args.out, lights=lights, colors=colors, camera=camera, overwrite=args.overwrite,
                             scale=args.scale, markers=not args.no_markers, **view_cut, **opts)
    print(f"wrote {args.out}: {numbers['triangles_lod']:,} of {numbers['triangles_full']:,} triangles, PSNR "
          f"{numbers['psnr_db']:.1f} dB, relative RMSE {numbers['relative_rmse']:.4f}")
    return 0


def cmd_turntable(args) -> int:
    from lodprt.display.pictures import check_fps, turntable
    from lodprt.store.bake_store import open_store

    check_fps(args.fps, os.path.splitext(str(args.out or ""))[1])  # a bad --fps fails before the store is opened
    cli_args.refuse_with_full(args)
    view_cut = _view_cut(args)  # and so do bad view-cut values
    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    written, stale = turntable(store, args.out, lights=lights, colors=colors, camera=camera, frames=args.frames,
                               light_turns=args.light_turns, fps=args.fps, lod=not args.full,
                               overwrite=args.overwrite, **view_cut, **_draw_options(args))
    # --overwrite over a longer sequence: say how many of its numbered frames were removed
    removed = f" (removed {stale} stale frame{'s' * (stale != 1)} of an earlier run)" if stale else ""
    print(f"wrote {written}{removed}")
    return 0


def cmd_view(args) -> int:
    from lodprt.cli.progress import set_lights_with_progress, transient_bar
    from lodprt.display.viewer import run_viewer
    from lodprt.store.bake_store import open_store

    cli_args.at_least("--frames", args.frames, 1)
    if args.headless and args.frames is None:
        raise LodprtError("--headless needs --frames N: there is no window to close")
    if args.screenshot is not None:
        from lodprt.display.pictures import check_output

        check_output(args.screenshot, (".png",), overwrite=True)
    view_cut = _view_cut(args)  # its values checked before the store is opened
    store = open_store(args.store)
    lights, colors, camera = _view_setup(args, store)
    return run_viewer(store, lights=lights, colors=colors, camera=camera, lod=not args.full, frames=args.frames,
                      screenshot=args.screenshot, frame_ms=args.frame_ms, headless=args.headless,
                      set_lights=set_lights_with_progress, path=args.path, path_frames=args.frames,
                      fixed_lights=bool(args.light), progress=transient_bar("opening: completing light samples",
                                                                            "sample"),
                      **view_cut, **_draw_options(args))
