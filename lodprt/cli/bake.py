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
    b.add_argument("--threshold-deg", type=float, default=5.0, metavar="E",
                   help="light cut: collapse lit siblings whose incident angles differ by less than E degrees (default 5)")
    b.add_argument("--full", action="store_true", help="keep every vertex (no light cut)")
    cli_args.add_jobs(b, "one light sample each")
    b.add_argument("--no-hierarchy", action="store_true", help="skip the vertex hierarchy (implies --full: no light cut, no LOD later)")
    b.set_defaults(handler=cmd_bake)


def cmd_bake(args) -> int:
    if args.environment is not None:
        return _bake_environment(args)
    from lodprt.devices import resolve_device
    from lodprt.model.scene import load_scene
    from lodprt.precompute.bake import bake

    cli_args.at_least("--jobs", args.jobs, 1)
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
            threshold_deg=None if args.full or args.no_hierarchy else args.threshold_deg,
            progress=bars.callback("bake", "sample"),
            hierarchy_progress=bars.callback("hierarchy", "collapse"),
        )
    _report(scene, res)
    return 0


def _bake_environment(args) -> int:
    """``bake SCENE --environment ENV``: distant-light transfer, as bake-environment with its defaults."""
    if args.full or args.no_hierarchy:
        raise LodprtError("--full and --no-hierarchy are point-light options; an environment bake has no light "
                          "cut (see bake-environment --lod-threshold)")
    options = {} if args.sh_order is None else {"sh_order": args.sh_order}
    return environment_cli.bake_environment(
        args.scene, args.out, environment=None if args.environment == "none" else args.environment,
        device=args.device or None, jobs=args.jobs, overwrite=args.overwrite, **options)


def _report(scene, res) -> None:
    import numpy as np

    kb = np.mean([s["bytes"] for s in res.samples]) / 1024
    kept = np.mean([s["vertices_kept"] for s in res.samples])
    print(f"kept {kept:,.0f} of {int(scene.referenced.sum()):,} vertices per sample on average", file=sys.stderr)
    print(
        f"wrote {res.path}: {res.coefficients_per_vertex} coefficient(s) x {res.channels} channel(s) per vertex, "
        f"{kb:,.0f} KiB per sample, bake {res.bake_seconds:.2f} s on {res.device} (+{res.load_seconds:.2f} s kernel load"
        + (f", +{res.hierarchy_seconds:.1f} s hierarchy)" if res.hierarchy_seconds is not None else ")")
    )
