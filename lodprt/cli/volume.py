"""The commands of transfer in space rather than on a surface (patent 4.3 and 5; docs/VOLUMES.md): bake-volume,
render-volume and bake-neighbourhood. (A neighbourhood store is drawn with its receiver by
``lodprt render-environment STORE --receiver MESH --at X Y Z``.) The work is done in
:mod:`lodprt.precompute.volume`, :mod:`lodprt.display.volume_render` and :mod:`lodprt.precompute.neighbourhood`.
"""

from __future__ import annotations

import sys

from lodprt.cli import args as cli_args
from lodprt.cli.progress import ProgressBars
from lodprt.errors import LodprtError

ENV_HELP = "lighting: a lat-long .hdr/.exr/.npy, a .npy cube, a folder of six faces, or sky, spots, constant"
VOLUME_HELP = ("'cloud' or 'cloud:N' (procedural, N voxels along x), a .npy (X, Y, Z) float32 density grid "
               "(with --bounds), or a .toml/.json description (density, bounds, albedo, density_scale)")
SH_ORDER = 3
VOLUME_RAYS = 128
VOLUME_BOUNCES = 2
NEIGHBOURHOOD_RAYS = 256
GRID = (16, 16, 16)
MARGIN = 1.0


def register(sub) -> None:
    """Add bake-volume, render-volume and bake-neighbourhood to ``sub`` (the lodprt parser's subparsers)."""
    _add_bake_volume(sub)
    _add_render_volume(sub)
    _add_bake_neighbourhood(sub)


def _add_bake_volume(sub) -> None:
    bv = sub.add_parser(
        "bake-volume",
        help="bake volumetric self-transfer (shadowed + scattered light per voxel) of a density grid",
        description="Per voxel of a participating medium, the SH transfer vector of the light it scatters "
        "(isotropic phase): attenuation along R directions through the grid (shadowed pass) plus --bounces "
        "scattering passes. Writes a lodprt-volume zarr store (docs/VOLUMES.md).",
    )
    bv.add_argument("volume", metavar="VOLUME", help=VOLUME_HELP)
    cli_args.add_store_output(bv, "volume")
    bv.add_argument("--bounds", type=cli_args.finite, nargs=6, default=None, metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
                    help="box of a .npy grid (overrides a description's bounds)")
    bv.add_argument("--albedo", type=cli_args.finite, nargs="+", default=None, metavar="A",
                    help="single-scattering albedo, one value or R G B in [0, 1] (default 0.9 or the description's)")
    bv.add_argument("--density-scale", type=cli_args.finite, default=None, metavar="S", help="multiply the density by S (default 1)")
    bv.add_argument("--sh-order", type=int, default=SH_ORDER, metavar="N", help=f"SH bands (default {SH_ORDER})")
    bv.add_argument("--rays", type=int, default=VOLUME_RAYS, metavar="R", help=f"directions per voxel (default {VOLUME_RAYS})")
    bv.add_argument("--bounces", type=int, default=VOLUME_BOUNCES, metavar="B",
                    help=f"most scattering passes after the shadowed one (default {VOLUME_BOUNCES})")
    bv.add_argument("--bounce-threshold", type=float, default=1e-3, metavar="T",
                    help="stop when a pass' energy is below T times the shadowed pass' (default 0.001)")
    bv.add_argument("--step", type=cli_args.finite, default=None, metavar="H",
                    help="largest ray-march step in scene units (default half the smallest voxel edge; at most "
                    "2^20 = 1,048,576 steps across the box's diagonal: a smaller H is refused)")
    bv.add_argument("--rotate-rays", action="store_true", help="turn the shadowed pass' ray set per voxel at random")
    bv.add_argument("--environment", default=None, metavar="ENV", help="store this lighting as the default; " + ENV_HELP)
    cli_args.add_device(bv)
    cli_args.add_jobs(bv, "each launching a range of voxels")
    bv.set_defaults(handler=cmd_bake_volume)


