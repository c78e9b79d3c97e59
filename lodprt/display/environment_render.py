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


# -- neighbourhood transfer: an object and a receiver it shadows (N-3..N-5, docs/VOLUMES.md) ---------------------


def render_neighbourhood(store, lighting, *, receiver=None, at=(0.0, 0.0, 0.0), eye, target=None, up=(0.0, 1.0, 0.0),
                         fov: float = 40.0, size=(800, 600), white: float | None = None):
    """Draw a neighbourhood store's object (relit by its own diffuse transfer, P-10) and ``receiver`` (a
    :class:`lodprt.model.scene.Scene`, every vertex of it, moved by ``at``) lit by the transferred lighting of the
    grid (N-3..N-5): (image (H, W, 3) uint8, radiance (V, 3) of the object's then the receiver's vertices)."""
    from lodprt.runtime.environment_relight import diffuse_radiance
    from lodprt.runtime.neighbourhood import receiver_radiance

    pos = store.read("object/positions").astype(np.float64)
    faces = store.read("object/faces")
    rad = diffuse_radiance(store.read("object/transfer"), lighting)
    if receiver is not None:
        rpos = receiver.positions + np.asarray(at, np.float64)
        kd = np.array([m.kd for m in receiver.materials], np.float64)[receiver.material_id]
        rrad, _ = receiver_radiance(store, lighting, rpos, receiver.normals, kd)
        faces = np.vstack([faces, receiver.faces + len(pos)])
        pos, rad = np.vstack([pos, rpos]), np.vstack([rad, rrad])
    if target is None:
        target = (pos.min(0) + pos.max(0)) / 2
    img = render(pos, faces, tone_map(rad, white), eye=eye, target=target, up=up, fov=fov, size=size)
    return img, rad


def open_relit(store_path, *, receiver=None, at=(0.0, 0.0, 0.0)):
    """The store at ``store_path`` and the function that draws it relit, ``draw(store, lighting, eye=..., target=...,
    fov=..., size=..., white=...) -> (image, radiance)``: :func:`render_relit` for a transfer store,
    :func:`render_neighbourhood` (with the receiver mesh or scene file ``receiver`` moved by ``at``) for a
    neighbourhood store. A receiver needs a neighbourhood store (LodprtError otherwise)."""
    import functools

    from lodprt.errors import LodprtError
    from lodprt.runtime.environment_relight import open_transfer
    from lodprt.runtime.neighbourhood import open_neighbourhood
    from lodprt.store.neighbourhood_store import is_neighbourhood_store

    if is_neighbourhood_store(store_path):
        scene = None
        if receiver is not None:
            from lodprt.model.scene import load_scene

            scene = load_scene(receiver)
        return open_neighbourhood(store_path), functools.partial(render_neighbourhood, receiver=scene, at=at)
    if receiver is not None:
        raise LodprtError(f"{store_path}: --receiver needs a neighbourhood store (lodprt bake-neighbourhood), "
                          "not a transfer store")
    return open_transfer(store_path), render_relit
