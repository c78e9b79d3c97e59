"""The arguments the ``lodprt`` commands share, each defined once, and the checks of their values.

Every command module (bake, inspect, frames, display, environment) builds its parsers from these helpers, so a
flag means the same thing, with the same default and help, wherever it appears.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from lodprt.errors import LodprtError

FOV = 40.0
"""Default vertical field of view in degrees."""
SIZE = (800, 600)
"""Default image (or screen) size in pixels, width and height."""
XYZ = ("X", "Y", "Z")


def finite(text: str) -> float:
    """argparse type: a finite number; nan and inf are refused naming the option (they surfaced deep inside, as a
    black picture or a traceback)."""
    value = float(text)  # ValueError: argparse says "invalid finite value"
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


class Given(argparse.Action):
    """``store``, noting the option's dest in ``namespace.given``: ``given(args, dest)`` tells an option given
    explicitly from its default (an option dropped unread is refused only when given)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.given = {*getattr(namespace, "given", ()), self.dest}


def given(args, dest: str) -> bool:
    """Whether the option of ``dest`` (added with ``action=Given``) was given on the command line."""
    return dest in getattr(args, "given", ())


def knob_type(knob, cls):
    """argparse type of a view-cut knob (``Knob``, of criterion class ``cls``): ``knob.parse``; a text it cannot
    read is refused with what the library's check says it must be ('abc' said: invalid target_arg value)."""

    def parse(text: str):
        try:
            return knob.parse(text)
        except ValueError:
            must = "must be a number"
            try:
                cls(**{knob.name: text})  # the library's check of a value that is no number
            except LodprtError as exc:
                must = str(exc).partition(": ")[2] or must
            except Exception:  # noqa: BLE001 - any other failure: the plain words above
                pass
            raise argparse.ArgumentTypeError(f"{text!r}: {must}") from None

    parse.__name__ = knob.name
    return parse


def add_store(p: argparse.ArgumentParser) -> None:
    """The store a command reads (positional)."""
    p.add_argument("store", metavar="OUT.zarr")


def add_scene(p: argparse.ArgumentParser) -> None:
    """The scene a bake reads (positional)."""
    p.add_argument("scene", metavar="SCENE", help="'demo', a .toml scene file, or a mesh (obj, ply, stl, off, glb)")


def add_output(p: argparse.ArgumentParser, metavar: str, what: str = "output", *,
               replaces: str = "an existing output") -> None:
    """``-o/--out`` (required) and ``--overwrite``: an existing output is never replaced without it."""
    p.add_argument("-o", "--out", required=True, metavar=metavar, help=f"{what} (not replaced without --overwrite)")
    p.add_argument("--overwrite", action="store_true", help=f"replace {replaces}")


def add_store_output(p: argparse.ArgumentParser, kind: str) -> None:
    """``-o OUT.zarr`` and ``--overwrite`` of a bake writing a ``kind`` store."""
    add_output(p, "OUT.zarr", "store to write", replaces=f"OUT if it is an existing {kind} store")


def add_device(p: argparse.ArgumentParser, purpose: str = "") -> None:
    """``--device``: the Warp device (``purpose`` e.g. ' of the per-frame kernels')."""
    p.add_argument("--device", default=None, metavar="DEV",
                   help=f"Warp device{purpose}: cpu, cuda, cuda:N (default: cuda if present, else cpu)")


def add_jobs(p: argparse.ArgumentParser, each: str) -> None:
    """``--jobs``: CPU threads of a bake (``each`` says what one thread does)."""
    p.add_argument("--jobs", type=int, default=None, metavar="J", help=f"CPU threads, {each} (default: all cores)")


def add_hierarchy_method(p: argparse.ArgumentParser) -> None:
    """``--hierarchy sequential|rounds|pymeshlab``: the vertex hierarchy's build (``build_hierarchy(method=...)``)."""
    from lodprt.model.hierarchy_build import METHODS

    p.add_argument("--hierarchy", default=METHODS[0], metavar="METHOD", action=Given,
                   help=f"vertex hierarchy build: {', '.join(METHODS)} (default {METHODS[0]}: QEM half-edge "
                   "collapses one at a time in Warp kernels, one thread per mesh unit; rounds: rounds of parallel QEM "
                   "collapses; pymeshlab: the same rounds replaying pymeshlab's QEM halvings; docs/HIERARCHY.md)")


def add_json(p: argparse.ArgumentParser, what: str = "a JSON object") -> None:
    """``--json``: machine-readable output instead of the text."""
    p.add_argument("--json", action="store_true", help=f"print {what}")


def add_sample(p, *, required: bool = False) -> None:
    """``--sample K``: a light sample of the bake (``p`` may be a parser or a mutually exclusive group)."""
    p.add_argument("--sample", type=int, required=required, metavar="K", help="light sample index (see lodprt info)")


