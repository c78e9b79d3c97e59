"""The environment-lighting commands of ``lodprt``: irradiance, bake-environment, render-environment.

:func:`register` adds them to the lodprt parser; :func:`bake_environment` and :func:`render_environment` are also
what the short forms ``lodprt bake SCENE --environment ENV`` and ``lodprt render OUT --environment ENV`` call. The
work is done in :mod:`lodprt.model.environment`, :mod:`lodprt.model.irradiance`, :mod:`lodprt.precompute.transfer`
and :mod:`lodprt.runtime.environment_relight`.
"""

from __future__ import annotations

import json
import sys

from lodprt.cli import args as cli_args
from lodprt.cli.progress import ProgressBars
from lodprt.errors import LodprtError

ENV_HELP = ("environment: a lat-long .hdr/.exr/.npy (H, 2H, 3), a .npy cube (6, N, N, 3), a folder of six faces "
            "px nx py ny pz nz, or a procedural name: sky, spots, constant (sky:256 sets the resolution)")

# bake-environment's defaults (also those of the short form bake --environment)
SH_ORDER = 3
#: lodprt.precompute.transfer.MODES, copied so that `lodprt --help` imports no bake (tests/test_architecture.py
#: checks that the two agree)
TRANSFERS = ("unshadowed", "shadowed", "interreflected")
TRANSFER = "interreflected"
RAYS = 256
BOUNCES = 4
BOUNCE_THRESHOLD = 1e-3


def register(sub) -> None:
    """Add irradiance, bake-environment and render-environment to ``sub`` (the lodprt parser's subparsers)."""
    _add_irradiance(sub)
    _add_bake_environment(sub)
    _add_render_environment(sub)


def _add_irradiance(sub) -> None:
    ir = sub.add_parser(
        "irradiance",
        help="9-coefficient irradiance of an environment (Ramamoorthi-Hanrahan): coefficients, constants, matrices",
        description="Project the environment's linear RGB radiance onto 9 SH coefficients per channel and print "
        "them with A_l, the table-1 constants c1..c5, the 4x4 matrix M of E(n) = n^T M n per channel and the 7 "
        "vec4 shader registers cAr..cC.",
    )
    ir.add_argument("environment", metavar="ENV", help=ENV_HELP)
    ir.add_argument("--mip", type=int, default=0, metavar="K", help="project from mip level K (each level halves the resolution)")
    _add_window(ir, "the 9 coefficients printed")
    cli_args.add_json(ir)
    ir.add_argument("--format", choices=("gltf", "unity", "filament"), default=None,
                    help="print only the 9 x 3 irradiance coefficients as JSON in an engine's convention "
                    "(docs/EXPORT.md): gltf (KHR_lights_environment irradianceCoefficients), unity "
                    "(SphericalHarmonicsL2 and its shader constants), filament (cmgen's pre-scaled sh.txt)")
    ir.set_defaults(handler=cmd_irradiance)


def _add_window(p, what: str) -> None:
    """--window and --window-width (de-ringing, lodprt.model.windowing) applied to ``what``."""
    p.add_argument("--window", choices=("auto", "hann", "lanczos", "none"), default="none",
                   help=f"de-ringing window on the SH bands of {what} (default none): auto narrows a Hann or Lanczos "
                   "window until the irradiance is >= 0 everywhere on the sphere (none when it already is) and "
                   "reports the window chosen; hann, lanczos: that window at --window-width bands")
    p.add_argument("--window-width", type=float, default=None, metavar="W",
                   help="width in bands of --window hann|lanczos (default: the SH order; band l >= W is dropped)")


