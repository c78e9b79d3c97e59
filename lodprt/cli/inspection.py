"""``lodprt info`` and ``radiance``: what a bake store holds and the radiance it reconstructs toward an eye."""

from __future__ import annotations

import json
import sys

from lodprt.cli import args as cli_args
from lodprt.errors import LodprtError, StoreError


def register(sub) -> None:
    """Add info and radiance to ``sub`` (the subparsers object of the lodprt parser)."""
    _add_info(sub)
    _add_radiance(sub)


def _add_info(sub) -> None:
    i = sub.add_parser("info", help="summarise a store", description="Print what a bake store holds: mesh, SH order, hierarchy, the light box (the sampled region of --light), bake time, bytes and the light samples; of a transfer, volume or neighbourhood store, its settings and arrays.")
    cli_args.add_store(i)
    cli_args.add_json(i, "a JSON object (vertices, sh_order, bake_seconds, light_box, samples, damage, ...)")
    i.add_argument("--verify", action="store_true",
                   help="read every array whole, so that a garbled chunk is found too (without it: chunk files "
                        "missing only); a damaged store exits with status 1")
    i.set_defaults(handler=cmd_info)


def _add_radiance(sub) -> None:
    r = sub.add_parser(
        "radiance",
        help="radiance toward an eye for every vertex, from a light sample or arbitrary point lights",
        description="Reconstruct the radiance toward the eye of every scene vertex (store order) and save it as "
        "a (V, 3) float32 .npy (linear RGB): either of light sample K (--sample) or of point lights anywhere in "
        "the sampled region (--light, repeatable; the light's direct term exactly plus the 8 nearest samples' "
        "interpolated residual by default, or their radiance blended with --interpolation thesis, T-12; summed). "
        "Vertices the light cut did not keep are completed from their pre-collapse neighbours (T-15).",
    )
    cli_args.add_store(r)
    which = r.add_mutually_exclusive_group(required=True)
    cli_args.add_sample(which)
    cli_args.add_light(which)
    cli_args.add_colors(r)
    cli_args.add_outside(r)
    cli_args.add_interpolation(r)
    cli_args.add_eye(r)
    cli_args.add_output(r, "rad.npy", "output .npy")
    r.set_defaults(handler=cmd_radiance)


def cmd_info(args) -> int:
    from lodprt.store.bake_store import open_store

    other = other_store(args.store)
    if other is not None:  # a transfer, volume or neighbourhood store: what it holds, as it is stored
        return print_summary(other.summary(verify=args.verify), args.json)
    store = open_store(args.store)
    try:
        info = store.info(verify=args.verify)
    except StoreError:  # a part the summary reads is gone or garbled: what is damaged says which
        if not (found := store.damage(verify=args.verify)):
            raise
        if args.json:  # no summary: what is damaged only
            print(json.dumps({"store": str(args.store), "damage": found}, indent=2))
        return report_damage(args.store, found)
    if args.json:
        print(json.dumps(info, indent=2))
        return report_damage(args.store, info["damage"])
    mode = str(info["mode"]) + (f", threshold {info['threshold_deg']} deg" if info.get("threshold_deg") is not None else "")
    print(f"{args.store}: lodprt store v{info['format_version']} ({mode}) from {info['source']}")
    print(f"  vertices {info['vertices']:,}, triangles {info['faces']:,}")
    print(
        f"  SH order {info['sh_order']}: {info['coefficients_per_vertex']} coefficient(s) x {info['channels']} channel(s)"
    )
    if info["hierarchy_nodes"] is not None:
        print(f"  hierarchy {info['hierarchy_nodes']:,} nodes, {info['hierarchy_roots']:,} roots, depth "
              f"{info['hierarchy_depth']}, built ({info['hierarchy_method']}) in {info['hierarchy_seconds']:.1f} s")
    box, lights = info["light_box"], info["lights"]
    print(f"  light box [{', '.join(f'{v:.4g}' for v in box[:3])}] - [{', '.join(f'{v:.4g}' for v in box[3:])}] "
          f"(grid {' x '.join(map(str, lights['grid']))}, falloff {lights['falloff']}; --light outside it is "
          "clamped into it, or refused with --outside error)")
    print(f"  bake {info['bake_seconds']:.2f} s on {info['device']}; {info['bytes_total'] / 1024:,.0f} KiB payload, "
          f"{info['bytes_on_disk'] / 1024:,.0f} KiB on disk")
    n = max(len(info["samples"]), 1)
    print(f"  codec {info['codec']}: {payload_per_sample(info) / 1024:,.1f} KiB per sample payload"
          + ("" if info["codec"] == "none" else f" (store-level codec arrays included; float32: "
             f"{info['bytes_raw_total'] / n / 1024:,.1f} KiB)"))
    print(f"  {'sample':>6} {'position':>30} {'kept':>9} {'lit':>9} {'shadowed':>9} {'KiB':>9}")
    for s in info["samples"]:
        pos = "(" + ", ".join(f"{x:.3g}" for x in s["position"]) + ")"
        print(f"  {s['index']:>6} {pos:>30} {s['vertices_kept']:>9,} {s['lit']:>9,} {s['shadowed']:>9,} {s['bytes'] / 1024:>9,.0f}")
    return report_damage(args.store, info["damage"])


