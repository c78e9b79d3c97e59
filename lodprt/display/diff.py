"""Difference pictures like thesis figures 14-17: the light cut's completed radiance against the full-resolution
radiance of the same light sample, rendered offscreen with a false-colour error scale."""

from __future__ import annotations

import numpy as np

from lodprt.store.bake_store import Store, radiance_toward


def full_resolution_radiance(store: Store, sample: int, eye, device: str) -> np.ndarray:
    """Re-bake ``sample`` at full resolution from the stored scene (same float32 arrays as the bake): (V, 3)."""
    from lodprt.devices import load_kernels
    from lodprt.precompute.baker import Baker, bake_kernels

    scene = store.scene()
    load_kernels(device, *bake_kernels())
    ids = np.flatnonzero(scene.referenced).astype(np.int32)
    baker = Baker(scene, store.sh_order, device, ids)
    coeffs, _ = baker.sample(store.light_positions[sample].astype(np.float64))
    full = np.zeros((store.num_vertices,) + coeffs.shape[1:], np.float64)
    full[ids] = coeffs
    return radiance_toward(store.positions, store.normals, full, eye, store.intensity)


def diff_figure(store: Store, sample: int, eye, out_png, *, target=None, size=(640, 480), fov=40.0, device="cpu",
                scale: float | None = None, white: float | None = None) -> dict:
    """Write a PNG with three panels (cut, full, |cut - full| / white in false colour with its scale); returns the
    numbers in its title (``error_figure.error_numbers`` over the vertices either radiance lights, as ``compare``
    over pixels), ``white`` and ``error``: the per-vertex |cut - full| averaged over RGB, over white (V,).

    ``white`` (default the run time's fixed white, ``lodprt.runtime.samples.default_white``, as renders and
    ``compare`` use) both tone-maps the two radiance panels and normalises the error. ``scale``: the error at the
    top of the colour scale (default its 99th percentile; the title gives the scale and the largest error)."""
    from lodprt.display.error_figure import ERROR_LABEL, check_scale, error_numbers, error_scale, false_colour, panel_figure
    from lodprt.display.render import render, tone_map
    from lodprt.runtime.samples import default_white

    check_scale(scale)
    eye = np.asarray(eye, np.float64)
    positions = store.positions
    if target is None:
        target = 0.5 * (positions.min(0) + positions.max(0))
    cut = store.radiance(sample, eye).astype(np.float64)
    full = full_resolution_radiance(store, sample, eye, device)
    white = float(white) if white is not None else default_white(store)
    numbers, rel, covered = error_numbers(cut, full, white)
    vmax, how = error_scale(numbers, scale)
    kept = len(store.sample(sample)[0])
    views = [tone_map(cut, white), tone_map(full, white), false_colour(rel, vmax)]
    titles = [f"light cut ({kept:,} of {store.num_vertices:,} vertices), completed", "full resolution", ERROR_LABEL]
    images = [render(positions, store.faces, c, eye=eye, target=target, fov=fov, size=size) for c in views]
    panel_figure(out_png, images, titles, vmax,
                 f"sample {sample}, light cut threshold {store.attrs.get('threshold_deg')} deg: PSNR "
                 f"{numbers['psnr_db']:.1f} dB (clipped at white), relative RMSE {numbers['relative_rmse']:.4f}, "
                 f"mean {numbers['mean_difference']:.4f}\nerror = |cut - full| / white (white {white:.3g}, the run "
                 f"time's), per vertex; {how}")
    return {**numbers, "vertices_kept": kept, "white": white, "error": rel}