def _add_bake_environment(sub) -> None:
    be = sub.add_parser(
        "bake-environment",
        help="bake distant-light transfer (diffuse vectors, glossy matrices) for every vertex of a scene",
        description="Bake per-vertex transfer for distant (environment) lighting: diffuse unshadowed, shadowed or "
        "interreflected transfer vectors, and glossy transfer matrices for materials with ks > 0. Writes a "
        "lodprt-transfer zarr store (docs/ENVIRONMENT.md).",
    )
    cli_args.add_scene(be)
    cli_args.add_store_output(be, "transfer")
    be.add_argument("--environment", default=None, metavar="ENV", help="store this environment's coefficients as the default lighting; " + ENV_HELP)
    be.add_argument("--sh-order", type=int, default=SH_ORDER, metavar="N",
                    help=f"SH bands of the transfer (default {SH_ORDER}: {SH_ORDER * SH_ORDER} coefficients)")
    be.add_argument("--transfer", choices=TRANSFERS, default=TRANSFER, help=f"diffuse transfer (default {TRANSFER})")
    be.add_argument("--rays", type=int, default=RAYS, metavar="R", help=f"rays per vertex (spherical Fibonacci set, default {RAYS})")
    be.add_argument("--bounces", type=int, default=BOUNCES, metavar="B", help=f"most interreflection passes (default {BOUNCES})")
    be.add_argument("--bounce-threshold", type=float, default=BOUNCE_THRESHOLD, metavar="T",
                    help=f"stop when a pass' energy is below T times the direct pass' (default {BOUNCE_THRESHOLD:g})")
    be.add_argument("--rotate-rays", action="store_true", help="turn the ray set by a random rotation per vertex")
    be.add_argument("--no-glossy", action="store_true", help="skip the glossy matrices")
    be.add_argument("--glossy-order", type=int, default=None, metavar="N", help="bands of the glossy transferred radiance (default: --sh-order)")
    be.add_argument("--lod-threshold", type=float, default=None, metavar="E",
                    help="level of detail: build the vertex hierarchy and store transfer vectors only where they differ "
                    "by more than E (relative) across a node's leaves; the rest are completed on reading (T-15)")
    cli_args.add_device(be)
    cli_args.add_jobs(be, "each launching a range of vertices")
    be.set_defaults(handler=cmd_bake_environment)


def _add_render_environment(sub) -> None:
    re = sub.add_parser(
        "render-environment",
        help="render a transfer bake relit by an environment, optionally rotated about +y",
        description="Relight a lodprt-transfer store by an environment turned by --rotate degrees about +y "
        "(diffuse dot products, glossy matrix-vector + Phong convolution + evaluation in the reflection "
        "direction) and draw it offscreen (EGL) into a PNG.",
    )
    cli_args.add_store(re)
    re.add_argument("--environment", default=None, metavar="ENV", help="lighting (default: the one stored by the bake); " + ENV_HELP)
    re.add_argument("--rotate", type=cli_args.finite, default=0.0, metavar="DEG", help="turn the environment about +y by DEG degrees")
    re.add_argument("--frames", type=int, default=1, metavar="N",
                    help="N > 1: N images turning the environment by 360/N degrees each, OUT_0000.png ... (default "
                    "1); with --overwrite, the numbered frames of an earlier, longer run of OUT are removed")
    cli_args.add_camera(re)
    re.add_argument("--white", type=cli_args.finite, default=None, metavar="L", help="radiance shown as white (default: 99th percentile of the first frame)")
    _add_window(re, "the lighting (chosen once: a band window commutes with --rotate)")
    re.add_argument("--receiver", default=None, metavar="MESH",
                    help="with a neighbourhood store (lodprt bake-neighbourhood): also draw this mesh (or scene file), "
                    "lit by the object's transferred lighting: its shadow and reflected light (docs/VOLUMES.md)")
    re.add_argument("--at", type=cli_args.finite, nargs=3, default=(0.0, 0.0, 0.0), metavar=cli_args.XYZ,
                    help="move the --receiver by X Y Z (default 0 0 0)")
    cli_args.add_output(re, "img.png", "output PNG")
    re.set_defaults(handler=cmd_render_environment)


