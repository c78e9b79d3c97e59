"""``lodprt bake``: SH radiance transfer for every light sample of a scene (or, with ``--environment``, distant-light
transfer as ``lodprt bake-environment`` with its defaults)."""

from __future__ import annotations

import argparse
import sys

from lodprt.cli import args as cli_args
from lodprt.cli import environment as environment_cli
from lodprt.cli.progress import ProgressBars
from lodprt.errors import LodprtError

EPILOG_BAKE = """\
examples:
  lodprt bake demo -o demo.zarr
  lodprt bake scene.toml -o bunny.zarr --sh-order 4 --overwrite
  lodprt bake scene.toml -o bunny_gi.zarr --bounces 2 --gi-rays 128 --threshold-deg 0.5   (docs/GI.md)
  lodprt bake scene.toml -o bunny.zarr --hierarchy pymeshlab   (docs/HIERARCHY.md)
  lodprt bake scene.toml -o bunny.zarr --resume          (after a killed bake)
  lodprt bake finer.toml -o bunny.zarr --add-samples     (finer.toml: the same scene, a finer light grid)
  lodprt -v bake scene.toml -o bunny.zarr --workers 4    (dask; -v prints the dashboard link)
  lodprt bake big.toml -o big.zarr --workers 8 --vertex-range 1000000   (a sample as tasks of 1M vertices)
SCENE is 'demo' (the embedded default), a TOML scene file (docs/SCENE.md) or a mesh path."""


def register(sub) -> None:
    """Add ``bake`` to ``sub`` (the subparsers object of the lodprt parser)."""
    b = sub.add_parser(
        "bake",
        help="bake SH radiance transfer for every light sample of a scene",
        description="Bake, for every point-light sample of SCENE, each vertex's outgoing radiance as SH "
        "coefficients over the view direction, and write a zarr store.",
        epilog=EPILOG_BAKE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cli_args.add_scene(b)
    cli_args.add_store_output(b, "lodprt")
    b.add_argument("--sh-order", type=int, default=None, metavar="N",
                   help="SH bands (N*N coefficients), default 4 (3 with --environment)")
    b.add_argument("--environment", default=None, metavar="ENV",
                   help="bake distant-light transfer instead (as bake-environment with its defaults, which lists the "
                   "transfer options): ENV is stored as the default lighting; 'none' stores none")
    cli_args.add_device(b)
    b.add_argument("--threshold-deg", type=float, default=5.0, action=cli_args.Given, metavar="E",
                   help="light cut: collapse lit siblings whose incident angles differ by less than E degrees (default 5)")
    b.add_argument("--full", action="store_true", help="keep every vertex (no light cut)")
    cli_args.add_jobs(b, "one light sample each")
    b.add_argument("--no-hierarchy", action="store_true", help="skip the vertex hierarchy (implies --full: no light cut, no LOD later)")
    cli_args.add_hierarchy_method(b)
    b.add_argument("--resume", action="store_true",
                   help="continue an interrupted bake of OUT (same scene and settings, checked against what it "
                   "recorded): keep its finished samples and bake the rest; a finished OUT is left as it is")
    b.add_argument("--add-samples", action="store_true",
                   help="extend the existing store OUT to the scene's light grid (a finer grid or a bigger box that "
                   "contains every old sample position), baking only the new samples (docs/DISTRIBUTED.md)")
    b.add_argument("--workers", type=int, default=None, metavar="N",
                   help="bake the light samples on a local dask cluster of N worker processes, --jobs threads each "
                   "(default 1); needs pip install 'lodprt[distributed]'")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="bake the light samples on the running dask cluster at ADDRESS (tcp://host:port); every "
                   "worker must see OUT's folder at the same path")
    b.add_argument("--vertex-range", type=int, default=None, metavar="N",
                   help="with --workers or --scheduler: split a light sample of more than N baked vertices into "
                   "ceil(vertices/N) dask tasks of contiguous vertex ranges on different workers, joined into the "
                   "same store (default: off, a sample is one task; not with --bounces; docs/DISTRIBUTED.md)")
    gi = b.add_argument_group("interreflection (docs/GI.md)")
    gi.add_argument("--bounces", type=int, default=0, metavar="B",
                    help="diffuse interreflection passes after the direct light (default 0: direct light only)")
    gi.add_argument("--bounce-threshold", type=float, default=1e-3, action=cli_args.Given, metavar="T",
                    help="stop the passes early once one carries less than T times the direct light's power "
                    "(default 1e-3)")
    gi.add_argument("--gi-rays", type=int, default=64, action=cli_args.Given, metavar="R",
                    help="gathering rays per vertex and pass, cosine-weighted (default 64)")
    gi.add_argument("--indirect-threshold-deg", type=float, default=10.0, action=cli_args.Given, metavar="E",
                    help="light cut: gather indirect light only on the indirect cut, whose nodes' bounding spheres "
                    "and normal cones span at most E degrees seen from the nearest surface (default 10); the other "
                    "vertices are completed (T-15)")
    gi.add_argument("--indirect-tolerance", type=float, default=None, action=cli_args.Given, metavar="TAU",
                    help="light cut: choose where to gather per sample and pass by the indirect light itself "
                    "instead of --indirect-threshold-deg (G-9): refine from a coarse level of the hierarchy where "
                    "the gathered irradiance departs from its completion (T-15), within a budget: each pass' "
                    "estimated error against gathering at every vertex within TAU times the RMS direct radiance "
                    "(RMS over the vertices); the actual error runs up to 2 times that at 0.01-0.02, more at smaller "
                    "TAU (e.g. 0.01; in (0, 1]; default: off; docs/GI.md)")
    b.add_argument("--compress", default="none", metavar="CODEC",
                   help="store the light samples with a lossy codec (format version 2, docs/FORMAT.md): none "
                   "(default, float32), f16, q8, q10, q12 (integers per vertex and SH band) or "
                   "cpca:CLUSTERS:VECTORS[:BITS] (clustered PCA over vertices x samples, e.g. cpca:256:3); the "
                   "finished store is re-encoded in place, as lodprt compress does")
    b.set_defaults(handler=cmd_bake)


