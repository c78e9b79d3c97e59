"""The ``lodprt`` command line: bake, info, radiance, frames, diff, render, compare, turntable, view, irradiance,
bake-environment, render-environment, bake-volume, render-volume, bake-neighbourhood, export, compress.

The parser is built from the command modules' ``register`` functions (:mod:`lodprt.cli.bake`,
:mod:`lodprt.cli.inspection`, :mod:`lodprt.cli.frames`, :mod:`lodprt.cli.display`, :mod:`lodprt.cli.environment`,
:mod:`lodprt.cli.volume`, :mod:`lodprt.cli.export`; their shared arguments are in :mod:`lodprt.cli.args`). Errors lodprt raises on purpose (bad scene, bad store,
unavailable device) are printed as one line naming the file and field, with exit code 2; anything else is a bug and
keeps its traceback.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys

from lodprt.cli import bake, compress, display, environment, export, frames, inspection, volume
from lodprt.errors import LodprtError

COMMAND_MODULES = (bake, compress, inspection, frames, display, environment, volume, export)
"""The command families, in the order ``lodprt --help`` lists their commands."""


def build_parser() -> argparse.ArgumentParser:
    """The ``lodprt`` parser: ``-v`` and one subcommand per command, each with its ``handler``."""
    p = argparse.ArgumentParser(
        prog="lodprt",
        description="Level-of-detail based precomputed local radiance transfer (bake, inspect, reconstruct).",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details to stderr")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMAND_MODULES:
        module.register(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(name)s: %(message)s")
    try:
        return args.handler(args)
    except LodprtError as exc:
        print(f"lodprt {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (lodprt info ... | head): stop quietly, as Unix tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
