"""What ``lodprt diff`` and ``lodprt compare`` share: one error normalisation (``|a - b|`` averaged over RGB, over the
run time's fixed white) with its numbers, one colour scale rule, and one three-panel layout in which the panels are
placed pixel for pixel (no resampling) and fill the figure."""

from __future__ import annotations

import numpy as np

from lodprt.runtime.frame_error import clipped_mse

#: the colour map of the error panels: its zero (dark purple) differs from the black background, so the covered
#: region shows where the error is zero
ERROR_CMAP = "viridis"
#: the percentile of the covered error that maps to the top of the default colour scale (larger errors saturate)
SCALE_PERCENTILE = 99.0
ERROR_LABEL = "|difference| / white"

GAP = 4  # pixels between panels
TITLE = 34  # pixels for the figure title (two lines)
BAR = 12  # colour bar width
BAR_TEXT = 52  # colour bar ticks and label


def error_numbers(a, b, white: float) -> tuple[dict, np.ndarray, np.ndarray]:
    """The error of radiance ``a`` against ``b`` (same shape (..., 3), linear, the same units as ``white``):
    (numbers, rel, covered). rel = ``|a - b|`` averaged over RGB, over ``white`` (shape ``a.shape[:-1]``); covered:
    where either is non-zero (pixels either frame covers, vertices either bake lights). numbers, over the covered
    entries: psnr_db (both clipped at ``white``, in units of white), relative_rmse (unclipped, over the RMS of
    ``b``), mean_difference, max_difference and p99_difference (of rel)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    white = float(white)
    covered = (a.max(-1) > 0) | (b.max(-1) > 0)
    rel = np.abs(a - b).mean(-1) / white
    d = rel[covered]
    if not d.size:
        return ({"psnr_db": float("inf"), "relative_rmse": 0.0, "mean_difference": 0.0, "max_difference": 0.0,
                 "p99_difference": 0.0}, rel, covered)
    mse = clipped_mse(a, b, white)[0]
    rms_b = max(float(np.sqrt(np.mean(b[covered] ** 2))), 1e-30)
    numbers = {"psnr_db": float(10 * np.log10(1.0 / mse)) if mse > 0 else float("inf"),
               "relative_rmse": float(np.sqrt(np.mean((a - b)[covered] ** 2)) / rms_b),
               "mean_difference": float(d.mean()), "max_difference": float(d.max()),
               "p99_difference": float(np.percentile(d, SCALE_PERCENTILE))}
    return numbers, rel, covered


def check_scale(scale: float | None) -> None:
    """LodprtError naming ``--scale`` unless it is None or a positive number."""
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        from lodprt.errors import LodprtError

        raise LodprtError(f"--scale {scale}: must be a positive number")


def error_scale(numbers: dict, scale: float | None) -> tuple[float, str]:
    """(top of the colour scale, how it was chosen) for ``error_numbers``' numbers: ``scale`` when given, else the
    99th percentile of the covered error (the largest error when that is 0)."""
    check_scale(scale)
    if scale is not None:
        how = f"--scale {scale:g}"
        vmax = float(scale)
    else:
        vmax = numbers["p99_difference"] or numbers["max_difference"]
        how = f"{SCALE_PERCENTILE:g}th percentile"
        vmax = max(vmax, 1e-12)
    top = f"colour scale 0-{vmax:.3g} ({how}); max {numbers['max_difference']:.3g}"
    if numbers["max_difference"] > vmax:
        top += " saturates"
    return vmax, top


def false_colour(rel: np.ndarray, vmax: float, covered: np.ndarray | None = None) -> np.ndarray:
    """rel / vmax through ``ERROR_CMAP`` (clipped to [0, 1]) as RGB in [0, 1]; black where not ``covered``."""
    import matplotlib

    rgb = matplotlib.colormaps[ERROR_CMAP](np.clip(np.asarray(rel) / vmax, 0, 1))[..., :3]
    return rgb if covered is None else rgb * np.asarray(covered)[..., None]


def layout(width: int, height: int) -> dict:
    """The figure's pixel layout for three ``width`` x ``height`` panels: size (W, H), each panel's lower-left
    corner (x, y) in pixels from the figure's lower left, and the colour bar's rectangle (x, y, w, h)."""
    xs = [k * (width + GAP) for k in range(3)]
    bar_x = xs[2] + width + GAP
    size = (bar_x + BAR + BAR_TEXT, height + TITLE)
    # the bar 6 px in from the panels' top and bottom; on panels under 14 px, as tall as they are (at least 1 px)
    inset = 6 if height >= 14 else 0
    return {"size": size, "panels": [(x, 0) for x in xs], "bar": (bar_x, inset, BAR, max(height - 2 * inset, 1))}


def panel_figure(out, images, titles, vmax: float, suptitle: str) -> dict:
    """Write the three panels ``images`` ((H, W, 3) uint8 or floats in [0, 1], one size) side by side, pixel for
    pixel, each ``titles`` entry written inside its panel's top left corner, a colour bar 0..``vmax`` of
    ``ERROR_CMAP`` labelled ``ERROR_LABEL`` with ticks at the right of the third, ``suptitle`` (up to two lines)
    above. Returns ``layout``'s dict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h, w = np.asarray(images[0]).shape[:2]
    geo = layout(w, h)
    fw, fh = geo["size"]
    fig = plt.figure(figsize=(fw / 100, fh / 100), dpi=100)
    for img, title, (x, y) in zip(images, titles, geo["panels"]):
        img = np.asarray(img)
        if img.dtype != np.uint8:
            img = np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)
        fig.figimage(img[:, :, :3], xo=x, yo=y, origin="upper")
        fig.text((x + 4) / fw, (y + h - 4) / fh, title, color="white", fontsize=8, va="top", ha="left",
                 bbox={"facecolor": "black", "alpha": 0.55, "edgecolor": "none", "pad": 1.5})
    bx, by, bw, bh = geo["bar"]
    cax = fig.add_axes((bx / fw, by / fh, bw / fw, bh / fh))
    sm = matplotlib.cm.ScalarMappable(norm=matplotlib.colors.Normalize(0, vmax), cmap=ERROR_CMAP)
    bar = fig.colorbar(sm, cax=cax)
    bar.ax.tick_params(labelsize=7, length=3, pad=1)
    bar.set_label(ERROR_LABEL, fontsize=8, labelpad=2)
    fig.text(0.5, 1 - 3 / fh, suptitle, ha="center", va="top", fontsize=8.5, linespacing=1.25)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return geo