def cmd_irradiance(args) -> int:
    from lodprt.model import irradiance as irr
    from lodprt.model.environment import load_environment

    env = load_environment(args.environment)
    if args.mip is not None:
        env = env.mip(args.mip)
    from lodprt.model.windowing import apply_window, choose_window

    coeffs = irr.lighting_coefficients(env)
    choice = choose_window(coeffs, args.window, width=args.window_width)
    doc = irr.describe(apply_window(coeffs, choice.factors))
    doc["window"] = choice.to_json()
    doc["environment"] = {"source": env.source, "kind": env.kind, "shape": list(env.data.shape[:-1]),
                          "mip_level": args.mip}
    if args.format is not None:
        if args.json:
            raise LodprtError("--json and --format exclude each other (--format prints JSON itself)")
        from lodprt.model.irradiance_formats import export_document

        print(json.dumps(export_document(args.format, apply_window(coeffs, choice.factors), source=env.source),
                         indent=2))
        return 0
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    _print_irradiance(env, doc)
    if args.window != "none":
        print(f"window: {choice.describe()}")
    return 0


def _print_irradiance(env, doc) -> None:
    print(f"{env.source}: {env.kind} {' x '.join(map(str, env.data.shape[:-1]))}, linear RGB radiance")
    print(f"{'':6}" + "".join(f"{n:>12}" for n in doc["coefficient_names"]))
    for c in "rgb":
        print(f"{c:>6}" + "".join(f"{x:12.6f}" for x in doc["coefficients"][c]))
    print("A_l = pi, 2pi/3, pi/4;  " + ", ".join(f"{k} = {v:.6f}" for k, v in doc["constants"].items()))
    for c in "rgb":
        print(f"M_{c} (E(n) = n^T M n, n = (x, y, z, 1)):")
        for row in doc["matrices"][c]:
            print("    " + "".join(f"{x:12.6f}" for x in row))
    print("shader registers (vec4 x y z w):")
    for k, v in doc["registers"].items():
        print(f"  {k:>4} " + "".join(f"{x:12.6f}" for x in v))
    lo, hi = doc["irradiance_min"], doc["irradiance_max"]
    print("E(n) over the sphere: " + ", ".join(f"{c} [{a:.6g}, {b:.6g}]" for c, a, b in zip("rgb", lo, hi)))
    if min(lo) < 0:
        print("warning: negative irradiance somewhere (ringing of the 9-coefficient expansion of a sharp light)",
              file=sys.stderr)


def cmd_bake_environment(args) -> int:
    return bake_environment(args.scene, args.out, environment=args.environment, sh_order=args.sh_order,
                            transfer=args.transfer, rays=args.rays, bounces=args.bounces,
                            bounce_threshold=args.bounce_threshold, rotate_rays=args.rotate_rays,
                            glossy=not args.no_glossy, glossy_order=args.glossy_order,
                            lod_threshold=args.lod_threshold, device=args.device, jobs=args.jobs,
                            overwrite=args.overwrite)


def bake_environment(scene_path, out, *, environment: str | None = None, sh_order: int = SH_ORDER,
                     transfer: str = TRANSFER, rays: int = RAYS, bounces: int = BOUNCES,
                     bounce_threshold: float = BOUNCE_THRESHOLD, rotate_rays: bool = False, glossy: bool = True,
                     glossy_order: int | None = None, lod_threshold: float | None = None, device: str | None = None,
                     jobs: int | None = None, overwrite: bool = False) -> int:
    """``lodprt bake-environment`` with these values (its defaults where not given): bake, report, exit code 0."""
    from lodprt.devices import resolve_device
    from lodprt.model.environment import load_environment
    from lodprt.model.scene import load_scene
    from lodprt.precompute.transfer import bake_transfer

    cli_args.at_least("--jobs", jobs, 1)
    device = resolve_device(device)
    env = load_environment(environment) if environment else None
    scene = load_scene(scene_path)
    print(f"scene {scene.source}: {scene.num_vertices:,} vertices, {len(scene.faces):,} triangles", file=sys.stderr)
    with ProgressBars() as bars:
        res = bake_transfer(scene, out, sh_order=sh_order, mode=transfer, rays=rays, bounces=bounces,
                            bounce_threshold=bounce_threshold, glossy=glossy, glossy_order=glossy_order, rotate=rotate_rays,
                            environment=env, device=device, lod_threshold=lod_threshold, overwrite=overwrite,
                            progress=bars.callback("transfer", "pass"), jobs=jobs)
    e = res.diffuse.energy
    print(f"wrote {res.path}: order {sh_order} {transfer} transfer, {rays} rays/vertex, "
          f"{len(e) - 1} bounce pass(es) (energy " + ", ".join(f"{x:.3g}" for x in e) + f"), "
          f"{len(res.glossy_ids):,} glossy matrices"
          + (f" ({len(res.glossy_kept_ids):,} baked, the rest completed)" if res.cut_nodes is not None else "") + "; "
          + (f"LOD keeps {len(res.cut_nodes):,} of {scene.num_vertices:,} vertices; " if res.cut_nodes is not None else "")
          + f"bake {res.seconds:.2f} s on {res.device} "
          f"(+{res.load_seconds:.2f} s kernel load)")
    return 0


