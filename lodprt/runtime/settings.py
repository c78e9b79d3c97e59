"""The run time's numeric settings, checked where a user hands them over (``Runtime``, the criteria, the viewer):
each is a finite number in its range, or a ``LodprtError`` that names the setting, the value given and what it
must be (a value that is no number at all included: never a ValueError from deep inside).

    error_bound      >= 0                         (S-1 / T-14's bound; ``lodprt.runtime.criteria``)
    alpha            in [0, 1]                    (T-14's weight of e_geo)
    target_psnr      in (0, 200] dB, or "off"     (E-3's target; ``lodprt.runtime.frame_error``)
    frame_ms         in (0, 1e6] ms               (B-2's budget; ``lodprt.runtime.budgets``)
    triangle_budget  a whole number >= 1          (B-1's budget)
    max_passes       a whole number >= 1          (refinement passes a frame; ``Runtime`` and its ``update``)
"""

from __future__ import annotations

import math

from lodprt.errors import LodprtError, is_number, is_whole, shown


def checked_number(value, field: str, must: str, *, low: float, high: float = math.inf,
                   low_open: bool = False) -> float:
    """``value`` as a finite float in [low, high] ((low, high] with ``low_open``); otherwise LodprtError
    "``field`` ``value``: must ``must``" (a string or a bool is no number here, as for every setting: ``is_number``)."""
    x = float(value) if is_number(value) else math.nan
    if not (math.isfinite(x) and (low < x if low_open else low <= x) and x <= high):
        raise LodprtError(f"{field} {shown(value)}: must {must}")
    return x


def check_bound(error_bound) -> float:
    """``error_bound`` as a finite float >= 0."""
    return checked_number(error_bound, "error_bound", "be a finite number >= 0", low=0.0)


def check_alpha(alpha) -> float:
    """T-14's ``alpha`` as a float in [0, 1]."""
    return checked_number(alpha, "alpha", "lie in [0, 1]", low=0.0, high=1.0)


def check_target(psnr) -> float | None:
    """E-3's target ``psnr`` as a float in (0, 200] dB, or None (None or "off": no target)."""
    if psnr is None or (isinstance(psnr, str) and psnr.strip().lower() == "off"):
        return None
    return checked_number(psnr, "target_psnr", "be a PSNR in dB in (0, 200], or 'off'", low=0.0, high=200.0,
                          low_open=True)


def check_frame_ms(value) -> float | None:
    """B-2's budget ``value`` as a float in (0, 1e6] ms, or None."""
    if value is None:
        return None
    return checked_number(value, "frame_ms", "be a frame time in milliseconds in (0, 1e6]", low=0.0, high=1e6,
                          low_open=True)


def check_triangle_budget(value) -> int | None:
    """B-1's budget ``value`` as an int >= 1 (a whole number: 2.5 triangles is refused, not rounded), or None."""
    if value is None:
        return None
    must = "be a whole number of triangles >= 1"
    n = checked_number(value, "triangle_budget", must, low=1.0)
    if n != math.floor(n):
        raise LodprtError(f"triangle_budget {shown(value)}: must {must}")
    return int(n)


def check_max_passes(value) -> int:
    """``max_passes`` as an int >= 1 (a whole number: 1.9 passes is refused, not truncated; NaN or "2" too)."""
    if not is_whole(value, 1):
        raise LodprtError(f"max_passes {shown(value)}: must be a whole number of passes >= 1")
    return int(value)
