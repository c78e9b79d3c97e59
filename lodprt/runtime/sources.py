"""What the display draws from (``frame_source``): the run time for a store with a hierarchy, full-resolution frames
for one without."""

from __future__ import annotations

import contextlib
import logging

from lodprt.runtime.criteria import resolve_criterion
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.frames import StoreFrames
from lodprt.runtime.session import Runtime

log = logging.getLogger(__name__)


def frame_source(store, *, criterion="screen", lod: bool = True, interpolation: str = DEFAULT_INTERPOLATION,
                 outside: str = "clamp", error_bound: float | None = None, alpha: float | None = None,
                 target_psnr=None, frame_ms: float | None = None, progress=None, white: float | None = None):
    """What the display draws from: the run time (``store.runtime``: moving lights, view-dependent cut under
    ``criterion``, a ``lodprt.runtime.criteria.Criterion`` or a name with its settings as keywords; ``lod`` False
    starts with the full mesh) when the store has a hierarchy, else ``StoreFrames`` (full resolution); both light a
    light between samples by ``interpolation`` (``lodprt.runtime.direct_light.INTERPOLATIONS``) and treat a light
    outside the light box by ``outside`` ("clamp" with one warning per source, or "error"); ``frame_ms``: the
    run time's frame-time budget (B-2, ``lodprt.runtime.budgets``); ``progress(done, total)``: the light samples the
    run time completes as it opens (``Runtime``'s); ``white``: the radiance the run time's errors are in units of
    (default the store's, ``Runtime``'s), the white the picture is drawn with."""
    criterion = resolve_criterion(criterion, error_bound=error_bound, alpha=alpha, target_psnr=target_psnr)
    if store.has_hierarchy:
        return Runtime(store, criterion=criterion, lod=lod, interpolation=interpolation, outside=outside,
                       frame_ms=frame_ms, progress=progress, white=white)
    if lod:
        log.warning("%s: no hierarchy (or no run time): drawing full resolution", store.path)
    return StoreFrames(store, interpolation=interpolation, outside=outside)


def sample_cache(source):
    """The light-sample cache of a frame source (``lodprt.runtime.samples.SampleCache``); None for one that has
    none (``StoreFrames``: full resolution, every sample read from the store)."""
    return getattr(source, "samples", None)


def reporting(source, callback):
    """A context in which ``callback(done, total)`` is also told of the light samples ``source`` completes
    (``SampleCache.reporting``: (0, n) before the first of n, (i, n) after the i-th); nothing for a source without
    a cache."""
    cache = sample_cache(source)
    return contextlib.nullcontext() if cache is None else cache.reporting(callback)
