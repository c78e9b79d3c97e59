"""The view cut's criteria (docs/RUNTIME.md): what a node's error is and which knobs steer it, one class each, and
their registry.

    "screen"  S-1 with S-2: the shading a coarse node could get wrong, weighted by the pixels it covers, and its
              geometric error in pixels, against one bound in display units of white (the default)
    "thesis"  T-14: ``alpha e_geo + (1 - alpha) e_lumi`` against a bound on that blend

A criterion is a frozen value: its settings (``error_bound`` and its own knobs), the per-node bounds its frames read
(``node_bounds``: ``lodprt.runtime.node_bounds``), its inputs to the ``view_errors`` kernel (``kernel_inputs``: the
kernel's mode and float scalars) and what the CLI and the viewer show of it (``KNOBS``, ``describe``). The Warp
kernel ``lodprt.kernels.runtime.view_errors`` evaluates it; ``tests/errors_reference.py`` is its float64 oracle.

Adding a criterion: a class here (its settings, ``NAME``, ``MODE``, ``NODE_BOUNDS``, ``KNOBS``, ``kernel_inputs``),
its branch of ``view_errors`` and of the oracle, and one line in ``CRITERIA``; the CLI's options and the viewer's
sliders come from ``KNOBS``.
"""

from __future__ import annotations

import dataclasses
import typing

from lodprt.errors import LodprtError
from lodprt.runtime.settings import check_alpha, check_bound, check_target, checked_number


class Knob(typing.NamedTuple):
    """A setting of a criterion: its field (also the CLI's ``--name`` with dashes), its slider's range in the viewer
    (None: no slider), its default, its help text and the CLI's metavar."""

    name: str
    range: tuple[float, float] | None
    default: float | None
    help: str
    metavar: str
    parse: typing.Callable = float  # the CLI's type


@dataclasses.dataclass(frozen=True)
class Criterion:
    """What every criterion has: ``error_bound`` (refine above it, coarsen at or below bound / HYSTERESIS)."""

    error_bound: float

    NAME: typing.ClassVar[str] = ""
    SUMMARY: typing.ClassVar[str] = ""  # one line for the CLI's --criterion help
    MODE: typing.ClassVar[int] = -1  # view_errors' ``criterion`` switch
    NODE_BOUNDS: typing.ClassVar[tuple[str, ...]] = ()  # the per-node bounds its frames read
    KNOBS: typing.ClassVar[tuple[Knob, ...]] = ()  # error_bound first
    #: settings of other criteria this one accepts and does not read (``make_criterion``)
    IGNORES: typing.ClassVar[tuple[str, ...]] = ()

    def __post_init__(self):
        object.__setattr__(self, "error_bound", check_bound(self.error_bound))

    @property
    def name(self) -> str:
        return self.NAME

    def with_bound(self, error_bound: float) -> "Criterion":
        """The same criterion with another bound (the steering and ``Runtime.set_error_bound``)."""
        return dataclasses.replace(self, error_bound=error_bound)

    def with_alpha(self, alpha: float) -> "Criterion":
        """The same criterion with T-14's ``alpha`` (checked; kept only by a criterion that reads it)."""
        check_alpha(alpha)
        return self

    def settings(self) -> dict:
        """Its settings by name (what ``make_criterion`` takes)."""
        return dataclasses.asdict(self)

    def steered(self) -> bool:
        """Whether the run time steers the bound toward a frame target (E-4)."""
        return False

    def kernel_inputs(self, width: int, height: int, measured: bool = False) -> tuple[int, float, float, float]:
        """``view_errors``' (criterion, geo_rate, area_ref, alpha) for a ``width`` x ``height`` screen; ``measured``:
        the frame's error is measured on every pixel (E-5's still frame), not bounded node by node."""
        raise NotImplementedError

    def describe(self) -> str:
        """The criterion and its knobs as the overlay and the summaries print them."""
        return f"{self.NAME} criterion, error bound {self.error_bound:.4g}"


#: "screen": the geometric error on screen, pixels, that weighs as much as the default bound (the exchange rate
#: between pixels of displacement and units of white: 1 px = the default bound)
PIXEL_TOLERANCE = 1.0
#: "screen": the share of the screen a node may cover at the bound's per-pixel error; a larger node's shading term
#: grows with sqrt(area / (AREA_SHARE W H)), so its squared error summed over its pixels stays under
#: bound^2 AREA_SHARE W H (S-1): it adds at most bound^2 AREA_SHARE to the frame's mean squared error
AREA_SHARE = 1.0 / 32768
#: "screen": the frame's error target when neither a bound nor a triangle budget is given (E-1..E-5): the stated
#: 35 dB against the full mesh and 1 dB for the estimate's sampling error in motion (E-2's grid; a still frame is
#: measured on every pixel and refined where its error is, E-5)
DEFAULT_TARGET_PSNR = 36.0
#: "screen": the default bound (units of white): fixed with the target off, the steering's start with it on
SCREEN_BOUND = 0.8


