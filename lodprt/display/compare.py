"""Comparison figures like thesis figures 14-17: the view-cut (LOD) frame, the full-resolution frame of the same
lights and camera, and their per-pixel difference in false colour with its scale, side by side."""

from __future__ import annotations

import numpy as np

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
    the top of the colour scale (default the 99.5th percentile over the covered pixels; larger ones saturate). ``wireframe`` overlays the cut on the LOD panel.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = check_output(out, (".png", ".exr"), overwrite=overwrite)
    if out.suffix.lower() == ".exr":
        check_exr()
    source = frame_source(store, criterion=criterion, lod=True, interpolation=interpolation, outside=outside,
                          error_bound=error_bound, alpha=alpha, target_psnr=target_psnr)
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
    psnr, rmse = numbers["psnr_db"], numbers["relative_rmse"]
    diff = rel[covered]
    vmax = float(scale) if scale is not None else max(float(np.percentile(diff, 99.5)) if diff.size else 0.0, 1e-12)
    n_lod, n_full = int(len(lod.triangles)), int(len(full.triangles))
    cmap = plt.get_cmap("inferno")
    w, h = camera.width, camera.height
    fig, axes = plt.subplots(1, 3, figsize=(3 * w / 100 + 1, h / 100 + 0.9), dpi=100)
    panels = [
        (img_lod, f"view cut: {n_lod:,} triangles ({len(lod.positions):,} vertices)"),
        (img_full, f"full resolution: {n_full:,} triangles"),
        (cmap(np.clip(rel / vmax, 0, 1))[:, :, :3] * covered[:, :, None], "|cut - full| / white"),
    ]
    for ax, (img, title) in zip(axes, panels):
        ax.imshow(img)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    sm = matplotlib.cm.ScalarMappable(norm=matplotlib.colors.Normalize(0, vmax), cmap=cmap)
    fig.colorbar(sm, ax=axes[2], fraction=0.046, pad=0.02).set_label("difference / white", fontsize=8)
    if cut_criterion is None:  # a store without a hierarchy: no view cut, both panels are full resolution
        what = "no hierarchy (full resolution both)"
    else:
        what = cut_criterion.describe()
    fig.suptitle(f"{what}: PSNR {psnr:.1f} dB (clipped at white), relative "
                 f"RMSE {rmse:.4f}, mean |diff| {float(diff.mean()) if diff.size else 0.0:.4f} of white", fontsize=10)
    fig.savefig(out, bbox_inches="tight", pad_inches=0.1)
    plt.close(fig)
    return {"triangles_lod": n_lod, "triangles_full": n_full, **numbers, "white": float(white)}


def frame_error(renderer, lod, full, white: float, *, per_vertex: bool = False) -> tuple[dict, np.ndarray, np.ndarray]:
    """The image error of frame ``lod`` against frame ``full`` (same camera), both drawn linear by ``renderer``:
    (numbers, |lod - full| / white averaged over RGB (H, W), covered (H, W) bool). Pixels either frame covers
    count. numbers: psnr_db (both clipped at ``white``, in units of white), relative_rmse (unclipped, over the full
    frame's RMS), mean_difference and max_difference (of the RGB-mean difference, units of white)."""
    lin_lod = renderer.image(lod, linear=True, per_vertex=per_vertex).astype(np.float64)
    lin_full = renderer.image(full, linear=True, per_vertex=per_vertex).astype(np.float64)
    covered = (lin_lod.max(2) > 0) | (lin_full.max(2) > 0)
    rel = np.abs(lin_lod - lin_full).mean(2) / white
    diff = rel[covered]
    mse = float(np.mean((np.minimum(lin_lod, white) - np.minimum(lin_full, white))[covered] ** 2)) / white**2 if diff.size else 0.0
    psnr = float(10 * np.log10(1.0 / mse)) if mse > 0 else float("inf")
    rms_full = max(float(np.sqrt(np.mean(lin_full[covered] ** 2))) if diff.size else 0.0, 1e-30)
    rmse = float(np.sqrt(np.mean((lin_lod - lin_full)[covered] ** 2)) / rms_full) if diff.size else 0.0
    numbers = {"psnr_db": psnr, "relative_rmse": rmse, "mean_difference": float(diff.mean()) if diff.size else 0.0,
               "max_difference": float(rel.max()) if rel.size else 0.0}
    return numbers, rel, covered


def error_against_full(renderer, store, frame, white: float) -> dict:
    """``frame_error``'s numbers for a run-time ``frame`` against the full-resolution frame of ``store`` under the
    same camera and lights (``lodprt.runtime.frames.full_frame``)."""
    full = full_frame(store, frame.camera, lights=frame.lights, colors=frame.light_colors)
    return frame_error(renderer, frame, full, white)[0]