def cmd_render_environment(args) -> int:
    return render_environment(args.store, args.out, eye=args.eye, environment=args.environment, rotate=args.rotate,
                              frames=args.frames, target=args.target, fov=args.fov, size=args.size,
                              white=args.white, overwrite=args.overwrite, window=args.window,
                              window_width=args.window_width, receiver=args.receiver, at=args.at)


def render_environment(store_path, out, *, eye, environment: str | None = None, rotate: float = 0.0, frames: int = 1,
                       target=None, fov: float = cli_args.FOV, size=cli_args.SIZE, white: float | None = None,
                       overwrite: bool = False, window: str = "none", window_width: float | None = None,
                       receiver=None, at=(0.0, 0.0, 0.0)) -> int:
    """``lodprt render-environment`` with these values: relight, draw and write the PNG(s), report, exit code 0."""
    cli_args.check_picture(fov, white)
    import numpy as np

    from lodprt.display.environment_render import open_relit, save_png
    from lodprt.runtime.environment_relight import rotated_lighting, stored_or_given_lighting

    out = cli_args.require_suffix(out, ".png")
    cli_args.at_least("--frames", frames, 1)
    store, draw = open_relit(store_path, receiver=receiver, at=at)  # a neighbourhood store draws its receiver
    lighting = stored_or_given_lighting(store, store_path, environment)
    from lodprt.model.windowing import apply_window, choose_window

    choice = choose_window(lighting, window, width=window_width)  # before any turn: W-1 commutes with P-4
    lighting = apply_window(lighting, choice.factors)
    paths = [out] if frames == 1 else [out.with_name(f"{out.stem}_{k:04d}.png") for k in range(frames)]
    for p in paths:
        cli_args.refuse_existing(p, overwrite)
    for k, p in enumerate(paths):
        deg = rotate + 360.0 * k / frames
        img, rad = draw(store, rotated_lighting(lighting, deg), eye=eye, target=target, fov=fov,
                                size=tuple(size), white=white)
        if white is None:  # keep the first frame's white for the whole sequence
            pos = rad[rad > 0]
            white = float(np.percentile(pos, 99)) if pos.size else 1.0
        save_png(p, img)
    stale = 0
    if overwrite:  # the numbered frames of an earlier, longer run past these (all of them under one picture)
        from lodprt.display.pictures import remove_stale_frames

        stale = remove_stale_frames(out.parent, f"{out.stem}_", ".png", frames if frames > 1 else 0)
    print(f"wrote {paths[0]}" + (f" ... {paths[-1].name} ({len(paths)} frames)" if len(paths) > 1 else "")
          + f": environment turned {rotate:g} deg" + (f" + 360/{frames} per frame" if len(paths) > 1 else "")
          + (f"; {choice.describe()}" if window != "none" else "")
          + (f" (removed {stale} stale frame{'s' * (stale != 1)} of an earlier run)" if stale else ""))
    return 0