def add_eye(p: argparse.ArgumentParser, *, required: bool = True) -> None:
    """``--eye X Y Z`` (when not required, the default is a three-quarter view of the scene)."""
    p.add_argument("--eye", type=finite, nargs=3, required=required, default=None, metavar=XYZ,
                   help="eye position" + ("" if required else " (default: a three-quarter view of the scene)"))


def add_screen(p: argparse.ArgumentParser, *, size=SIZE, size_what: str = "image size in pixels") -> None:
    """``--fov`` and ``--size W H``."""
    p.add_argument("--fov", type=finite, default=FOV, metavar="DEG",
                   help=f"vertical field of view in degrees (default {FOV:g})")
    p.add_argument("--size", type=int, nargs=2, default=tuple(size), metavar=("W", "H"),
                   help=f"{size_what} (default {size[0]} {size[1]})")


def add_camera(p: argparse.ArgumentParser, *, eye_required: bool = True, up: bool = False, size=SIZE,
               size_what: str = "image size in pixels") -> None:
    """The camera: ``--eye``, ``--target``, optionally ``--up``, then ``--fov`` and ``--size``."""
    add_eye(p, required=eye_required)
    p.add_argument("--target", type=finite, nargs=3, default=None, metavar=XYZ, help="look-at point (default: scene centre)")
    if up:
        p.add_argument("--up", type=finite, nargs=3, default=(0.0, 1.0, 0.0), metavar=XYZ, help="up direction (default +y)")
    add_screen(p, size=size, size_what=size_what)


def add_view_cut(p: argparse.ArgumentParser) -> None:
    """The view cut's criterion and its knobs (docs/RUNTIME.md), from the registry
    ``lodprt.runtime.criteria.CRITERIA``: ``--criterion`` and one option per knob (``Knob``; a knob several criteria
    have, as ``--error-bound``, once, its default then the criterion's); ``criterion(args)`` makes the object."""
    from lodprt.runtime.criteria import CRITERIA

    names = tuple(CRITERIA)
    p.add_argument("--criterion", choices=names, default=names[0], action=Given,
                   help="view-cut criterion: " + ", ".join(c.SUMMARY for c in CRITERIA.values()))
    knobs: dict = {}
    owner: dict = {}
    for cls in CRITERIA.values():
        for knob in cls.KNOBS:
            knobs.setdefault(knob.name, []).append(knob)
            owner.setdefault(knob.name, cls)
    for name, same in knobs.items():
        defaults = {k.default for k in same}
        default = defaults.pop() if len(defaults) == 1 else None  # None: each criterion's own
        own = "" if default is None or len(same) > 1 else f" (default {default:g})"
        what = "view cut error bound (default " if name == "error_bound" else ""
        text = what + "; ".join(k.help for k in same) + (")" if what else "") + own
        p.add_argument("--" + name.replace("_", "-"), type=knob_type(same[0], owner[name]), default=default,
                       metavar=same[0].metavar, help=text, action=Given)
    add_interpolation(p)
    add_outside(p)


def criterion(args):
    """The ``lodprt.runtime.criteria.Criterion`` that ``add_view_cut``'s parsed options name (LodprtError naming a
    bad value, or a knob another criterion reads: ``--target-psnr`` with 'thesis')."""
    from lodprt.runtime.criteria import criterion_of

    return criterion_of(args)


def view_cut_given(args) -> list[str]:
    """The view-cut options given explicitly (``add_view_cut``'s criterion and knobs, ``--frame-ms``,
    ``--triangle-budget``), as flags: what LOD off (``--full``) leaves unread."""
    from lodprt.runtime.criteria import CRITERIA

    dests = ["criterion", *dict.fromkeys(k.name for c in CRITERIA.values() for k in c.KNOBS), "frame_ms",
             "triangle_budget"]
    return ["--" + d.replace("_", "-") for d in dests if given(args, d)]


def refuse_with_full(args) -> None:
    """Refuse view-cut options given with ``--full`` (they were dropped without a word): the full mesh has no view
    cut for them to choose or steer."""
    unread = view_cut_given(args) if getattr(args, "full", False) else []
    if unread:
        raise LodprtError(f"{', '.join(unread)} and --full: --full draws the full mesh, with no view cut for "
                          f"{'them' if len(unread) > 1 else 'it'} to choose or steer")


def add_frame_ms(p: argparse.ArgumentParser) -> None:
    """``--frame-ms``: the run time's frame-time budget (B-2, ``lodprt.runtime.budgets``)."""
    p.add_argument("--frame-ms", type=float, default=None, metavar="MS", action=Given,
                   help="frame-time budget in milliseconds: while the frames in motion take longer, the view cut's "
                        "bound gets a floor that rises (x1.25 a frame) until they fit, and falls again under 80%% of "
                        "it (B-2); frames that estimate their error are not counted (default: none)")


