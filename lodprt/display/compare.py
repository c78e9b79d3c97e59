"""Comparison figures like thesis figures 14-17: the view-cut (LOD) frame, the full-resolution frame of the same
lights and camera, and their per-pixel difference in false colour with its scale, side by side."""

from __future__ import annotations

import numpy as np

from lodprt.display.error_figure import ERROR_LABEL, check_scale, error_numbers, error_scale, false_colour, panel_figure
from lodprt.display.pictures import check_exr, check_output, write_exr
from lodprt.display.render import Renderer
from lodprt.runtime.frames import auto_white, full_frame
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.sources import frame_source


def compare_figure(store, out, *, lights, camera, colors=None, error_bound: float | None = None, alpha: float | None = None,
                   criterion="screen", interpolation: str = DEFAULT_INTERPOLATION, target_psnr=None,
                   outside: str = "clamp",
                   overwrite: bool = False, scale: float | None = None, wireframe: bool = False,
                   per_vertex: bool = False, exposure: float = 0.0, white: float | None = None,
                   markers: bool = True) -> dict:
    """Write the three-panel PNG ``out`` (or, for ``out`` ending in .exr, the panels' linear radiance side by side as
    OpenEXR float32 RGB: cut, full, |cut - full|, no titles); returns the numbers in its title.

    Both frames come from one run time (``frame_source``; LOD switched off for the second), share the white point
    (``white``, default the run time's) and are drawn linear for the difference: ``|LOD - full|`` averaged over
    RGB, over ``white``; pixels either frame covers count (silhouette changes show). ``scale``: the difference at
    the top of the colour scale (default the 99th percentile over the covered pixels; larger ones saturate; the
    title gives the scale and the largest difference). Panels are drawn pixel for pixel (``error_figure``). ``wireframe`` overlays the cut on the LOD panel.
    """
    out = check_output(out, (".png", ".exr"), overwrite=overwrite)
    check_scale(scale)
    if out.suffix.lower() == ".exr":
        check_exr()
    source = frame_source(store, criterion=criterion, lod=True, interpolation=interpolation, outside=outside,
                          error_bound=error_bound, alpha=alpha, target_psnr=target_psnr, white=white)
    cut_criterion = getattr(source, "criterion", None)  # None: a store without a hierarchy
    source.set_lights(lights, colors)
    source.set_camera(camera)
    lod = source.update()
    source.set_lod(False)
    full = source.update()
    if white is None:
        white = getattr(source, "white", None) or auto_white(full.radiance)
    draw = {"per_vertex": per_vertex, "exposure": exposure, "white": white, "light_markers": markers}
    with Renderer() as r:
        numbers, rel, covered = frame_error(r, lod, full, white, per_vertex=per_vertex)
        if out.suffix.lower() == ".exr":  # the linear panels: cut | full | |cut - full|, in radiance
            lin = [r.image(f, linear=True, per_vertex=per_vertex) for f in (lod, full)]
            write_exr(out, np.concatenate([lin[0], lin[1], np.abs(lin[0] - lin[1])], axis=1))
            return {"triangles_lod": int(len(lod.triangles)), "triangles_full": int(len(full.triangles)), **numbers,
                    "white": float(white)}
        img_lod = r.image(lod, wireframe=wireframe, **draw)
        img_full = r.image(full, **draw)
    n_lod, n_full = int(len(lod.triangles)), int(len(full.triangles))
    vmax, how = error_scale(numbers, scale)
    panels = [img_lod, img_full, false_colour(rel, vmax, covered)]
    titles = [f"view cut: {n_lod:,} triangles ({len(lod.positions):,} vertices)", f"full resolution: {n_full:,} triangles",
              ERROR_LABEL]
    if cut_criterion is None:  # a store without a hierarchy: no view cut, both panels are full resolution
        what = "no hierarchy (full resolution both)"
    else:  # the bound the frame was cut at (under a target, where the steering settled: E-4) and the target
        what = cut_criterion.with_bound(float(getattr(source, "error_bound", cut_criterion.error_bound))).describe()
        target, est = getattr(source, "target_psnr", None), lod.stats.get("estimated_psnr_db")
        if target is not None:
            what += f", steered to {target:g} dB" + ("" if est is None else f" (estimated {est:.1f} dB)")
    panel_figure(out, panels, titles, vmax,
                 f"{what}: PSNR {numbers['psnr_db']:.1f} dB (clipped at white), relative RMSE "
                 f"{numbers['relative_rmse']:.4f}, mean {numbers['mean_difference']:.4f}\n"
                 f"error = |cut - full| / white (white {white:.3g}, the run time's); {how}")
    return {"triangles_lod": n_lod, "triangles_full": n_full, **numbers, "white": float(white)}


def frame_error(renderer, lod, full, white: float, *, per_vertex: bool = False) -> tuple[dict, np.ndarray, np.ndarray]:
    """The image error of frame ``lod`` against frame ``full`` (same camera), both drawn linear by ``renderer``:
    (numbers, |lod - full| / white averaged over RGB (H, W), covered (H, W) bool). Pixels either frame covers
    count. numbers: psnr_db (both clipped at ``white``, in units of white), relative_rmse (unclipped, over the full
    frame's RMS), mean_difference, max_difference and p99_difference (of the RGB-mean difference, units of white):
    ``lodprt.display.error_figure.error_numbers``, which ``diff`` uses too."""
    lin_lod = renderer.image(lod, linear=True, per_vertex=per_vertex)
    lin_full = renderer.image(full, linear=True, per_vertex=per_vertex)
    return error_numbers(lin_lod, lin_full, white)


def error_against_full(renderer, store, frame, white: float, interpolation: str = DEFAULT_INTERPOLATION) -> dict:
    """``frame_error``'s numbers for a run-time ``frame`` against the full-resolution frame of ``store`` under the
    same camera and lights (``lodprt.runtime.frames.full_frame``) and the run time's ``interpolation``: the view
    cut's error, not the interpolations' difference."""
    full = full_frame(store, frame.camera, lights=frame.lights, colors=frame.light_colors, interpolation=interpolation)
    return frame_error(renderer, frame, full, white)[0]