def _add_render_volume(sub) -> None:
    rv = sub.add_parser(
        "render-volume",
        help="render a volume bake relit by an environment (ray marching, alpha compositing)",
        description="Relight a lodprt-volume store (one dot product per voxel and channel) and ray-march it with "
        "front-to-back alpha compositing in an OpenGL fragment shader (offscreen EGL) into a PNG.",
    )
    cli_args.add_store(rv)
    rv.add_argument("--environment", default=None, metavar="ENV", help="lighting (default: the bake's own); " + ENV_HELP)
    rv.add_argument("--rotate", type=cli_args.finite, default=0.0, metavar="DEG", help="turn the environment about +y by DEG degrees")
    cli_args.add_camera(rv)
    rv.add_argument("--step", type=cli_args.finite, default=None, metavar="H", help="largest march step (default: the bake's)")
    rv.add_argument("--white", type=cli_args.finite, default=None, metavar="L",
                    help="radiance shown as white (default: 99th percentile of the covered pixels)")
    rv.add_argument("--background", type=cli_args.finite, nargs=3, default=(0.0, 0.0, 0.0), metavar=("R", "G", "B"),
                    help="linear radiance behind the medium (default black)")
    cli_args.add_output(rv, "img.png", "output PNG")
    rv.set_defaults(handler=cmd_render_volume)


def _add_bake_neighbourhood(sub) -> None:
    bn = sub.add_parser(
        "bake-neighbourhood",
        help="bake neighbourhood transfer: matrices on a 3-D grid around one object of a scene (its shadow and "
        "reflected light on receivers placed later)",
        description="At each point of a grid around --object, the matrix M_p that maps the distant lighting's SH "
        "to the SH of the radiance arriving at p as the object modifies it (occlusion, and the light the object "
        "reflects). Other objects of the scene are ignored. Writes a lodprt-neighbourhood zarr store; draw it with "
        "lodprt render-environment STORE --receiver MESH --at X Y Z (docs/VOLUMES.md).",
    )
    cli_args.add_scene(bn)
    bn.add_argument("--object", required=True, metavar="NAME", help="the object O whose neighbourhood is baked")
    cli_args.add_store_output(bn, "neighbourhood")
    bn.add_argument("--grid", type=int, nargs=3, default=GRID, metavar=("NX", "NY", "NZ"),
                    help=f"grid points per axis, corners included (default {' '.join(map(str, GRID))})")
    bn.add_argument("--margin", type=float, default=MARGIN, metavar="M",
                    help=f"the grid reaches M times the object's largest extent beyond its bounds (default {MARGIN:g})")
    bn.add_argument("--sh-order", type=int, default=SH_ORDER, metavar="N", help=f"SH bands of the lighting (default {SH_ORDER})")
    bn.add_argument("--transferred-order", type=int, default=None, metavar="N",
                    help="SH bands of the transferred radiance L'_p (default --sh-order; more bands keep more of "
                    "the product of occlusion and lighting, docs/VOLUMES.md)")
    bn.add_argument("--rays", type=int, default=NEIGHBOURHOOD_RAYS, metavar="R",
                    help=f"directions per grid point (default {NEIGHBOURHOOD_RAYS})")
    bn.add_argument("--no-reflection", action="store_true", help="occlusion only: leave out the light O reflects")
    bn.add_argument("--bounces", type=int, default=1, metavar="B",
                    help="interreflection passes of O's own transfer, which its reflected light uses (default 1)")
    bn.add_argument("--environment", default=None, metavar="ENV", help="store this lighting as the default; " + ENV_HELP)
    cli_args.add_device(bn)
    cli_args.add_jobs(bn, "each launching a range of grid points")
    bn.set_defaults(handler=cmd_bake_neighbourhood)