def add_outside(p: argparse.ArgumentParser) -> None:
    """``--outside clamp|error``: a light outside the store's light box (``lodprt info`` prints it)."""
    p.add_argument("--outside", choices=("clamp", "error"), default="clamp",
                   help="a light outside the sampled region (the light box, see lodprt info): clamp it into the box "
                        "with one warning naming where it went (default), or refuse it")


def add_interpolation(p: argparse.ArgumentParser) -> None:
    """``--interpolation``: how a light between samples is lit (docs/RUNTIME.md, "Lights anywhere")."""
    from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION, INTERPOLATIONS

    p.add_argument("--interpolation", choices=INTERPOLATIONS, default=DEFAULT_INTERPOLATION,
                   help="a light between samples: 'direct' (default) evaluates its direct Phong light exactly with "
                        "a shadow ray per vertex, plus the samples' interpolated residual (indirect light); "
                        "'direct-agree' casts rays only where the samples disagree; 'direct-blend' blends the "
                        "samples' visibility instead of casting rays; 'thesis' blends the samples' radiance (T-12)")


def add_light(p, *, required: bool = False, help: str = "a point light's position (repeat for several lights)") -> None:
    """``--light X Y Z``, repeatable (``p`` may be a parser or a mutually exclusive group)."""
    p.add_argument("--light", type=float, nargs=3, action="append", required=required, default=None, metavar=XYZ,
                   help=help)


def add_colors(p: argparse.ArgumentParser) -> None:
    """``--color R G B``, repeatable: one per ``--light``."""
    p.add_argument("--color", type=float, nargs=3, action="append", default=None, metavar=("R", "G", "B"),
                   help="RGB intensity of each --light, in order (default: the bake's intensity)")


def check_colors(colors, lights) -> None:
    """Refuse a ``--color`` count that is not the ``--light`` count (none is fine)."""
    if colors is not None and len(colors) != len(lights):
        raise LodprtError(f"--color: {len(colors)} given for {len(lights)} --light; give one per light or none")


def check_tone(white, exposure) -> None:
    """Refuse ``--white`` (None: the default) not a positive finite radiance and ``--exposure`` out of the tone
    mapping's range, named as the options, before any work (``lodprt.runtime.frames.tone_scale``)."""
    from lodprt.runtime.frames import tone_scale

    tone_scale(1.0 if white is None else white, exposure, "--")


def check_picture(fov: float, white: float | None, background=(0.0, 0.0, 0.0)) -> None:
    """Refuse, before any work, a ``--fov`` outside (0, 180) degrees, a ``--white`` (None: the default) that is
    not > 0 and a ``--background`` under 0 (they drew black or saturated pictures without a word)."""
    from lodprt.runtime.frames import check_white

    if not 0.0 < fov < 180.0:
        raise LodprtError(f"--fov {fov:g}: must lie strictly between 0 and 180 degrees")
    if white is not None:
        check_white(white, "--")
    if min(background) < 0:
        raise LodprtError(f"--background {' '.join(f'{b:g}' for b in background)}: must be >= 0 (linear radiance)")


def at_least(flag: str, value, low: int, note: str = "") -> None:
    """Refuse ``flag value`` below ``low`` (``None``, not given, passes)."""
    if value is not None and value < low:
        raise LodprtError(f"{flag} {value}: must be >= {low}{note}")


def require_suffix(out, suffix: str) -> Path:
    """``out`` as the path of a file to write: refused unless it ends with ``suffix`` (e.g. ``.png``, in any case),
    its folder exists and it is not itself a folder. Checked before any work, so a bad path fails at once."""
    from lodprt.display.pictures import check_output

    return check_output(out, (suffix,), overwrite=None, option="--overwrite")


def refuse_folder(path) -> None:
    """Refuse an output ``path`` that is an existing folder: a file never replaces one, even with --overwrite."""
    from lodprt.display.pictures import refuse_replacing

    refuse_replacing(path, None, "--overwrite")


def refuse_existing(path, overwrite: bool) -> None:
    """Refuse to replace an existing ``path`` without ``--overwrite``, and a folder even with it."""
    from lodprt.display.pictures import refuse_replacing

    refuse_replacing(path, overwrite, "--overwrite")


def new_output(out, suffix: str, overwrite: bool) -> Path:
    """An output file, checked before any work: the right suffix (in any case: ``.NPY`` is a ``.npy``), an existing
    folder, not a folder itself, and not an existing file unless ``overwrite``."""
    from lodprt.display.pictures import check_output

    return check_output(out, (suffix,), overwrite=overwrite, option="--overwrite")
