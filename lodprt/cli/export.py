"""``lodprt export``: a lit frame of a bake store (view cut or full mesh) as a binary glTF with per-vertex radiance
and SH coefficients (:mod:`lodprt.display.export`, docs/EXPORT.md)."""

from __future__ import annotations

from lodprt.cli import args as cli_args


def register(sub) -> None:
    """Add export to ``sub`` (the subparsers object of the lodprt parser)."""
    ex = sub.add_parser(
        "export",
        help="write a lit frame as a .glb: mesh (view cut or full), COLOR_0 radiance, SH coefficients _SH_0..",
        description="Light the store (light sample K, or point lights interpolated as in render), choose the view "
        "cut for the camera as render does (--full: the full mesh) and write a binary glTF 2.0 file: positions, "
        "normals, triangles, COLOR_0 = the radiance toward the eye (--vertex-colors display: tone-mapped as render "
        "shows it, before the sRGB curve a glTF viewer applies; linear: the radiance over its maximum), the custom attributes "
        "_SH_0.._SH_{n-1} (VEC3 float: the RGB SH coefficients of the outgoing radiance over the view direction, "
        "intensities applied), _RADIANCE (linear radiance: their SH reconstruction, unclipped, which can ring below 0) "
        "and _VERTEX_ID (index in the store), and an unlit "
        "material (docs/EXPORT.md).",
    )
    cli_args.add_store(ex)
    which = ex.add_mutually_exclusive_group()
    cli_args.add_sample(which)
    cli_args.add_light(which, help="a point light's position (repeat for several lights; default: one light at "
                       "the middle light sample)")
    cli_args.add_colors(ex)
    cli_args.add_camera(ex, eye_required=False, up=True, size_what="screen size the view cut is chosen for")
    cli_args.add_view_cut(ex)
    ex.add_argument("--full", action="store_true", help="LOD off: export the full-resolution mesh")
    ex.add_argument("--vertex-colors", choices=("display", "linear"), default="display",
                    help="COLOR_0 (glTF keeps it in [0, 1]): display = clip(2^exposure L / white, 0, 1) in linear "
                    "light, as render shows it (default); linear = L / max(L), proportional to the radiance L (the "
                    "scale is in asset.extras.lodprt.color_scale); _RADIANCE always holds L unclipped (the SH "
                    "reconstruction: it can ring below 0)")
    ex.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="display colours: exposure in stops (default 0)")
    ex.add_argument("--white", type=float, default=None, metavar="L",
                    help="display colours: radiance shown as white (default: the run time's white point, as render)")
    cli_args.add_output(ex, "OUT.glb", "output .glb")
    ex.set_defaults(handler=cmd_export)


def cmd_export(args) -> int:
    from lodprt.display.export import check_glb_output, export_glb
    from lodprt.store.bake_store import open_store

    check_glb_output(args.out, args.overwrite)  # before the store is read and lit
    cli_args.check_tone(args.white, args.exposure)
    if args.light is not None:
        cli_args.check_colors(args.color, args.light)
    cli_args.refuse_with_full(args)
    criterion = cli_args.criterion(args)
    store = open_store(args.store)
    stats = export_glb(store, args.out, sample=args.sample, lights=args.light, colors=args.color, eye=args.eye,
                       target=args.target, up=args.up, fov=args.fov, size=args.size, lod=not args.full,
                       criterion=criterion, interpolation=args.interpolation, outside=args.outside,
                       vertex_colors=args.vertex_colors, white=args.white, exposure=args.exposure,
                       overwrite=args.overwrite)
    mapping = (f"white {stats['white']:.4g}" if "white" in stats else f"scale {stats['color_scale']:.4g}")
    print(f"wrote {stats['path']}: {stats['vertices']:,} vertices, {stats['triangles']:,} triangles "
          f"({'view cut' if stats['lod'] else 'full resolution'}), {stats['sh_coefficients']} SH coefficient(s) "
          f"per channel, COLOR_0 {args.vertex_colors} ({mapping}), {stats['bytes'] / 1024:,.0f} KiB")
    return 0
