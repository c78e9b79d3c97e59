"""The environment-lighting commands of ``lodprt``: irradiance, bake-environment, render-environment.

``lodprt.cli.main`` registers them with :func:`add_parsers` and dispatches through :data:`COMMANDS`; the work is done
in :mod:`lodprt.model.environment`, :mod:`lodprt.model.irradiance`, :mod:`lodprt.precompute.transfer` and :mod:`lodprt.runtime.environment_relight`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from lodprt.errors import LodprtError

ENV_HELP = ("environment: a lat-long .hdr/.exr/.npy (H, 2H, 3), a .npy cube (6, N, N, 3), a folder of six faces "
            "px nx py ny pz nz, or a procedural name: sky, spots, constant (sky:256 sets the resolution)")


def add_parsers(sub) -> None:
    """Add the three subcommands to ``sub`` (the subparsers object of the lodprt parser)."""
    ir = sub.add_parser(
        "irradiance",
        help="9-coefficient irradiance of an environment (Ramamoorthi-Hanrahan): coefficients, constants, matrices",
        description="Project the environment's linear RGB radiance onto 9 SH coefficients per channel and print "
        "them with A_l, the table-1 constants c1..c5, the 4x4 matrix M of E(n) = n^T M n per channel and the 7 "
        "vec4 shader registers cAr..cC.",
    )
    ir.add_argument("environment", metavar="ENV", help=ENV_HELP)
    ir.add_argument("--mip", type=int, default=0, metavar="K", help="project from mip level K (each level halves the resolution)")
    ir.add_argument("--json", action="store_true", help="print a JSON object")

    be = sub.add_parser(
        "bake-environment",
        help="bake distant-light transfer (diffuse vectors, glossy matrices) for every vertex of a scene",
        description="Bake per-vertex transfer for distant (environment) lighting: diffuse unshadowed, shadowed or "
        "interreflected transfer vectors, and glossy transfer matrices for materials with ks > 0. Writes a "
        "lodprt-transfer zarr store (docs/ENVIRONMENT.md).",
    )
    be.add_argument("scene", metavar="SCENE", help="'demo', a .toml scene file, or a mesh")
    be.add_argument("-o", "--out", required=True, metavar="OUT.zarr", help="store to write (never replaced without --overwrite)")
    be.add_argument("--environment", default=None, metavar="ENV", help="store this environment's coefficients as the default lighting; " + ENV_HELP)
    be.add_argument("--sh-order", type=int, default=3, metavar="N", help="SH bands of the transfer (default 3: 9 coefficients)")
    be.add_argument("--transfer", choices=["unshadowed", "shadowed", "interreflected"], default="interreflected",
                    help="diffuse transfer (default interreflected)")
    be.add_argument("--rays", type=int, default=256, metavar="R", help="rays per vertex (spherical Fibonacci set, default 256)")
    be.add_argument("--bounces", type=int, default=4, metavar="B", help="most interreflection passes (default 4)")
    be.add_argument("--bounce-threshold", type=float, default=1e-3, metavar="T",
                    help="stop when a pass' energy is below T times the direct pass' (default 1e-3)")
    be.add_argument("--rotate-rays", action="store_true", help="turn the ray set by a random rotation per vertex")
    be.add_argument("--no-glossy", action="store_true", help="skip the glossy matrices")
    be.add_argument("--glossy-order", type=int, default=None, metavar="N", help="bands of the glossy transferred radiance (default: --sh-order)")
    be.add_argument("--lod-threshold", type=float, default=None, metavar="E",
                    help="level of detail: build the vertex hierarchy and store transfer vectors only where they differ "
                    "by more than E (relative) across a node's leaves; the rest are completed on reading (T-15)")
    be.add_argument("--device", default=None, metavar="DEV", help="Warp device: cpu, cuda, cuda:N")
    be.add_argument("--jobs", type=int, default=None, metavar="J", help="CPU threads launching vertex ranges (default: all cores)")
    be.add_argument("--overwrite", action="store_true", help="replace OUT if it is an existing transfer store")

    re = sub.add_parser(
        "render-environment",
        help="render a transfer bake relit by an environment, optionally rotated about +y",
        description="Relight a lodprt-transfer store by an environment turned by --rotate degrees about +y "
        "(diffuse dot products, glossy matrix-vector + Phong convolution + evaluation in the reflection "
        "direction) and draw it offscreen (EGL) into a PNG.",
    )
    re.add_argument("store", metavar="OUT.zarr")
    re.add_argument("--environment", default=None, metavar="ENV", help="lighting (default: the one stored by the bake); " + ENV_HELP)
    re.add_argument("--rotate", type=float, default=0.0, metavar="DEG", help="turn the environment about +y by DEG degrees")
    re.add_argument("--frames", type=int, default=1, metavar="N",
                    help="N > 1: N images turning the environment by 360/N degrees each, OUT_0000.png ... (default 1)")
    re.add_argument("--eye", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"), help="eye position")
    re.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"), help="look-at point (default: scene centre)")
    re.add_argument("--fov", type=float, default=40.0, metavar="DEG", help="vertical field of view (default 40)")
    re.add_argument("--size", type=int, nargs=2, default=(800, 600), metavar=("W", "H"), help="image size in pixels")
    re.add_argument("--white", type=float, default=None, metavar="L", help="radiance shown as white (default: 99th percentile of the first frame)")
    re.add_argument("-o", "--out", required=True, metavar="img.png", help="output PNG (not replaced without --overwrite)")
    re.add_argument("--overwrite", action="store_true", help="replace existing output")


def _cmd_irradiance(args) -> int:
    from lodprt.model import irradiance as irr
    from lodprt.model.environment import load_environment

    env = load_environment(args.environment)
    if args.mip:
        env = env.mip(args.mip)
    coeffs = irr.lighting_coefficients(env)
    doc = irr.describe(coeffs)
    doc["environment"] = {"source": env.source, "kind": env.kind, "shape": list(env.data.shape[:-1]),
                          "mip_level": args.mip}
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
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
    return 0


def _cmd_bake_environment(args) -> int:
    from tqdm import tqdm

    from lodprt.devices import resolve_device
    from lodprt.model.environment import load_environment
    from lodprt.model.scene import load_scene
    from lodprt.precompute.transfer import bake_transfer

    if args.jobs is not None and args.jobs < 1:
        raise LodprtError(f"--jobs {args.jobs}: must be >= 1")
    device = resolve_device(args.device)
    env = load_environment(args.environment) if args.environment else None
    scene = load_scene(args.scene)
    print(f"scene {scene.source}: {scene.num_vertices:,} vertices, {len(scene.faces):,} triangles", file=sys.stderr)
    bar = None

    def progress(done, total):
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, unit="pass", desc="transfer", file=sys.stderr)
        bar.update(done - bar.n)

    try:
        res = bake_transfer(scene, args.out, order=args.sh_order, mode=args.transfer, rays=args.rays,
                            bounces=args.bounces, threshold=args.bounce_threshold, glossy=not args.no_glossy,
                            glossy_order=args.glossy_order, rotate=args.rotate_rays, environment=env, device=device,
                            lod_threshold=args.lod_threshold, overwrite=args.overwrite, progress=progress,
                            jobs=args.jobs)
    finally:
        if bar is not None:
            bar.close()
    e = res.diffuse.energy
    print(f"wrote {res.path}: order {args.sh_order} {args.transfer} transfer, {args.rays} rays/vertex, "
          f"{len(e) - 1} bounce pass(es) (energy " + ", ".join(f"{x:.3g}" for x in e) + f"), "
          f"{len(res.glossy_ids):,} glossy matrices; "
          + (f"LOD keeps {len(res.cut_nodes):,} of {scene.num_vertices:,} vertices; " if res.cut_nodes is not None else "")
          + f"bake {res.seconds:.2f} s on {res.device} "
          f"(+{res.load_seconds:.2f} s kernel load)")
    return 0


def _cmd_render_environment(args) -> int:
    import numpy as np

    from lodprt.model.environment import load_environment
    from lodprt.runtime.environment_relight import open_transfer, render_relit, rotated_lighting, save_png

    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise LodprtError(f"{out}: the output must be a .png file")
    if args.frames < 1:
        raise LodprtError(f"--frames {args.frames}: must be >= 1")
    store = open_transfer(args.store)
    if args.environment:
        lighting = load_environment(args.environment).project(store.order)
    elif store.has("environment/coefficients"):
        lighting = store.read("environment/coefficients")
    else:
        raise LodprtError(f"{args.store}: the bake stored no environment; pass --environment ENV")
    paths = [out] if args.frames == 1 else [out.with_name(f"{out.stem}_{k:04d}.png") for k in range(args.frames)]
    for p in paths:
        if p.exists() and not args.overwrite:
            raise LodprtError(f"{p}: already exists; pass --overwrite to replace it")
    white = args.white
    for k, p in enumerate(paths):
        deg = args.rotate + 360.0 * k / args.frames
        img, rad = render_relit(store, rotated_lighting(lighting, deg), eye=args.eye, target=args.target, fov=args.fov,
                                size=tuple(args.size), white=white)
        if white is None:  # keep the first frame's white for the whole sequence
            pos = rad[rad > 0]
            white = float(np.percentile(pos, 99)) if pos.size else 1.0
        save_png(p, img)
    print(f"wrote {paths[0]}" + (f" ... {paths[-1].name} ({len(paths)} frames)" if len(paths) > 1 else "")
          + f": environment turned {args.rotate:g} deg" + (f" + 360/{args.frames} per frame" if len(paths) > 1 else ""))
    return 0


COMMANDS = {
    "irradiance": _cmd_irradiance,
    "bake-environment": _cmd_bake_environment,
    "render-environment": _cmd_render_environment,
}
