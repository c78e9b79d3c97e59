"""Errors lodprt raises for bad input (each names the file and the field it is about), a full disk, and Ctrl-C; and
the whole-number test that the settings' checks share."""

import math
import numbers


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


def is_whole(value, low: float = -math.inf, high: float = math.inf, *, integer_type: bool = False) -> bool:
    """Whether ``value`` is a whole number in [low, high], as the settings' checks ask before they name a bad one:
    a bool never is, nor a string or a non-finite float; 3.0 is 3 unless ``integer_type`` asks for an int type
    (numpy's included)."""
    kinds = numbers.Integral if integer_type else numbers.Real
    if isinstance(value, bool) or not isinstance(value, kinds):
        return False
    if not isinstance(value, numbers.Integral) and not (math.isfinite(value) and int(value) == value):
        return False
    return low <= value <= high