def report_damage(store, found: list[str]) -> int:
    """``lodprt info``'s last lines: what is damaged, on stderr, and the exit status (1 when anything is)."""
    for line in found:
        print(f"{store}: damaged: {line}", file=sys.stderr)
    if found:
        print(f"{store}: the store is damaged; bake it again", file=sys.stderr)
    return 1 if found else 0


def cmd_radiance(args) -> int:
    import numpy as np

    from lodprt.store.bake_store import open_store

    out = cli_args.new_output(args.out, ".npy", args.overwrite)  # before the store is read
    store = open_store(args.store)
    if args.sample is not None:
        if args.color:
            raise LodprtError("--color goes with --light, not with --sample")
        rad = store.radiance(args.sample, args.eye)
    else:
        cli_args.check_colors(args.color, args.light)
        from lodprt.runtime.frames import light_radiance

        rad = light_radiance(store, args.light, args.eye, colors=args.color, outside=args.outside,
                             interpolation=args.interpolation)
    with open(out, "wb") as f:  # np.save(path) would add .npy to a name ending in .NPY
        np.save(f, rad)
    print(f"wrote {out}: {rad.shape} float32, mean {rad.mean():.4g}, max {rad.max():.4g}")
    return 0


def payload_per_sample(info: dict) -> float:
    """Bytes per light sample a store holds as it is stored (its codec's, the store-level codec arrays included),
    from ``Store.info()``: what ``info`` prints and ``compress`` compares with."""
    return (info["bytes_total"] + info["codec_bytes"]) / max(len(info["samples"]), 1)


def other_store(path):
    """The store at ``path`` opened as a transfer, volume or neighbourhood store when it is one (else None: a bake
    store, or not a store, which ``open_store`` says)."""
    from lodprt.store.neighbourhood_store import NeighbourhoodStore, is_neighbourhood_store
    from lodprt.store.transfer_store import TransferStore, is_transfer_store
    from lodprt.store.volume_store import VolumeStore, is_volume_store

    for test, kind in ((is_transfer_store, TransferStore), (is_volume_store, VolumeStore),
                       (is_neighbourhood_store, NeighbourhoodStore)):
        if test(path):
            return kind(path)
    return None


def print_summary(summary: dict, as_json: bool) -> int:
    """``lodprt info`` of a transfer, volume or neighbourhood store (``FormatStore.summary``)."""
    if as_json:
        print(json.dumps(summary, indent=2))
        return report_damage(summary["store"], summary["damage"])
    print(f"{summary['store']}: {summary['kind']} v{summary['format_version']} (baked by {summary['baked_by']}; "
          f"{summary['bytes_on_disk'] / 1024:,.0f} KiB on disk)")
    for k, v in summary["attrs"].items():
        print(f"  {k}: {json.dumps(v) if isinstance(v, (dict, list)) else v}")
    for name, a in summary["arrays"].items():
        print(f"  {name}: {' x '.join(map(str, a['shape'])) or 'scalar'} {a['dtype']}")
    return report_damage(summary["store"], summary["damage"])
