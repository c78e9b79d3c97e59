"""What the display draws from (``frame_source``): the run time for a store with a hierarchy, full-resolution frames
for one without."""

from __future__ import annotations

import logging

from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.frames import StoreFrames
from lodprt.runtime.session import Runtime

log = logging.getLogger(__name__)


def frame_source(store, *, error_bound: float | None = None, alpha: float = 0.6, lod: bool = True,
                 criterion: str = "screen", interpolation: str = DEFAULT_INTERPOLATION, target_psnr=None,
                 outside: str = "clamp"):
    """What the display draws from: the run time (``store.runtime``: moving lights, view-dependent cut; ``lod``
    False starts with the full mesh) when the store has a hierarchy, else ``StoreFrames`` (full resolution); both
    light a light between samples by ``interpolation`` (``lodprt.runtime.direct_light.INTERPOLATIONS``) and treat
    a light outside the light box by ``outside`` ("clamp" with one warning per source, or "error")."""
    if store.has_hierarchy:
        return Runtime(store, error_bound=error_bound, alpha=alpha, lod=lod, criterion=criterion,
                       interpolation=interpolation, target_psnr=target_psnr, outside=outside)
    if lod:
        log.warning("%s: no hierarchy (or no run time): drawing full resolution", store.path)
    return StoreFrames(store, interpolation=interpolation, outside=outside)