def cmd_bake_volume(args) -> int:
    from lodprt.devices import resolve_device
    from lodprt.model.environment import load_environment
    from lodprt.model.volume import load_volume
    from lodprt.model.volume import check_bounds
    from lodprt.precompute.volume import bake_volume, check_step

    cli_args.at_least("--jobs", args.jobs, 1)
    if args.bounds is not None:
        check_bounds(args.bounds[:3], args.bounds[3:], "--bounds")
    device = resolve_device(args.device)
    vol = load_volume(args.volume, bounds=args.bounds, albedo=args.albedo, density_scale=args.density_scale)
    check_step(vol, args.step, "--step")  # before any work: a tiny step marched without end
    env = load_environment(args.environment) if args.environment else None
    print(f"volume {vol.source}: {' x '.join(map(str, vol.shape))} voxels, box {vol.lo.tolist()} .. {vol.hi.tolist()}, "
          f"albedo {vol.albedo.tolist()}", file=sys.stderr)
    with ProgressBars() as bars:
        res = bake_volume(vol, args.out, sh_order=args.sh_order, rays=args.rays, bounces=args.bounces,
                          bounce_threshold=args.bounce_threshold, step=args.step, rotate=args.rotate_rays, environment=env,
                          device=device, overwrite=args.overwrite, progress=bars.callback("volume", "pass"),
                          jobs=args.jobs)
    t = res.transfer
    print(f"wrote {res.path}: order {t.order}, {t.rays} rays/voxel, {len(t.energy) - 1} scattering pass(es) (energy "
          + ", ".join(f"{e:.3g}" for e in t.energy) + f"), step {t.step:.4g}; bake {t.seconds:.2f} s on {res.device} "
          f"(+{res.load_seconds:.2f} s kernel load)")
    return 0


def cmd_render_volume(args) -> int:
    from lodprt.display.volume_render import render_volume, save_png
    from lodprt.runtime.environment_relight import rotated_lighting, stored_or_given_lighting
    from lodprt.runtime.volume_relight import open_volume

    cli_args.check_picture(args.fov, args.white, args.background)
    out = cli_args.new_output(args.out, ".png", args.overwrite)
    store = open_volume(args.store)
    lighting = rotated_lighting(stored_or_given_lighting(store, args.store, args.environment), args.rotate)
    img, _, alpha = render_volume(store, lighting, eye=args.eye, target=args.target, fov=args.fov,
                                  size=tuple(args.size), white=args.white, step=args.step, background=args.background)
    save_png(out, img)
    print(f"wrote {out}: {img.shape[1]} x {img.shape[0]}, medium covers {float((alpha > 0.01).mean()):.1%} of the "
          f"pixels, environment turned {args.rotate:g} deg")
    return 0


def cmd_bake_neighbourhood(args) -> int:
    from lodprt.devices import resolve_device
    from lodprt.model.environment import load_environment
    from lodprt.model.scene import load_scene
    from lodprt.precompute.neighbourhood import bake_neighbourhood

    cli_args.at_least("--jobs", args.jobs, 1)
    device = resolve_device(args.device)
    scene = load_scene(args.scene)
    env = load_environment(args.environment) if args.environment else None
    with ProgressBars() as bars:
        res = bake_neighbourhood(scene, args.object, args.out, grid=tuple(args.grid), margin=args.margin,
                                 sh_order=args.sh_order, transferred_order=args.transferred_order, rays=args.rays,
                                 reflection=not args.no_reflection, bounces=args.bounces, environment=env,
                                 device=device, overwrite=args.overwrite, progress=bars.callback("grid", "pass"),
                                 jobs=args.jobs)
    print(f"wrote {res.path}: object {args.object!r} ({res.object_vertices:,} vertices), grid "
          f"{' x '.join(map(str, res.shape))} over {res.lo.round(4).tolist()} .. {res.hi.round(4).tolist()}, "
          f"matrices {res.matrices.shape[-2]} x {res.matrices.shape[-1]}"
          + (" with reflection" if res.reflection else " (occlusion only)")
          + f"; bake {res.seconds:.2f} s on {res.device}")
    return 0