def cmd_bake(args) -> int:
    if args.environment is not None:
        return _bake_environment(args)
    from lodprt.devices import resolve_device
    from lodprt.model.scene import load_scene
    from lodprt.precompute.bake import bake

    _refuse_unread(args)
    cli_args.at_least("--jobs", args.jobs, 1)
    cli_args.at_least("--workers", args.workers, 1)
    cli_args.at_least("--vertex-range", args.vertex_range, 1)
    if args.workers is not None and args.scheduler is not None:
        raise LodprtError("--workers and --scheduler: give one (a local cluster, or the address of a running one)")
    from lodprt.store.codecs import parse_codec

    parse_codec(args.compress, "--compress")  # a bad codec fails before any work
    from lodprt.model.hierarchy_build import check_method

    check_method(args.hierarchy)  # and so does an unknown hierarchy build
    from lodprt.precompute.bake import check_hierarchy, check_sh_order, light_cut_threshold

    if args.sh_order is not None:  # and a bad order or threshold, named as the options
        check_sh_order(args.sh_order, name="--sh-order")
    full = args.full or args.no_hierarchy
    check_hierarchy(not args.no_hierarchy, light_cut_threshold(args.threshold_deg, full=full,
                                                                 hierarchy=not args.no_hierarchy),
                    args.hierarchy, name="--threshold-deg")
    from lodprt.precompute.gi import GISettings

    tol = args.indirect_tolerance
    if tol is not None and not 0 < tol <= 1:  # the library's words name None, no option
        raise LodprtError(f"--indirect-tolerance {tol:g}: must lie in (0, 1] (a relative RMS error of the indirect "
                          "radiance, G-9)")
    GISettings(args.bounces, args.bounce_threshold, args.gi_rays, args.indirect_threshold_deg,  # and bad GI values
               indirect_tolerance=args.indirect_tolerance)
    device = resolve_device(args.device)  # refuse an unavailable device before loading anything
    scene = load_scene(args.scene)
    n = scene.lights.positions.shape[0]
    print(
        f"scene {scene.source}: {scene.num_vertices:,} vertices ({int(scene.referenced.sum()):,} referenced), "
        f"{len(scene.faces):,} triangles, {n} light samples",
        file=sys.stderr,
    )
    with ProgressBars() as bars:
        res = bake(
            scene,
            args.out,
            sh_order=4 if args.sh_order is None else args.sh_order,
            device=device,
            overwrite=args.overwrite,
            jobs=args.jobs,
            hierarchy=not args.no_hierarchy,
            hierarchy_method=args.hierarchy,
            threshold_deg=args.threshold_deg, full=args.full or args.no_hierarchy,
            progress=bars.callback("bake", "sample"),
            hierarchy_progress=bars.callback("hierarchy", "collapse"),
            resume=args.resume,
            add_samples=args.add_samples,
            workers=args.workers,
            scheduler=args.scheduler,
            vertex_range=args.vertex_range,
            bounces=args.bounces,
            bounce_threshold=args.bounce_threshold,
            gi_rays=args.gi_rays,
            indirect_threshold_deg=args.indirect_threshold_deg,
            indirect_tolerance=args.indirect_tolerance,
            compress=args.compress,
        )
    _report(scene, res)
    return 0


