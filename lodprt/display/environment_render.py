"""Pictures of transfer stores relit by an environment (P-10..P-12 through ``lodprt.runtime.environment_relight``):
per-vertex radiance, tone-mapped and drawn offscreen."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lodprt.display.render import render, tone_map
from lodprt.runtime.environment_relight import relit_radiance


def render_relit(store, lighting, *, eye, target=None, up=(0.0, 1.0, 0.0), fov: float = 40.0, size=(800, 600),
                 white: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Render the store relit by ``lighting`` (3, n^2) from ``eye``: (image (H, W, 3) uint8, radiance (V, 3)).

    Per-vertex radiance, tone-mapped with :func:`lodprt.display.render.tone_map` (``white`` = radiance shown as white,
    default the 99th percentile), drawn with :func:`lodprt.display.render.render` (offscreen EGL).
    """
    pos = store.read("scene/positions")
    faces = store.read("scene/faces")
    if target is None:
        used = np.unique(faces)
        target = (pos[used].min(0) + pos[used].max(0)) / 2
    rad = relit_radiance(store, lighting, eye)
    img = render(pos, faces, tone_map(rad, white), eye=eye, target=target, up=up, fov=fov, size=size)
    return img, rad


def save_png(path, image) -> Path:
    """Write an (H, W, 3) uint8 image as PNG (matplotlib's writer, a runtime dependency already)."""
    import matplotlib.image

    path = Path(path)
    matplotlib.image.imsave(path, image)
    return path
