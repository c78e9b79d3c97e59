"""``lodprt compress``: re-encode an existing bake store with a lossy codec (format version 2, docs/FORMAT.md), or
back to float32 with ``--codec none``."""

from __future__ import annotations

import argparse
import sys

from lodprt.cli import args as cli_args
from lodprt.cli.progress import ProgressBars

EPILOG = """\
codecs (error bounds in docs/FORMAT.md, "Compressed bake store"):
  f16                      float16 after a power-of-two scale per sample
  q8 | q10 | q12           integers per vertex and SH band with a float16 scale each, B - l bits for band l
  cpca:CLUSTERS:VECTORS    clustered PCA over every (vertex, light sample) row of the store, 8-bit weights
  cpca:CLUSTERS:VECTORS:W  the same with W = 16-bit or 32 (float32) weights
  none                     float32 (format version 1): decompresses a version-2 store
examples:
  lodprt compress bunny.zarr -o bunny_q8.zarr --codec q8
  lodprt compress bunny.zarr -o bunny_cpca.zarr --codec cpca:256:3"""


def register(sub) -> None:
    """Add ``compress`` to ``sub`` (the subparsers object of the lodprt parser)."""
    c = sub.add_parser(
        "compress",
        help="re-encode a bake store with a lossy codec (f16, q8, q10, q12, cpca:CLUSTERS:VECTORS)",
        description="Write the bake store IN again at OUT with its light samples encoded by CODEC (format "
        "version 2; the scene, lights and hierarchy are copied unchanged). The new store is written next to OUT "
        "and moved into place when complete. Prints the bytes per sample before and after and the largest "
        "coefficient error.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    c.add_argument("input", metavar="IN.zarr", help="the bake store to re-encode (format version 1 or 2)")
    cli_args.add_store_output(c, "lodprt")
    c.add_argument("--codec", required=True, metavar="CODEC",
                   help="none, f16, q8, q10, q12 or cpca:CLUSTERS:VECTORS[:BITS] (see below)")
    c.set_defaults(handler=cmd_compress)


def cmd_compress(args) -> int:
    from lodprt.cli.inspection import payload_per_sample
    from lodprt.store.bake_store import open_store
    from lodprt.store.codecs import parse_codec
    from lodprt.store.compress import compress_store

    codec = parse_codec(args.codec, "--codec")
    src = open_store(args.input)
    was = payload_per_sample(src.info())  # before OUT, which may be IN with --overwrite, replaces it
    with ProgressBars() as bars:
        res = compress_store(src, args.out, codec, overwrite=args.overwrite,
                             progress=bars.callback("compress", "sample"))
    samples = res["samples"]
    enc = (sum(s["bytes"] for s in samples) + res["codec_bytes"]) / max(len(samples), 1)
    worst = max((s["max_abs_error"] for s in samples), default=0.0)
    print(f"wrote {res['path']}: codec {res['codec']}, {enc / 1024:,.1f} KiB per sample (was {was / 1024:,.1f} KiB, "
          f"{size_change(was, enc)}; store-level codec arrays included), largest coefficient error "
          f"{worst:.3g}, {res['seconds']:.1f} s", file=sys.stderr)
    return 0


def size_change(was: float, now: float) -> str:
    """'2.8x smaller', '1.9x larger', or 'the same size' for a ratio under 1.05 either way."""
    if now < was and was / max(now, 1) >= 1.05:
        return f"{was / max(now, 1):.1f}x smaller"
    if now > was and now / max(was, 1) >= 1.05:
        return f"{now / max(was, 1):.1f}x larger"
    return "the same size"
