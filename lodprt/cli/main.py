"""The ``lodprt`` command line: bake, info, radiance, frames, diff, render, compare, turntable, view, irradiance,
bake-environment, render-environment, bake-volume, render-volume, bake-neighbourhood, export, compress.

The parser is built from the command modules' ``register`` functions (:mod:`lodprt.cli.bake`,
:mod:`lodprt.cli.inspection`, :mod:`lodprt.cli.frames`, :mod:`lodprt.cli.display`, :mod:`lodprt.cli.environment`,
:mod:`lodprt.cli.volume`, :mod:`lodprt.cli.export`; their shared arguments are in :mod:`lodprt.cli.args`). Errors lodprt raises on purpose (bad scene, bad store,
unavailable device, a full disk) are printed as one line naming the file and field, with exit code 2; Ctrl-C
(SIGINT) prints one line saying what the command left and exits with 130; anything else is a bug and keeps its
traceback. The command's threads allocate from one malloc arena (:mod:`lodprt.allocator`).
"""

from __future__ import annotations

import argparse
import errno
import logging
import os
import re
import sys

from lodprt.allocator import one_malloc_arena
from lodprt.cli import bake, compress, display, environment, export, frames, inspection, volume
from lodprt.errors import LodprtError
from lodprt.version import __version__

COMMAND_MODULES = (bake, compress, inspection, frames, display, environment, volume, export)
"""The command families, in the order ``lodprt --help`` lists their commands."""


def build_parser() -> argparse.ArgumentParser:
    """The ``lodprt`` parser: ``-v`` and one subcommand per command, each with its ``handler``."""
    p = argparse.ArgumentParser(
        prog="lodprt",
        description="Level-of-detail based precomputed local radiance transfer (bake, inspect, reconstruct).",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details to stderr")
    p.add_argument("--version", action="version", version=f"lodprt {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMAND_MODULES:
        module.register(sub)
    return p


#: the library's words for an argument, and the flag the command line has for it
FLAGS = {"overwrite=True": "--overwrite", "frame_ms ": "--frame-ms "}


def option_flags(parser: argparse.ArgumentParser, command: str) -> dict[str, str]:
    """The options of ``command``, its long flag by the library's name for it (``gi_rays``: ``--gi-rays``)."""
    # argparse lists no actions publicly: its _actions
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return {a.dest: a.option_strings[-1] for a in sub._actions
            if a.option_strings and a.option_strings[-1] == "--" + a.dest.replace("_", "-")}


def as_flags(message: str, flags: dict[str, str] | None = None) -> str:
    """A library error as the command line says it: ``overwrite=True`` becomes ``--overwrite``, and an option's
    library name (``flags``, from ``option_flags``) its flag: a name with an underscore wherever it stands as a
    word, another only as "NAME VALUE: ..." leading the message ("gi_rays 0: must ..." said the Python name)."""
    for api, flag in FLAGS.items():
        message = message.replace(api, flag)
    for name, flag in (flags or {}).items():
        if "_" in name:
            message = re.sub(rf"(?<![\w./-]){name}\b", flag, message)
        elif re.match(rf"{re.escape(name)} [^\s:]+:", message):
            message = flag + message[len(name):]
    return message


def main(argv: list[str] | None = None) -> int:
    one_malloc_arena()  # before any thread allocates (lodprt.allocator: run-time and bake peaks)
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(name)s: %(message)s")
    try:
        return args.handler(args)
    except LodprtError as exc:
        print(f"lodprt {args.command}: error: {as_flags(str(exc), option_flags(parser, args.command))}",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C: a bake's Interrupted says what it left (bake --resume)
        print(f"lodprt {args.command}: interrupted" + (f": {exc}" if str(exc) else ""), file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (lodprt info ... | head): stop quietly, as Unix tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        if exc.errno != errno.ENOSPC:
            raise
        where = getattr(args, "out", None) or exc.filename  # a full disk outside a store writer's arrays
        print(f"lodprt {args.command}: error: {where}: no space left on the device ({exc.filename or 'writing'})",
              file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
