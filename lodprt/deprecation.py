"""Keyword arguments renamed for one name per concept: the old name still works, with a DeprecationWarning."""

from __future__ import annotations

import functools
import warnings

from lodprt.errors import LodprtError


def renamed_arguments(**renames: str):
    """Decorator: each ``old=new`` lets callers pass ``old`` for ``new`` (warning once per call); both is an error."""
    def wrap(fn):
        @functools.wraps(fn)
        def call(*args, **kwargs):
            for old, new in renames.items():
                if old in kwargs:
                    if new in kwargs:
                        raise LodprtError(f"{fn.__name__}: pass {new}, not both {new} and its old name {old}")
                    warnings.warn(f"{fn.__name__}({old}=...) is now {new}=...", DeprecationWarning, stacklevel=2)
                    kwargs[new] = kwargs.pop(old)
            return fn(*args, **kwargs)
        call.renamed_arguments = dict(renames)
        return call
    return wrap