def target_arg(text: str):
    """The CLI's ``--target-psnr``: a PSNR in dB, or 'off' (a fixed bound)."""
    return "off" if text.strip().lower() == "off" else float(text)


@dataclasses.dataclass(frozen=True)
class ScreenCriterion(Criterion):
    """S-1 with S-2 (docs/RUNTIME.md): ``max(E0 g_px / tau_px, e_detail cover)``, the geometric error in pixels at
    ``pixel_tolerance`` pixels per default bound E0 and the S-2 detail bound weighted by the pixels the node covers
    (above AREA_SHARE of the screen by the square root of its area), against ``error_bound`` in display units of
    white; ``target_psnr``: refine the cut until the frame's estimated PSNR meets it (E-1..E-5: the bound steered
    in motion, ``error_bound`` its start; a still frame refined where its error is measured; DEFAULT_TARGET_PSNR
    unless a bound is given alone; "off" or None: a fixed bound)."""

    error_bound: float | None = None  # None: SCREEN_BOUND
    target_psnr: float | str | None = "default"  # DEFAULT_TARGET_PSNR, or None when a bound is given alone
    pixel_tolerance: float = PIXEL_TOLERANCE

    NAME: typing.ClassVar[str] = "screen"
    MODE: typing.ClassVar[int] = 0
    NODE_BOUNDS: typing.ClassVar[tuple[str, ...]] = ("detail",)
    KNOBS: typing.ClassVar[tuple[Knob, ...]] = (
        Knob("error_bound", (0.0, 1.0), 0.8, "0.8 of white for 'screen', where the default target's steering "
             "starts; given alone, a fixed bound: each coarse node adds at most E^2 / 32768 to the frame's mean "
             "squared error", "E"),
        Knob("target_psnr", None, None, "'screen': refine the cut until the frame's estimated PSNR against the full "
             f"mesh meets this (E-1..E-5 in docs/RUNTIME.md; default {DEFAULT_TARGET_PSNR:g}; a still frame is "
             "measured on every pixel and refined where its error is, frames in motion steer the bound, "
             "--error-bound being its start; 'off': a fixed bound, as when --error-bound or --triangle-budget is "
             "given alone)",
             "DB", target_arg),
    )
    SUMMARY: typing.ClassVar[str] = ("'screen' bounds the error on screen (luminance in units of white, geometry in "
                                     "pixels; default)")
    IGNORES: typing.ClassVar[tuple[str, ...]] = ("alpha",)  # as before the criterion objects: accepted, unread

    def __post_init__(self):
        if isinstance(self.target_psnr, str) and self.target_psnr == "default":  # a bound given alone: fixed
            object.__setattr__(self, "target_psnr", DEFAULT_TARGET_PSNR if self.error_bound is None else None)
        if self.error_bound is None:
            object.__setattr__(self, "error_bound", SCREEN_BOUND)
        super().__post_init__()
        object.__setattr__(self, "pixel_tolerance", checked_number(
            self.pixel_tolerance, "pixel_tolerance", "be a positive number of pixels", low=0.0, low_open=True))
        object.__setattr__(self, "target_psnr", check_target(self.target_psnr))

    def steered(self) -> bool:
        return self.target_psnr is not None

    def geo_rate(self, measured: bool = False) -> float:
        """S-1: units of white per pixel of geometric error (the default bound per pixel tolerance; with a
        target_psnr the steered bound's, so that the geometric error stays at pixel_tolerance pixels in motion). On
        E-5's still frame (``measured``: every pixel's error measured against the full mesh, and the nodes carrying
        it split) the default bound's again: geometry the measurement sees is refined where it errs, and geometry it
        cannot see (hidden, behind the object) is not held at pixel_tolerance pixels for nothing."""
        bound = self.error_bound if self.target_psnr is not None and not measured else SCREEN_BOUND
        return max(bound, 1e-12) / self.pixel_tolerance

    @staticmethod
    def area_ref(width: int, height: int) -> float:
        """S-1: the pixels a node may cover before its shading term grows (AREA_SHARE of the screen)."""
        return AREA_SHARE * width * height

    def kernel_inputs(self, width: int, height: int, measured: bool = False) -> tuple[int, float, float, float]:
        return self.MODE, self.geo_rate(measured), self.area_ref(width, height), ThesisCriterion.alpha  # alpha unread