#: the interreflection options (a light cut's indirect cut: the last two), which only --bounces reads
GI_OPTIONS = ("bounce_threshold", "gi_rays", "indirect_threshold_deg", "indirect_tolerance")


def _flags(args, dests) -> list[str]:
    """The options of ``dests`` given explicitly (``cli_args.Given``), as flags."""
    return ["--" + d.replace("_", "-") for d in dests if cli_args.given(args, d)]


def _refuse_unread(args) -> None:
    """Refuse options given explicitly that this bake would drop unread (they were ignored without a word)."""
    if args.environment is not None:
        return  # _bake_environment refuses the point-light options
    if not args.bounces:
        unread = _flags(args, GI_OPTIONS)
        if unread:
            raise LodprtError(f"{', '.join(unread)} without --bounces: with no --bounces B >= 1 the bake is direct "
                              "light only, which reads no interreflection option")
    if cli_args.given(args, "indirect_threshold_deg") and args.indirect_tolerance is not None:
        raise LodprtError("--indirect-threshold-deg and --indirect-tolerance: the tolerance chooses where to gather "
                          "instead of the angle (G-9); give one")
    full = "--no-hierarchy" if args.no_hierarchy else "--full" if args.full else None
    if full is None:
        return
    if args.no_hierarchy:
        unread = _flags(args, ("hierarchy",))
        if unread:
            raise LodprtError(f"--hierarchy {args.hierarchy} and --no-hierarchy: --no-hierarchy builds no hierarchy")
    unread = _flags(args, ("threshold_deg",))
    if unread:
        raise LodprtError(f"--threshold-deg {args.threshold_deg:g} and {full}: the light cut needs the hierarchy; "
                          f"{full} bakes every vertex (no light cut)")
    unread = _flags(args, GI_OPTIONS[2:]) if args.bounces else []
    if unread:
        raise LodprtError(f"{', '.join(unread)} and {full}: the indirect cut is a light cut's; {full} gathers at "
                          "every vertex (no light cut)")


def _bake_environment(args) -> int:
    """``bake SCENE --environment ENV``: distant-light transfer, as bake-environment with its defaults."""
    if (args.resume or args.add_samples or args.workers is not None or args.scheduler is not None
            or args.vertex_range is not None):
        raise LodprtError("--resume, --add-samples, --workers, --scheduler and --vertex-range are point-light bake "
                          "options; an environment bake runs in one process and starts afresh")
    if args.bounces:
        raise LodprtError("--bounces is a point-light option; an environment bake takes its passes from "
                          "bake-environment --bounces")
    if args.compress != "none":
        raise LodprtError("--compress is a point-light option; the transfer store of --environment has no codec")
    from lodprt.model.hierarchy_build import METHODS

    if cli_args.given(args, "hierarchy"):
        raise LodprtError("--hierarchy is a point-light option; an environment bake builds its hierarchy with "
                          f"bake-environment --lod-threshold ({METHODS[0]})")
    if args.full or args.no_hierarchy:
        raise LodprtError("--full and --no-hierarchy are point-light options; an environment bake has no light "
                          "cut (see bake-environment --lod-threshold)")
    unread = _flags(args, ("threshold_deg", *GI_OPTIONS))
    if unread:
        raise LodprtError(f"{', '.join(unread)}: point-light bake option{'s' * (len(unread) > 1)}; an environment "
                          "bake takes its own from bake-environment (--lod-threshold, --rays, --bounce-threshold)")
    options = {} if args.sh_order is None else {"sh_order": args.sh_order}
    return environment_cli.bake_environment(
        args.scene, args.out, environment=None if args.environment == "none" else args.environment,
        device=args.device or None, jobs=args.jobs, overwrite=args.overwrite, **options)


def _report(scene, res) -> None:
    import numpy as np

    kb = np.mean([s["bytes"] for s in res.samples]) / 1024
    if res.reused_samples:
        print(f"{res.reused_samples} of {len(res.samples)} light samples were already in the store; baked "
              f"{len(res.samples) - res.reused_samples}", file=sys.stderr)
    kept = np.mean([s["vertices_kept"] for s in res.samples])
    print(f"kept {kept:,.0f} of {int(scene.referenced.sum()):,} vertices per sample on average", file=sys.stderr)
    print(
        f"wrote {res.path}: {res.coefficients_per_vertex} coefficient(s) x {res.channels} channel(s) per vertex, "
        f"{kb:,.0f} KiB per sample, bake {res.bake_seconds:.2f} s on {res.device} (+{res.load_seconds:.2f} s kernel load"
        + (f", +{res.hierarchy_seconds:.1f} s hierarchy)" if res.hierarchy_seconds is not None else ")")
    )
