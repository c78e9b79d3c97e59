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
                scale: float | None = None) -> dict:
    """Write a PNG with three panels (cut, full, |cut - full| in false colour with its scale); returns the numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lodprt.display.render import render, tone_map

    eye = np.asarray(eye, np.float64)
    positions = store.positions
    if target is None:
        target = 0.5 * (positions.min(0) + positions.max(0))
    cut = store.radiance(sample, eye).astype(np.float64)
    full = full_resolution_radiance(store, sample, eye, device)
    err = np.abs(cut - full).mean(1)
    peak = float(np.abs(full).max()) or 1.0
    rel = err / peak
    vmax = float(scale) if scale is not None else max(float(rel.max()), 1e-12)
    white = float(np.percentile(full[full > 0], 99)) if (full > 0).any() else 1.0
    cmap = plt.get_cmap("inferno")
    kept = len(store.sample(sample)[0])
    views = [
        (tone_map(cut, white), f"light cut ({kept:,} of {store.num_vertices:,} vertices), completed"),
        (tone_map(full, white), "full resolution"),
        (cmap(np.clip(rel / vmax, 0, 1))[:, :3], "|cut - full| / max radiance"),
    ]
    tri = store.faces
    fig, axes = plt.subplots(1, 3, figsize=(3 * size[0] / 100 + 1, size[1] / 100 + 0.8), dpi=100)
    for ax, (colours, title) in zip(axes, views):
        ax.imshow(render(positions, tri, colours, eye=eye, target=target, fov=fov, size=size))
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    sm = matplotlib.cm.ScalarMappable(norm=matplotlib.colors.Normalize(0, vmax), cmap=cmap)
    fig.colorbar(sm, ax=axes[2], fraction=0.046, pad=0.02).set_label("relative error", fontsize=8)
    rmse = float(np.sqrt(np.mean((cut - full) ** 2)) / max(np.sqrt(np.mean(full**2)), 1e-30))
    fig.suptitle(f"sample {sample}, threshold {store.attrs.get('threshold_deg')} deg: relative RMSE {rmse:.4f}, "
                 f"max {float(rel.max()):.4f}", fontsize=10)
    fig.savefig(out_png)
    plt.close(fig)
    return {"relative_rmse": rmse, "relative_max": float(rel.max()), "vertices_kept": kept}
