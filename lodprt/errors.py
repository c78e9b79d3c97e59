"""Errors lodprt raises for bad input (each names the file and the field it is about), a full disk, and Ctrl-C; and
the tests of a number that the settings' checks share, with the short form of a bad value their messages show."""

import math
import numbers

import numpy as np


class LodprtError(Exception):
    """Base class of every error lodprt raises on purpose (the CLI prints these without a traceback)."""


class SceneError(LodprtError, ValueError):
    """A scene file, mesh or scene field is missing, unreadable or out of range."""


class StoreError(LodprtError, ValueError):
    """A bake store is missing, malformed, of another format version, or would be overwritten."""


class DiskFull(StoreError):
    """The file system ran out of space while a store was written (OSError ENOSPC); the message names the store,
    what was being written and, where known, the bytes it needed."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) stopped a bake; the message says what it left (the CLI prints it in one line, exit 130)."""


def is_number(value) -> bool:
    """A real number (numpy's included, and a 0-d numpy array of one), not a bool or a string: what every setting
    that takes a number asks first."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def shown(value, width: int = 60) -> str:
    """``value`` as a bad-value message shows it: one line (an array by its shape and type, a long repr cut)."""
    if isinstance(value, np.ndarray) and value.ndim > 0:
        return f"an array of shape {value.shape} ({value.dtype})"
    text = " ".join(repr(value).split())
    return text if len(text) <= width else text[:width - 3] + "..."


def is_whole(value, low: float = -math.inf, high: float = math.inf, *, integer_type: bool = False) -> bool:
    """Whether ``value`` is a whole number in [low, high], as the settings' checks ask before they name a bad one:
    a bool never is, nor a string or a non-finite float; 3.0 is 3 unless ``integer_type`` asks for an int type
    (numpy's included)."""
    if not is_number(value) or (integer_type and not isinstance(value, numbers.Integral)):
        return False
    value = value.item() if isinstance(value, np.ndarray) else value
    if not isinstance(value, numbers.Integral) and not (math.isfinite(value) and int(value) == value):
        return False
    return low <= value <= high