@dataclasses.dataclass(frozen=True)
class ThesisCriterion(Criterion):
    """T-14: ``alpha e_geo + (1 - alpha) e_lumi`` (e_geo the error vector on screen over the diagonal, e_lumi the
    display spread of the leaves' radiance) against ``error_bound``; ``alpha`` in [0, 1] weighs e_geo."""

    error_bound: float = 0.25
    alpha: float = 0.6

    NAME: typing.ClassVar[str] = "thesis"
    MODE: typing.ClassVar[int] = 1
    NODE_BOUNDS: typing.ClassVar[tuple[str, ...]] = ("box_centre", "box_half")
    KNOBS: typing.ClassVar[tuple[Knob, ...]] = (
        Knob("error_bound", (0.0, 1.0), 0.25, "0.25 for 'thesis'", "E"),
        Knob("alpha", (0.0, 1.0), 0.6, "'thesis' only: weight of the geometric error against the luminance error",
             "A"),
    )
    SUMMARY: typing.ClassVar[str] = "'thesis' is T-14's blend alpha e_geo + (1 - alpha) e_lumi"
    IGNORES: typing.ClassVar[tuple[str, ...]] = ("pixel_tolerance",)

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "alpha", check_alpha(self.alpha))

    def with_alpha(self, alpha: float) -> "Criterion":
        return dataclasses.replace(self, alpha=alpha)

    def kernel_inputs(self, width: int, height: int, measured: bool = False) -> tuple[int, float, float, float]:
        return self.MODE, 1.0, 1.0, self.alpha  # geo_rate and area_ref are S-1's, unread by T-14

    def describe(self) -> str:
        return super().describe() + f", alpha {self.alpha:.2f}"


#: the criteria by name, the default first: the one registration a new criterion needs
CRITERIA: dict[str, type[Criterion]] = {"screen": ScreenCriterion, "thesis": ThesisCriterion}
#: default error bound of each criterion: display units of white for "screen", T-14's blend for "thesis"
DEFAULT_ERROR_BOUND = {name: cls().error_bound for name, cls in CRITERIA.items()}


#: the check of each setting a criterion accepts and does not read (``IGNORES``)
IGNORED_CHECKS: dict[str, typing.Callable] = {"alpha": check_alpha}


def retuned(old: Criterion, new) -> Criterion:
    """``new``, when it is ``old`` with another bound or alpha (what a running ``Runtime`` may change: the steering,
    the budgets, ``set_error_bound``); otherwise LodprtError: its kind and other settings are fixed when made, with
    the per-node bounds and the steering they need."""
    if not isinstance(new, Criterion):
        raise LodprtError(f"criterion {new!r}: a running Runtime's criterion is a Criterion object; choose its kind "
                          "when making the Runtime (set_error_bound changes its bound and alpha)")
    other = dataclasses.replace(new, error_bound=old.error_bound)
    if type(new) is not type(old) or other.with_alpha(getattr(old, "alpha", 0.0)) != old:
        raise LodprtError(f"criterion ({new.describe()}): a running Runtime "
                          "changes only its criterion's bound and alpha (set_error_bound); make another Runtime for "
                          "another criterion or target")
    return new


def make_criterion(name: str = "screen", **settings) -> Criterion:
    """The criterion ``name`` with ``settings`` (None: its default). A setting another criterion reads but this one
    does not is refused (LodprtError naming it), unless this one lists it in ``IGNORES``; an unknown one too."""
    cls = CRITERIA.get(name) if isinstance(name, str) else None
    if cls is None:
        raise LodprtError(f"criterion {name!r}: choose one of {', '.join(CRITERIA)}")
    own = {f.name for f in dataclasses.fields(cls)}
    known = {f.name for c in CRITERIA.values() for f in dataclasses.fields(c)}
    kept = {}
    for key, value in settings.items():
        if value is None:
            continue
        if key in cls.IGNORES and key not in own:
            IGNORED_CHECKS[key](value)  # unread, yet in its range: --alpha 7 with 'screen' was taken
            continue
        if key not in known:
            raise LodprtError(f"{key}: not a setting of any view-cut criterion ({', '.join(sorted(known))})")
        if key not in own:
            others = [n for n, c in CRITERIA.items() if key in {f.name for f in dataclasses.fields(c)}]
            raise LodprtError(f"{key} {value}: a setting of criterion {' or '.join(map(repr, others))}, not with "
                              f"criterion {name!r}")
        kept[key] = value
    return cls(**kept)


def resolve_criterion(criterion="screen", **settings) -> Criterion:
    """A ``Criterion`` as given, or the one ``make_criterion`` makes from a name and keyword settings (the keyword
    API of ``Runtime`` and the display); an object with settings besides is refused, naming them."""
    if isinstance(criterion, Criterion):
        given = [k for k, v in settings.items() if v is not None]
        if given:
            raise LodprtError(f"criterion {criterion.name!r} given as an object: its settings are its own, not also "
                              f"{', '.join(given)}")
        return criterion
    return make_criterion(criterion, **settings)


def criterion_of(args) -> Criterion:
    """The criterion a parsed command line names: ``--criterion`` and every criterion's knobs (``KNOBS``, the
    options ``lodprt.cli.args.add_view_cut`` adds), through ``make_criterion``."""
    settings = {k.name: getattr(args, k.name, None) for c in CRITERIA.values() for k in c.KNOBS}
    if getattr(args, "triangle_budget", None) is not None and args.criterion == "screen" and \
            settings.get("target_psnr") is None:
        settings["target_psnr"] = "off"  # the budget steers the bound instead
    return make_criterion(args.criterion, **settings)
